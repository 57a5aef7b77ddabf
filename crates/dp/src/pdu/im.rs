//! I&M (identification and maintenance) records over DP-V1: I&M0..I&M4
//! through the "Call" service on index 255 (layouts in
//! `shared/reference/dpv1-c2-im-alarms.md` §4.6, where the ABB FPBA-01,
//! Balluff BTL7, ifm AC412S, AUMA and HEIDENHAIN manuals and the Hilscher
//! slave API agree).
//!
//! ```text
//! Write.req  5F slot FF len  08 00 FI_hi FI_lo [record]   select (and write)
//! Read.req   5E slot FF len                               then read
//! Read.res   5E slot FF len  08 00 FI_hi FI_lo record[64]
//! ```
//!
//! FI_Index 65000..=65004 (0xFDE8..=0xFDEC) select I&M0..I&M4. Each
//! record is 64 bytes: a 10-byte manufacturer header and 54 bytes of
//! fields. This is the PROFIBUS layout; PROFINET's I&M0 (60 bytes with a
//! 6-byte block header) is a different record and not handled here.

/// Index of the call service.
pub const CALL_INDEX: u8 = 255;
/// Extended_Function_Num of the call header ("Call").
pub const CALL_FUNCTION: u8 = 0x08;
/// Length of the call header.
pub const CALL_HEADER_LEN: usize = 4;
/// Length of every I&M record.
pub const RECORD_LEN: usize = 64;
/// FI_Index of I&M0.
pub const FI_INDEX_IM0: u16 = 65000;
/// Length of the manufacturer header at the start of every record.
pub const HEADER_LEN: usize = 10;

/// The call header `08 00 FI_Index`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CallHeader {
    /// FI_Index (IM_Index): 65000..=65199 are reserved for I&M.
    pub fi_index: u16,
}

/// An I&M data unit that cannot be decoded or encoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ImError {
    /// Fewer than 4 bytes of call header.
    #[error("I&M call header needs 4 bytes, got {0}")]
    ShortHeader(usize),
    /// The first byte is not the call function 0x08.
    #[error("I&M call header starts with 0x{0:02X}, not 0x08 (Call)")]
    NotCall(u8),
    /// An FI_Index outside I&M0..I&M4.
    #[error("FI_Index {0} is not I&M0..I&M4 (65000..65004)")]
    NotImIndex(u16),
    /// A record of the wrong length.
    #[error("I&M{number} record of {got} bytes, needs 64")]
    RecordLength {
        /// Record number.
        number: u8,
        /// Bytes present.
        got: usize,
    },
    /// A text too long for its field.
    #[error("{field} is {got} bytes long, at most {max} fit")]
    TooLong {
        /// Field name.
        field: &'static str,
        /// Bytes given.
        got: usize,
        /// Field length.
        max: usize,
    },
    /// A text with characters outside printable ASCII.
    #[error("{field} must be printable ASCII")]
    NotAscii {
        /// Field name.
        field: &'static str,
    },
}

impl CallHeader {
    /// The call header of I&M`number`.
    pub fn im(number: u8) -> CallHeader {
        CallHeader {
            fi_index: FI_INDEX_IM0 + u16::from(number),
        }
    }

    /// Decode the header at the start of `data`; returns it and the bytes
    /// after it. The reserved second byte is ignored.
    pub fn parse(data: &[u8]) -> Result<(CallHeader, &[u8]), ImError> {
        if data.len() < CALL_HEADER_LEN {
            return Err(ImError::ShortHeader(data.len()));
        }
        if data[0] != CALL_FUNCTION {
            return Err(ImError::NotCall(data[0]));
        }
        Ok((
            CallHeader {
                fi_index: u16::from_be_bytes([data[2], data[3]]),
            },
            &data[CALL_HEADER_LEN..],
        ))
    }

