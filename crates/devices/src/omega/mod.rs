//! Baumüller PROFIBUS-DP slave option board PBDP-01 for the Omega
//! Drive-Line II (ident 0x00D0), after its manual "Option board
//! PROFIBUS-DP — Slave for Ωmega Drive-Line II", Technical Description and
//! Operating Instructions (Baumüller, document 5.01013.03, edition
//! September 2001; cited as Lnnn = manual line N, see `docs/sources.md`).
//!
//! # Configuration (Chk_Cfg)
//!
//! The modules of `BNF_00D0.GSD` (L1462-1547), with these rules
//! (L569-625, L686): the service data (PKW) module, if present, comes
//! first; the status/control module must be present and precede the
//! value modules; at least one setpoint and one actual value; a
//! standard module (status/control plus values) may only be preceded by
//! the service data module; a block-consistent module (PKW, status and
//! values in one) stands alone; at most 8 setpoints and 8 actual values
//! (one actual value module and one setpoint module, Max_Module = 4).
//! A violation, or counts other than the emulated PLC's si_NR_WR_VALUE /
//! si_NR_RD_VALUE when given ([`Omega::with_counts`], L378), is a
//! configuration fault and sets b_MESSAGE 3 ("setpoint / actual value
//! configuration error").
//!
//! Where the manual contradicts itself:
//!
//! - **0x73** is both the service data module and the standard module
//!   "1 actual value, 1 setpoint" (L630, L649). A 0x73 followed by other
//!   modules is the service data module (it must come first); a 0x73
//!   alone is the standard module, since a service data module alone
//!   (without status/control) would be invalid anyway.
//! - **Block-consistent modules**: table 5.4.3 (L673-680) gives 4/4 =
//!   0xFB, 5/5 = 0xFD, 6/6 = 0xFF, 7/7 = 0xC0,209,209, one step off its
//!   own word counts; the GSD file and the identifier bits give 3/3 =
//!   0xFB … 7/7 = 0xC0,211,211. We follow the bits (= the GSD).
//! - **0xC0,81,67 and 0xC0,213,199** ("8 actual values, 1 setpoint"):
//!   by the standard the first length byte after 0xC0 is the output
//!   length, so they mean 18 (22) words out and 4 (8) words in, the
//!   reverse of the names (L632, L679). Every master and the board's
//!   SPC3 chip size the buffers that way, so the emulation does too: the
//!   modules carry 8 setpoints and 1 actual value.
//!
//! # Cyclic data (L769-837)
//!
//! Inputs: [PKE IND PWE1 PWE2] if configured, status word 1 and 2, actual
//! values 1..n (32 bit each, high word first). Outputs: the same with
//! control words and setpoints. The emulated drive sets status word 1 bit
//! 9 "Remote" (L1333-1347) and follows its setpoints: actual value i is
//! setpoint i (0 where there is no setpoint i); P218 reads actual value
//! 1.
//!
//! # PKW ([`PKW`], L840-1178)
//!
//! PNU 0..999 address the V-controller parameters
//! ([`params::ParamTable`]), 1000..2047 the Omega's DINT array (double
//! word only, commands 1 and 3, L1632-1633, L1241-1246). Errors:
//! unknown PNU 0x0008; word/double-word command that does not match the
//! parameter's format 0x0005 (also command 2 on the array); write to a
//! protected parameter 0x0001; outside min/max 0x0002; IND ≠ 0 outside
//! PBE 0x0003; PBE element other than 1, 2, 5, 6 → 0x0104; minimum or
//! maximum of a double-word parameter → 0x0103 (the PBE response carries
//! only PWE2); PBE on the array → 0x0102; reserved command codes 0x0080;
//! a new command without PKE = 0 before → 0x0101 (the manual names the
//! cause, L1024, but no number). Responses come after a processing delay
//! (default 5 ms; the drive works "at low priority", L967).
//!
//! # Monitoring (L440-490, L1650-1680, L1765-1780, L1905-1925)
//!
//! b_MESSAGE: 2 (field bus error) while no Data_Exchange came for
//! t_TIMEOUT_PB_DP (1000 ms) after data exchange began; 3 after a
//! configuration fault; 4 while a Slave_Diag was answered during data
//! exchange (until the next Data_Exchange). b_ERR bit 7 (cyclic data
//! timeout) when no Data_Exchange came for t_TIMEOUT_CYCLIC (1000 ms),
//! kept until acknowledged (x_QUIT, [`Omega::quit`]). Changes are `status`
//! device events.
//!
//! The board supports sync and freeze (GSD) and takes its address from
//! the rotary switches S40/S41 (hex, L498-511): [`profile`].

pub mod drivecom;
pub mod params;
pub mod profile;

use crate::kit::{EventQueue, InboxSchedule};
use crate::pkw::{Command, Dialect, Pkw, PkwEngine, PkwServer, Reply, PKW_LEN};
use crate::ControlError;
use crate::ControlInbox;
use drivecom::{DeviceControl, DriveState};
use params::ParamTable;
use profibus_dp::pdu::cfg::{identifiers, CfgError};
use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{
    expect_user_prm_len, ClearReason, Device, DeviceEvent, DiagWriter, Features, IoLayout, Reason,
};
use profibus_fdl::Instant;
use std::time::Duration;

