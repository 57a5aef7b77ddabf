//! Jetter JX2-PROFI1: the PROFIBUS-DP slave module of a Jetter PLC, as the
//! PLC program sees it (Jetter AG, "JX2-PROFI1 Peripheriemodul",
//! Betriebsanleitung, Auflage 1.05.1; Lnnn below = manual line N, see
//! `docs/sources.md`).
//!
//! The module is driven entirely through registers `1x100 … 1x999`
//! (`1x` = `1` followed by the module number: `12100` for module 2). This
//! module keeps that register interface as a sans-IO core, [`Jx2`]: the
//! PLC side reads and writes registers ([`Jx2::read`], [`Jx2::write`]), the
//! bus side is the [`Device`](profibus_dp::slave::Device) the DP slave
//! core runs (`device.rs`). [`Plc`] adds the PLC's own registers (the
//! `COPY (4, 1000, 12500)` of the manual's examples reads R1000) and
//! [`SharedJx2`] shares one PLC between the bus and any number of register
//! clients. [`script`] is the line protocol people and tests use to play
//! the PLC.
//!
//! What the module does, in the manual's order:
//! - **Configuration** (L531-564, L769-1000): word counts, buffer starts,
//!   data-record areas and consistent windows may change only before the
//!   station address is written. Every write of a configuration register
//!   re-validates the whole layout; a bad layout clears status bit 0 and
//!   reports error 2 (cyclic areas, or IN + OUT > 208 words), 3 (data
//!   record areas; the read and write areas may share their start) or 12
//!   (consistent areas, and 1x124 + 1x128 ≤ 1x102, 1x125 + 1x129 ≤ 1x103).
//!   Writing 1x107 initialises the controller (status bit 13, BUSY, for
//!   [`INIT_TIME`]), after which the station takes part in the bus; it is
//!   error 1 when the address is out of 0..=126, already set, or the
//!   buffer layout invalid, and error 6 with init error 49 when
//!   `IN·3 + OUT·3 + AC > 632` (L1240). Command 5 resets everything except
//!   the error registers.
//! - **Register access** (L1189-1211): registers 300..999 outside every
//!   configured area, and all of them while the layout is invalid, read −1
//!   and ignore writes. Output words read the master's values in
//!   Data_Exch and −65536 otherwise; they cannot be written. Data-record
//!   areas are locked (status bit 6) from command 11 until the master has
//!   fetched the record: access then reads −1, is ignored, and sets bit 7.
//! - **Cyclic data**: one register is one 16-bit word; on the bus a word
//!   is high byte first (the manual does not say; PROFIBUS convention).
//!   Command 15 copies the consistent inputs into the input words at the
//!   window's offset; bit 8 is set once a Data_Exchange response carried
//!   them. Command 16 copies the window of the next outputs received into
//!   the consistent output registers and sets bit 9.
//! - **Chk_Cfg** is accepted when the input and output word totals match
//!   1x102/1x103 and each consistent window (1x124/1x128, 1x125/1x129)
//!   lies inside **one** consistent module of the master's configuration
//!   ("dass der konsistente Datenbereich innerhalb eines konsistenten
//!   Eingangsmoduls liegt", L950, L969). Other modules may be consistent
//!   too, and a consistent module without a window is accepted (more
//!   consistency than asked for does no harm); otherwise error 8 and
//!   Cfg_Fault. A refused Set_Prm (ident number, lock bits,
//!   more User_Prm_Data than the 22 user bytes the registers mirror) is
//!   error 7. Prm and Cfg bytes accepted are mirrored in 1x160… and
//!   1x180….
//! - **Diagnosis** (L1380-1425): 1x140 = 10..=32 bytes including the 6
//!   standard bytes and the 4-byte DP-V1 status header (bytes 7..10; byte
//!   7, the header length, is rewritten by each 1x140 write); user bytes
//!   from bus byte 11 (1x146… word-wise low byte first, or 1x210… byte-
//!   wise). Commands 7 (status), 8 (extended: Ext_Diag, needs > 10 bytes,
//!   else error 9), 9 (static: Stat_Diag, the master stops exchanging data
//!   until a 7 or 8), 10 (abort). 1x139 holds the command until a master
//!   fetched the diagnosis; a new command meanwhile is error 10.
//! - **Data records** (L1431-1473): a master's MSAC_C1 read sets bit 4
//!   and 1x118/1x120/1x122 (length truncated to the area); the master's
//!   polls are answered "not yet" until command 11 (the area's words, high
//!   byte first) or 12 (DP-V1 error "application: read error"). A write
//!   lands in the area, sets bit 5 and 1x119/1x121/1x123 and waits for 13
//!   or 14 ("application: write error"); a write longer than the area is
//!   refused at once ("access: write length error") and sets no bit.
//!
//! Choices where the manual is silent or contradicts itself (see
//! `docs/devices/jx2.md`): the ident number 0x0DC3 is ours
//! (`crates/devices/gsd/JX2P0DC3.GSD`); 1x102/1x103 go to 122 (not 102); the diagnosis
//! length is 10..=32 (not 6..=32); the DS-write length is 1x119; status
//! reads 0x2001 while BUSY after a reset, 0x0001 after; error 11 (memory
//! test) can only be provoked on purpose ([`Jx2::fail_memory_test`]).

mod device;
pub mod profile;
pub mod script;
mod scripted;
mod shared;

pub use scripted::ScriptedJx2;
pub use shared::{BadModuleNumber, Plc, SharedJx2};

use crate::kit::EventQueue;
use profibus_dp::slave::SlaveState;
use profibus_fdl::Instant;
use std::fmt;
use std::time::Duration;

