//! Slave_Diag: the diagnosis response (slave SSAP 60; IEC 61158-6-3).
//!
//! ```text
//! byte 0  Station_Status_1   byte 1  Station_Status_2
//! byte 2  Station_Status_3   byte 3  Diag.Master_Add (255 = none)
//! byte 4-5 Ident_Number      byte 6… Ext_Diag_Data blocks (total ≤ 244)
//! ```
//!
//! [`SlaveDiag`] reads and writes the fixed part; [`ext_blocks`] walks the
//! extended diagnosis blocks (device-, identifier-, channel-related and the
//! DP-V1 alarm/status blocks) and [`ExtDiagBlock::describe`] puts them into
//! words.

use profibus_fdl::wire::Hex;
use std::fmt::Write as _;

bitflags::bitflags! {
    /// Station_Status_1 (S = set by the slave, M = set by the master).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub struct StationStatus1: u8 {
        /// M: the slave does not answer.
        const STATION_NON_EXISTENT = 0x01;
        /// S: the slave is not ready for data exchange.
        const STATION_NOT_READY = 0x02;
        /// S: the configuration from Chk_Cfg does not match.
        const CFG_FAULT = 0x04;
        /// S: extended diagnosis data are present.
        const EXT_DIAG = 0x08;
        /// S: a requested function (sync, freeze) is not supported.
        const NOT_SUPPORTED = 0x10;
        /// M: the slave's response was invalid.
        const INVALID_SLAVE_RESPONSE = 0x20;
        /// S: the last parameter telegram was faulty.
        const PRM_FAULT = 0x40;
        /// M: the slave is parameterised by another master.
        const MASTER_LOCK = 0x80;
    }
}

bitflags::bitflags! {
    /// Station_Status_2.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub struct StationStatus2: u8 {
        /// S: the slave must be parameterised again.
        const PRM_REQ = 0x01;
        /// S: static diagnosis: the master keeps fetching diagnosis and
        /// does not exchange data until the bit clears.
        const STAT_DIAG = 0x02;
        /// S: always 1.
        const ALWAYS_ONE = 0x04;
        /// S: the watchdog is on.
        const WD_ON = 0x08;
        /// S: freeze mode is active.
        const FREEZE_MODE = 0x10;
        /// S: sync mode is active.
        const SYNC_MODE = 0x20;
        /// Reserved.
        const RESERVED = 0x40;
        /// M: the slave is deactivated in the master's bus parameters.
        const DEACTIVATED = 0x80;
    }
}

bitflags::bitflags! {
    /// Station_Status_3.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub struct StationStatus3: u8 {
        /// S: there is more diagnosis than fits into the telegram.
        const EXT_DIAG_OVERFLOW = 0x80;
    }
}

/// Diag.Master_Add value meaning "not parameterised by any master".
pub const NO_MASTER: u8 = 255;
/// Length of the fixed part of a Slave_Diag response.
pub const DIAG_HEADER_LEN: usize = 6;
/// Longest Slave_Diag response.
pub const MAX_DIAG_LEN: usize = 244;

/// A Slave_Diag response, borrowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlaveDiag<'a> {
    /// Byte 0.
    pub status1: StationStatus1,
    /// Byte 1.
    pub status2: StationStatus2,
    /// Byte 2.
    pub status3: StationStatus3,
    /// Byte 3: address of the master that parameterised the slave, 255
    /// when none.
    pub master_address: u8,
    /// Bytes 4-5.
    pub ident_number: u16,
    /// Bytes 6…: the extended diagnosis blocks.
    pub ext_diag: &'a [u8],
}

/// A Slave_Diag response that cannot be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DiagError {
    /// Fewer than 6 bytes.
    #[error("Slave_Diag of {0} bytes is shorter than the 6 standard bytes")]
    TooShort(usize),
}