/// Omega Drive-Line II option board (Omega manual L871-926): requests 1
/// read, 2 write word, 3 write double word, 4 PBE; responses 1 word, 2
/// double word, 3 description element, 7 error.
pub const PKW: Dialect = Dialect {
    name: "Omega Drive-Line II",
    describe: Some(4),
    resp_element: Some(3),
    reset_required: true,
    not_reset_error: 0x0101,
    errors: &[
        (0x0000, "no error"),
        (0x0001, "cannot change parameter"),
        (0x0002, "value outside MIN / MAX limit"),
        (0x0003, "wrong index entry"),
        (0x0004, "no array"),
        (0x0005, "wrong data type"),
        (0x0006, "no setting permitted"),
        (0x0007, "cannot change description element"),
        (0x0008, "impermissible parameter number"),
        (0x0080, "received uninterpretable command"),
        (0x0081, "no configuration / initialisation performed"),
        (0x0082, "error reading actual value"),
        (0x0083, "error writing setpoint"),
        (0x0084, "actual value configuration error"),
        (0x0085, "setpoint configuration error"),
        (0x0101, "unspecified error"),
        (0x0102, "service not implemented"),
        (0x0103, "parameter format too large for PKW area"),
        (
            0x0104,
            "parameter information does not exist (request via index)",
        ),
    ],
    ..Dialect::BASE
};

/// The ident number (BNF_00D0.GSD).
pub const IDENT: u16 = 0x00D0;

/// `BNF_00D0.GSD` as printed in the manual (Latin-1, with its quirks).
pub const GSD: &[u8] = crate::gsd_files::BNF_00D0;

/// Length of the User_Prm_Data (GSD `User_Prm_Data_Len=5`).
pub const USER_PRM_LEN: usize = 5;

/// Most setpoints and actual values.
pub const MAX_VALUES: usize = 8;

/// First PNU of the Omega's own DINT array.
pub const OMEGA_ARRAY_FIRST: u16 = 1000;
/// Entries of the array (1000..=2047).
pub const OMEGA_ARRAY_LEN: usize = 1048;

/// Default t_TIMEOUT_PB_DP and t_TIMEOUT_CYCLIC.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(1000);

/// Default t_TIMEOUT_SD_DATA (L456).
pub const DEFAULT_SD_TIMEOUT: Duration = Duration::from_millis(5000);

/// b_ERR bit 1: no access to the option board (function block not
/// processing data, L1914).
pub const B_ERR_BOARD_ACCESS: u8 = 1 << 1;

/// b_ERR bit 3: service data access on the option board timeout.
pub const B_ERR_SD_BOARD_TIMEOUT: u8 = 1 << 3;
/// b_ERR bit 4: service data access on the V controller timeout.
pub const B_ERR_SD_CONTROLLER_TIMEOUT: u8 = 1 << 4;

/// P127 "M communication monitoring" value bit that activates process data
/// communication monitoring (L1080-1083).
const P127_MONITORING: i64 = 4;

/// Default PKW processing delay.
pub const DEFAULT_PKW_DELAY: Duration = Duration::from_millis(5);

/// Status word 1 bit 9: remote (PROFIBUS control enabled).
pub const STATUS_REMOTE: u16 = 1 << 9;

/// b_ERR bit 7: cyclic data transmission timeout.
pub const B_ERR_CYCLIC_TIMEOUT: u8 = 1 << 7;

/// The data layout a configuration gives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Layout {
    /// The PKW words come first.
    pub pkw: bool,
    /// Number of setpoints (outputs).
    pub setpoints: usize,
    /// Number of actual values (inputs).
    pub actual_values: usize,
    /// Block-consistent transmission.
    pub block: bool,
}

impl Layout {
    /// Input bytes.
    pub fn input_bytes(&self) -> usize {
        self.pkw as usize * PKW_LEN + 4 + 4 * self.actual_values
    }

    /// Output bytes.
    pub fn output_bytes(&self) -> usize {
        self.pkw as usize * PKW_LEN + 4 + 4 * self.setpoints
    }
}

/// One module of the board's GSD, as the configuration check sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Module {
    Service,
    StatusControl,
    /// Standard module: status/control with (setpoints, actual values).
    Standard(usize, usize),
    /// Block-consistent: PKW, status/control, (setpoints, actual values).
    Block(usize, usize),
    Actual(usize),
    Setpoint(usize),
}

fn module(raw: &[u8], first: bool, alone: bool) -> Option<Module> {
    Some(match raw {
        [0x73] if first && !alone => Module::Service,
        [0x73] => Module::Standard(1, 1),
        [0x71] => Module::StatusControl,
        [0x75] => Module::Standard(2, 2),
        [0x79] => Module::Standard(4, 4),
        [0xC0, 0x51, 0x43] => Module::Standard(8, 1),
        [0xC0, 0x51, 0x51] => Module::Standard(8, 8),
        [0xF7] => Module::Block(1, 1),
        [0xF9] => Module::Block(2, 2),
        [0xFB] => Module::Block(3, 3),
        [0xFD] => Module::Block(4, 4),
        [0xFF] => Module::Block(5, 5),
        [0xC0, 0xD1, 0xD1] => Module::Block(6, 6),
        [0xC0, 0xD3, 0xD3] => Module::Block(7, 7),
        [0xC0, 0xD5, 0xC7] => Module::Block(8, 1),
        [0xC0, 0xD5, 0xD5] => Module::Block(8, 8),
        [b @ 0x51..=0x5F] if b % 2 == 1 => Module::Actual(((b - 0x51) / 2 + 1) as usize),
        [b @ 0x61..=0x6F] if b % 2 == 1 => Module::Setpoint(((b - 0x61) / 2 + 1) as usize),
        _ => return None,
    })
}