/// `JX2P0DC3.GSD`, written for this project from the manual.
pub const GSD: &[u8] = include_bytes!("../../gsd/JX2P0DC3.GSD");

/// Ident number of the emulation (ours: the manual gives none).
pub const IDENT: u16 = 0x0DC3;

/// Software version in 1x199 (1.03 → 103, L1176).
pub const SOFTWARE_VERSION: i32 = 103;

/// How long the module is BUSY (status bit 13) after a reset or after the
/// station address was written.
pub const INIT_TIME: Duration = Duration::from_millis(20);

/// Value of a register that is not in a configured area (L1191).
pub const NOT_CONFIGURED: i32 = -1;

/// Value of an output word while not in data exchange (0xFF0000 as a
/// 24-bit register, L1199).
pub const NO_OUTPUT: i32 = -65536;

/// Register numbers within a module (the `zzz` of `1xzzz`).
pub mod reg {
    /// Status bits ([`super::status`]).
    pub const STATUS: u16 = 100;
    /// Command register; reads the last command.
    pub const COMMAND: u16 = 101;
    /// Number of input words (slave → master), 0..=122.
    pub const IN_WORDS: u16 = 102;
    /// Number of output words (master → slave), 0..=122.
    pub const OUT_WORDS: u16 = 103;
    /// Station address, 0..=126; writing it initialises the controller.
    pub const ADDRESS: u16 = 107;
    /// First register of the input words, 300..=999.
    pub const IN_START: u16 = 112;
    /// First register of the output words.
    pub const OUT_START: u16 = 113;
    /// Registers of the data-record read area, 1..=120.
    pub const DSR_WORDS: u16 = 114;
    /// Registers of the data-record write area, 1..=120.
    pub const DSW_WORDS: u16 = 115;
    /// First register of the data-record read area.
    pub const DSR_START: u16 = 116;
    /// First register of the data-record write area.
    pub const DSW_START: u16 = 117;
    /// Bytes the master reads (set by the master).
    pub const DSR_LEN: u16 = 118;
    /// Bytes the master wrote.
    pub const DSW_LEN: u16 = 119;
    /// Slot of the read request.
    pub const DSR_SLOT: u16 = 120;
    /// Slot of the write request.
    pub const DSW_SLOT: u16 = 121;
    /// Index of the read request.
    pub const DSR_INDEX: u16 = 122;
    /// Index of the write request.
    pub const DSW_INDEX: u16 = 123;
    /// Consistent input words, 0..=122.
    pub const CIN_WORDS: u16 = 124;
    /// Consistent output words.
    pub const COUT_WORDS: u16 = 125;
    /// First register of the consistent input words.
    pub const CIN_START: u16 = 126;
    /// First register of the consistent output words.
    pub const COUT_START: u16 = 127;
    /// Word offset of the consistent inputs in the telegram.
    pub const CIN_OFFSET: u16 = 128;
    /// Word offset of the consistent outputs in the telegram.
    pub const COUT_OFFSET: u16 = 129;
    /// DP state: 0 Wait_Prm, 1 Wait_Cfg, 2 Data_Exch.
    pub const DP_STATE: u16 = 132;
    /// Detected baud rate code (0 = 12 M … 9 = 9.6 k).
    pub const BAUD: u16 = 133;
    /// Error number ([`super::ErrorNumber`]).
    pub const ERROR: u16 = 134;
    /// Baud watch: 0 Baud_Search, 1 Baud_Control, 2 DP_Control.
    pub const BAUD_WATCH: u16 = 135;
    /// Init error: 0, or 49 (controller memory too small).
    pub const INIT_ERROR: u16 = 136;
    /// Pending diagnosis command: 0 none, 1 status, 2 extended, 3 static.
    pub const DIAG_PENDING: u16 = 139;
    /// Diagnosis length in bytes, 10..=32.
    pub const DIAG_LEN: u16 = 140;
    /// Diagnosis bytes word-wise, low byte first (141..=145 system).
    pub const DIAG_WORDS: u16 = 141;
    /// First user diagnosis word (bus bytes 11, 12).
    pub const DIAG_USER_WORDS: u16 = 146;
    /// Length of the Prm data received.
    pub const PRM_LEN: u16 = 160;
    /// Prm data word-wise (161..=165 system, 166..=176 user).
    pub const PRM_WORDS: u16 = 161;
    /// Length of the Cfg data received.
    pub const CFG_LEN: u16 = 180;
    /// Cfg data word-wise (181..=196).
    pub const CFG_WORDS: u16 = 181;
    /// Software version.
    pub const VERSION: u16 = 199;
    /// Diagnosis bytes byte-wise (200..=209 system, 210..=231 user).
    pub const DIAG_BYTES: u16 = 200;
    /// First user diagnosis byte.
    pub const DIAG_USER_BYTES: u16 = 210;
    /// Prm data byte-wise (232..=263).
    pub const PRM_BYTES: u16 = 232;
    /// Cfg data byte-wise (264..=295).
    pub const CFG_BYTES: u16 = 264;
    /// First data buffer register.
    pub const DATA_FIRST: u16 = 300;
    /// Last data buffer register.
    pub const DATA_LAST: u16 = 999;
}

