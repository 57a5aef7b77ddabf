//! DP-V1 alarm and status blocks: the device-related blocks of a DP-V1
//! slave's extended diagnosis, and what enables them in Set_Prm
//! (IEC 61158-6-3; layouts in `shared/reference/dpv1-c2-im-alarms.md`
//! §4.5, where the PROFIBUS web book, the Beckhoff EL6731 and Siemens
//! CP 5613 manuals and the ifm AC412S manual agree).
//!
//! ```text
//! byte 0  header: b7-6 = 00, b5-0 = block length incl. header (4..=63)
//! byte 1  Alarm_Type (b7 = 0) or Status_Type (b7 = 1)
//! byte 2  Slot_Number (0..=254)
//! byte 3  Alarm_Specifier: b7-3 Seq_Nr, b2 Add_Ack, b1-0 appears/
//!         disappears; a status block's specifier has only b1-0
//! byte 4… Diagnostic_User_Data (at most 59 bytes)
//! ```
//!
//! The master acknowledges each alarm with Alarm_Ack (DSAP 50, SSAP 51,
//! `5C slot type specifier`, see [`crate::pdu::dpv1`]); status blocks need
//! no acknowledgement. Alarm_Mode (DPV1_Status_3 b2-0) limits the alarms
//! outstanding at once ([`AlarmMode::limit`]).

use crate::pdu::diag::{ext_blocks, ExtDiagBlock};
use crate::pdu::prm::Dpv1Status2;

/// Longest Diagnostic_User_Data of one block (63 − 4 header bytes).
pub const MAX_ALARM_DATA_LEN: usize = 59;
/// Highest sequence number (5 bits).
pub const MAX_SEQ: u8 = 31;

profibus_fdl::enum_with_unknown! {
    /// Alarm_Type (byte 1 of an alarm block, b7 = 0). 32..=126 are
    /// manufacturer-specific, the rest reserved ([`AlarmType::word`]).
    pub enum AlarmType(u8) {
        /// 1: diagnostic alarm.
        Diagnostic = 1 => "diagnostic",
        /// 2: process alarm.
        Process = 2 => "process",
        /// 3: pull alarm (a module was removed).
        Pull = 3 => "pull",
        /// 4: plug alarm (a module was inserted).
        Plug = 4 => "plug",
        /// 5: status alarm.
        Status = 5 => "status",
        /// 6: update alarm.
        Update = 6 => "update",
    }
}

impl AlarmType {
    /// Manufacturer-specific (32..=126).
    pub fn is_manufacturer(self) -> bool {
        matches!(self.code(), 32..=126)
    }

    /// One word for JSON and tables: the listed name, "manufacturer" or
    /// "reserved".
    pub fn word(self) -> &'static str {
        match self.name() {
            Some(n) => n,
            None if self.is_manufacturer() => "manufacturer",
            None => "reserved",
        }
    }

    /// The Set_Prm enable this alarm type needs (DPV1_Status_2), `None`
    /// for reserved types.
    pub fn enable(self) -> Option<AlarmEnable> {
        Some(match self {
            AlarmType::Diagnostic => AlarmEnable::Diagnostic,
            AlarmType::Process => AlarmEnable::Process,
            AlarmType::Pull | AlarmType::Plug => AlarmEnable::PullPlug,
            AlarmType::Status => AlarmEnable::Status,
            AlarmType::Update => AlarmEnable::Update,
            t if t.is_manufacturer() => AlarmEnable::Manufacturer,
            AlarmType::Unknown(_) => return None,
        })
    }

    /// Parse a word as [`AlarmType::word`] prints it, or a number.
    pub fn from_word(s: &str) -> Option<AlarmType> {
        let t = match s {
            "diagnostic" => AlarmType::Diagnostic,
            "process" => AlarmType::Process,
            "pull" => AlarmType::Pull,
            "plug" => AlarmType::Plug,
            "status" => AlarmType::Status,
            "update" => AlarmType::Update,
            "manufacturer" => AlarmType::from_code(32),
            n => {
                let n: u8 = n.parse().ok()?;
                if n == 0 || n > 126 {
                    return None;
                }
                AlarmType::from_code(n)
            }
        };
        Some(t)
    }
}