/// Why a configuration breaks the board's rules (module docs).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// No identifier.
    #[error("empty configuration")]
    Empty,
    /// The bytes do not decode as identifiers.
    #[error(transparent)]
    Identifier(#[from] CfgError),
    /// An identifier that is no module of the GSD.
    #[error("module {index} ({}) is not a module of BNF_00D0.GSD", hex_list(raw))]
    UnknownModule {
        /// Its position.
        index: usize,
        /// Its bytes.
        raw: Vec<u8>,
    },
    /// A block-consistent module with others.
    #[error("a block-consistent module must not be combined with other modules")]
    BlockCombined,
    /// A standard module after something else than the service data module.
    #[error("a standard module may only be preceded by the service data module")]
    StandardPreceded,
    /// No status / control module where it must be.
    #[error("the status / control module must be present, after the service data module and before the value modules")]
    StatusControl,
    /// Two actual value or two setpoint modules.
    #[error("more than one actual value or setpoint module")]
    TwoValueModules,
    /// Two status / control modules.
    #[error("a second status / control module")]
    SecondStatusControl,
    /// No setpoint or no actual value.
    #[error("at least one setpoint and one actual value must be configured")]
    NoValues,
    /// Counts other than the drive's si_NR_WR_VALUE / si_NR_RD_VALUE.
    #[error("the master configured {} setpoints and {} actual values, the drive has {} and {} (si_NR_WR_VALUE / si_NR_RD_VALUE)", configured.0, configured.1, drive.0, drive.1)]
    Counts {
        /// (setpoints, actual values) configured.
        configured: (usize, usize),
        /// (setpoints, actual values) of the drive.
        drive: (usize, usize),
    },
}

fn hex_list(raw: &[u8]) -> String {
    raw.iter()
        .map(|b| format!("0x{b:02X}"))
        .collect::<Vec<_>>()
        .join(",")
}

/// si_NR_WR_VALUE or si_NR_RD_VALUE outside 1..=8.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CountError {
    /// si_NR_WR_VALUE.
    #[error("si_NR_WR_VALUE {0} outside 1..8 (b_ERR bit 5, setpoint number error)")]
    Setpoints(usize),
    /// si_NR_RD_VALUE.
    #[error("si_NR_RD_VALUE {0} outside 1..8 (b_ERR bit 6, actual value number error)")]
    ActualValues(usize),
}

/// Check a configuration against the board's rules (module docs).
pub fn check_configuration(cfg: &[u8]) -> Result<Layout, ConfigError> {
    let mut raws: Vec<&[u8]> = vec![];
    for id in identifiers(cfg) {
        raws.push(id?.raw);
    }
    if raws.is_empty() {
        return Err(ConfigError::Empty);
    }
    let alone = raws.len() == 1;
    let mut mods = vec![];
    for (i, r) in raws.iter().enumerate() {
        mods.push(
            module(r, i == 0, alone).ok_or_else(|| ConfigError::UnknownModule {
                index: i,
                raw: r.to_vec(),
            })?,
        );
    }
    if let [Module::Block(sp, av)] = mods[..] {
        return Ok(Layout {
            pkw: true,
            setpoints: sp,
            actual_values: av,
            block: true,
        });
    }
    if mods.iter().any(|m| matches!(m, Module::Block(..))) {
        return Err(ConfigError::BlockCombined);
    }
    let pkw = mods[0] == Module::Service;
    let rest = &mods[pkw as usize..];
    if let [Module::Standard(sp, av)] = rest[..] {
        return Ok(Layout {
            pkw,
            setpoints: sp,
            actual_values: av,
            block: false,
        });
    }
    if rest.iter().any(|m| matches!(m, Module::Standard(..))) {
        return Err(ConfigError::StandardPreceded);
    }
    if rest.first() != Some(&Module::StatusControl) {
        return Err(ConfigError::StatusControl);
    }
    let (mut sp, mut av) = (0usize, 0usize);
    for m in &rest[1..] {
        match *m {
            Module::Actual(n) if av == 0 => av = n,
            Module::Setpoint(n) if sp == 0 => sp = n,
            Module::Actual(_) | Module::Setpoint(_) => return Err(ConfigError::TwoValueModules),
            Module::StatusControl => return Err(ConfigError::SecondStatusControl),
            Module::Service => unreachable!("0x73 after the first module is a standard module"),
            Module::Standard(..) | Module::Block(..) => unreachable!("handled above"),
        }
    }
    if sp == 0 || av == 0 {
        return Err(ConfigError::NoValues);
    }
    Ok(Layout {
        pkw,
        setpoints: sp,
        actual_values: av,
        block: false,
    })
}

/// The drive's parameters: the PKW server.
#[derive(Debug, Clone)]
struct Drive {
    table: ParamTable,
    values: Vec<i64>,
    array: Vec<u32>,
    actual1: Option<u32>,
    /// x_EN of PB_COMM_SLAVE: the PLC's function blocks run.
    running: bool,
    /// 0x0084 / 0x0085 after a count mismatch (L920-921, L1298-1299).
    count_error: Option<u16>,
    /// V-controller parameters parameterised as cyclic setpoints or
    /// actual values (BAPS): not reachable by service data (L1020, L1062).
    cyclic: Vec<u16>,
    /// The V controller does not answer within t_TIMEOUT_SD_DATA.
    timed_out: bool,
}

const E_CANNOT_CHANGE: u16 = 0x0001;
const E_MIN_MAX: u16 = 0x0002;
const E_INDEX: u16 = 0x0003;
const E_TYPE: u16 = 0x0005;
const E_PNU: u16 = 0x0008;
const E_UNINTERPRETABLE: u16 = 0x0080;
const E_NOT_INITIALISED: u16 = 0x0081;
const E_READ_ACTUAL: u16 = 0x0082;
const E_WRITE_SETPOINT: u16 = 0x0083;
/// PKW error: the master configured other actual values than
/// si_NR_RD_VALUE.
pub const E_ACTUAL_CONFIG: u16 = 0x0084;
/// PKW error: the master configured other setpoints than si_NR_WR_VALUE.
pub const E_SETPOINT_CONFIG: u16 = 0x0085;
const E_NOT_IMPLEMENTED: u16 = 0x0102;
const E_TOO_LARGE: u16 = 0x0103;
const E_NO_INFO: u16 = 0x0104;