impl<'a> SlaveDiag<'a> {
    /// Decode a Slave_Diag data unit (longer ones than 244 bytes are
    /// accepted on receive).
    pub fn parse(du: &'a [u8]) -> Result<SlaveDiag<'a>, DiagError> {
        if du.len() < DIAG_HEADER_LEN {
            return Err(DiagError::TooShort(du.len()));
        }
        Ok(SlaveDiag {
            status1: StationStatus1::from_bits_retain(du[0]),
            status2: StationStatus2::from_bits_retain(du[1]),
            status3: StationStatus3::from_bits_retain(du[2]),
            master_address: du[3],
            ident_number: u16::from_be_bytes([du[4], du[5]]),
            ext_diag: &du[DIAG_HEADER_LEN..],
        })
    }

    /// Whether bit 2 of Station_Status_2, which a slave always sets
    /// (EN 50170 Vol. 2 / IEC 61158-6-3, Station_Status_2 bit 2 "always
    /// 1"), is set. Some home-made and older slave cores leave it clear
    /// (e.g. `02 08 00 02 00 2B`): their answer with the SAPs of a
    /// Slave_Diag answer is still a diagnosis, and a master acts on it and
    /// counts the missing bit as a warning. It is not proof against stray
    /// telegrams: a late Data_Exchange reply has no SAPs and is rejected by
    /// the FDL's reply matching.
    pub fn is_valid(&self) -> bool {
        self.status2.contains(StationStatus2::ALWAYS_ONE)
    }

    /// Encode into `buf`; returns the length or `None` when `buf` is too
    /// small.
    pub fn emit(&self, buf: &mut [u8]) -> Option<usize> {
        let n = DIAG_HEADER_LEN + self.ext_diag.len();
        if buf.len() < n {
            return None;
        }
        let id = self.ident_number.to_be_bytes();
        buf[..DIAG_HEADER_LEN].copy_from_slice(&[
            self.status1.bits(),
            self.status2.bits(),
            self.status3.bits(),
            self.master_address,
            id[0],
            id[1],
        ]);
        buf[DIAG_HEADER_LEN..n].copy_from_slice(self.ext_diag);
        Some(n)
    }

    /// Whether the slave is ready for Data_Exchange with master `master`:
    /// no Station_Not_Ready, Cfg_Fault, Prm_Fault, Prm_Req or Stat_Diag,
    /// and parameterised by `master`.
    pub fn ready_for(&self, master: u8) -> bool {
        !self.status1.intersects(
            StationStatus1::STATION_NOT_READY
                | StationStatus1::CFG_FAULT
                | StationStatus1::PRM_FAULT
                | StationStatus1::NOT_SUPPORTED,
        ) && !self
            .status2
            .intersects(StationStatus2::PRM_REQ | StationStatus2::STAT_DIAG)
            && self.master_address == master
    }

    /// The station status bits in words, e.g. `"Cfg_Fault, Prm_Req"`.
    pub fn status_words(&self) -> String {
        let mut out = String::new();
        let mut add = |s: &str| {
            if !out.is_empty() {
                out.push_str(", ");
            }
            out.push_str(s);
        };
        for (flag, name) in [
            (StationStatus1::STATION_NON_EXISTENT, "Station_Non_Existent"),
            (StationStatus1::STATION_NOT_READY, "Station_Not_Ready"),
            (StationStatus1::CFG_FAULT, "Cfg_Fault"),
            (StationStatus1::EXT_DIAG, "Ext_Diag"),
            (StationStatus1::NOT_SUPPORTED, "Not_Supported"),
            (
                StationStatus1::INVALID_SLAVE_RESPONSE,
                "Invalid_Slave_Response",
            ),
            (StationStatus1::PRM_FAULT, "Prm_Fault"),
            (StationStatus1::MASTER_LOCK, "Master_Lock"),
        ] {
            if self.status1.contains(flag) {
                add(name);
            }
        }
        for (flag, name) in [
            (StationStatus2::PRM_REQ, "Prm_Req"),
            (StationStatus2::STAT_DIAG, "Stat_Diag"),
            (StationStatus2::WD_ON, "WD_On"),
            (StationStatus2::FREEZE_MODE, "Freeze_Mode"),
            (StationStatus2::SYNC_MODE, "Sync_Mode"),
            (StationStatus2::DEACTIVATED, "Deactivated"),
        ] {
            if self.status2.contains(flag) {
                add(name);
            }
        }
        if !self.status2.contains(StationStatus2::ALWAYS_ONE) {
            add("always-1 bit (Station_Status_2 bit 2) clear");
        }
        if self.status3.contains(StationStatus3::EXT_DIAG_OVERFLOW) {
            add("Ext_Diag_Overflow");
        }
        if out.is_empty() {
            out.push_str("OK");
        }
        out
    }
}

/// Direction of a channel in a channel-related diagnosis block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelIo {
    /// Bits 7-6 = 00 (reserved).
    Reserved,
    /// Input channel.
    Input,
    /// Output channel.
    Output,
    /// Input/output channel.
    InOut,
}