/// The alarm enables of Set_Prm (DPV1_Status_2), one per bus-file name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AlarmEnable {
    /// Enable_Diagnostic_Alarm (0x20).
    Diagnostic,
    /// Enable_Process_Alarm (0x40).
    Process,
    /// Enable_Pull_Plug_Alarm (0x80).
    PullPlug,
    /// Enable_Status_Alarm (0x08).
    Status,
    /// Enable_Update_Alarm (0x04).
    Update,
    /// Enable_Manufacturer_Specific_Alarm (0x10).
    Manufacturer,
}

impl AlarmEnable {
    /// Every enable, in the order of the bus file's documentation.
    pub const ALL: [AlarmEnable; 6] = [
        AlarmEnable::Diagnostic,
        AlarmEnable::Process,
        AlarmEnable::PullPlug,
        AlarmEnable::Status,
        AlarmEnable::Update,
        AlarmEnable::Manufacturer,
    ];

    /// The bus-file name (`alarms = ["diagnostic", …]`).
    pub fn name(self) -> &'static str {
        match self {
            AlarmEnable::Diagnostic => "diagnostic",
            AlarmEnable::Process => "process",
            AlarmEnable::PullPlug => "pull_plug",
            AlarmEnable::Status => "status",
            AlarmEnable::Update => "update",
            AlarmEnable::Manufacturer => "manufacturer",
        }
    }

    /// From a bus-file name.
    pub fn from_name(s: &str) -> Option<AlarmEnable> {
        AlarmEnable::ALL.into_iter().find(|e| e.name() == s)
    }

    /// Its bit in DPV1_Status_2.
    pub fn bit(self) -> Dpv1Status2 {
        match self {
            AlarmEnable::Diagnostic => Dpv1Status2::DIAGNOSTIC_ALARM,
            AlarmEnable::Process => Dpv1Status2::PROCESS_ALARM,
            AlarmEnable::PullPlug => Dpv1Status2::PULL_PLUG_ALARM,
            AlarmEnable::Status => Dpv1Status2::STATUS_ALARM,
            AlarmEnable::Update => Dpv1Status2::UPDATE_ALARM,
            AlarmEnable::Manufacturer => Dpv1Status2::MANUFACTURER_ALARM,
        }
    }

    /// The GSD keyword that declares it.
    pub fn gsd_keyword(self) -> &'static str {
        match self {
            AlarmEnable::Diagnostic => "Diagnostic_Alarm_supp",
            AlarmEnable::Process => "Process_Alarm_supp",
            AlarmEnable::PullPlug => "Pull_Plug_Alarm_supp",
            AlarmEnable::Status => "Status_Alarm_supp",
            AlarmEnable::Update => "Update_Alarm_supp",
            AlarmEnable::Manufacturer => "Manufacturer_Specific_Alarm_supp",
        }
    }
}

/// Appears/disappears (Alarm_Specifier b1-0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AlarmChange {
    /// 0: no further distinction.
    None,
    /// 1: the event appears, the slot is disturbed.
    Appears,
    /// 2: the event disappears, the slot is OK.
    Disappears,
    /// 3: the event disappears, the slot is still disturbed.
    DisappearsStillFaulty,
}

impl AlarmChange {
    /// From b1-0.
    pub fn from_bits(b: u8) -> AlarmChange {
        match b & 3 {
            1 => AlarmChange::Appears,
            2 => AlarmChange::Disappears,
            3 => AlarmChange::DisappearsStillFaulty,
            _ => AlarmChange::None,
        }
    }

    /// b1-0.
    pub fn bits(self) -> u8 {
        match self {
            AlarmChange::None => 0,
            AlarmChange::Appears => 1,
            AlarmChange::Disappears => 2,
            AlarmChange::DisappearsStillFaulty => 3,
        }
    }

    /// One word for JSON: "none", "appears", "disappears",
    /// "disappears-still-faulty".
    pub fn word(self) -> &'static str {
        match self {
            AlarmChange::None => "none",
            AlarmChange::Appears => "appears",
            AlarmChange::Disappears => "disappears",
            AlarmChange::DisappearsStillFaulty => "disappears-still-faulty",
        }
    }

    /// From [`AlarmChange::word`].
    pub fn from_word(s: &str) -> Option<AlarmChange> {
        [
            AlarmChange::None,
            AlarmChange::Appears,
            AlarmChange::Disappears,
            AlarmChange::DisappearsStillFaulty,
        ]
        .into_iter()
        .find(|c| c.word() == s)
    }
}

