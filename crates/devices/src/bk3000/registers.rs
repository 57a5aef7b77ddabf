//! The register set of a complex terminal's channel (manual p. 41,
//! "Registersatz eines Analogkanals": user area, manufacturer settings,
//! software version, length, auxiliary process image; "the meaning of the
//! registers and status bytes is explained in the terminals' data
//! sheets"). The numbers and defaults below are from Beckhoff's data
//! sheets (KL3xx2 / IP3102 register overview), **not from the manual**:
//!
//! | register | meaning | access in the emulation |
//! |---|---|---|
//! | R0 | raw ADC value (before any scaling) | read |
//! | R6 | diagnosis: the status byte in the low byte | read |
//! | R7 | command (0x7000 restores the factory settings) | write with code word |
//! | R8 | terminal type (e.g. 3102) | read |
//! | R9 | software version, ASCII (0x3141 = "1A") | read |
//! | R11 | signal channels | read |
//! | R16-R30 | manufacturer settings (R19 offset, R20 gain ×256) | read; writes refused (the manufacturer code word is not published) |
//! | R31 | code word: 0x1235 opens the user area | read/write |
//! | R32 | feature register: bit 0 user scaling, bit 1 manufacturer scaling, bit 9/10 limit 1/2 | write with code word |
//! | R33/R34 | user offset (signed) and gain (×256, 0x0100 = 1) | write with code word |
//! | R35/R36 | limit values 1 and 2 | write with code word |
//! | R37 | filter: our model, an exponential average over 2^(R37 & 0x0F) cycles (0: off) | write with code word |
//!
//! The process value of an input channel: raw X; with manufacturer
//! scaling `Y = R19 + R20·X/256`; with user scaling `Y = R33 + R34·Y/256`;
//! then the filter. The status byte (process data mode): bit 0
//! underrange (below -0x8000, below 0 on unipolar ranges), bit 1
//! overrange (above 0x7FFF), bits 2-3 limit 1 and 4-5 limit 2 (01 value
//! above, 10 below, 11 equal), bit 6 error (over- or underrange); the
//! value is clamped to the range.

use super::catalogue::{Scale, TerminalType};

/// The user code word that opens the user area (R31).
pub const USER_CODE_WORD: u16 = 0x1235;

/// Registers of a channel.
pub const REGISTERS: usize = 64;

/// Status byte bits (process data mode).
pub mod status {
    /// Underrange.
    pub const UNDERRANGE: u8 = 1 << 0;
    /// Overrange.
    pub const OVERRANGE: u8 = 1 << 1;
    /// General error.
    pub const ERROR: u8 = 1 << 6;
}

/// Why a register write was not stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WriteRefused {
    /// Read-only register (R0-R6, R8-R15).
    #[error("R{0} is read-only")]
    ReadOnly(u8),
    /// The user area needs the code word.
    #[error("R{0} is write-protected: write the user code word 0x1235 to R31 first")]
    Protected(u8),
    /// The manufacturer area.
    #[error("R{0} is a manufacturer setting (needs the manufacturer code word)")]
    Manufacturer(u8),
}

/// One channel's registers and filter state.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    regs: [u16; REGISTERS],
    defaults: [u16; REGISTERS],
    filtered: Option<f64>,
}

impl Channel {
    /// The registers of channel `channel` of `ty` at their defaults.
    pub fn new(ty: &TerminalType) -> Channel {
        let mut r = [0u16; REGISTERS];
        r[8] = ty.type_number();
        r[9] = 0x3141;
        r[11] = ty.channels as u16;
        r[20] = 0x0100;
        r[32] = 0x0002;
        r[34] = 0x0100;
        for &(k, v) in ty.registers {
            if (k as usize) < REGISTERS {
                r[k as usize] = v;
            }
        }
        Channel {
            regs: r,
            defaults: r,
            filtered: None,
        }
    }

    /// Register `r`.
    pub fn read(&self, r: u8) -> u16 {
        self.regs.get(r as usize).copied().unwrap_or(0)
    }

    /// Write register `r` (the rules of the module docs).
    pub fn write(&mut self, r: u8, v: u16) -> Result<(), WriteRefused> {
        let open = self.regs[31] == USER_CODE_WORD;
        match r {
            31 => {}
            7 if open => {
                if v == 0x7000 {
                    self.regs[32..].copy_from_slice(&self.defaults[32..]);
                    self.filtered = None;
                }
            }
            0..=6 | 8..=15 => return Err(WriteRefused::ReadOnly(r)),
            16..=30 => return Err(WriteRefused::Manufacturer(r)),
            _ if !open => return Err(WriteRefused::Protected(r)),
            _ if (r as usize) < REGISTERS => {}
            _ => return Err(WriteRefused::ReadOnly(r)),
        }
        self.regs[r as usize] = v;
        Ok(())
    }

    /// The process value and status byte of the raw value `raw` (the
    /// module docs); R0 and R6 follow.
    pub fn process(&mut self, raw: i64, scale: &Scale) -> (i64, u8) {
        self.regs[0] = raw.clamp(-32768, 65535) as u16;
        let feature = self.regs[32];
        let mut y = raw;
        if feature & 0x0002 != 0 {
            y = self.regs[19] as i16 as i64 + (self.regs[20] as i64 * y) / 256;
        }
        if feature & 0x0001 != 0 {
            y = self.regs[33] as i16 as i64 + (self.regs[34] as i16 as i64 * y) / 256;
        }
        let k = self.regs[37] & 0x0F;
        if k > 0 {
            let f = self.filtered.get_or_insert(y as f64);
            *f += (y as f64 - *f) / f64::from(1u16 << k);
            y = f.round() as i64;
        } else {
            self.filtered = None;
        }
        let min = if scale.is_unipolar() { 0 } else { -32768 };
        let mut st = 0u8;
        if y > 32767 {
            st |= status::OVERRANGE | status::ERROR;
        }
        if y < min {
            st |= status::UNDERRANGE | status::ERROR;
        }
        let y = y.clamp(min, 32767);
        for (bit, reg, shift) in [(9, 35, 2), (10, 36, 4)] {
            if feature & (1 << bit) != 0 {
                let limit = self.regs[reg] as i16 as i64;
                let code = match y.cmp(&limit) {
                    std::cmp::Ordering::Greater => 0b01,
                    std::cmp::Ordering::Less => 0b10,
                    std::cmp::Ordering::Equal => 0b11,
                };
                st |= code << shift;
            }
        }
        self.regs[6] = st as u16;
        (y, st)
    }
}