/// P218 "L rev actual value".
const P_REV_ACTUAL: u16 = 218;

impl PkwServer for Drive {
    fn execute(&mut self, _now: Instant, pnu: u16, ind: u16, cmd: Command) -> Result<Reply, u16> {
        if matches!(cmd, Command::Unsupported(_)) {
            return Err(E_UNINTERPRETABLE);
        }
        // "Function blocks PB_COMM_SLAVE and / or BAPS_SD_CONTROL not run"
        // (L1023, L1070): no initialisation performed.
        if !self.running {
            return Err(E_NOT_INITIALISED);
        }
        // "Errors are indicated … in the service data communication PWE
        // area" after a configuration mismatch (L1298-1299, L1197).
        if let Some(e) = self.count_error {
            return Err(e);
        }
        // Reading goes to the controller as "actual value", writing as
        // "setpoint" (L1045-1047, L1096-1097): a parameter that is mapped
        // cyclically (L1020, L1067) or a controller that does not answer
        // in time (t_TIMEOUT_SD_DATA, L1195) gives 0x0082 / 0x0083.
        let write = matches!(cmd, Command::WriteWord(_) | Command::WriteDword(_));
        if self.timed_out || (pnu < OMEGA_ARRAY_FIRST && self.cyclic.contains(&pnu)) {
            return Err(if write {
                E_WRITE_SETPOINT
            } else {
                E_READ_ACTUAL
            });
        }
        let plain = !matches!(cmd, Command::Describe(_));
        if plain && ind != 0 {
            return Err(E_INDEX);
        }
        if pnu >= OMEGA_ARRAY_FIRST {
            let i = (pnu - OMEGA_ARRAY_FIRST) as usize;
            return match cmd {
                Command::Read => Ok(Reply::Dword(self.array[i])),
                Command::WriteDword(v) => {
                    self.array[i] = v;
                    Ok(Reply::Dword(v))
                }
                Command::WriteWord(_) => Err(E_TYPE),
                _ => Err(E_NOT_IMPLEMENTED),
            };
        }
        let Some(idx) = self.table.params.iter().position(|p| p.pnu == pnu) else {
            return Err(E_PNU);
        };
        let p = &self.table.params[idx];
        let value = if pnu == P_REV_ACTUAL {
            self.actual1.map_or(self.values[idx], |v| p.from_raw(v))
        } else {
            self.values[idx]
        };
        match cmd {
            Command::Read if p.dword => Ok(Reply::Dword(p.raw(value))),
            Command::Read => Ok(Reply::Word(p.raw(value) as u16)),
            Command::WriteWord(_) if p.dword => Err(E_TYPE),
            Command::WriteDword(_) if !p.dword => Err(E_TYPE),
            Command::WriteWord(_) | Command::WriteDword(_) if p.protected => Err(E_CANNOT_CHANGE),
            Command::WriteWord(w) => {
                let v = p.from_raw(w as u32);
                if v < p.min || v > p.max {
                    return Err(E_MIN_MAX);
                }
                self.values[idx] = v;
                Ok(Reply::Word(w))
            }
            Command::WriteDword(d) => {
                let v = p.from_raw(d);
                if v < p.min || v > p.max {
                    return Err(E_MIN_MAX);
                }
                self.values[idx] = v;
                Ok(Reply::Dword(d))
            }
            Command::Describe(1) => Ok(Reply::Element(p.attribute())),
            Command::Describe(2) => Ok(Reply::Element(p.info())),
            Command::Describe(5 | 6) if p.dword => Err(E_TOO_LARGE),
            Command::Describe(5) => Ok(Reply::Element(p.raw(p.min) as u16)),
            Command::Describe(6) => Ok(Reply::Element(p.raw(p.max) as u16)),
            Command::Describe(_) => Err(E_NO_INFO),
            _ => Err(E_UNINTERPRETABLE),
        }
    }
}

/// The Omega Drive-Line II option board; see the module docs.
#[derive(Debug)]
pub struct Omega {
    drive: Drive,
    counts: Option<(usize, usize)>,
    cfg: Vec<u8>,
    layout: Option<Layout>,
    engine: PkwEngine,
    control: [u16; 2],
    setpoints: [u32; MAX_VALUES],
    actual: [u32; MAX_VALUES],
    device_control: DeviceControl,
    b_message: i8,
    /// A warning b_MESSAGE −1 or −2 set by control `warn` (0: none).
    warning: i8,
    /// The PLC has no access to the option board (control `board off`).
    board_lost: bool,
    b_err: u8,
    t_pb_dp: Duration,
    t_cyclic: Duration,
    t_sd: Duration,
    pkw_delay: Duration,
    /// A service data job the controller does not answer: when b_ERR
    /// gets its timeout bit, and which bit.
    sd_timeout: Option<(Instant, u8)>,
    auto_enable: bool,
    last_exchange: Option<Instant>,
    events: EventQueue,
    inbox: InboxSchedule,
}

/// The default Get_Cfg before a configuration: service data,
/// status/control, 2 actual values, 2 setpoints.
const DEFAULT_CFG: [u8; 4] = [0x73, 0x71, 0x53, 0x63];