/// Alarm_Specifier: sequence number, Add_Ack and appears/disappears.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct AlarmSpecifier {
    /// Seq_Nr (0..=31), b7-3.
    pub seq: u8,
    /// Add_Ack, b2: the user must confirm the alarm beyond Alarm_Ack
    /// (e.g. with a Write).
    pub add_ack: bool,
    /// b1-0.
    pub change: AlarmChange,
}

impl AlarmSpecifier {
    /// From the specifier byte.
    pub fn from_byte(b: u8) -> AlarmSpecifier {
        AlarmSpecifier {
            seq: b >> 3,
            add_ack: b & 0x04 != 0,
            change: AlarmChange::from_bits(b),
        }
    }

    /// The specifier byte.
    pub fn byte(self) -> u8 {
        ((self.seq & MAX_SEQ) << 3) | (u8::from(self.add_ack) << 2) | self.change.bits()
    }
}

/// An alarm block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AlarmBlock<'a> {
    /// Alarm_Type.
    pub alarm_type: AlarmType,
    /// Slot_Number (0 is often the device, but some devices number from
    /// 1: do not assume).
    pub slot: u8,
    /// Alarm_Specifier.
    pub specifier: AlarmSpecifier,
    /// Diagnostic_User_Data.
    pub data: &'a [u8],
}

/// A status block (no acknowledgement).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StatusBlock<'a> {
    /// Status_Type with b7 set: 0x81 status message, 0x82 module
    /// status, 0x83 DXB link status, 0x9E PrmCmdAck, 0x9F Red_State,
    /// 0xA0..=0xFE manufacturer ([`crate::pdu::diag::status_type_text`]).
    pub status_type: u8,
    /// Slot_Number.
    pub slot: u8,
    /// Status_Specifier b1-0 (3 is reserved for status blocks).
    pub change: AlarmChange,
    /// Status data.
    pub data: &'a [u8],
}

/// A DP-V1 device-related block: alarm or status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DiagBlock<'a> {
    /// Alarm block (type b7 = 0).
    Alarm(AlarmBlock<'a>),
    /// Status block (type b7 = 1).
    Status(StatusBlock<'a>),
}

/// A block that is not a valid DP-V1 alarm or status block.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AlarmParseError {
    /// Fewer than the 4 header bytes.
    #[error("DP-V1 alarm/status block of {0} bytes, needs at least 4")]
    TooShort(usize),
    /// The header is not a device-related header (b7-6 must be 00).
    #[error("header 0x{0:02X} is not a device-related block")]
    NotDevice(u8),
    /// The header's length runs past the data.
    #[error("block header says {length} bytes, {available} present")]
    Length {
        /// Length from the header.
        length: usize,
        /// Bytes present.
        available: usize,
    },
    /// Alarm type 0 or 127 (reserved), which no slave sends.
    #[error("alarm type {0} is reserved")]
    ReservedType(u8),
}

impl<'a> DiagBlock<'a> {
    /// Decode the body of a device-related block (the bytes after the
    /// header byte, as [`ExtDiagBlock::Device`] gives them).
    pub fn from_body(body: &'a [u8]) -> Result<DiagBlock<'a>, AlarmParseError> {
        if body.len() < 3 {
            return Err(AlarmParseError::TooShort(body.len() + 1));
        }
        let (t, slot, spec, data) = (body[0], body[1], body[2], &body[3..]);
        if t & 0x80 != 0 {
            return Ok(DiagBlock::Status(StatusBlock {
                status_type: t,
                slot,
                change: AlarmChange::from_bits(spec),
                data,
            }));
        }
        if t == 0 || t == 127 {
            return Err(AlarmParseError::ReservedType(t));
        }
        Ok(DiagBlock::Alarm(AlarmBlock {
            alarm_type: AlarmType::from_code(t),
            slot,
            specifier: AlarmSpecifier::from_byte(spec),
            data,
        }))
    }

    /// Decode a whole block with its header from the start of `bytes`;
    /// returns the block and the bytes after it.
    pub fn parse(bytes: &'a [u8]) -> Result<(DiagBlock<'a>, &'a [u8]), AlarmParseError> {
        let &h = bytes.first().ok_or(AlarmParseError::TooShort(0))?;
        if h >> 6 != 0 {
            return Err(AlarmParseError::NotDevice(h));
        }
        let length = (h & 0x3F) as usize;
        if length > bytes.len() {
            return Err(AlarmParseError::Length {
                length,
                available: bytes.len(),
            });
        }
        if length < 4 {
            return Err(AlarmParseError::TooShort(length));
        }
        Ok((DiagBlock::from_body(&bytes[1..length])?, &bytes[length..]))
    }
}

impl AlarmBlock<'_> {
    /// Encode with its header; returns the length, `None` when `buf` is
    /// too small or the data exceed 59 bytes.
    pub fn emit(&self, buf: &mut [u8]) -> Option<usize> {
        emit_block(
            buf,
            self.alarm_type.code() & 0x7F,
            self.slot,
            self.specifier.byte(),
            self.data,
        )
    }