/// Bits of the status register 1x100.
pub mod status {
    /// Buffer configuration valid.
    pub const BUFFER_OK: i32 = 1 << 0;
    /// Station address valid (written and accepted).
    pub const ADDRESS_OK: i32 = 1 << 1;
    /// PROFIBUS controller initialised.
    pub const INITIALISED: i32 = 1 << 2;
    /// Data exchange with a master.
    pub const DATA_EXCHANGE: i32 = 1 << 3;
    /// A data-record read waits for command 11/12.
    pub const DS_READ: i32 = 1 << 4;
    /// A data-record write waits for command 13/14.
    pub const DS_WRITE: i32 = 1 << 5;
    /// Data-record areas locked (a record is being transferred).
    pub const ACYCLIC_BUSY: i32 = 1 << 6;
    /// A data-record area was accessed while locked.
    pub const ACYCLIC_ERROR: i32 = 1 << 7;
    /// Consistent inputs sent to the master.
    pub const CIN_SENT: i32 = 1 << 8;
    /// Consistent outputs received from the master.
    pub const COUT_RECEIVED: i32 = 1 << 9;
    /// BUSY after a reset or the address write.
    pub const BUSY: i32 = 1 << 13;
    /// An error is in 1x134.
    pub const ERROR: i32 = 1 << 15;
}

/// Commands of register 1x101.
pub mod cmd {
    /// Reset the module (keeps the error).
    pub const RESET: i32 = 5;
    /// Clear the error bit and 1x134.
    pub const CLEAR_ERROR: i32 = 6;
    /// Send a status diagnosis.
    pub const DIAG_STATUS: i32 = 7;
    /// Send an extended diagnosis.
    pub const DIAG_EXTENDED: i32 = 8;
    /// Enter static diagnosis.
    pub const DIAG_STATIC: i32 = 9;
    /// Abort the pending diagnosis.
    pub const DIAG_ABORT: i32 = 10;
    /// Data-record read OK.
    pub const DS_READ_OK: i32 = 11;
    /// Data-record read refused.
    pub const DS_READ_NOK: i32 = 12;
    /// Data-record write OK.
    pub const DS_WRITE_OK: i32 = 13;
    /// Data-record write refused.
    pub const DS_WRITE_NOK: i32 = 14;
    /// Send the consistent inputs.
    pub const SEND_CONSISTENT: i32 = 15;
    /// Receive the consistent outputs.
    pub const RECEIVE_CONSISTENT: i32 = 16;
}

/// Error numbers of 1x134 (L1060-1104).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ErrorNumber {
    /// Invalid station address: out of range, already set, or the buffer
    /// configuration is invalid.
    Address = 1,
    /// Cyclic input or output area: length, range or overlap.
    CyclicArea = 2,
    /// Data-record area: length, range or overlap.
    AcyclicArea = 3,
    /// Controller initialisation failed (see 1x136).
    ControllerInit = 6,
    /// The master's Set_Prm does not match.
    Prm = 7,
    /// The master's Chk_Cfg does not match.
    Cfg = 8,
    /// Diagnosis length out of 10..=32 (or ≤ 10 for an extended
    /// diagnosis).
    DiagLength = 9,
    /// A diagnosis is still pending.
    DiagPending = 10,
    /// Memory test failed after a reset.
    MemoryTest = 11,
    /// Consistent area: length, range or overlap.
    ConsistentArea = 12,
}

impl ErrorNumber {
    /// The number in 1x134.
    pub fn number(self) -> u8 {
        self as u8
    }

    /// The error in words.
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorNumber::Address => "invalid station address",
            ErrorNumber::CyclicArea => "cyclic input/output area invalid",
            ErrorNumber::AcyclicArea => "data-record area invalid",
            ErrorNumber::ControllerInit => "PROFIBUS controller initialisation failed",
            ErrorNumber::Prm => "parameter telegram does not match",
            ErrorNumber::Cfg => "configuration telegram does not match",
            ErrorNumber::DiagLength => "diagnosis length invalid",
            ErrorNumber::DiagPending => "previous diagnosis not fetched yet",
            ErrorNumber::MemoryTest => "memory test failed",
            ErrorNumber::ConsistentArea => "consistent area invalid",
        }
    }
}

impl fmt::Display for ErrorNumber {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "error {}: {}", self.number(), self.as_str())
    }
}

/// Init error 49 of 1x136: the controller's memory is too small.
pub const INIT_ERROR_MEMORY: i32 = 49;

/// Controller memory limit: `IN·3 + OUT·3 + AC ≤ 632` (L1240).
pub const MEMORY_LIMIT: u32 = 632;

/// At most this many input plus output words (L1250).
pub const MAX_IO_WORDS: i32 = 208;

/// What a register write did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WriteEffect {
    /// The value was taken.
    Applied,
    /// The module ignored the write, for this reason.
    Ignored(&'static str),
}

/// The diagnosis kinds of commands 7, 8, 9 (values of 1x139).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DiagKind {
    /// Status diagnosis (command 7).
    Status = 1,
    /// Extended diagnosis (command 8): Ext_Diag.
    Extended = 2,
    /// Static diagnosis (command 9): Stat_Diag.
    Static = 3,
}

/// A diagnosis telegram's extended part as the module sends it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct DiagTelegram {
    kind: DiagKind,
    len: usize,
    bytes: [u8; 32],
}

/// A data-record request the PLC has to answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Record {
    /// Waiting for the PLC's command (status bit 4 / 5).
    pending: bool,
    /// The PLC's answer, not yet fetched by the master.
    answer: Option<bool>,
    len: u8,
    slot: u8,
    index: u8,
}

/// The writable configuration registers 102..=129, as written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Layout {
    in_words: i32,
    out_words: i32,
    in_start: i32,
    out_start: i32,
    dsr_words: i32,
    dsw_words: i32,
    dsr_start: i32,
    dsw_start: i32,
    cin_words: i32,
    cout_words: i32,
    cin_start: i32,
    cout_start: i32,
    cin_offset: i32,
    cout_offset: i32,
}