impl Omega {
    /// A board with the V-controller parameter set `table`, accepting any
    /// valid configuration.
    pub fn new(table: ParamTable) -> Omega {
        let values = table.params.iter().map(|p| p.default).collect();
        Omega {
            drive: Drive {
                table,
                values,
                array: vec![0; OMEGA_ARRAY_LEN],
                actual1: None,
                running: true,
                count_error: None,
                cyclic: vec![],
                timed_out: false,
            },
            counts: None,
            cfg: DEFAULT_CFG.to_vec(),
            layout: None,
            engine: PkwEngine::new(&PKW, DEFAULT_PKW_DELAY),
            control: [0; 2],
            setpoints: [0; MAX_VALUES],
            actual: [0; MAX_VALUES],
            device_control: DeviceControl::new(),
            b_message: 0,
            warning: 0,
            board_lost: false,
            b_err: 0,
            t_pb_dp: DEFAULT_TIMEOUT,
            t_cyclic: DEFAULT_TIMEOUT,
            t_sd: DEFAULT_SD_TIMEOUT,
            pkw_delay: DEFAULT_PKW_DELAY,
            sd_timeout: None,
            auto_enable: false,
            last_exchange: None,
            events: EventQueue::default(),
            inbox: InboxSchedule::default(),
        }
    }

    /// The board with the shipped default parameter set: what `dpctl
    /// demo` runs.
    pub fn with_defaults() -> Omega {
        Omega::new(ParamTable::default_table())
    }

    /// Require exactly `setpoints` setpoints and `actual_values` actual
    /// values (si_NR_WR_VALUE / si_NR_RD_VALUE, 1..=8).
    pub fn with_counts(
        mut self,
        setpoints: usize,
        actual_values: usize,
    ) -> Result<Omega, CountError> {
        if !(1..=MAX_VALUES).contains(&setpoints) {
            return Err(CountError::Setpoints(setpoints));
        }
        if !(1..=MAX_VALUES).contains(&actual_values) {
            return Err(CountError::ActualValues(actual_values));
        }
        self.counts = Some((setpoints, actual_values));
        Ok(self)
    }

    /// Set t_TIMEOUT_PB_DP and t_TIMEOUT_CYCLIC (zero: off).
    pub fn with_timeouts(mut self, pb_dp: Duration, cyclic: Duration) -> Omega {
        self.t_pb_dp = pb_dp;
        self.t_cyclic = cyclic;
        self
    }

    /// Set the PKW processing delay: how long the V controller takes to
    /// answer a service data job. Longer than t_TIMEOUT_SD_DATA, every
    /// job times out ([`Omega::with_sd_timeout`]).
    pub fn with_pkw_delay(mut self, delay: Duration) -> Omega {
        self.pkw_delay = delay;
        self.engine = PkwEngine::new(&PKW, delay);
        self
    }

    /// Set t_TIMEOUT_SD_DATA (default 5000 ms, zero: off; L456,
    /// L1667-1673). A job the controller does not answer within it is
    /// answered with 0x0082 (read) or 0x0083 (write) at the timeout, and
    /// b_ERR bit 4 (V controller) or bit 3 (the Omega's array) is set.
    pub fn with_sd_timeout(mut self, timeout: Duration) -> Omega {
        self.t_sd = timeout;
        self
    }

    /// Parameterise V-controller parameters `pnus` as cyclic setpoints or
    /// actual values: service data on them answer 0x0082 / 0x0083.
    pub fn with_cyclic_parameters(mut self, pnus: Vec<u16>) -> Omega {
        self.drive.cyclic = pnus;
        self
    }

    /// Let the Omega's own program enable the drive (shutdown, then
    /// enable operation) instead of the master's control word 1; the
    /// master's fault-reset bit still resets a fault. For plants that only
    /// want a drive that follows its setpoints.
    pub fn with_auto_enable(mut self) -> Omega {
        self.auto_enable = true;
        self
    }

    /// The drive's device control state.
    pub fn drive_state(&self) -> DriveState {
        self.device_control.state()
    }

    /// Status word 1 as sent.
    pub fn status_word(&self) -> u16 {
        let remote = if self.drive.running { STATUS_REMOTE } else { 0 };
        self.device_control.status_word() | remote
    }

    /// A controller fault with error number `code` (16#0003: process
    /// data timeout, 16#0004: service data timeout, L1195-1196; any other
    /// from the control input).
    pub fn fault(&mut self, code: u16) {
        if let Some(s) = self.device_control.fault(code) {
            self.events.note("drive", s.to_string());
        }
    }

    /// x_EN of the PLC's PB_COMM_SLAVE: off, the remote bit is 0 (L1366)
    /// and service data answer 0x0081.
    pub fn set_plc_running(&mut self, on: bool) {
        self.drive.running = on;
    }

    /// Read control commands from `inbox` (see [`Omega::control`]).
    pub fn with_inbox(mut self, inbox: ControlInbox) -> Omega {
        self.inbox.set(inbox);
        self
    }

    /// The layout of the accepted configuration.
    pub fn layout(&self) -> Option<Layout> {
        self.layout
    }

    /// b_MESSAGE.
    pub fn b_message(&self) -> i8 {
        self.b_message
    }

    /// b_ERR.
    pub fn b_err(&self) -> u8 {
        self.b_err
    }

    /// Control words 1 and 2 last received.
    pub fn control_words(&self) -> [u16; 2] {
        self.control
    }

    /// Setpoint `i` (0-based) last received.
    pub fn setpoint(&self, i: usize) -> Option<u32> {
        self.setpoints.get(i).copied()
    }

