//! `dpctl im`: a slave's I&M0..I&M4 (identification and maintenance) in
//! words, over class 1 (the bus file's master, MSAC_C1, the path of
//! `dpctl dpv1`) or class 2 (`--class2`, a connection of a master of its
//! own). `--write-tag FUNCTION LOCATION` writes I&M1 first.
//!
//! Each record is selected by writing its call header (`08 00 FI_Index`)
//! to index 255 of slot 0 and then read (`profibus_dp::master::records::
//! ImReader`). IM_SUPPORTED is decoded as the Hilscher slave API reads it
//! (bit n: I&Mn) with its raw value shown, and I&M1..4 are probed
//! whatever it says, because manuals disagree on its bits.
//!
//! Exit 0 when I&M0 was read (and I&M1 written, if asked), else 1 with
//! the reason in words.

use crate::dpv1::Link;
use crate::out::outln;
use anyhow::{bail, Result};
use profibus_dp::master::records::{ImRead, ImReader};
use profibus_dp::pdu::im::{text, Im0, ImRecord};
use serde_json::{json, Map, Value};
use std::fmt::Write as _;

/// Read a slave's I&M records (and write I&M1).
#[derive(clap::Args)]
pub struct Args {
    /// The line, the slave, and which class of master asks.
    #[command(flatten)]
    link: Link,
    /// Write I&M1 first: TAG_FUNCTION (up to 32 characters) and
    /// TAG_LOCATION (up to 22), printable ASCII, blank-padded.
    #[arg(long, num_args = 2, value_names = ["FUNCTION", "LOCATION"])]
    write_tag: Option<Vec<String>>,
}

pub fn run(args: Args) -> Result<()> {
    let write = match args.write_tag.as_deref() {
        Some([function, location]) => Some(
            ImRecord::im1(function, location).map_err(|e| anyhow::anyhow!("--write-tag: {e}"))?,
        ),
        _ => None,
    };
    let link = &args.link;
    if let (Some(path), true) = (&link.via, link.class2) {
        return Err(crate::via::no_class2(path));
    }
    let (reader, via, failed) = if link.class2 {
        match link.run_class2(ImReader::new(0, write))? {
            Ok((r, opened)) => {
                let via = match opened {
                    Some(o) => format!("class 2, SAP {}", o.sap),
                    None => "class 2".into(),
                };
                (r, via, None)
            }
            Err((e, r)) => (r, "class 2".into(), Some(e.to_string())),
        }
    } else {
        (
            link.run_class1(ImReader::new(0, write))?,
            "class 1".into(),
            None,
        )
    };
    let report = Report {
        slave: link.slave,
        class: if link.class2 { 2 } else { 1 },
        via,
        reader: &reader,
        failed: failed.as_deref(),
    };
    if link.json {
        outln!("{}", crate::common::json_line(&report.json()))?;
    } else {
        crate::out::out!("{}", report.text())?;
    }
    if let Some(e) = failed {
        bail!("{e}");
    }
    match (&reader.records[0], &reader.written) {
        (_, Some(Err(e))) => bail!(
            "slave {}: writing I&M1 failed: {}",
            link.slave,
            e.describe()
        ),
        (Some(ImRead::Record(_)), _) => Ok(()),
        (Some(ImRead::Refused(e)), _) => {
            bail!("slave {} does not serve I&M0: {}", link.slave, e.describe())
        }
        (Some(ImRead::Invalid(why)), _) => {
            bail!("slave {}: I&M0 is not valid: {why}", link.slave)
        }
        (None, _) => bail!("slave {}: I&M0 was not read", link.slave),
    }
}

/// What was read, for printing.
struct Report<'a> {
    slave: u8,
    class: u8,
    via: String,
    reader: &'a ImReader,
    failed: Option<&'a str>,
}

/// PROFILE_ID in words (the ids the reference names).
fn profile_words(id: u16) -> &'static str {
    match id {
        0x0000 => "no profile",
        0x3A00 => "PROFIdrive",
        0xF600 => "generic device",
        _ => "profile",
    }
}

/// PROFILE_SPECIFIC_TYPE with its words where the reference has them.
fn type_words(t: u16) -> String {
    match t {
        3 => "type 3 (I/O)".into(),
        4 => "type 4 (communication module)".into(),
        5 => "type 5 (interface module)".into(),
        t => format!("type {t}"),
    }
}

/// A text field, "(blank)" when empty.
fn or_blank(s: String) -> String {
    if s.is_empty() {
        "(blank)".into()
    } else {
        s
    }
}

