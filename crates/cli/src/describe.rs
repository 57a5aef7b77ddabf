//! Human-readable and JSON descriptions of telegrams, shared by `decode`
//! and `sniff`.

use profibus_dp::sap;
use profibus_fdl::wire::{Format, FunctionCode, Telegram};
use serde_json::{json, Value};

/// Bytes as space-separated upper-case hex (`01 0A FF`).
pub fn hex(bytes: &[u8]) -> String {
    profibus_fdl::wire::Hex(bytes).to_string()
}

/// `named`: the SAP is the slave's side of the service (DSAP of a request,
/// SSAP of a response), so it names the DP service.
fn sap_text(label: &str, s: u8, named: bool) -> String {
    if s & 0x40 != 0 {
        return format!("{label}=segment {}", s & 0x3F);
    }
    match sap::name(s & 0x3F).filter(|_| named) {
        Some(n) => format!("{label}={} ({n})", s & 0x3F),
        None => format!("{label}={}", s & 0x3F),
    }
}

/// One line describing a valid telegram.
pub fn line(t: &Telegram<'_>) -> String {
    let fmt = t.format().name();
    match t {
        Telegram::ShortAck => format!("{fmt} short acknowledge"),
        Telegram::Token { da, sa } => format!("{fmt} token {sa}→{da}"),
        Telegram::Data(d) => {
            let mut s = format!("{fmt} {}→{} {}", d.sa, addr(d.da), d.fc);
            if let Some(x) = d.dsap {
                s.push(' ');
                s.push_str(&sap_text("DSAP", x, d.fc.is_request()));
            }
            if let Some(x) = d.ssap {
                s.push(' ');
                s.push_str(&sap_text("SSAP", x, !d.fc.is_request()));
            } else if d.dsap.is_none() && d.fc.is_request() && !d.data.is_empty() {
                s.push_str(" (default SAP)");
            }
            if !d.data.is_empty() {
                s.push_str(&format!(" DU[{}]={}", d.data.len(), hex(d.data)));
            }
            s.push_str(" FCS ok");
            s
        }
    }
}

fn addr(a: u8) -> String {
    if a == 127 {
        "127(broadcast)".into()
    } else {
        a.to_string()
    }
}

/// A JSON object describing a valid telegram.
pub fn json(t: &Telegram<'_>, raw: &[u8]) -> Value {
    let fmt = t.format().name();
    match t {
        Telegram::ShortAck => json!({"format": fmt, "type": "short_ack", "raw": hex(raw)}),
        Telegram::Token { da, sa } => {
            json!({"format": fmt, "type": "token", "da": da, "sa": sa, "raw": hex(raw)})
        }
        Telegram::Data(d) => {
            let mut v = json!({
                "format": Format::from_start_delimiter(raw[0]).map(|f| f.name()).unwrap_or(fmt),
                "da": d.da,
                "sa": d.sa,
                "fc": d.fc.to_byte(),
                "data": hex(d.data),
                "data_len": d.data.len(),
                "fcs_ok": true,
                "raw": hex(raw),
            });
            let o = v.as_object_mut().expect("object");
            match d.fc {
                FunctionCode::Request { kind, fcb, fcv } => {
                    o.insert("type".into(), "request".into());
                    o.insert("service".into(), kind.mnemonic().into());
                    o.insert("function".into(), kind.code().into());
                    o.insert("fcb".into(), fcb.into());
                    o.insert("fcv".into(), fcv.into());
                }
                FunctionCode::Response { status, station } => {
                    o.insert("type".into(), "response".into());
                    o.insert("status".into(), status.mnemonic().into());
                    o.insert("status_code".into(), status.code().into());
                    o.insert("station_type".into(), station.describe().into());
                }
            }
            let req = d.fc.is_request();
            for (k, s, named) in [("dsap", d.dsap, req), ("ssap", d.ssap, !req)] {
                if let Some(s) = s {
                    o.insert(k.into(), (s & 0x3F).into());
                    if let Some(n) = sap::name(s & 0x3F).filter(|_| named) {
                        o.insert("service_sap".into(), n.into());
                    }
                    if s & 0x40 != 0 {
                        o.insert(format!("{k}_segment"), true.into());
                    }
                }
            }
            v
        }
    }
}