    /// The value of V-controller parameter `pnu`.
    pub fn parameter(&self, pnu: u16) -> Option<i64> {
        let i = self.drive.table.params.iter().position(|p| p.pnu == pnu)?;
        Some(self.drive.values[i])
    }

    /// Entry `pnu` (1000..=2047) of the Omega's DINT array.
    pub fn omega_value(&self, pnu: u16) -> Option<i32> {
        let i = pnu.checked_sub(OMEGA_ARRAY_FIRST)? as usize;
        self.drive.array.get(i).map(|v| *v as i32)
    }

    /// x_QUIT: acknowledge b_ERR bits whose cause is gone.
    pub fn quit(&mut self) {
        let kept = if self.board_lost {
            B_ERR_BOARD_ACCESS
        } else {
            0
        };
        if self.b_err != kept {
            self.b_err = kept;
            self.report();
        }
        self.refresh_message();
    }

    /// The PLC loses (`false`) or regains (`true`) access to the option
    /// board: b_ERR bit 1 (L1914) and b_MESSAGE 1; x_QUIT clears the bit
    /// once access is back.
    pub fn set_board_access(&mut self, ok: bool) {
        self.board_lost = !ok;
        if !ok && self.b_err & B_ERR_BOARD_ACCESS == 0 {
            self.b_err |= B_ERR_BOARD_ACCESS;
            self.report();
        }
        self.refresh_message();
    }

    /// Set the warning b_MESSAGE −1 (general) or −2 (wire breakage), or
    /// none (0). The manual lists them (L1776-1777) without a cause, so
    /// they are set on demand; errors (1..4) take precedence.
    pub fn set_warning(&mut self, warning: i8) {
        self.warning = warning;
        self.refresh_message();
    }

    /// b_MESSAGE when no event-driven message (2, 3, 4) stands: 1
    /// (general error) while b_ERR bit 0 or 1 says the function block
    /// processes no data; else a warning set by [`Omega::set_warning`];
    /// else −3 (timeout warning) while a service data timeout (b_ERR bit 3
    /// or 4) is not acknowledged, since cyclic data go on; else 0
    /// (L1769-1779, L1912-1919; the pairing is this project's reading).
    fn idle_message(&self) -> i8 {
        if self.b_err & 0b11 != 0 {
            1
        } else if self.warning != 0 {
            self.warning
        } else if self.b_err & (B_ERR_SD_BOARD_TIMEOUT | B_ERR_SD_CONTROLLER_TIMEOUT) != 0 {
            -3
        } else {
            0
        }
    }

    fn refresh_message(&mut self) {
        if !matches!(self.b_message, 2..=4) {
            self.set_message(self.idle_message());
        }
    }

    /// b_MESSAGE and b_ERR in words.
    pub fn status_text(&self) -> String {
        let m = match self.b_message {
            0 => "no warning, no error",
            1 => "general error",
            2 => "field bus error",
            3 => "setpoint / actual value configuration error",
            4 => "diagnostic function active",
            -1 => "general warning",
            -2 => "wire breakage warning",
            -3 => "timeout warning",
            _ => "reserved",
        };
        let mut s = format!(
            "b_MESSAGE {} ({m}), b_ERR 16#{:02X}",
            self.b_message, self.b_err
        );
        for (bit, text) in [
            (B_ERR_BOARD_ACCESS, "no access to option board"),
            (
                B_ERR_SD_BOARD_TIMEOUT,
                "service data access on option board timeout",
            ),
            (
                B_ERR_SD_CONTROLLER_TIMEOUT,
                "service data access on V controller timeout",
            ),
            (B_ERR_CYCLIC_TIMEOUT, "cyclic data transmission timeout"),
        ] {
            if self.b_err & bit != 0 {
                s.push_str(&format!(" ({text})"));
            }
        }
        s.push_str(&format!(
            ", drive {}, status word 1 16#{:04X}",
            self.drive_state(),
            self.status_word()
        ));
        s
    }

