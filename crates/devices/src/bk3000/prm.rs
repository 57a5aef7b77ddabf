//! User_Prm_Data of the BK3000 and the coupler's manufacturer-specific
//! diagnosis (the "old format" every BK3xx0 has).
//!
//! User_Prm_Data (bytes counted from 0 after the 7 standard Set_Prm
//! bytes; manual pages 44-48, English edition pages 42-46):
//!
//! | byte | bits | meaning | BK3000 |
//! |---|---|---|---|
//! | 0 | 7 | DPV1 class-1 services | must be 0 (no DP-V1, p. 55) |
//! | 1 | 0 | RunOnCfgFault mode (p. 46; byte inferred) | 0/1 |
//! | 2 | 3 | DPV1 diagnosis format | must be 0 (old format only) |
//! | 3 | 0-1 | start-up mode: 0 data exchange, 1 parameter mode, 2 parameter mode with Stat_Diag | 3 is faulty |
//! | 3 | 3 | K-bus cycle counter (Beckhoff infosys "UserPrmData of the Bus Couplers") | 0/1 |
//! | 5 | 0 | 2-byte PLC interface | 0/1 |
//! | 5 | 1 | 2-byte diagnosis interface (BK3x10 only) | must be 0 |
//! | 9 | 1 | 0 auto configuration, 1 programmed configuration | 1 needs a stored table |
//!
//! Fewer than [`USER_PRM_LEN`] bytes is "too little User_Prm_Data"; a
//! value the BK3000 does not support is "faulty byte n". The other bytes
//! and bits are accepted as they are (the summary and the English edition
//! do not say which values the coupler refuses there: inferred).
//!
//! Diagnosis (old format, English edition pages 50-51): Ext_Diag_Data
//! start with their length byte (which makes them a device-related block)
//! and a reserved 0, then 8-byte messages. The coupler's first message is
//! `0, 255, UserPrm error, first faulty UserPrm byte, CfgData error,
//! first faulty CfgData byte, 0, 0`. Its second message carries the
//! initialisation and K-bus error bits; its first two bytes and the
//! position of the K-bus error code and argument in it are not printed in
//! the sources we have, so the emulation's layout `0, 254, init errors,
//! K-bus errors, K-bus error code, argument, 0, 0` is **inferred**.

use std::fmt;

/// Bytes of User_Prm_Data the BK3000 needs (bytes 0..=9; the GSD's
/// `Max_User_Prm_Data_Len`).
pub const USER_PRM_LEN: usize = 10;

/// The 10 User_Prm_Data bytes of the default settings.
pub const DEFAULT_USER_PRM: [u8; USER_PRM_LEN] = [0; USER_PRM_LEN];

/// Start-up mode (User_Prm_Data byte 3, bits 0-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum StartupMode {
    /// 0: process data exchange at once.
    #[default]
    DataExchange,
    /// 1: parameter mode: ready for data exchange, K-bus not yet running.
    Parameter,
    /// 2: parameter mode, reporting static diagnosis (Stat_Diag).
    ParameterStatDiag,
}

/// The coupler settings a Set_Prm carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct UserPrm {
    /// Start-up mode.
    pub startup: StartupMode,
    /// K-bus cycle counter in the inputs.
    pub cycle_counter: bool,
    /// 2-byte PLC interface.
    pub plc_interface: bool,
    /// Programmed instead of automatic configuration.
    pub programmed: bool,
    /// RunOnCfgFault mode (p. 46): run with a maximal configuration.
    /// Byte 1 bit 0 (the summary cuts the byte off; Beckhoff's later
    /// couplers put "CfgData checking deactivated" there: inferred).
    pub run_on_cfg_fault: bool,
}

/// The UserPrm error of the coupler's diagnosis (manufacturer byte 2) and
/// the first faulty byte (byte 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PrmError {
    /// 2: too little User_Prm_Data (the length received).
    TooFew(usize),
    /// 3: byte n is faulty.
    FaultyByte(usize, &'static str),
}

impl PrmError {
    /// UserPrm error code (2 too few, 3 faulty byte).
    pub fn code(self) -> u8 {
        match self {
            PrmError::TooFew(_) => 2,
            PrmError::FaultyByte(..) => 3,
        }
    }

    /// First faulty byte (0 for too few).
    pub fn byte(self) -> u8 {
        match self {
            PrmError::TooFew(_) => 0,
            PrmError::FaultyByte(n, _) => n as u8,
        }
    }
}

impl fmt::Display for PrmError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PrmError::TooFew(n) => write!(
                f,
                "too little User_Prm_Data: {n} bytes, the BK3000 needs {USER_PRM_LEN}"
            ),
            PrmError::FaultyByte(n, why) => write!(f, "User_Prm_Data byte {n} faulty: {why}"),
        }
    }
}