impl Layout {
    /// Reset values (L735-1000).
    const RESET: Layout = Layout {
        in_words: 4,
        out_words: 4,
        in_start: 300,
        out_start: 400,
        dsr_words: 4,
        dsw_words: 4,
        dsr_start: 700,
        dsw_start: 800,
        cin_words: 0,
        cout_words: 0,
        cin_start: 500,
        cout_start: 600,
        cin_offset: 0,
        cout_offset: 0,
    };

    fn get(&self, z: u16) -> Option<i32> {
        Some(match z {
            reg::IN_WORDS => self.in_words,
            reg::OUT_WORDS => self.out_words,
            reg::IN_START => self.in_start,
            reg::OUT_START => self.out_start,
            reg::DSR_WORDS => self.dsr_words,
            reg::DSW_WORDS => self.dsw_words,
            reg::DSR_START => self.dsr_start,
            reg::DSW_START => self.dsw_start,
            reg::CIN_WORDS => self.cin_words,
            reg::COUT_WORDS => self.cout_words,
            reg::CIN_START => self.cin_start,
            reg::COUT_START => self.cout_start,
            reg::CIN_OFFSET => self.cin_offset,
            reg::COUT_OFFSET => self.cout_offset,
            _ => return None,
        })
    }

    fn field(&mut self, z: u16) -> Option<&mut i32> {
        Some(match z {
            reg::IN_WORDS => &mut self.in_words,
            reg::OUT_WORDS => &mut self.out_words,
            reg::IN_START => &mut self.in_start,
            reg::OUT_START => &mut self.out_start,
            reg::DSR_WORDS => &mut self.dsr_words,
            reg::DSW_WORDS => &mut self.dsw_words,
            reg::DSR_START => &mut self.dsr_start,
            reg::DSW_START => &mut self.dsw_start,
            reg::CIN_WORDS => &mut self.cin_words,
            reg::COUT_WORDS => &mut self.cout_words,
            reg::CIN_START => &mut self.cin_start,
            reg::COUT_START => &mut self.cout_start,
            reg::CIN_OFFSET => &mut self.cin_offset,
            reg::COUT_OFFSET => &mut self.cout_offset,
            _ => return None,
        })
    }

    /// The first problem of the layout, checked cyclic areas first, then
    /// data-record areas, then consistent areas.
    fn check(&self) -> Result<(), ErrorNumber> {
        let data = (reg::DATA_FIRST as i32)..=(reg::DATA_LAST as i32);
        let area_ok = |start: i32, words: i32| {
            data.contains(&start) && (words == 0 || start + words - 1 <= reg::DATA_LAST as i32)
        };
        let overlap =
            |a: (i32, i32), b: (i32, i32)| a.1 > 0 && b.1 > 0 && a.0 < b.0 + b.1 && b.0 < a.0 + a.1;
        let cyc_in = (self.in_start, self.in_words);
        let cyc_out = (self.out_start, self.out_words);
        let dsr = (self.dsr_start, self.dsr_words);
        let dsw = (self.dsw_start, self.dsw_words);
        let cin = (self.cin_start, self.cin_words);
        let cout = (self.cout_start, self.cout_words);
        // Cyclic areas (error 2).
        let words = 0..=122;
        if !words.contains(&self.in_words)
            || !words.contains(&self.out_words)
            || self.in_words + self.out_words > MAX_IO_WORDS
            || !area_ok(cyc_in.0, cyc_in.1)
            || !area_ok(cyc_out.0, cyc_out.1)
            || overlap(cyc_in, cyc_out)
        {
            return Err(ErrorNumber::CyclicArea);
        }
        // Data-record areas (error 3); read and write may share a start.
        let ds_words = 1..=120;
        if !ds_words.contains(&self.dsr_words)
            || !ds_words.contains(&self.dsw_words)
            || !area_ok(dsr.0, dsr.1)
            || !area_ok(dsw.0, dsw.1)
            || (overlap(dsr, dsw) && dsr.0 != dsw.0)
            || [cyc_in, cyc_out]
                .iter()
                .any(|&c| overlap(c, dsr) || overlap(c, dsw))
        {
            return Err(ErrorNumber::AcyclicArea);
        }
        // Consistent areas (error 12).
        if !words.contains(&self.cin_words)
            || !words.contains(&self.cout_words)
            || !(0..=122).contains(&self.cin_offset)
            || !(0..=122).contains(&self.cout_offset)
            || self.cin_words + self.cin_offset > self.in_words
            || self.cout_words + self.cout_offset > self.out_words
            || !area_ok(cin.0, cin.1)
            || !area_ok(cout.0, cout.1)
            || overlap(cin, cout)
            || [cyc_in, cyc_out, dsr, dsw]
                .iter()
                .any(|&c| overlap(c, cin) || overlap(c, cout))
        {
            return Err(ErrorNumber::ConsistentArea);
        }
        Ok(())
    }

    /// Controller memory the layout needs (L1240).
    fn memory(&self) -> u32 {
        let up4 = |v: i32| (v.max(0) as u32).div_ceil(4) * 4;
        up4(self.in_words) * 3 + up4(self.out_words) * 3 + up4(self.dsr_words.max(self.dsw_words))
    }

    fn contains(start: i32, words: i32, z: i32) -> bool {
        words > 0 && (start..start + words).contains(&z)
    }
}

/// Which configured area a data register is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Area {
    Inputs,
    Outputs,
    Record,
    Consistent,
}