/// One block of the extended diagnosis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExtDiagBlock<'a> {
    /// Device-related diagnosis (header 00xxxxxx); `data` excludes the
    /// header byte. For DP-V1 slaves its first byte may be an alarm type
    /// (bit 7 = 0) or a status type (bit 7 = 1), see [`ExtDiagBlock::describe`].
    Device {
        /// Bytes after the header.
        data: &'a [u8],
    },
    /// Identifier-related diagnosis (header 01xxxxxx): a bit field, bit n
    /// set = identifier (module) n has a fault.
    Identifier {
        /// The bit field.
        bits: &'a [u8],
    },
    /// Channel-related diagnosis (header 10xxxxxx), always 3 bytes.
    Channel {
        /// Identifier (module) number 0..=63.
        identifier: u8,
        /// Channel number 0..=63.
        channel: u8,
        /// Input, output or both.
        io: ChannelIo,
        /// Channel type code (bits 7-5 of byte 2): 1 bit, 2 2 bit, 3 4 bit,
        /// 4 byte, 5 word, 6 2 words.
        channel_type: u8,
        /// Error type (bits 4-0 of byte 2).
        error_type: u8,
    },
    /// Header 11xxxxxx or a block that runs past the end: the raw rest.
    Unknown {
        /// Remaining bytes from this header on.
        raw: &'a [u8],
    },
}

/// Iterator over extended diagnosis blocks.
#[derive(Debug, Clone)]
pub struct ExtBlocks<'a> {
    rest: &'a [u8],
}

/// Walk the extended diagnosis blocks of `ext_diag` (the bytes after the
/// 6 standard bytes).
pub fn ext_blocks(ext_diag: &[u8]) -> ExtBlocks<'_> {
    ExtBlocks { rest: ext_diag }
}

impl<'a> Iterator for ExtBlocks<'a> {
    type Item = ExtDiagBlock<'a>;

    fn next(&mut self) -> Option<ExtDiagBlock<'a>> {
        let &h = self.rest.first()?;
        let unknown = |rest: &mut &'a [u8]| {
            let raw = *rest;
            *rest = &[];
            Some(ExtDiagBlock::Unknown { raw })
        };
        match h >> 6 {
            0 | 1 => {
                let len = (h & 0x3F) as usize;
                if len == 0 || len > self.rest.len() {
                    return unknown(&mut self.rest);
                }
                let body = &self.rest[1..len];
                self.rest = &self.rest[len..];
                Some(if h >> 6 == 0 {
                    ExtDiagBlock::Device { data: body }
                } else {
                    ExtDiagBlock::Identifier { bits: body }
                })
            }
            2 => {
                if self.rest.len() < 3 {
                    return unknown(&mut self.rest);
                }
                let (b1, b2) = (self.rest[1], self.rest[2]);
                self.rest = &self.rest[3..];
                Some(ExtDiagBlock::Channel {
                    identifier: h & 0x3F,
                    channel: b1 & 0x3F,
                    io: match b1 >> 6 {
                        1 => ChannelIo::Input,
                        2 => ChannelIo::Output,
                        3 => ChannelIo::InOut,
                        _ => ChannelIo::Reserved,
                    },
                    channel_type: b2 >> 5,
                    error_type: b2 & 0x1F,
                })
            }
            _ => unknown(&mut self.rest),
        }
    }
}