impl UserPrm {
    /// Decode and validate User_Prm_Data; `programmed_available` says
    /// whether a programmed configuration (table 70) is stored.
    pub fn parse(data: &[u8], programmed_available: bool) -> Result<UserPrm, PrmError> {
        if data.len() < USER_PRM_LEN {
            return Err(PrmError::TooFew(data.len()));
        }
        if data[0] & 0x80 != 0 {
            return Err(PrmError::FaultyByte(
                0,
                "DPV1 services requested, the BK3000 has none",
            ));
        }
        if data[2] & 0x08 != 0 {
            return Err(PrmError::FaultyByte(
                2,
                "DPV1 diagnosis format requested, the BK3000 has only the old format",
            ));
        }
        let startup = match data[3] & 0x03 {
            0 => StartupMode::DataExchange,
            1 => StartupMode::Parameter,
            2 => StartupMode::ParameterStatDiag,
            _ => return Err(PrmError::FaultyByte(3, "start-up mode 3 does not exist")),
        };
        if data[5] & 0x02 != 0 {
            return Err(PrmError::FaultyByte(
                5,
                "2-byte diagnosis interface requested, only BK3x10 couplers have it",
            ));
        }
        let programmed = data[9] & 0x02 != 0;
        if programmed && !programmed_available {
            return Err(PrmError::FaultyByte(
                9,
                "programmed configuration requested, but none is stored (table 70)",
            ));
        }
        Ok(UserPrm {
            startup,
            cycle_counter: data[3] & 0x08 != 0,
            plc_interface: data[5] & 0x01 != 0,
            programmed,
            run_on_cfg_fault: data[1] & 0x01 != 0,
        })
    }

    /// The User_Prm_Data bytes of these settings.
    pub fn emit(&self) -> [u8; USER_PRM_LEN] {
        let mut b = DEFAULT_USER_PRM;
        b[3] = match self.startup {
            StartupMode::DataExchange => 0,
            StartupMode::Parameter => 1,
            StartupMode::ParameterStatDiag => 2,
        } | (self.cycle_counter as u8) << 3;
        b[1] = self.run_on_cfg_fault as u8;
        b[5] = self.plc_interface as u8;
        b[9] = (self.programmed as u8) << 1;
        b
    }
}

/// Initialisation error bits (second coupler message, byte 2; English
/// edition p. 51).
pub mod init_err {
    /// Error reading the EEPROM.
    pub const EEPROM: u8 = 1 << 0;
    /// Error checking the programmed configuration.
    pub const PROGRAMMED_CFG: u8 = 1 << 2;
    /// Error reading the terminal types on the K-bus.
    pub const TERMINAL_TYPES: u8 = 1 << 3;
    /// Terminal not supported.
    pub const TERMINAL_NOT_SUPPORTED: u8 = 1 << 4;
    /// Too much output data.
    pub const TOO_MUCH_OUTPUT: u8 = 1 << 6;
    /// Too much input data.
    pub const TOO_MUCH_INPUT: u8 = 1 << 7;
}

/// K-bus error bits (second coupler message, byte 3).
pub mod kbus_err {
    /// Too many timeouts on command execution (a terminal did not
    /// acknowledge).
    pub const TIMEOUT: u8 = 1 << 1;
    /// Too many errors receiving input data.
    pub const RECEIVE: u8 = 1 << 2;
    /// Terminal bus (K-bus) error.
    pub const KBUS: u8 = 1 << 5;
}

/// K-bus error code 4: data error, break behind terminal n (blink code
/// table of the Beckhoff couplers; the BK3000 summary cut the table off).
pub const KBUS_CODE_BREAK: u8 = 4;

/// K-bus error code 3, argument 0: K-bus command error (no terminal, or a
/// terminal defective: it does not answer). Beckhoff couplers' blink code
/// table (the BK3000 summary cut it off; not from the manual).
pub const KBUS_CODE_COMMAND: u8 = 3;

/// Error code 14, argument n: terminal n has the wrong format (the strip
/// changed since start-up). Beckhoff couplers' blink code table, not from
/// the manual.
pub const KBUS_CODE_FORMAT: u8 = 14;

/// First byte after the length byte (reserved, 0).
const RESERVED: u8 = 0;

/// Marker of the coupler's first message (byte 1).
pub const MSG_COUPLER_1: u8 = 255;
/// Marker of the coupler's second message (byte 1; inferred).
pub const MSG_COUPLER_2: u8 = 254;

/// What the coupler reports in its diagnosis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct CouplerDiag {
    /// UserPrm error code and first faulty byte.
    pub prm: (u8, u8),
    /// CfgData error code and first faulty byte.
    pub cfg: (u8, u8),
    /// Initialisation error bits.
    pub init: u8,
    /// K-bus error bits.
    pub kbus: u8,
    /// K-bus error code and argument.
    pub kbus_code: (u8, u8),
}