    /// Execute a control command: `status`, `quit` (x_QUIT), `get P`,
    /// `fault [CODE]` (a controller fault, default 16#0001), `plc on|off`
    /// (x_EN), `cyclic P… | none` (parameters mapped cyclically),
    /// `sd-delay MS` (the controller's service data answer time),
    /// `board on|off` (the PLC's access to the option board, b_ERR bit 1),
    /// `warn general|wire-break|none` (b_MESSAGE −1 / −2).
    pub fn control(&mut self, line: &str) -> Result<String, ControlError> {
        let arg = |m: String| ControlError::Argument(m);
        let mut w = line.split_whitespace();
        match w.next().unwrap_or("") {
            "status" => Ok(self.status_text()),
            "quit" => {
                self.quit();
                Ok(self.status_text())
            }
            "fault" => {
                let code = match w.next() {
                    None => 1,
                    Some(c) => parse_code(c)
                        .ok_or_else(|| arg(format!("fault code `{c}`: give 0..0xFFFF")))?,
                };
                self.fault(code);
                Ok(self.status_text())
            }
            "plc" => {
                match w.next() {
                    Some("on") => self.set_plc_running(true),
                    Some("off") => self.set_plc_running(false),
                    _ => return Err(arg("plc on|off".into())),
                }
                Ok(self.status_text())
            }
            "cyclic" => {
                let mut pnus = vec![];
                for p in w {
                    if p == "none" {
                        continue;
                    }
                    pnus.push(
                        p.trim_start_matches('P')
                            .parse::<u16>()
                            .ok()
                            .filter(|p| *p < OMEGA_ARRAY_FIRST)
                            .ok_or_else(|| {
                                arg(format!("`{p}`: give V-controller parameters P0..P999"))
                            })?,
                    );
                }
                let t = format!("cyclic parameters: {pnus:?}");
                self.drive.cyclic = pnus;
                Ok(t)
            }
            "board" => {
                match w.next() {
                    Some("on") => self.set_board_access(true),
                    Some("off") => self.set_board_access(false),
                    _ => return Err(arg("board on|off".into())),
                }
                Ok(self.status_text())
            }
            "warn" => {
                let m = match w.next() {
                    Some("general") => -1,
                    Some("wire-break") => -2,
                    Some("none") => 0,
                    _ => return Err(arg("warn general|wire-break|none".into())),
                };
                self.set_warning(m);
                Ok(self.status_text())
            }
            "sd-delay" => {
                let ms: u64 = w
                    .next()
                    .and_then(|m| m.parse().ok())
                    .ok_or_else(|| arg("sd-delay MS".into()))?;
                self.pkw_delay = Duration::from_millis(ms);
                Ok(format!("service data answer time {ms} ms"))
            }
            "get" => {
                let p: u16 = w
                    .next()
                    .and_then(|p| p.trim_start_matches('P').parse().ok())
                    .ok_or_else(|| arg("give a parameter number".into()))?;
                if p >= OMEGA_ARRAY_FIRST {
                    self.omega_value(p)
                        .map(|v| format!("P{p} = {v}"))
                        .ok_or_else(|| arg(format!("no parameter {p}")))
                } else {
                    self.parameter(p)
                        .map(|v| format!("P{p:03} = {v}"))
                        .ok_or_else(|| arg(format!("no parameter {p}")))
                }
            }
            other => Err(ControlError::Unknown {
                command: other.into(),
                known: "status, quit, get P, fault [CODE], plc on|off, cyclic P…|none, sd-delay MS, board on|off, warn general|wire-break|none",
            }),
        }
    }

    fn report(&mut self) {
        let t = self.status_text();
        self.events.note("status", t);
    }

    fn set_message(&mut self, m: i8) {
        if self.b_message != m {
            self.b_message = m;
            self.report();
        }
    }

    fn deadlines(&self) -> (Option<Instant>, Option<Instant>) {
        let Some(last) = self.last_exchange else {
            return (None, None);
        };
        let pb = (!self.t_pb_dp.is_zero() && self.b_message != 2).then(|| last + self.t_pb_dp);
        let cyc = (!self.t_cyclic.is_zero() && self.b_err & B_ERR_CYCLIC_TIMEOUT == 0)
            .then(|| last + self.t_cyclic);
        (pb, cyc)
    }

    fn monitoring(&self) -> bool {
        self.parameter(127)
            .is_some_and(|v| v & P127_MONITORING != 0)
    }

    fn on_control_word(&mut self, cw: u16) {
        let cws: &[u16] = if self.auto_enable && cw != 0 {
            &[0x06 | (cw & 0x80), 0x0F | (cw & 0x80)]
        } else if self.auto_enable {
            &[0x06, 0x0F]
        } else {
            &[cw]
        };
        for &cw in cws {
            if let Some(s) = self.device_control.on_control(cw) {
                self.events.note("drive", s.to_string());
            }
        }
    }
}

impl Omega {
    /// Setpoints and actual values are exchanged: the PLC runs and the
    /// configuration matches its counts.
    fn transmits(&self) -> bool {
        self.drive.running && self.drive.count_error.is_none()
    }
}

/// `0x…`, `16#…` or decimal.
fn parse_code(s: &str) -> Option<u16> {
    if let Some(h) = s.strip_prefix("0x").or_else(|| s.strip_prefix("16#")) {
        u16::from_str_radix(h, 16).ok()
    } else {
        s.parse().ok()
    }
}

fn be32(b: &[u8]) -> u32 {
    u32::from_be_bytes([b[0], b[1], b[2], b[3]])
}

impl Device for Omega {
    fn ident_number(&self) -> u16 {
        IDENT
    }

    fn real_cfg(&self) -> &[u8] {
        &self.cfg
    }