/// Words for a channel error type (EN 50170; 16..=31 vendor-specific).
pub fn channel_error_text(error_type: u8) -> &'static str {
    match error_type {
        0 => "reserved",
        1 => "short circuit",
        2 => "undervoltage",
        3 => "overvoltage",
        4 => "overload",
        5 => "overtemperature",
        6 => "line break",
        7 => "upper limit value exceeded",
        8 => "lower limit value undershot",
        9 => "error",
        10..=15 => "reserved",
        _ => "manufacturer-specific",
    }
}

fn channel_type_text(t: u8) -> &'static str {
    match t {
        1 => "bit",
        2 => "2 bit",
        3 => "4 bit",
        4 => "byte",
        5 => "word",
        6 => "2 words",
        _ => "unspecified",
    }
}

/// Words for a DP-V1 alarm type (type byte with bit 7 clear).
pub fn alarm_type_text(t: u8) -> &'static str {
    match t {
        1 => "diagnostic alarm",
        2 => "process alarm",
        3 => "pull alarm",
        4 => "plug alarm",
        5 => "status alarm",
        6 => "update alarm",
        32..=126 => "manufacturer-specific alarm",
        _ => "reserved alarm type",
    }
}

/// Words for a DP-V1 status type (type byte with bit 7 set).
pub fn status_type_text(t: u8) -> &'static str {
    match t {
        0x81 => "status message",
        0x82 => "module status",
        0x83 => "DXB link status",
        0x9E => "PrmCmdAck",
        0x9F => "red state",
        _ => "status",
    }
}

impl ExtDiagBlock<'_> {
    /// The block in words. `dpv1` interprets device-related blocks as
    /// DP-V1 alarm/status blocks (`type, slot, specifier, data`).
    pub fn describe(&self, dpv1: bool) -> String {
        match *self {
            ExtDiagBlock::Device { data } => {
                if dpv1 && data.len() >= 3 {
                    let (t, slot, spec) = (data[0], data[1], data[2]);
                    let what = if t & 0x80 == 0 {
                        alarm_type_text(t)
                    } else {
                        status_type_text(t)
                    };
                    let state = match spec & 3 {
                        1 => ", appears",
                        2 => ", disappears",
                        3 => ", disappears, other faults remain",
                        _ => "",
                    };
                    let ack = if spec & 4 != 0 {
                        ", needs Alarm_Ack"
                    } else {
                        ""
                    };
                    let mut s = format!(
                        "{what} (type {t}) slot {slot}, seq {}{state}{ack}",
                        spec >> 3
                    );
                    if data.len() > 3 {
                        let _ = write!(s, ": {}", Hex(&data[3..]));
                    }
                    s
                } else {
                    format!("device-related diagnosis: {}", Hex(data))
                }
            }
            ExtDiagBlock::Identifier { bits } => {
                let mut modules = vec![];
                for (i, b) in bits.iter().enumerate() {
                    for bit in 0..8 {
                        if b & (1 << bit) != 0 {
                            modules.push((i * 8 + bit).to_string());
                        }
                    }
                }
                if modules.is_empty() {
                    "identifier-related diagnosis: no module faulty".into()
                } else {
                    format!(
                        "identifier-related diagnosis: module(s) {} faulty",
                        modules.join(", ")
                    )
                }
            }
            ExtDiagBlock::Channel {
                identifier,
                channel,
                io,
                channel_type,
                error_type,
            } => {
                let dir = match io {
                    ChannelIo::Input => "input",
                    ChannelIo::Output => "output",
                    ChannelIo::InOut => "input/output",
                    ChannelIo::Reserved => "",
                };
                format!(
                    "channel diagnosis: module {identifier} {dir} channel {channel} ({}): {} (error type {error_type})",
                    channel_type_text(channel_type),
                    channel_error_text(error_type)
                )
            }
            ExtDiagBlock::Unknown { raw } => format!("undecoded diagnosis bytes: {}", Hex(raw)),
        }
    }
}