impl CouplerDiag {
    /// Whether anything is wrong.
    pub fn is_fault(&self) -> bool {
        *self != CouplerDiag::default()
    }

    /// The Ext_Diag_Data payload after the length byte: reserved byte and
    /// the coupler's messages (empty when nothing is wrong).
    pub fn payload(&self) -> Vec<u8> {
        if !self.is_fault() {
            return vec![];
        }
        let mut v = vec![RESERVED];
        v.extend_from_slice(&[
            0,
            MSG_COUPLER_1,
            self.prm.0,
            self.prm.1,
            self.cfg.0,
            self.cfg.1,
            0,
            0,
        ]);
        if self.init != 0 || self.kbus != 0 {
            v.extend_from_slice(&[
                0,
                MSG_COUPLER_2,
                self.init,
                self.kbus,
                self.kbus_code.0,
                self.kbus_code.1,
                0,
                0,
            ]);
        }
        v
    }

    /// Decode the Ext_Diag_Data of a BK3000 (from the length byte on).
    pub fn parse(ext: &[u8]) -> Option<CouplerDiag> {
        let len = *ext.first()? as usize;
        let body = ext.get(2..len.min(ext.len()))?;
        let mut d = CouplerDiag::default();
        let mut any = false;
        for m in body.chunks_exact(8) {
            match (m[0], m[1]) {
                (0, MSG_COUPLER_1) => {
                    d.prm = (m[2], m[3]);
                    d.cfg = (m[4], m[5]);
                    any = true;
                }
                (0, MSG_COUPLER_2) => {
                    d.init = m[2];
                    d.kbus = m[3];
                    d.kbus_code = (m[4], m[5]);
                    any = true;
                }
                _ => {}
            }
        }
        any.then_some(d)
    }

    /// The diagnosis in words, one line per fault, with the I/O-ERR blink
    /// code where the coupler shows one.
    pub fn describe(&self) -> Vec<String> {
        let mut out = vec![];
        match self.prm.0 {
            0 => {}
            2 => out.push("UserPrmData error 2: too little User_Prm_Data".to_string()),
            3 => out.push(format!(
                "UserPrmData error 3: User_Prm_Data byte {} faulty",
                self.prm.1
            )),
            c => out.push(format!("UserPrmData error {c}")),
        }
        match self.cfg.0 {
            0 => {}
            1 => out.push(format!(
                "CfgData error 1: too few CfgData; {}",
                blink_text(6, 0)
            )),
            2 => out.push(format!(
                "CfgData error 2: CfgData byte {} faulty; {}",
                self.cfg.1,
                blink_text(6, self.cfg.1.saturating_add(1))
            )),
            c => out.push(format!("CfgData error {c}")),
        }
        if self.init != 0 {
            let mut what = vec![];
            for (bit, text) in [
                (init_err::EEPROM, "error reading the EEPROM"),
                (
                    init_err::PROGRAMMED_CFG,
                    "error checking the programmed configuration",
                ),
                (init_err::TERMINAL_TYPES, "error reading the terminal types"),
                (init_err::TERMINAL_NOT_SUPPORTED, "terminal not supported"),
                (init_err::TOO_MUCH_OUTPUT, "too much output data"),
                (init_err::TOO_MUCH_INPUT, "too much input data"),
            ] {
                if self.init & bit != 0 {
                    what.push(text);
                }
            }
            out.push(format!(
                "initialisation error bits 0x{:02X}: {}",
                self.init,
                what.join(", ")
            ));
        }
        if self.kbus != 0 {
            let (code, arg) = self.kbus_code;
            let what = if code == KBUS_CODE_BREAK {
                if arg == 0 {
                    "K-bus data error, break behind the coupler".to_string()
                } else {
                    format!("K-bus data error, break behind terminal {arg}")
                }
            } else if code == KBUS_CODE_COMMAND {
                "K-bus command error: a terminal does not answer".to_string()
            } else if code == KBUS_CODE_FORMAT {
                format!("terminal {arg} has the wrong format: the strip changed")
            } else {
                format!("K-bus error code {code}, argument {arg}")
            };
            out.push(format!(
                "K-bus error bits 0x{:02X}: {what}; {}",
                self.kbus,
                blink_text(code, arg)
            ));
        }
        out
    }
}

/// The I/O-ERR LED's blink code in words: fast flicker, `pulses` slow
/// pulses (error code), then `arg` pulses (error argument).
pub fn blink_text(pulses: u8, arg: u8) -> String {
    format!("I/O-ERR blinks {pulses} pulses, then {arg}")
}