    /// The 4 header bytes.
    pub fn bytes(self) -> [u8; 4] {
        let i = self.fi_index.to_be_bytes();
        [CALL_FUNCTION, 0, i[0], i[1]]
    }

    /// 0..=4 for I&M0..I&M4.
    pub fn im_number(self) -> Option<u8> {
        self.fi_index
            .checked_sub(FI_INDEX_IM0)
            .filter(|n| *n <= 4)
            .map(|n| n as u8)
    }
}

/// SOFTWARE_REVISION: a letter (`V` official, `R` revision, `P`
/// prototype, `U` under test, `T` test) and three numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SoftwareRevision {
    /// The prefix letter as sent (ASCII).
    pub prefix: u8,
    /// Functional enhancement.
    pub major: u8,
    /// Bug fix.
    pub minor: u8,
    /// Internal change.
    pub internal: u8,
}

impl Default for SoftwareRevision {
    fn default() -> SoftwareRevision {
        SoftwareRevision {
            prefix: b'V',
            major: 1,
            minor: 0,
            internal: 0,
        }
    }
}

impl std::fmt::Display for SoftwareRevision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = if self.prefix.is_ascii_graphic() {
            self.prefix as char
        } else {
            '?'
        };
        write!(f, "{p}{}.{}.{}", self.major, self.minor, self.internal)
    }
}

impl SoftwareRevision {
    /// Parse "V1.2.3" (or "1.2.3", prefix V; "V1.2", internal 0).
    pub fn parse(s: &str) -> Option<SoftwareRevision> {
        let s = s.trim();
        let (prefix, rest) = match s.as_bytes().first()? {
            c @ (b'V' | b'R' | b'P' | b'U' | b'T') => (*c, &s[1..]),
            c if c.is_ascii_digit() => (b'V', s),
            _ => return None,
        };
        let mut parts = rest.split('.').map(|p| p.trim().parse::<u8>());
        let major = parts.next()?.ok()?;
        let minor = parts.next().unwrap_or(Ok(0)).ok()?;
        let internal = parts.next().unwrap_or(Ok(0)).ok()?;
        if parts.next().is_some() {
            return None;
        }
        Some(SoftwareRevision {
            prefix,
            major,
            minor,
            internal,
        })
    }
}

/// IM_SUPPORTED: which I&M records beyond I&M0 the device serves. This
/// crate reads it as the Hilscher slave API and the Siemens/ifm examples
/// do (bit 0 profile-specific I&M, bit n I&Mn); other manuals disagree,
/// so readers should show the raw value and probe I&M1..4 anyway.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ImSupported(pub u16);

impl ImSupported {
    /// I&M1..I&M`n` supported.
    pub fn up_to(n: u8) -> ImSupported {
        ImSupported((1..=n.min(15)).fold(0, |m, i| m | (1 << i)))
    }

    /// Whether I&M`n` (1..=15) is declared.
    pub fn has(self, n: u8) -> bool {
        n < 16 && self.0 & (1 << n) != 0
    }

    /// Bit 0: profile-specific I&M.
    pub fn profile_specific(self) -> bool {
        self.0 & 1 != 0
    }

    /// In words, e.g. "I&M1, I&M2, I&M3 (0x000E)".
    pub fn describe(self) -> String {
        let mut parts: Vec<String> = (1..16)
            .filter(|n| self.has(*n))
            .map(|n| format!("I&M{n}"))
            .collect();
        if self.profile_specific() {
            parts.push("profile-specific I&M".into());
        }
        if parts.is_empty() {
            parts.push("I&M0 only".into());
        }
        format!("{} (0x{:04X})", parts.join(", "), self.0)
    }
}