    /// The Alarm_Ack PDU that acknowledges this alarm.
    pub fn ack(&self) -> crate::pdu::dpv1::Pdu<'static> {
        crate::pdu::dpv1::Pdu::AlarmAck {
            slot: self.slot,
            alarm_type: self.alarm_type.code(),
            specifier: self.specifier.byte(),
        }
    }

    /// The alarm in words, e.g. "diagnostic alarm slot 2, seq 3, appears:
    /// 01 02".
    pub fn describe(&self) -> String {
        let mut s = format!(
            "{} alarm slot {}, seq {}, {}",
            self.alarm_type.word(),
            self.slot,
            self.specifier.seq,
            self.specifier.change.word()
        );
        if self.alarm_type.is_manufacturer() {
            s = format!("{s} (type {})", self.alarm_type.code());
        }
        if self.specifier.add_ack {
            s.push_str(", needs an extra user acknowledgement");
        }
        if !self.data.is_empty() {
            s.push(':');
            for b in self.data {
                s.push_str(&format!(" {b:02X}"));
            }
        }
        s
    }
}

impl StatusBlock<'_> {
    /// Encode with its header.
    pub fn emit(&self, buf: &mut [u8]) -> Option<usize> {
        emit_block(
            buf,
            self.status_type | 0x80,
            self.slot,
            self.change.bits(),
            self.data,
        )
    }
}

fn emit_block(buf: &mut [u8], t: u8, slot: u8, spec: u8, data: &[u8]) -> Option<usize> {
    let n = 4 + data.len();
    if data.len() > MAX_ALARM_DATA_LEN || buf.len() < n {
        return None;
    }
    buf[..4].copy_from_slice(&[n as u8, t, slot, spec]);
    buf[4..n].copy_from_slice(data);
    Some(n)
}

/// The alarm and status blocks in the extended diagnosis of a DP-V1
/// slave (the bytes after the 6 standard bytes); device-related blocks
/// that do not decode, and other blocks, are skipped.
pub fn dpv1_blocks(ext_diag: &[u8]) -> impl Iterator<Item = DiagBlock<'_>> {
    ext_blocks(ext_diag).filter_map(|b| match b {
        ExtDiagBlock::Device { data } => DiagBlock::from_body(data).ok(),
        _ => None,
    })
}

/// How many alarms may be outstanding at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AlarmLimit {
    /// One per alarm type.
    OnePerType,
    /// This many in total.
    Total(u8),
}

/// Alarm_Mode (DPV1_Status_3 b2-0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AlarmMode(pub u8);

impl AlarmMode {
    /// From DPV1_Status_3.
    pub fn from_status_3(s3: u8) -> AlarmMode {
        AlarmMode(s3 & 0x07)
    }

    /// The limit: 0 = one per type; 1..=7 = 2, 4, 8, 12, 16, 24, 32.
    pub fn limit(self) -> AlarmLimit {
        match self.0 & 7 {
            0 => AlarmLimit::OnePerType,
            m => AlarmLimit::Total([2, 4, 8, 12, 16, 24, 32][m as usize - 1]),
        }
    }