/// The JX2-PROFI1 module: register interface and bus side (see the
/// module docs).
#[derive(Debug, Clone)]
pub struct Jx2 {
    layout: Layout,
    layout_ok: bool,
    /// The address written to 1x107 and accepted.
    address: Option<u8>,
    /// What 1x107 reads.
    address_reg: i32,
    /// Controller initialised: on the bus.
    initialised: bool,
    busy_until: Option<Instant>,
    command: i32,
    error: Option<ErrorNumber>,
    /// Errors raised so far (also across resets).
    error_count: u64,
    init_error: i32,
    dp_state: SlaveState,
    baud_code: i32,
    dsr: Record,
    dsw: Record,
    /// The master's last record request was a read (for its polls).
    last_request_read: bool,
    acyclic_busy: bool,
    acyclic_error: bool,
    cin_sent: bool,
    cin_copied: bool,
    cout_received: bool,
    cout_wanted: bool,
    diag_len: i32,
    diag: [u8; 32],
    diag_pending: Option<DiagTelegram>,
    diag_current: Option<DiagTelegram>,
    diag_new: bool,
    prm: [u8; 32],
    prm_len: usize,
    cfg: [u8; 32],
    cfg_len: usize,
    real_cfg: Vec<u8>,
    memory: Vec<u16>,
    restart: bool,
    memory_fault: bool,
    events: EventQueue,
}

impl Default for Jx2 {
    fn default() -> Jx2 {
        Jx2::new()
    }
}

impl Jx2 {
    /// A module just switched on: reset values, no station address (ERR
    /// blinking), not on the bus.
    pub fn new() -> Jx2 {
        let mut j = Jx2 {
            layout: Layout::RESET,
            layout_ok: true,
            address: None,
            address_reg: 0,
            initialised: false,
            busy_until: None,
            command: 0,
            error: None,
            error_count: 0,
            init_error: 0,
            dp_state: SlaveState::WaitPrm,
            baud_code: 8,
            dsr: Record::default(),
            dsw: Record::default(),
            last_request_read: false,
            acyclic_busy: false,
            acyclic_error: false,
            cin_sent: false,
            cin_copied: false,
            cout_received: false,
            cout_wanted: false,
            diag_len: 10,
            diag: [0; 32],
            diag_pending: None,
            diag_current: None,
            diag_new: false,
            prm: [0; 32],
            prm_len: 0,
            cfg: [0; 32],
            cfg_len: 0,
            real_cfg: Vec::new(),
            memory: vec![0; (reg::DATA_LAST - reg::DATA_FIRST + 1) as usize],
            restart: false,
            memory_fault: false,
            events: EventQueue::default(),
        };
        j.reset_diag();
        j.real_cfg = j.build_real_cfg();
        j
    }

    fn reset_diag(&mut self) {
        self.diag = [0; 32];
        let id = IDENT.to_be_bytes();
        self.diag[4] = id[0];
        self.diag[5] = id[1];
        // DP-V1 status block header: length, status type, slot, specifier.
        self.diag[6] = (self.diag_len - 6) as u8;
        self.diag[7] = 0x81;
    }

    // ----- time ---------------------------------------------------------

    /// Let time pass: BUSY ends after [`INIT_TIME`], and after an address
    /// write the controller is then initialised (on the bus).
    pub fn settle(&mut self, now: Instant) {
        if let Some(t) = self.busy_until {
            if now >= t {
                self.busy_until = None;
                if self.address.is_some() && !self.initialised {
                    self.initialised = true;
                    self.restart = true;
                    self.events.note(
                        "jx2",
                        format!(
                            "controller initialised, station address {}",
                            self.address.unwrap_or(0)
                        ),
                    );
                }
            }
        }
    }