/// I&M0: the device's identity (read-only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Im0 {
    /// Manufacturer-specific header (often blanks).
    pub header: [u8; HEADER_LEN],
    /// MANUFACTURER_ID from the PI manufacturer table.
    pub manufacturer_id: u16,
    /// ORDER_ID, blank-padded visible string.
    pub order_id: [u8; 20],
    /// SERIAL_NUMBER, blank-padded visible string.
    pub serial_number: [u8; 16],
    /// HARDWARE_REVISION.
    pub hardware_revision: u16,
    /// SOFTWARE_REVISION.
    pub software_revision: SoftwareRevision,
    /// REVISION_COUNTER: counts parameter changes.
    pub revision_counter: u16,
    /// PROFILE_ID (0x3A00 PROFIdrive, 0xF600 generic device, 0 none).
    pub profile_id: u16,
    /// PROFILE_SPECIFIC_TYPE (3 I/O, 4 communication module, 5
    /// interface module).
    pub profile_specific_type: u16,
    /// IM_VERSION (major, minor), e.g. (1, 1).
    pub im_version: (u8, u8),
    /// IM_SUPPORTED.
    pub im_supported: ImSupported,
}

impl Default for Im0 {
    fn default() -> Im0 {
        Im0 {
            header: [b' '; HEADER_LEN],
            manufacturer_id: 0,
            order_id: [b' '; 20],
            serial_number: [b' '; 16],
            hardware_revision: 1,
            software_revision: SoftwareRevision::default(),
            revision_counter: 0,
            profile_id: 0xF600,
            profile_specific_type: 0,
            im_version: (1, 1),
            im_supported: ImSupported::up_to(4),
        }
    }
}

/// The text of a blank-padded visible-string field: trailing blanks and
/// NULs removed, other bytes outside printable ASCII as `?`.
pub fn text(field: &[u8]) -> String {
    let end = field
        .iter()
        .rposition(|b| *b != b' ' && *b != 0)
        .map_or(0, |i| i + 1);
    field[..end]
        .iter()
        .map(|&b| {
            if (0x20..0x7F).contains(&b) {
                b as char
            } else {
                '?'
            }
        })
        .collect()
}

/// A blank-padded field of `N` bytes from `s`; too long or not printable
/// ASCII is an error naming `field`.
pub fn padded<const N: usize>(field: &'static str, s: &str) -> Result<[u8; N], ImError> {
    if !s.bytes().all(|b| (0x20..0x7F).contains(&b)) {
        return Err(ImError::NotAscii { field });
    }
    if s.len() > N {
        return Err(ImError::TooLong {
            field,
            got: s.len(),
            max: N,
        });
    }
    let mut out = [b' '; N];
    out[..s.len()].copy_from_slice(s.as_bytes());
    Ok(out)
}

fn be(b: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([b[at], b[at + 1]])
}

impl Im0 {
    /// Decode the 64 record bytes.
    pub fn parse(b: &[u8]) -> Result<Im0, ImError> {
        if b.len() != RECORD_LEN {
            return Err(ImError::RecordLength {
                number: 0,
                got: b.len(),
            });
        }
        let mut im = Im0::default();
        im.header.copy_from_slice(&b[0..10]);
        im.manufacturer_id = be(b, 10);
        im.order_id.copy_from_slice(&b[12..32]);
        im.serial_number.copy_from_slice(&b[32..48]);
        im.hardware_revision = be(b, 48);
        im.software_revision = SoftwareRevision {
            prefix: b[50],
            major: b[51],
            minor: b[52],
            internal: b[53],
        };
        im.revision_counter = be(b, 54);
        im.profile_id = be(b, 56);
        im.profile_specific_type = be(b, 58);
        im.im_version = (b[60], b[61]);
        im.im_supported = ImSupported(be(b, 62));
        Ok(im)
    }