    /// The smallest mode that allows `n` outstanding alarms in total
    /// (`n` ≤ 1 gives mode 0, one per type).
    pub fn for_total(n: u8) -> AlarmMode {
        if n <= 1 {
            return AlarmMode(0);
        }
        (1..=7)
            .map(AlarmMode)
            .find(|m| matches!(m.limit(), AlarmLimit::Total(t) if t >= n))
            .unwrap_or(AlarmMode(7))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specifier_bits() {
        // Seq 3, Add_Ack, appears: 0001 1 1 01.
        let s = AlarmSpecifier::from_byte(0x1D);
        assert_eq!(s.seq, 3);
        assert!(s.add_ack);
        assert_eq!(s.change, AlarmChange::Appears);
        assert_eq!(s.byte(), 0x1D);
        assert_eq!(
            AlarmSpecifier::from_byte(0xFB).change,
            AlarmChange::DisappearsStillFaulty
        );
        assert_eq!(AlarmSpecifier::from_byte(0xFB).seq, 31);
    }

    #[test]
    fn diagnostic_alarm_block() {
        // header 07 (7 bytes), type 1, slot 2, seq 1 appears, 3 bytes.
        let bytes = [0x07, 0x01, 0x02, 0x09, 0xAA, 0xBB, 0xCC, 0x44];
        let (b, rest) = DiagBlock::parse(&bytes).unwrap();
        assert_eq!(rest, &[0x44]);
        let DiagBlock::Alarm(a) = b else { panic!() };
        assert_eq!(a.alarm_type, AlarmType::Diagnostic);
        assert_eq!(a.slot, 2);
        assert_eq!(a.specifier.seq, 1);
        assert_eq!(a.data, &[0xAA, 0xBB, 0xCC]);
        assert_eq!(
            a.describe(),
            "diagnostic alarm slot 2, seq 1, appears: AA BB CC"
        );
        let mut buf = [0; 64];
        assert_eq!(a.emit(&mut buf), Some(7));
        assert_eq!(&buf[..7], &bytes[..7]);
        let mut ack = [0; 4];
        a.ack().emit(&mut ack).unwrap();
        assert_eq!(ack, [0x5C, 0x02, 0x01, 0x09]);
    }

    #[test]
    fn status_and_manufacturer_blocks() {
        let (b, _) = DiagBlock::parse(&[0x05, 0x82, 0x00, 0x01, 0x10]).unwrap();
        assert!(matches!(
            b,
            DiagBlock::Status(StatusBlock {
                status_type: 0x82,
                change: AlarmChange::Appears,
                ..
            })
        ));
        let (b, _) = DiagBlock::parse(&[0x04, 40, 0x01, 0x02]).unwrap();
        let DiagBlock::Alarm(a) = b else { panic!() };
        assert_eq!(a.alarm_type.word(), "manufacturer");
        assert_eq!(a.alarm_type.enable(), Some(AlarmEnable::Manufacturer));
    }

    #[test]
    fn bad_blocks() {
        assert_eq!(DiagBlock::parse(&[]), Err(AlarmParseError::TooShort(0)));
        assert_eq!(
            DiagBlock::parse(&[0x43, 1, 2, 3]),
            Err(AlarmParseError::NotDevice(0x43))
        );
        assert_eq!(
            DiagBlock::parse(&[0x09, 1, 2, 3]),
            Err(AlarmParseError::Length {
                length: 9,
                available: 4
            })
        );
        assert_eq!(
            DiagBlock::parse(&[0x03, 1, 2]),
            Err(AlarmParseError::TooShort(3))
        );
        assert_eq!(
            DiagBlock::parse(&[0x04, 0, 2, 3]),
            Err(AlarmParseError::ReservedType(0))
        );
    }

    #[test]
    fn modes_and_enables() {
        assert_eq!(AlarmMode(0).limit(), AlarmLimit::OnePerType);
        assert_eq!(AlarmMode(1).limit(), AlarmLimit::Total(2));
        assert_eq!(AlarmMode(7).limit(), AlarmLimit::Total(32));
        assert_eq!(AlarmMode::for_total(10), AlarmMode(4));
        assert_eq!(
            AlarmEnable::from_name("pull_plug"),
            Some(AlarmEnable::PullPlug)
        );
        assert_eq!(AlarmEnable::PullPlug.bit().bits(), 0x80);
        assert_eq!(AlarmType::from_word("plug"), Some(AlarmType::Plug));
        assert_eq!(AlarmType::from_word("0"), None);
        let ext = [0x07, 0x01, 0x02, 0x09, 1, 2, 3, 0x43, 0, 0];
        assert_eq!(dpv1_blocks(&ext).count(), 1);
    }
}