    /// When [`Jx2::settle`] has something to do.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.busy_until
    }

    // ----- state for people ---------------------------------------------

    /// The station address, once the controller is initialised.
    pub fn station_address(&self) -> Option<u8> {
        self.address.filter(|_| self.initialised)
    }

    /// The error in 1x134, if any.
    pub fn error(&self) -> Option<ErrorNumber> {
        self.error
    }

    /// The status register 1x100.
    pub fn status(&self) -> i32 {
        let mut s = 0;
        let mut set = |b: i32, on: bool| {
            if on {
                s |= b
            }
        };
        set(status::BUFFER_OK, self.layout_ok);
        set(status::ADDRESS_OK, self.address.is_some());
        set(status::INITIALISED, self.initialised);
        set(status::DATA_EXCHANGE, self.in_data_exchange());
        set(status::DS_READ, self.dsr.pending);
        set(status::DS_WRITE, self.dsw.pending);
        set(status::ACYCLIC_BUSY, self.acyclic_busy);
        set(status::ACYCLIC_ERROR, self.acyclic_error);
        set(status::CIN_SENT, self.cin_sent);
        set(status::COUT_RECEIVED, self.cout_received);
        set(status::BUSY, self.busy_until.is_some());
        set(status::ERROR, self.error.is_some());
        s
    }

    /// The front LEDs (L513-516): DX lit in data exchange; ERR blinking
    /// without a valid station address, lit on an error (1x134), else
    /// off.
    pub fn leds(&self) -> (bool, &'static str) {
        let err = if self.error.is_some() {
            "on"
        } else if self.address.is_none() {
            "blinking"
        } else {
            "off"
        };
        (self.in_data_exchange(), err)
    }

    fn in_data_exchange(&self) -> bool {
        self.initialised && self.dp_state == SlaveState::DataExch
    }

    /// Set the baud rate code of 1x133 from a rate in bit/s.
    pub fn set_baud(&mut self, bps: u32) {
        self.baud_code = match bps {
            12_000_000 => 0,
            6_000_000 => 1,
            3_000_000 => 2,
            1_500_000 => 3,
            500_000 => 4,
            187_500 => 5,
            93_750 => 6,
            45_450 => 7,
            19_200 => 8,
            _ => 9,
        };
    }

    /// Make the memory test of the next reset (command 5) fail: error 11.
    /// A real module reports it only when its memory is broken.
    pub fn fail_memory_test(&mut self) {
        self.memory_fault = true;
    }

    /// How many errors were raised so far (a script tells a new error
    /// from an old one by it).
    pub fn error_count(&self) -> u64 {
        self.error_count
    }

    fn raise(&mut self, e: ErrorNumber) {
        self.error = Some(e);
        self.error_count += 1;
        self.events.note("jx2_error", e.to_string());
    }

    // ----- registers ----------------------------------------------------

    /// Read register `1xzzz` (`z` = 100..=999) at `now`.
    pub fn read(&mut self, now: Instant, z: u16) -> i32 {
        self.settle(now);
        let word = |b: &[u8], i: usize| b[2 * i] as i32 | (b[2 * i + 1] as i32) << 8;
        match z {
            reg::STATUS => self.status(),
            reg::COMMAND => self.command,
            reg::ADDRESS => self.address_reg,
            reg::DSR_LEN => self.dsr.len as i32,
            reg::DSW_LEN => self.dsw.len as i32,
            reg::DSR_SLOT => self.dsr.slot as i32,
            reg::DSW_SLOT => self.dsw.slot as i32,
            reg::DSR_INDEX => self.dsr.index as i32,
            reg::DSW_INDEX => self.dsw.index as i32,
            reg::DP_STATE => match self.dp_state {
                SlaveState::WaitPrm => 0,
                SlaveState::WaitCfg => 1,
                SlaveState::DataExch => 2,
            },
            reg::BAUD => self.baud_code,
            reg::ERROR => self.error.map_or(0, |e| e.number() as i32),
            reg::BAUD_WATCH => {
                if !self.initialised {
                    0
                } else if self.dp_state == SlaveState::DataExch {
                    2
                } else {
                    1
                }
            }
            reg::INIT_ERROR => self.init_error,
            reg::DIAG_PENDING => self.diag_pending.map_or(0, |d| d.kind as i32),
            reg::DIAG_LEN => self.diag_len,
            141..=156 => word(&self.diag, (z - reg::DIAG_WORDS) as usize),
            reg::PRM_LEN => self.prm_len as i32,
            161..=176 => word(&self.prm, (z - reg::PRM_WORDS) as usize),
            reg::CFG_LEN => self.cfg_len as i32,
            181..=196 => word(&self.cfg, (z - reg::CFG_WORDS) as usize),
            197 | 198 => 0,
            reg::VERSION => SOFTWARE_VERSION,
            200..=231 => self.diag[(z - reg::DIAG_BYTES) as usize] as i32,
            232..=263 => self.prm[(z - reg::PRM_BYTES) as usize] as i32,
            264..=295 => self.cfg[(z - reg::CFG_BYTES) as usize] as i32,
            reg::DATA_FIRST..=reg::DATA_LAST => self.read_data(z),
            _ => match self.layout.get(z) {
                Some(v) => v,
                None => NOT_CONFIGURED,
            },
        }
    }

    fn area(&self, z: u16) -> Option<Area> {
        let l = &self.layout;
        let z = z as i32;
        if Layout::contains(l.out_start, l.out_words, z) {
            Some(Area::Outputs)
        } else if Layout::contains(l.in_start, l.in_words, z) {
            Some(Area::Inputs)
        } else if Layout::contains(l.dsr_start, l.dsr_words, z)
            || Layout::contains(l.dsw_start, l.dsw_words, z)
        {
            Some(Area::Record)
        } else if Layout::contains(l.cin_start, l.cin_words, z)
            || Layout::contains(l.cout_start, l.cout_words, z)
        {
            Some(Area::Consistent)
        } else {
            None
        }
    }

    fn mem(&self, z: i32) -> u16 {
        self.memory[(z - reg::DATA_FIRST as i32) as usize]
    }

    fn mem_mut(&mut self, z: i32) -> &mut u16 {
        &mut self.memory[(z - reg::DATA_FIRST as i32) as usize]
    }

    fn read_data(&mut self, z: u16) -> i32 {
        if !self.layout_ok {
            return NOT_CONFIGURED;
        }
        match self.area(z) {
            None => NOT_CONFIGURED,
            Some(Area::Outputs) if !(self.in_data_exchange()) => NO_OUTPUT,
            Some(Area::Record) if self.acyclic_busy => {
                self.acyclic_error = true;
                NOT_CONFIGURED
            }
            Some(_) => self.mem(z as i32) as i32,
        }
    }

    /// Write `value` to register `1xzzz` at `now`.
    pub fn write(&mut self, now: Instant, z: u16, value: i64) -> WriteEffect {
        self.settle(now);
        let frozen = self.address.is_some();
        match z {
            reg::COMMAND => self.command(now, value),
            reg::ADDRESS => self.write_address(now, value),
            reg::DIAG_LEN => {
                if !(10..=32).contains(&value) {
                    self.raise(ErrorNumber::DiagLength);
                    return WriteEffect::Ignored("diagnosis length must be 10..=32");
                }
                self.diag_len = value as i32;
                self.diag[6] = (value - 6) as u8;
                WriteEffect::Applied
            }
            141..=156 => {
                let i = 2 * (z - reg::DIAG_WORDS) as usize;
                if i < 6 {
                    return WriteEffect::Ignored(
                        "system diagnosis bytes 1..6 are the controller's",
                    );
                }
                let v = value as u16;
                self.diag[i] = v as u8;
                self.diag[i + 1] = (v >> 8) as u8;
                WriteEffect::Applied
            }
            200..=231 => {
                let i = (z - reg::DIAG_BYTES) as usize;
                if i < 6 {
                    return WriteEffect::Ignored(
                        "system diagnosis bytes 1..6 are the controller's",
                    );
                }
                self.diag[i] = value as u8;
                WriteEffect::Applied
            }
            reg::DATA_FIRST..=reg::DATA_LAST => self.write_data(z, value),
            _ if self.layout.get(z).is_some() => {
                if frozen {
                    return WriteEffect::Ignored(
                        "the configuration is frozen once the station address is written (command 5 resets)",
                    );
                }
                *self.layout.field(z).expect("layout register") =
                    value.clamp(i32::MIN as i64, i32::MAX as i64) as i32;
                self.validate();
                self.real_cfg = self.build_real_cfg();
                WriteEffect::Applied
            }
            _ => WriteEffect::Ignored("read-only or reserved register"),
        }
    }

    fn validate(&mut self) {
        match self.layout.check() {
            Ok(()) => self.layout_ok = true,
            Err(e) => {
                self.layout_ok = false;
                self.raise(e);
            }
        }
    }

    fn write_data(&mut self, z: u16, value: i64) -> WriteEffect {
        if !self.layout_ok {
            return WriteEffect::Ignored("the buffer configuration is invalid");
        }
        match self.area(z) {
            None => WriteEffect::Ignored("not in a configured area"),
            Some(Area::Outputs) => WriteEffect::Ignored("output words are written by the master"),
            Some(Area::Record) if self.acyclic_busy => {
                self.acyclic_error = true;
                WriteEffect::Ignored("data-record area locked (status bit 6)")
            }
            Some(_) => {
                *self.mem_mut(z as i32) = value as u16;
                WriteEffect::Applied
            }
        }
    }

    fn write_address(&mut self, now: Instant, value: i64) -> WriteEffect {
        if self.address.is_some() {
            self.raise(ErrorNumber::Address);
            return WriteEffect::Ignored("the station address is already set (command 5 resets)");
        }
        if !(0..=126).contains(&value) {
            self.raise(ErrorNumber::Address);
            return WriteEffect::Ignored("station address out of 0..=126");
        }
        if !self.layout_ok {
            self.raise(ErrorNumber::Address);
            return WriteEffect::Ignored("the buffer configuration is invalid");
        }
        if self.layout.memory() > MEMORY_LIMIT {
            self.init_error = INIT_ERROR_MEMORY;
            self.raise(ErrorNumber::ControllerInit);
            return WriteEffect::Ignored(
                "controller memory too small: IN·3 + OUT·3 + AC > 632 (init error 49)",
            );
        }
        self.address = Some(value as u8);
        self.address_reg = value as i32;
        self.busy_until = Some(now + INIT_TIME);
        WriteEffect::Applied
    }

    fn command(&mut self, now: Instant, value: i64) -> WriteEffect {
        if !(0..=255).contains(&value) {
            return WriteEffect::Ignored("commands are 0..=255");
        }
        let c = value as i32;
        self.command = c;
        match c {
            cmd::RESET => self.reset(now),
            cmd::CLEAR_ERROR => {
                self.error = None;
                self.init_error = 0;
                self.acyclic_error = false;
            }
            cmd::DIAG_STATUS => self.diag_command(DiagKind::Status),
            cmd::DIAG_EXTENDED => self.diag_command(DiagKind::Extended),
            cmd::DIAG_STATIC => self.diag_command(DiagKind::Static),
            cmd::DIAG_ABORT => {
                self.diag_pending = None;
                self.diag_new = false;
            }
            cmd::DS_READ_OK | cmd::DS_READ_NOK => {
                if !self.dsr.pending {
                    return WriteEffect::Ignored("no data-record read is pending");
                }
                self.dsr.pending = false;
                self.dsr.answer = Some(c == cmd::DS_READ_OK);
                self.acyclic_busy = c == cmd::DS_READ_OK;
            }
            cmd::DS_WRITE_OK | cmd::DS_WRITE_NOK => {
                if !self.dsw.pending {
                    return WriteEffect::Ignored("no data-record write is pending");
                }
                self.dsw.pending = false;
                self.dsw.answer = Some(c == cmd::DS_WRITE_OK);
            }
            cmd::SEND_CONSISTENT => {
                let l = self.layout;
                if self.layout_ok && l.cin_words > 0 {
                    for i in 0..l.cin_words {
                        let v = self.mem(l.cin_start + i);
                        *self.mem_mut(l.in_start + l.cin_offset + i) = v;
                    }
                }
                self.cin_sent = false;
                self.cin_copied = true;
            }
            cmd::RECEIVE_CONSISTENT => {
                self.cout_received = false;
                self.cout_wanted = true;
            }
            _ => return WriteEffect::Ignored("not a command of the module"),
        }
        WriteEffect::Applied
    }

    fn diag_command(&mut self, kind: DiagKind) {
        if self.diag_pending.is_some() {
            self.raise(ErrorNumber::DiagPending);
            return;
        }
        if kind == DiagKind::Extended && self.diag_len <= 10 {
            self.raise(ErrorNumber::DiagLength);
            return;
        }
        self.diag_pending = Some(DiagTelegram {
            kind,
            len: self.diag_len as usize,
            bytes: self.diag,
        });
        self.diag_new = true;
    }

    /// Command 5: everything back to the reset values except the error
    /// registers; BUSY for [`INIT_TIME`]; off the bus.
    fn reset(&mut self, now: Instant) {
        let keep = (
            self.error,
            self.init_error,
            self.baud_code,
            self.memory_fault,
        );
        let count = self.error_count;
        *self = Jx2 {
            events: std::mem::take(&mut self.events),
            ..Jx2::new()
        };
        (self.error, self.init_error, self.baud_code, _) = keep;
        self.error_count = count;
        self.command = cmd::RESET;
        self.busy_until = Some(now + INIT_TIME);
        self.restart = true;
        if keep.3 {
            self.raise(ErrorNumber::MemoryTest);
        }
        self.events.note("jx2", "module reset".into());
    }

    // ----- the layout on the bus ----------------------------------------

    /// The configuration the module expects (Get_Cfg): input words
    /// before, in and after the consistent window, then the output words
    /// likewise; at most 16 words per general identifier, consistent
    /// windows over 16 words in one special identifier.
    fn build_real_cfg(&self) -> Vec<u8> {
        let l = &self.layout;
        let mut v = Vec::new();
        let dir = |v: &mut Vec<u8>, words: i32, cwords: i32, offset: i32, input: bool| {
            if !(0..=122).contains(&words) {
                return;
            }
            let (cwords, offset) = if cwords > 0 && cwords + offset <= words {
                (cwords, offset)
            } else {
                (0, words)
            };
            words_ids(v, offset, false, input);
            words_ids(v, cwords, true, input);
            words_ids(v, words - offset - cwords, false, input);
        };
        dir(&mut v, l.in_words, l.cin_words, l.cin_offset, true);
        dir(&mut v, l.out_words, l.cout_words, l.cout_offset, false);
        v
    }

    /// The Chk_Cfg rule (see the module docs); the reason when refused.
    fn check_cfg_bytes(&self, cfg: &[u8]) -> Result<(usize, usize), CfgMismatch> {
        let l = &self.layout;
        let mut inputs = 0usize;
        let mut outputs = 0usize;
        let mut cin: Vec<(usize, usize)> = Vec::new();
        let mut cout: Vec<(usize, usize)> = Vec::new();
        for id in profibus_dp::pdu::cfg::identifiers(cfg) {
            let id = id?;
            if let Some(len) = id.input {
                let n = id.input_bytes();
                if len.consistent {
                    cin.push((inputs, n));
                }
                inputs += n;
            }
            if let Some(len) = id.output {
                let n = id.output_bytes();
                if len.consistent {
                    cout.push((outputs, n));
                }
                outputs += n;
            }
        }
        let want = (
            2 * l.in_words.max(0) as usize,
            2 * l.out_words.max(0) as usize,
        );
        if (inputs, outputs) != want {
            return Err(CfgMismatch::Lengths {
                inputs,
                outputs,
                want,
                words: (l.in_words, l.out_words),
            });
        }
        for (got, words, offset, what) in [
            (cin, l.cin_words, l.cin_offset, "input"),
            (cout, l.cout_words, l.cout_offset, "output"),
        ] {
            if words <= 0 {
                continue;
            }
            let (start, len) = (2 * offset as usize, 2 * words as usize);
            let want = vec![(start, len)];
            if !got.iter().any(|&(o, n)| o <= start && start + len <= o + n) {
                let show = |w: &[(usize, usize)]| match w {
                    [] => "none".to_string(),
                    _ => w
                        .iter()
                        .map(|(o, n)| format!("{} words at word {}", n / 2, o / 2))
                        .collect::<Vec<_>>()
                        .join(", "),
                };
                return Err(CfgMismatch::Consistent {
                    what,
                    got: show(&got),
                    want: show(&want),
                });
            }
        }
        Ok((inputs, outputs))
    }
}