    /// The 64 record bytes.
    pub fn bytes(&self) -> [u8; RECORD_LEN] {
        let mut b = [0u8; RECORD_LEN];
        b[0..10].copy_from_slice(&self.header);
        b[10..12].copy_from_slice(&self.manufacturer_id.to_be_bytes());
        b[12..32].copy_from_slice(&self.order_id);
        b[32..48].copy_from_slice(&self.serial_number);
        b[48..50].copy_from_slice(&self.hardware_revision.to_be_bytes());
        let s = self.software_revision;
        b[50..54].copy_from_slice(&[s.prefix, s.major, s.minor, s.internal]);
        b[54..56].copy_from_slice(&self.revision_counter.to_be_bytes());
        b[56..58].copy_from_slice(&self.profile_id.to_be_bytes());
        b[58..60].copy_from_slice(&self.profile_specific_type.to_be_bytes());
        b[60] = self.im_version.0;
        b[61] = self.im_version.1;
        b[62..64].copy_from_slice(&self.im_supported.0.to_be_bytes());
        b
    }

    /// ORDER_ID as text.
    pub fn order_id(&self) -> String {
        text(&self.order_id)
    }

    /// SERIAL_NUMBER as text.
    pub fn serial_number(&self) -> String {
        text(&self.serial_number)
    }
}

/// I&M1..I&M4: the writable maintenance records, kept as their 64 bytes
/// (10-byte header and 54 bytes of fields).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImRecord {
    /// 1..=4.
    pub number: u8,
    /// The whole record.
    pub bytes: [u8; RECORD_LEN],
}

impl ImRecord {
    /// The default content: blanks for I&M1..3, zeros for I&M4 (its
    /// signature), header blanks.
    pub fn empty(number: u8) -> ImRecord {
        let fill = if number == 4 { 0 } else { b' ' };
        let mut bytes = [fill; RECORD_LEN];
        bytes[..HEADER_LEN].fill(b' ');
        ImRecord { number, bytes }
    }

    /// From 64 bytes.
    pub fn parse(number: u8, b: &[u8]) -> Result<ImRecord, ImError> {
        if b.len() != RECORD_LEN {
            return Err(ImError::RecordLength {
                number,
                got: b.len(),
            });
        }
        let mut bytes = [0; RECORD_LEN];
        bytes.copy_from_slice(b);
        Ok(ImRecord { number, bytes })
    }

    /// I&M1 with TAG_FUNCTION (32) and TAG_LOCATION (22).
    pub fn im1(tag_function: &str, tag_location: &str) -> Result<ImRecord, ImError> {
        let mut r = ImRecord::empty(1);
        r.bytes[10..42].copy_from_slice(&padded::<32>("TAG_FUNCTION", tag_function)?);
        r.bytes[42..64].copy_from_slice(&padded::<22>("TAG_LOCATION", tag_location)?);
        Ok(r)
    }

    /// I&M2 with INSTALLATION_DATE ("YYYY-MM-DD hh:mm", 16).
    pub fn im2(installation_date: &str) -> Result<ImRecord, ImError> {
        let mut r = ImRecord::empty(2);
        r.bytes[10..26].copy_from_slice(&padded::<16>("INSTALLATION_DATE", installation_date)?);
        Ok(r)
    }

    /// I&M3 with DESCRIPTOR (54).
    pub fn im3(descriptor: &str) -> Result<ImRecord, ImError> {
        let mut r = ImRecord::empty(3);
        r.bytes[10..64].copy_from_slice(&padded::<54>("DESCRIPTOR", descriptor)?);
        Ok(r)
    }