/// The channel block the tests write and read: module 3, input channel 2
/// (word), line break.
#[cfg(test)]
pub(crate) const LINE_BREAK_3_2: ExtDiagBlock<'static> = ExtDiagBlock::Channel {
    identifier: 3,
    channel: 2,
    io: ChannelIo::Input,
    channel_type: 5,
    error_type: 6,
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn et200s_example() {
        // trace of pyprofibus issue #26: 02 05 00 FF 80 6A | 49 00…(8) | 14 82 00 00 …
        let mut du = vec![0x02, 0x05, 0x00, 0xFF, 0x80, 0x6A, 0x49];
        du.extend([0u8; 8]);
        du.push(0x14);
        du.extend([0x82, 0, 0]);
        du.extend([0u8; 16]);
        let d = SlaveDiag::parse(&du).unwrap();
        assert_eq!(d.master_address, NO_MASTER);
        assert_eq!(d.ident_number, 0x806A);
        assert_eq!(d.status_words(), "Station_Not_Ready, Prm_Req");
        assert!(!d.ready_for(2));
        let blocks: Vec<_> = ext_blocks(d.ext_diag).collect();
        assert_eq!(blocks.len(), 2);
        assert!(matches!(blocks[0], ExtDiagBlock::Identifier { bits } if bits.len() == 8));
        assert!(matches!(blocks[1], ExtDiagBlock::Device { data } if data.len() == 19));
        assert!(blocks[1].describe(true).starts_with("module status"));
    }

    #[test]
    fn channel_block_and_round_trip() {
        let du = [0x08, 0x0C, 0x00, 0x02, 0x00, 0x08, 0x83, 0x42, 0xA6];
        let d = SlaveDiag::parse(&du).unwrap();
        assert!(!d.ready_for(2) || d.status1.contains(StationStatus1::EXT_DIAG));
        let b = ext_blocks(d.ext_diag).next().unwrap();
        assert_eq!(b, LINE_BREAK_3_2);
        assert_eq!(
            b.describe(false),
            "channel diagnosis: module 3 input channel 2 (word): line break (error type 6)"
        );
        let mut out = [0u8; 16];
        assert_eq!(d.emit(&mut out), Some(9));
        assert_eq!(out[..9], du);
    }

    #[test]
    fn ready() {
        let d = SlaveDiag::parse(&[0, 0x0C, 0, 2, 0, 8]).unwrap();
        assert!(d.ready_for(2));
        assert!(!d.ready_for(3));
        assert_eq!(d.status_words(), "WD_On");
    }

    #[test]
    fn broken_blocks_never_panic() {
        for h in 0..=255u8 {
            for len in 0..4 {
                let mut v = vec![h];
                v.extend(std::iter::repeat_n(0xFF, len));
                for b in ext_blocks(&v) {
                    let _ = b.describe(true);
                }
            }
        }
    }
}

fn has_unit_diag(g: &crate::config::gsd::Gsd) -> bool {
    !g.unit_diag_bits.is_empty()
        || !g.unit_diag_not_bits.is_empty()
        || !g.unit_diag_areas.is_empty()
}

/// The GSD's texts (`Unit_Diag_Bit`, `Unit_Diag_Not_Bit`,
/// `Unit_Diag_Area`) for the bits of a device-related block's `body` (the
/// bytes after its header byte; bit 0 is bit 0 of its first byte), only
/// for bits from `first_bit` on. A DP-V1 alarm block's
/// Diagnostic_User_Data starts at bit 24, after Alarm_Type, Slot_Number
/// and Alarm_Specifier (this stack's reading of the GSD specification,
/// which counts from the byte after the header).
pub fn unit_diag_words(g: &crate::config::gsd::Gsd, body: &[u8], first_bit: u32) -> Vec<String> {
    let mut out = vec![];
    let bit = |n: u32| {
        body.get(n as usize / 8)
            .is_some_and(|byte| byte & (1 << (n % 8)) != 0)
    };
    let total = body.len() as u32 * 8;
    for n in first_bit..total {
        let t = if bit(n) {
            g.unit_diag_bit_text(n)
        } else {
            g.unit_diag_not_bit_text(n)
        };
        if let Some(t) = t {
            out.push(t.to_string());
        }
    }
    for area in &g.unit_diag_areas {
        if area.first < first_bit
            || area.last >= total
            || area.first > area.last
            || area.last - area.first > 31
        {
            continue;
        }
        let mut v = 0i64;
        for n in (area.first..=area.last).rev() {
            v = v << 1 | bit(n) as i64;
        }
        if let Some(t) = area.values.iter().find(|x| x.value == v) {
            out.push(t.text.clone());
        }
    }
    out
}