/// Why a Chk_Cfg does not fit the module's register settings.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CfgMismatch {
    /// An identifier does not decode.
    #[error(transparent)]
    Identifier(#[from] profibus_dp::pdu::cfg::CfgError),
    /// The lengths differ from 1x102 / 1x103.
    #[error(
        "the configuration has {inputs} input and {outputs} output bytes, the module {} and {} (1x102 = {}, 1x103 = {})",
        want.0, want.1, words.0, words.1
    )]
    Lengths {
        /// Input bytes configured.
        inputs: usize,
        /// Output bytes configured.
        outputs: usize,
        /// Input and output bytes the module wants.
        want: (usize, usize),
        /// Registers 1x102 and 1x103 (input and output words).
        words: (i32, i32),
    },
    /// No consistent module holds the module's window.
    #[error("consistent {what} identifiers: {got}; the module's window ({want}) must lie inside one of them")]
    Consistent {
        /// `input` or `output`.
        what: &'static str,
        /// The consistent ranges configured.
        got: String,
        /// The module's consistent window.
        want: String,
    },
}

/// Append identifiers for `words` input or output words.
fn words_ids(v: &mut Vec<u8>, mut words: i32, consistent: bool, input: bool) {
    let c = if consistent { 0x80 } else { 0 };
    if consistent && words > 16 {
        while words > 0 {
            let n = words.min(64);
            v.push(if input { 0x40 } else { 0x80 });
            v.push(c | 0x40 | (n - 1) as u8);
            words -= n;
        }
        return;
    }
    while words > 0 {
        let n = words.min(16);
        v.push(c | 0x40 | if input { 0x10 } else { 0x20 } | (n - 1) as u8);
        words -= n;
    }
}

#[cfg(test)]
mod tests;