    fn features(&self) -> Features {
        Features {
            sync: true,
            freeze: true,
            max_diag_len: 16,
            ..Features::default()
        }
    }

    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        expect_user_prm_len(prm, USER_PRM_LEN)?;
        Ok(())
    }

    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        // A configuration against the GSD rules is refused (the board's
        // SPC3 and the GSD); one that only differs from the PLC's
        // si_NR_WR_VALUE / si_NR_RD_VALUE is accepted on the bus, and then
        // "setpoint / actual value transmission stops", b_MESSAGE is 3 and
        // the PKW area answers 0x0084 / 0x0085 (L378, L920-921, L1197,
        // L1298-1299).
        match check_configuration(cfg) {
            Ok(l) => {
                self.layout = Some(l);
                self.cfg = cfg.to_vec();
                self.engine.reset();
                self.drive.count_error = match self.counts {
                    Some((_, av)) if av != l.actual_values => Some(E_ACTUAL_CONFIG),
                    Some((sp, _)) if sp != l.setpoints => Some(E_SETPOINT_CONFIG),
                    _ => None,
                };
                if let (Some(code), Some(drive)) = (self.drive.count_error, self.counts) {
                    let e = ConfigError::Counts {
                        configured: (l.setpoints, l.actual_values),
                        drive,
                    };
                    self.set_message(3);
                    self.events.note(
                        "status",
                        format!(
                            "{e}: no setpoint / actual value transmission, PKW error 16#{code:04X}"
                        ),
                    );
                } else if self.b_message == 3 {
                    self.set_message(self.idle_message());
                }
                Ok(IoLayout {
                    inputs: l.input_bytes(),
                    outputs: l.output_bytes(),
                })
            }
            Err(e) => {
                self.layout = None;
                self.set_message(3);
                Err(
                    format!("setpoint / actual value configuration error (b_MESSAGE 3): {e}")
                        .into(),
                )
            }
        }
    }

    fn write_outputs(&mut self, now: Instant, outputs: &[u8]) {
        let Some(l) = self.layout else { return };
        self.last_exchange = Some(now);
        if matches!(self.b_message, 2 | 4) {
            self.set_message(self.idle_message());
        }
        let mut at = 0;
        if l.pkw {
            if let Some(req) = Pkw::parse(outputs) {
                // The controller answers after `pkw_delay`; beyond
                // t_TIMEOUT_SD_DATA the board gives up at the timeout.
                let late = !self.t_sd.is_zero() && self.pkw_delay > self.t_sd;
                self.drive.timed_out = late;
                self.engine
                    .set_delay(if late { self.t_sd } else { self.pkw_delay });
                if let Some(job) = self.engine.on_request(now, req, &mut self.drive) {
                    self.events
                        .note("pkw", format!("PKW {} -> {}", job.request, job.response));
                    if late && self.drive.running && self.drive.count_error.is_none() {
                        let bit = if req.pnu() >= OMEGA_ARRAY_FIRST {
                            B_ERR_SD_BOARD_TIMEOUT
                        } else {
                            B_ERR_SD_CONTROLLER_TIMEOUT
                        };
                        self.sd_timeout = Some((now + self.t_sd, bit));
                    }
                }
                self.drive.timed_out = false;
            }
            at = PKW_LEN;
        }
        let Some(cw) = outputs.get(at..at + 4) else {
            return;
        };
        if !self.transmits() {
            return;
        }
        self.control = [
            u16::from_be_bytes([cw[0], cw[1]]),
            u16::from_be_bytes([cw[2], cw[3]]),
        ];
        self.on_control_word(self.control[0]);
        for i in 0..l.setpoints {
            if let Some(b) = outputs.get(at + 4 + 4 * i..at + 8 + 4 * i) {
                self.setpoints[i] = be32(b);
            }
        }
        // The actual values follow the setpoints only in "operation
        // enabled"; elsewhere they keep their last value.
        if self.device_control.operation_enabled() {
            for i in 0..MAX_VALUES {
                self.actual[i] = if i < l.setpoints {
                    self.setpoints[i]
                } else {
                    0
                };
            }
        }
        self.drive.actual1 = Some(self.actual[0]);
    }

    fn read_inputs(&mut self, now: Instant, inputs: &mut [u8]) {
        let Some(l) = self.layout else { return };
        let mut at = 0;
        if l.pkw {
            self.engine.response(now).emit(inputs);
            at = PKW_LEN;
        }
        if !self.transmits() {
            return;
        }
        let status1 = self.status_word();
        let status2 = 0u16;
        if let Some(sw) = inputs.get_mut(at..at + 4) {
            sw[..2].copy_from_slice(&status1.to_be_bytes());
            sw[2..].copy_from_slice(&status2.to_be_bytes());
        }
        for i in 0..l.actual_values {
            let v = self.actual[i];
            if let Some(b) = inputs.get_mut(at + 4 + 4 * i..at + 8 + 4 * i) {
                b.copy_from_slice(&v.to_be_bytes());
            }
        }
    }

    fn clear_outputs(&mut self, _now: Instant, _why: ClearReason) {
        self.control = [0; 2];
        self.setpoints = [0; MAX_VALUES];
        // Control word 0 is "disable voltage".
        if let Some(s) = self.device_control.on_control(0) {
            self.events.note("drive", s.to_string());
        }
        self.engine.reset();
        self.sd_timeout = None;
    }

    fn diagnosis(&mut self, _now: Instant, _diag: &mut DiagWriter<'_>) {
        // "Process data communication is halted for this function" (L1182):
        // a diagnosis read during data exchange is b_MESSAGE 4.
        if self.last_exchange.is_some() && self.layout.is_some() && self.b_message <= 0 {
            self.set_message(4);
            // "If communication monitoring is activated …, activation of
            // this diagnostic function triggers an error response" (L1186).
            if self.monitoring() {
                self.fault(0x0003);
            }
        }
    }

    fn poll_event(&mut self) -> Option<DeviceEvent> {
        self.events.pop()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let (pb, cyc) = self.deadlines();
        let inbox = self.inbox.deadline();
        // The PKW engine needs no wake-up: a held response is shown by the
        // first read_inputs after its time.
        let sd = self.sd_timeout.map(|(t, _)| t);
        [pb, cyc, inbox, sd].into_iter().flatten().min()
    }

    fn handle_timeout(&mut self, now: Instant) {
        let (pb, cyc) = self.deadlines();
        if pb.is_some_and(|t| now >= t) {
            self.set_message(2);
        }
        if cyc.is_some_and(|t| now >= t) {
            self.b_err |= B_ERR_CYCLIC_TIMEOUT;
            self.report();
            // P127 = 4: the controller signals the process data timeout as
            // error 16#0003 (L1080-1083, L1195).
            if self.monitoring() {
                self.fault(0x0003);
            }
        }
        if let Some((_, bit)) = self.sd_timeout.filter(|(t, _)| now >= *t) {
            self.sd_timeout = None;
            self.b_err |= bit;
            self.report();
            self.refresh_message();
        }
        for line in self.inbox.due(now) {
            match self.control(&line) {
                Ok(t) => self.events.note("control", t),
                Err(e) => self.events.note("control_error", e.to_string()),
            }
        }
    }
}

#[cfg(test)]
mod tests;