/// The fields of I&M1..4 as (snake_case name, value).
fn record_fields(n: usize, bytes: &[u8; 64]) -> Vec<(&'static str, String)> {
    match n {
        1 => vec![
            ("tag_function", text(&bytes[10..42])),
            ("tag_location", text(&bytes[42..64])),
        ],
        2 => vec![("installation_date", text(&bytes[10..26]))],
        3 => vec![("descriptor", text(&bytes[10..64]))],
        _ => vec![(
            "signature",
            profibus_fdl::wire::Hex(&bytes[10..64]).to_string(),
        )],
    }
}

/// I&M0 as `dpctl im --json` (and `dpctl scan --json`) writes it.
pub(crate) fn im0_json(im: &Im0) -> Value {
    let sup = im.im_supported;
    json!({
        "manufacturer_id": im.manufacturer_id,
        "order_id": im.order_id(),
        "serial_number": im.serial_number(),
        "hardware_revision": im.hardware_revision,
        "software_revision": im.software_revision.to_string(),
        "revision_counter": im.revision_counter,
        "profile_id": im.profile_id,
        "profile_specific_type": im.profile_specific_type,
        "im_version": format!("{}.{}", im.im_version.0, im.im_version.1),
        "im_supported": {
            "raw": format!("0x{:04X}", sup.0),
            "records": (1..16).filter(|n| sup.has(*n)).collect::<Vec<u8>>(),
            "profile_specific": sup.profile_specific(),
        },
    })
}

impl Report<'_> {
    fn json(&self) -> Value {
        let mut o = Map::new();
        o.insert("slave".into(), self.slave.into());
        o.insert("class".into(), self.class.into());
        if let Some(w) = &self.reader.written {
            o.insert(
                "write_tag".into(),
                match w {
                    Ok(()) => json!({"ok": true}),
                    Err(e) => json!({"ok": false, "error": e.describe()}),
                },
            );
        }
        for (n, r) in self.reader.records.iter().enumerate() {
            let v = match r {
                None => continue,
                Some(ImRead::Refused(e)) => json!({"error": e.describe()}),
                Some(ImRead::Invalid(why)) => json!({"error": why}),
                Some(ImRead::Record(b)) if n == 0 => match Im0::parse(b) {
                    Ok(im) => im0_json(&im),
                    Err(e) => json!({"error": e.to_string()}),
                },
                Some(ImRead::Record(b)) => Value::Object(
                    record_fields(n, b)
                        .into_iter()
                        .map(|(k, v)| (k.to_string(), Value::String(v)))
                        .collect(),
                ),
            };
            o.insert(format!("im{n}"), v);
        }
        if let Some(e) = self.failed {
            o.insert("error".into(), e.into());
        }
        Value::Object(o)
    }

    fn text(&self) -> String {
        let mut s = String::new();
        let slave = self.slave;
        if let Some(w) = &self.reader.written {
            let _ = match w {
                Ok(()) => writeln!(s, "slave {slave} I&M1 written"),
                Err(e) => writeln!(s, "slave {slave} I&M1 not written: {}", e.describe()),
            };
        }
        for (n, r) in self.reader.records.iter().enumerate() {
            let _ = match r {
                None => continue,
                Some(ImRead::Refused(e)) => {
                    writeln!(s, "slave {slave} I&M{n}: not served: {}", e.describe())
                }
                Some(ImRead::Invalid(why)) => writeln!(s, "slave {slave} I&M{n}: invalid: {why}"),
                Some(ImRead::Record(b)) if n == 0 => match Im0::parse(b) {
                    Ok(im) => writeln!(s, "slave {slave} I&M0 ({}):\n{}", self.via, im0_text(&im)),
                    Err(e) => writeln!(s, "slave {slave} I&M0: invalid: {e}"),
                },
                Some(ImRead::Record(b)) if n == 4 && b[10..].iter().all(|x| *x == 0) => {
                    writeln!(s, "slave {slave} I&M4: signature none (zeros)")
                }
                Some(ImRead::Record(b)) => {
                    let fields: Vec<String> = record_fields(n, b)
                        .into_iter()
                        .map(|(k, v)| match k {
                            "signature" => format!("signature {v}"),
                            k => format!("{} \"{v}\"", k.replace('_', " ")),
                        })
                        .collect();
                    writeln!(s, "slave {slave} I&M{n}: {}", fields.join(", "))
                }
            };
        }
        s
    }
}