/// The extended diagnosis blocks of `ext` (the bytes after the six-byte
/// header) in words, one or more per block; with the slave's GSD the bits
/// of a device-related block are named by its `Unit_Diag_*` texts
/// (`device: TEXT`), see [`describe`].
pub fn ext_words(ext: &[u8], gsd: Option<&crate::config::gsd::Gsd>, dpv1: bool) -> Vec<String> {
    let mut out = vec![];
    for b in ext_blocks(ext) {
        match (b, gsd) {
            (ExtDiagBlock::Device { data }, Some(g))
                if !(dpv1 && data.len() >= 3) && has_unit_diag(g) =>
            {
                let named = unit_diag_words(g, data, 0);
                if named.is_empty() {
                    out.push(b.describe(dpv1));
                }
                out.extend(named.into_iter().map(|t| format!("device: {t}")));
            }
            _ => out.push(b.describe(dpv1)),
        }
    }
    out
}

/// A whole Slave_Diag response in words: the station status bits, the
/// parameterising master, the ident number and every extended diagnosis
/// block. With the slave's GSD, bits of the device-related diagnosis are
/// named by its `Unit_Diag_Bit` / `Unit_Diag_Not_Bit` / `Unit_Diag_Area`
/// texts; bit 0 is bit 0 of the first byte after the block's header byte
/// (this stack's reading of the GSD specification; the manuals at hand
/// do not say). `dpv1` reads device-related blocks of DP-V1 slaves as
/// alarm/status blocks.
pub fn describe(du: &[u8], gsd: Option<&crate::config::gsd::Gsd>, dpv1: bool) -> Vec<String> {
    let d = match SlaveDiag::parse(du) {
        Ok(d) => d,
        Err(e) => return vec![e.to_string()],
    };
    let mut out = vec![format!("station status: {}", d.status_words())];
    out.push(match d.master_address {
        NO_MASTER => "not parameterised by any master".to_string(),
        m => format!("parameterised by master {m}"),
    });
    out.push(format!("ident number 0x{:04X}", d.ident_number));
    out.extend(ext_words(d.ext_diag, gsd, dpv1));
    if d.status3.contains(StationStatus3::EXT_DIAG_OVERFLOW) {
        out.push("more diagnosis than fits into one telegram (Ext_Diag_Overflow)".into());
    }
    out
}

#[cfg(test)]
mod describe_tests {
    use super::*;
    use crate::config::gsd::{Gsd, ParseOptions};

    #[test]
    fn unit_diag_texts_from_the_gsd() {
        let text =
            "#Profibus_DP\nGSD_Revision=1\nIdent_Number=0x1234\nProtocol_Ident=0\nStation_Type=0\n\
            Unit_Diag_Bit(0)=\"Sensor missing\"\nUnit_Diag_Bit(9)=\"Overtemperature\"\n\
            Unit_Diag_Not_Bit(1)=\"Supply off\"\n";
        let g = Gsd::parse(text, ParseOptions { lenient: true })
            .unwrap()
            .gsd;
        // Ext_Diag, device block of 3 bytes: header 03, bits 0 and 9 set, bit 1 clear.
        let du = [0x08, 0x0C, 0, 2, 0x12, 0x34, 0x03, 0x01, 0x02];
        let words = describe(&du, Some(&g), false);
        assert_eq!(words[0], "station status: Ext_Diag, WD_On");
        assert!(
            words.contains(&"device: Sensor missing".to_string()),
            "{words:?}"
        );
        assert!(words.contains(&"device: Overtemperature".to_string()));
        assert!(words.contains(&"device: Supply off".to_string()));
        assert_eq!(words[1], "parameterised by master 2");
    }
}