    /// The record's text fields as (standard name, text).
    pub fn fields(&self) -> Vec<(&'static str, String)> {
        let b = &self.bytes;
        match self.number {
            1 => vec![
                ("TAG_FUNCTION", text(&b[10..42])),
                ("TAG_LOCATION", text(&b[42..64])),
            ],
            2 => vec![("INSTALLATION_DATE", text(&b[10..26]))],
            3 => vec![("DESCRIPTOR", text(&b[10..64]))],
            _ => vec![(
                "SIGNATURE",
                b[10..64].iter().map(|x| format!("{x:02X}")).collect(),
            )],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn call_header_of_the_reference_sequence() {
        // "read I&M0: Write.req 5F 00 FF 04 08 00 FD E8" (§4.6).
        let (h, rest) = CallHeader::parse(&[0x08, 0x00, 0xFD, 0xE8]).unwrap();
        assert_eq!(h.fi_index, 65000);
        assert_eq!(h.im_number(), Some(0));
        assert!(rest.is_empty());
        assert_eq!(CallHeader::im(1).bytes(), [0x08, 0x00, 0xFD, 0xE9]);
        assert_eq!(CallHeader::im(4).bytes(), [0x08, 0x00, 0xFD, 0xEC]);
        assert_eq!(CallHeader { fi_index: 65005 }.im_number(), None);
        assert_eq!(
            CallHeader::parse(&[0x09, 0, 0xFD, 0xE8]),
            Err(ImError::NotCall(9))
        );
        assert_eq!(CallHeader::parse(&[8, 0]), Err(ImError::ShortHeader(2)));
    }

    #[test]
    fn im0_fields_at_their_offsets() {
        let mut raw = [b' '; 64];
        raw[10..12].copy_from_slice(&[0x00, 0x1A]); // ABB
        raw[12..20].copy_from_slice(b"FPBA-01 ");
        raw[32..36].copy_from_slice(b"1234");
        raw[48..50].copy_from_slice(&[0x00, 0x02]);
        raw[50..54].copy_from_slice(&[b'V', 3, 0, 8]);
        raw[54..56].copy_from_slice(&[0, 5]);
        raw[56..58].copy_from_slice(&[0x3A, 0x00]);
        raw[58..60].copy_from_slice(&[0x00, 0x04]);
        raw[60..62].copy_from_slice(&[0x01, 0x01]);
        raw[62..64].copy_from_slice(&[0x00, 0x0E]);
        let im = Im0::parse(&raw).unwrap();
        assert_eq!(im.manufacturer_id, 0x1A);
        assert_eq!(im.order_id(), "FPBA-01");
        assert_eq!(im.serial_number(), "1234");
        assert_eq!(im.hardware_revision, 2);
        assert_eq!(im.software_revision.to_string(), "V3.0.8");
        assert_eq!(im.revision_counter, 5);
        assert_eq!(im.profile_id, 0x3A00);
        assert_eq!(im.im_version, (1, 1));
        assert_eq!(im.im_supported.describe(), "I&M1, I&M2, I&M3 (0x000E)");
        assert_eq!(im.bytes(), raw);
        assert!(Im0::parse(&raw[..60]).is_err());
    }

    #[test]
    fn maintenance_records() {
        let r = ImRecord::im1("pump 3", "hall B").unwrap();
        assert_eq!(&r.bytes[10..16], b"pump 3");
        assert_eq!(r.bytes[41], b' ');
        assert_eq!(&r.bytes[42..48], b"hall B");
        assert_eq!(
            r.fields(),
            vec![
                ("TAG_FUNCTION", "pump 3".to_string()),
                ("TAG_LOCATION", "hall B".to_string())
            ]
        );
        assert_eq!(
            ImRecord::im1("x", &"y".repeat(23)),
            Err(ImError::TooLong {
                field: "TAG_LOCATION",
                got: 23,
                max: 22
            })
        );
        assert_eq!(ImRecord::empty(4).bytes[63], 0);
        assert_eq!(ImRecord::empty(3).bytes[63], b' ');
        assert_eq!(
            SoftwareRevision::parse("V1.2.3"),
            Some(SoftwareRevision {
                prefix: b'V',
                major: 1,
                minor: 2,
                internal: 3
            })
        );
        assert_eq!(
            SoftwareRevision::parse("2.1").unwrap().to_string(),
            "V2.1.0"
        );
        assert_eq!(SoftwareRevision::parse("x"), None);
        assert_eq!(ImSupported::up_to(4).0, 0x001E);
    }
}