fn im0_text(im: &Im0) -> String {
    let rows = [
        (
            "manufacturer",
            format!("0x{:04X} ({})", im.manufacturer_id, im.manufacturer_id),
        ),
        ("order number", or_blank(im.order_id())),
        ("serial number", or_blank(im.serial_number())),
        ("hardware revision", im.hardware_revision.to_string()),
        ("software revision", im.software_revision.to_string()),
        ("revision counter", im.revision_counter.to_string()),
        (
            "profile",
            format!(
                "0x{:04X} ({}), {}",
                im.profile_id,
                profile_words(im.profile_id),
                type_words(im.profile_specific_type)
            ),
        ),
        (
            "I&M version",
            format!("{}.{}", im.im_version.0, im.im_version.1),
        ),
        ("I&M supported", im.im_supported.describe()),
    ];
    rows.iter()
        .map(|(k, v)| format!("  {k:<18} {v}"))
        .collect::<Vec<_>>()
        .join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_dp::class2::{RecordAnswer, RecordOp, RecordOps};
    use profibus_dp::pdu::im::{ImSupported, SoftwareRevision};

    #[test]
    fn im_records_in_words_and_json() {
        let mut im = Im0 {
            manufacturer_id: 0x001A,
            hardware_revision: 2,
            software_revision: SoftwareRevision::parse("V1.2.3").unwrap(),
            profile_specific_type: 3,
            im_supported: ImSupported(0x000E),
            ..Im0::default()
        };
        im.order_id[..7].copy_from_slice(b"FPBA-01");
        let mut r = ImReader::new(0, Some(ImRecord::im1("pump 3", "hall B").unwrap()));
        let mut selected = 0u8;
        while let Some(op) = r.next_op() {
            let a = match &op {
                RecordOp::Write { data, .. } => {
                    selected = data[3] - 0xE8;
                    if selected == 4 {
                        RecordAnswer::Negative(profibus_dp::pdu::dpv1::Dpv1Error::dpv1(
                            0x5F, 0xB, 0,
                        ))
                    } else {
                        RecordAnswer::Written(data.len() as u8)
                    }
                }
                _ => {
                    let mut d = vec![0x08, 0x00, 0xFD, 0xE8 + selected];
                    d.extend(match selected {
                        0 => im.bytes(),
                        1 => ImRecord::im1("pump 3", "hall B").unwrap().bytes,
                        n => ImRecord::empty(n).bytes,
                    });
                    RecordAnswer::Read(d)
                }
            };
            r.answered(&op, &a);
        }
        let report = Report {
            slave: 8,
            class: 2,
            via: "class 2, SAP 48".into(),
            reader: &r,
            failed: None,
        };
        let text = report.text();
        assert!(text.starts_with("slave 8 I&M1 written\nslave 8 I&M0 (class 2, SAP 48):\n"));
        assert!(
            text.contains("  manufacturer       0x001A (26)\n"),
            "{text}"
        );
        assert!(text.contains("  order number       FPBA-01\n"), "{text}");
        assert!(text.contains("  software revision  V1.2.3\n"), "{text}");
        assert!(
            text.contains("  profile            0xF600 (generic device), type 3 (I/O)\n"),
            "{text}"
        );
        assert!(
            text.contains("  I&M supported      I&M1, I&M2, I&M3 (0x000E)\n"),
            "{text}"
        );
        assert!(
            text.contains("slave 8 I&M1: tag function \"pump 3\", tag location \"hall B\"\n"),
            "{text}"
        );
        assert!(
            text.contains("slave 8 I&M4: not served: write failed: access: invalid index"),
            "{text}"
        );
        let j = report.json();
        assert_eq!(j["im0"]["manufacturer_id"], 26);
        assert_eq!(j["im0"]["order_id"], "FPBA-01");
        assert_eq!(j["im0"]["software_revision"], "V1.2.3");
        assert_eq!(j["im0"]["im_version"], "1.1");
        assert_eq!(j["im0"]["im_supported"]["raw"], "0x000E");
        assert_eq!(j["im0"]["im_supported"]["records"], json!([1, 2, 3]));
        assert_eq!(j["im1"]["tag_function"], "pump 3");
        assert_eq!(j["im1"]["tag_location"], "hall B");
        assert_eq!(j["im2"]["installation_date"], "");
        assert!(j["im4"]["error"]
            .as_str()
            .unwrap()
            .contains("invalid index"));
        assert_eq!(j["write_tag"]["ok"], true);
    }
}
