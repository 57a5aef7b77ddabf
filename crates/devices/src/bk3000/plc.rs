//! The 2-byte PLC interface (User_Prm_Data byte 5 bit 0, manual p. 44;
//! identifier 0xB1 first in the configuration, p. 48): one control/status
//! byte and one data byte each way, through which the PLC reaches the
//! coupler's register tables (table 0 settings, 9 terminal list, 70
//! programmed configuration, 98 cycle-time measurement; p. 56-57, 64, 66)
//! and the registers of the terminals, and starts the K-bus in the
//! start-up parameter mode (p. 45).
//!
//! Beckhoff's byte sequence on these two bytes is in none of our sources,
//! so the emulation defines its own (**our protocol**, documented in
//! `docs/devices/bk3000.md`): each step is one function in the control
//! byte, executed when bit 7 (toggle) changes; the status byte echoes
//! the toggle and the function once done, bit 6 on error; the data byte
//! carries the argument out and the answer in.
//!
//! | function | data out | effect | data in |
//! |---|---|---|---|
//! | 1 | terminal (0 = coupler, then the terminals with process data) | select | — |
//! | 2 | table (terminal: channel − 1) | select | — |
//! | 3 | register | select | — |
//! | 4 / 5 | value high / low byte | latch | — |
//! | 6 | — | read the register | high byte |
//! | 7 | — | — | low byte of the last read |
//! | 8 | — | write the latched value | — |
//! | 9 | — | leave parameter mode (start the K-bus) | — |

/// What a step asks of the coupler.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// Read a register.
    Read {
        /// 0 the coupler, n the n-th terminal with process data.
        terminal: u8,
        /// Table (a terminal's channel − 1).
        table: u8,
        /// Register.
        register: u8,
    },
    /// Write a register.
    Write {
        /// As in `Read`.
        terminal: u8,
        /// As in `Read`.
        table: u8,
        /// As in `Read`.
        register: u8,
        /// The value.
        value: u16,
    },
    /// Start the K-bus (leave the start-up parameter mode).
    StartKbus,
}

/// The interface's state.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct PlcInterface {
    toggle: u8,
    function: u8,
    terminal: u8,
    table: u8,
    register: u8,
    value: u16,
    read: u16,
    answer: u8,
    error: bool,
}

impl PlcInterface {
    /// The output bytes of a Data_Exchange; returns what the coupler must
    /// do when the toggle changed and the function needs it.
    pub fn step(&mut self, control: u8, data: u8) -> Option<Request> {
        let toggle = control & 0x80;
        if toggle == self.toggle {
            return None;
        }
        self.toggle = toggle;
        self.function = control & 0x3F;
        self.error = false;
        self.answer = 0;
        match self.function {
            1 => self.terminal = data,
            2 => self.table = data,
            3 => self.register = data,
            4 => self.value = (self.value & 0x00FF) | (u16::from(data) << 8),
            5 => self.value = (self.value & 0xFF00) | u16::from(data),
            6 => {
                return Some(Request::Read {
                    terminal: self.terminal,
                    table: self.table,
                    register: self.register,
                })
            }
            7 => self.answer = self.read as u8,
            8 => {
                return Some(Request::Write {
                    terminal: self.terminal,
                    table: self.table,
                    register: self.register,
                    value: self.value,
                })
            }
            9 => return Some(Request::StartKbus),
            _ => self.error = true,
        }
        None
    }

    /// The coupler did what [`PlcInterface::step`] asked; `v` is the
    /// register's value.
    pub fn done(&mut self, v: u16) {
        self.read = v;
        if self.function == 6 {
            self.answer = (v >> 8) as u8;
        }
    }

    /// The coupler refused the request.
    pub fn failed(&mut self) {
        self.error = true;
    }

    /// Status and data byte of the inputs.
    pub fn answer(&self) -> (u8, u8) {
        (
            self.toggle | (self.error as u8) << 6 | self.function,
            self.answer,
        )
    }
}
