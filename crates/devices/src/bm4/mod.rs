//! Baumüller b maXX PLC option module BM4-O-PRO-01 (PROFIBUS-DP slave,
//! ident 0x0008), after its Applikationshandbuch "BM4-O-PRO-01
//! Optionsmodul PROFIBUS-DP-Slave für b maXX PLC" (Baumüller, document
//! 5.03058.03, Stand 27.07.2015; cited as Lnnn = manual line N, see
//! `docs/sources.md`).
//!
//! The emulated PLC's **variable table** ([`vars::VarTable`], a TOML file)
//! is the device's configuration, as the manual's "PROFIBUS-PLC-Slave
//! Konfigurator" defines it: each variable is a module whose identifier
//! carries its parameter number; the GSD file is generated from it
//! ([`Bm4::gsd_text`]). Without a table the device has the default
//! configuration of `BM4OPRO1.GSD`.
//!
//! # Behaviour and the choices made where the manual is silent or
//! contradicts itself
//!
//! - **Chk_Cfg** must consist of modules of the table, each at most once,
//!   in any order, optionally preceded by the PKW module 0x73 (only as
//!   the first module, L1473, L1490); with the default table also the
//!   "all modules" compact module. Anything else is a configuration
//!   fault, with the LED state "configuration error" (L2057-2059). The
//!   manual does not describe the check; this is the
//!   strictest reading that accepts everything a master can build from
//!   the generated GSD.
//! - **Process data** follow the configured modules in Chk_Cfg order,
//!   after the 8 PKW bytes if configured, each element in Motorola byte
//!   order (L1224-1226). Consistency over all modules (L1237) holds by
//!   construction: the slave takes and gives whole telegrams.
//! - **PKW** ([`PKW`], L1492-1647): PNU = parameter number.
//!   Variables of 1 or 2 bytes per element use the word commands (value
//!   in PWE2, PWE1 = 0; SINT/INT sign-extended to 16 bits), 4-byte
//!   variables the double-word commands. Error numbers: variable number
//!   not in the table → 0x000B; write to an INPUT variable → 0x0001;
//!   word command on a 4-byte variable or double-word command on a
//!   shorter one, a plain command on an array or an element command on a
//!   single variable → 0x0005; a word value outside the variable's type
//!   range (e.g. 300 for a USINT) → 0x0005, as the manual has no range
//!   error; element index beyond the array or IND ≠ 0 for a plain
//!   command → 0x0003; AK 4 (PBE, "not supported", L1520) and every
//!   reserved AK → 0x0016. A variable configured as cyclic process data
//!   is answered with an error (L1190, L1566) whose number the manual
//!   does not give: we answer 0x000B ("address": the variable is not
//!   addressable by PKW while it is cyclic). Write responses mirror the
//!   value (L1637). Jobs are answered in the next cycle.
//! - **Diagnosis**: the module's own 6 standard bytes; a user diagnosis
//!   ([`Bm4::sdiag`], the PLC's FB SDIAG, L1826-1983) adds a
//!   device-related block: its header byte is the 7th byte and the user
//!   bytes start at the 8th (L1310, L1852; L1363's "9th byte" counts
//!   differently in a master's display and is not followed). SDIAG sets
//!   Ext_Diag (x_ED_FLAG must be TRUE, else error 16#82 01 01) and, with
//!   x_ED_OV, Ext_Diag_Overflow; it is announced with "data high" and
//!   `sdiag_ok` (x_OK) becomes true once a master fetched it (L1294-1300).
//!   A second SDIAG before the first was fetched is refused with 16#80
//!   B6 00 ("diag send currently impossible"). The user block stays in
//!   every later diagnosis until [`Bm4::sdiag_clear`].
//! - **Station address** ([`Addressing`], L779-861, L1730-1747).
//! - **Status** in words of the module's LEDs ([`Led`], L1158-1166,
//!   L2041-2049), reported as `led` device events.
//! - Baud rates as the GSD says (9.6 k … 12 M, L2214-2222), found by the
//!   slave's auto-baud; sync and freeze are not supported (GSD).

pub mod profile;
pub mod vars;

use crate::address::{AddressFileError, StoredAddress};
use crate::kit::{EventQueue, InboxSchedule};
use crate::pkw::{Command, Dialect, Pkw, PkwEngine, PkwServer, Reply, PKW_LEN, PKW_MODULE};
use crate::{ControlError, ControlInbox};
use profibus_dp::config::gsd::{decode_latin1, Gsd, ParseOptions};
use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{
    expect_user_prm_len, ClearReason, Device, DeviceEvent, DiagWriter, Features, IoLayout, Reason,
};
use profibus_fdl::{Baud, Instant};
use std::path::{Path, PathBuf};
use std::time::Duration;
use vars::{IecType, VarModule, VarTable, Variable};

/// BM4-O-PRO-01 (BM4 manual L1514-1560): requests 1 read, 2 write word,
/// 3 write double word, 4 PBE (not supported), 6 array element read,
/// 7/8 array element write word/double word; responses 1 word, 2 double
/// word, 4/5 array element word/double word, 7 error.
pub const PKW: Dialect = Dialect {
    name: "BM4-O-PRO-01",
    read_element: Some(6),
    write_element_word: Some(7),
    write_element_dword: Some(8),
    resp_element_word: Some(4),
    resp_element_dword: Some(5),
    errors: &[
        (0x0001, "read only (the variable is an INPUT module)"),
        (0x0003, "array subindex does not exist"),
        (
            0x0005,
            "incorrect type (the variable's format is not the command's)",
        ),
        (
            0x000B,
            "variable does not exist (or is configured as cyclic process data)",
        ),
        (0x0016, "unknown command code"),
    ],
    ..Dialect::BASE
};

/// The ident number (GSD L2205).
pub const IDENT: u16 = 0x0008;

/// The default GSD file `BM4OPRO1.GSD` as printed in the manual (Latin-1).
pub const DEFAULT_GSD: &[u8] = crate::gsd_files::BM4OPRO1;

/// Length of the User_Prm_Data (GSD `User_Prm_Data_Len=3`).
pub const USER_PRM_LEN: usize = 3;

/// Most user diagnosis bytes (FB SDIAG i_LEN, L1876).
pub const SDIAG_MAX: usize = 60;
/// Fewest user diagnosis bytes.
pub const SDIAG_MIN: usize = 3;

/// The default GSD, parsed.
pub fn default_gsd() -> Gsd {
    // Parsed once (about 2 ms in a debug build): every new module needs it.
    static PARSED: std::sync::OnceLock<Gsd> = std::sync::OnceLock::new();
    PARSED
        .get_or_init(|| {
            Gsd::parse(&decode_latin1(DEFAULT_GSD), ParseOptions { lenient: true })
                .expect("BM4OPRO1.GSD parses leniently")
                .gsd
        })
        .clone()
}

/// How the station address was chosen (`us_DEVICE` of FB
/// PROFIBUS_INIT_SL, L1730-1747, and the rotary switch).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AddressMode {
    /// 1..=125 set by the PLC (or the switch); Set_Slave_Add refused.
    Fixed,
    /// us_DEVICE 126 (or 128 with the switch at 0x7E..0xFF): set once by
    /// the master with Set_Slave_Add and kept across restarts in the
    /// state file (L517, L836). Refused once set.
    SetOnce,
    /// us_DEVICE 127: set by the master after every start, not kept
    /// (L521, L861).
    EveryStart,
}

/// The station address and how it came about.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Addressing {
    /// The address at start.
    pub address: u8,
    /// The mode.
    pub mode: AddressMode,
    /// Where a set-once address is kept (the program running the slave
    /// writes it when the master sets the address).
    pub store: Option<PathBuf>,
    /// A set-once address is stored already.
    pub stored: bool,
}

/// Name of the state file in `--state-dir`.
pub const STATE_FILE: &str = "bm4-address";

/// The address a Set_Slave_Add device waits at.
pub const DEFAULT_ADDRESS: u8 = 126;

impl Addressing {
    /// A fixed address (us_DEVICE = `address`).
    pub fn fixed(address: u8) -> Addressing {
        Addressing {
            address,
            mode: AddressMode::Fixed,
            store: None,
            stored: false,
        }
    }

    /// The address from us_DEVICE, the rotary switch (for us_DEVICE 128)
    /// and the state directory (for set-once addresses):
    ///
    /// | us_DEVICE | switch | address |
    /// |---|---|---|
    /// | 1..=125 | – | us_DEVICE |
    /// | 126 | – | set once by the master, kept in `DIR/bm4-address` |
    /// | 127 | – | set by the master after every start |
    /// | 128 | 0x01..=0x7D | the switch |
    /// | 128 | 0x7E..=0xFF | as 126 |
    /// | 128 | 0x00 | error (L787 "error at initialisation"; L1740 only says "reserved") |
    /// | 0, 129..=255 | – | error (PROFIBUS_INIT_SL u_ERROR 4, L1804-1810) |
    ///
    /// Until a master sets it, a set-once or every-start device waits at
    /// address 126.
    pub fn from_us_device(
        us_device: u8,
        switch: Option<u8>,
        state_dir: Option<&Path>,
    ) -> Result<Addressing, AddressingError> {
        let set_once = |dir: Option<&Path>| -> Result<Addressing, AddressingError> {
            let store = dir.ok_or(AddressingError::NoStateDir)?.join(STATE_FILE);
            let saved = StoredAddress::load(&store)?;
            Ok(Addressing {
                address: saved.map_or(DEFAULT_ADDRESS, |s| s.address),
                mode: AddressMode::SetOnce,
                stored: saved.is_some(),
                store: Some(store),
            })
        };
        match us_device {
            1..=125 => Ok(Addressing::fixed(us_device)),
            126 => set_once(state_dir),
            127 => Ok(Addressing {
                address: DEFAULT_ADDRESS,
                mode: AddressMode::EveryStart,
                store: None,
                stored: false,
            }),
            128 => match switch {
                None => Err(AddressingError::NoSwitch),
                Some(0) => Err(AddressingError::SwitchZero),
                Some(s @ 1..=125) => Ok(Addressing::fixed(s)),
                Some(_) => set_once(state_dir),
            },
            _ => Err(AddressingError::UsDevice(us_device)),
        }
    }

    /// Whether the device accepts Set_Slave_Add now.
    pub fn accepts_set_slave_add(&self) -> bool {
        match self.mode {
            AddressMode::Fixed => false,
            AddressMode::SetOnce => !self.stored,
            AddressMode::EveryStart => true,
        }
    }
}

/// Why us_DEVICE, the rotary switch and the state directory give no
/// address.
#[derive(Debug, thiserror::Error)]
pub enum AddressingError {
    /// us_DEVICE 126 without a state directory.
    #[error("a set-once address (us_DEVICE 126) is kept in a state file: give --state-dir DIR")]
    NoStateDir,
    /// us_DEVICE 128 without a switch value.
    #[error("us_DEVICE 128 reads the rotary switch: give --switch N")]
    NoSwitch,
    /// Rotary switch 0x00.
    #[error("rotary switch 0x00 is reserved: PROFIBUS_INIT_SL reports an initialisation error")]
    SwitchZero,
    /// us_DEVICE outside its values.
    #[error("us_DEVICE {0} is invalid (1..125, 126, 127, 128): PROFIBUS_INIT_SL u_ERROR 4")]
    UsDevice(u8),
    /// The state file cannot be read (the message includes the cause,
    /// which is therefore not also returned as `source()`).
    #[error("state file {0}")]
    StateFile(AddressFileError),
}

impl From<AddressFileError> for AddressingError {
    fn from(e: AddressFileError) -> Self {
        AddressingError::StateFile(e)
    }
}

/// The module's status as its LEDs show it (L1158-1166, L2041-2049).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Led {
    /// H3 green: waiting for parameterisation and configuration.
    ParameteriseConfigure,
    /// H1 green: cyclic data exchange.
    DataExchange,
    /// H2 red: bus error or watchdog expired.
    BusError,
    /// H2 and H4 red: the b maXX PLC did not configure the module (no
    /// "bmaXX_Variables" worksheet from the PROFIBUS-PLC-Slave
    /// configurator, L2057-2059), not a master's configuration.
    ConfigurationError,
    /// All four LEDs on: the module no longer works; switch the b maXX
    /// 4400 off and on (L2046, L2061-2065).
    SoftwareWatchdog,
    /// H2 and H4 blink together N times, then a pause (L2047-2049,
    /// L2071-2075): 1 hardware defect or no PROFIBUS hardware, 2 no
    /// PROFIBUS slave software, 3 newer PROFIBUS software needed, 4
    /// hardware error of the b maXX base unit.
    Blink(u8),
}

impl Led {
    /// The state in words, with the LEDs.
    pub fn as_str(self) -> &'static str {
        match self {
            Led::ParameteriseConfigure => "parameterise / configure (H3 green)",
            Led::DataExchange => "data exchange (H1 green)",
            Led::BusError => "bus error / watchdog (H2 red)",
            Led::ConfigurationError => "configuration error (H2 and H4 red)",
            Led::SoftwareWatchdog => "software watchdog (H1 H2 H3 H4 on)",
            Led::Blink(1) => "H2/H4 blink 1x: hardware defect or no PROFIBUS hardware",
            Led::Blink(2) => "H2/H4 blink 2x: no PROFIBUS slave software",
            Led::Blink(3) => "H2/H4 blink 3x: newer PROFIBUS software needed",
            Led::Blink(_) => "H2/H4 blink 4x: hardware error of the b maXX base unit",
        }
    }

    /// The module cannot work in this state (software watchdog, a
    /// blink code): it refuses Set_Prm and Chk_Cfg.
    pub fn is_fatal(self) -> bool {
        matches!(self, Led::SoftwareWatchdog | Led::Blink(_))
    }
}

/// Why the PLC cannot write a variable ([`Bm4::set_value`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ValueError {
    /// No variable with that parameter number.
    #[error("no variable {0}")]
    NoVariable(usize),
    /// The element is beyond the array.
    #[error("{name} has {length} elements")]
    NoElement {
        /// The variable.
        name: String,
        /// Its elements.
        length: usize,
    },
    /// The value does not fit the type.
    #[error("{value} is outside {ty}'s range {lo}..={hi}")]
    OutOfRange {
        /// The value.
        value: i64,
        /// The IEC type's name.
        ty: &'static str,
        /// Smallest value.
        lo: i64,
        /// Largest value.
        hi: i64,
    },
}

/// Why FB SDIAG refused a diagnosis (its d_STATUS, L1965-1983).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SdiagError {
    /// 16#80 B6 00: a diagnosis is waiting to be fetched.
    #[error("diagnosis send currently impossible: the last one was not fetched yet (d_STATUS 16#{:08X})", self.d_status())]
    Busy,
    /// 16#82 01 01: x_ED_FLAG is FALSE.
    #[error("x_ED_FLAG is FALSE (d_STATUS 16#{:08X})", self.d_status())]
    EdFlag,
    /// 16#84 01 01: i_LEN < 3.
    #[error("i_LEN below 3 (d_STATUS 16#{:08X})", self.d_status())]
    TooShort,
    /// 16#84 01 02: i_LEN > 60.
    #[error("i_LEN above 60 (d_STATUS 16#{:08X})", self.d_status())]
    TooLong,
    /// 16#80 B7 00: internal error, a parameter out of its range (L1977).
    #[error("internal error: parameter out of range (d_STATUS 16#{:08X})", self.d_status())]
    OutOfRange,
    /// 16#80 C3 02: internal error, the stack has no memory (L1978).
    #[error("internal error: the stack has no memory (d_STATUS 16#{:08X})", self.d_status())]
    NoMemory,
}

impl SdiagError {
    /// d_STATUS: byte 0 Function_Num (0), byte 1 Error_Decode, bytes 2
    /// and 3 Error_Code 1 and 2 (L1967 labels byte 3 "Error_Code 1"
    /// too; read as 2).
    pub fn d_status(self) -> u32 {
        let (decode, c1, c2) = match self {
            SdiagError::Busy => (0x80, 0xB6, 0x00),
            SdiagError::EdFlag => (0x82, 0x01, 0x01),
            SdiagError::TooShort => (0x84, 0x01, 0x01),
            SdiagError::TooLong => (0x84, 0x01, 0x02),
            SdiagError::OutOfRange => (0x80, 0xB7, 0x00),
            SdiagError::NoMemory => (0x80, 0xC3, 0x02),
        };
        u32::from_le_bytes([0x00, decode, c1, c2])
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct Sdiag {
    data: Vec<u8>,
    overflow: bool,
    fetched: bool,
}

/// Where a configured variable sits in the process image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Slot {
    var: usize,
    offset: usize,
}

/// The PLC's variables: the PKW server.
#[derive(Debug, Clone)]
struct Vars {
    table: VarTable,
    /// Per variable: its bytes in bus order.
    data: Vec<Vec<u8>>,
    /// Per variable: configured as cyclic process data.
    cyclic: Vec<bool>,
}

/// PKW error numbers (L1549-1560).
const E_READ_ONLY: u16 = 0x0001;
const E_SUBINDEX: u16 = 0x0003;
const E_TYPE: u16 = 0x0005;
const E_ADDRESS: u16 = 0x000B;
const E_ACCESS: u16 = 0x0016;

impl Vars {
    fn new(table: VarTable) -> Vars {
        let data = table
            .vars
            .iter()
            .map(|v| {
                let mut b = vec![0u8; v.bytes()];
                for (i, x) in v.initial.iter().enumerate() {
                    v.encode(*x, &mut b[i * v.ty.size()..]);
                }
                b
            })
            .collect();
        let cyclic = vec![false; table.vars.len()];
        Vars {
            table,
            data,
            cyclic,
        }
    }

    fn element(&self, var: usize, i: usize) -> u32 {
        let v = &self.table.vars[var];
        let n = v.ty.size();
        let b = &self.data[var][i * n..(i + 1) * n];
        match (n, v.ty.signed()) {
            (1, true) => b[0] as i8 as i16 as u16 as u32,
            (1, false) => b[0] as u32,
            (2, _) => u16::from_be_bytes([b[0], b[1]]) as u32,
            _ => u32::from_be_bytes([b[0], b[1], b[2], b[3]]),
        }
    }

    fn set_element(&mut self, var: usize, i: usize, value: u32) {
        let n = self.table.vars[var].ty.size();
        let b = value.to_be_bytes();
        self.data[var][i * n..(i + 1) * n].copy_from_slice(&b[4 - n..]);
    }

    /// A word value for a 1- or 2-byte type, checked against its range.
    fn word_fits(ty: IecType, w: u16) -> bool {
        match ty {
            IecType::Bool => w <= 1,
            IecType::Usint | IecType::Byte => w <= 0xFF,
            IecType::Sint => (-128..=127).contains(&(w as i16)),
            _ => true,
        }
    }

    fn write(&mut self, var: usize, i: usize, value: u32, dword: bool) -> Result<(), u16> {
        let v = &self.table.vars[var];
        if v.module == VarModule::Input {
            return Err(E_READ_ONLY);
        }
        if dword != (v.ty.size() == 4) {
            return Err(E_TYPE);
        }
        if !dword && !Vars::word_fits(v.ty, value as u16) {
            return Err(E_TYPE);
        }
        self.set_element(var, i, value);
        Ok(())
    }
}

impl PkwServer for Vars {
    fn execute(&mut self, _now: Instant, pnu: u16, ind: u16, cmd: Command) -> Result<Reply, u16> {
        let var = pnu as usize;
        let Some(v) = self.table.vars.get(var) else {
            return Err(if matches!(cmd, Command::Unsupported(_)) {
                E_ACCESS
            } else {
                E_ADDRESS
            });
        };
        let (array, len, dword) = (v.is_array(), v.length, v.ty.size() == 4);
        let plain = matches!(
            cmd,
            Command::Read | Command::WriteWord(_) | Command::WriteDword(_)
        );
        if matches!(cmd, Command::Unsupported(_) | Command::Describe(_)) {
            return Err(E_ACCESS);
        }
        if self.cyclic[var] {
            return Err(E_ADDRESS);
        }
        if plain && array || !plain && !array {
            return Err(E_TYPE);
        }
        if plain && ind != 0 || !plain && ind as usize >= len {
            return Err(E_SUBINDEX);
        }
        let i = ind as usize;
        match cmd {
            Command::Read => Ok(if dword {
                Reply::Dword(self.element(var, 0))
            } else {
                Reply::Word(self.element(var, 0) as u16)
            }),
            Command::ReadElement(_) => Ok(if dword {
                Reply::ElementDword(self.element(var, i))
            } else {
                Reply::ElementWord(self.element(var, i) as u16)
            }),
            Command::WriteWord(w) => self.write(var, 0, w as u32, false).map(|_| Reply::Word(w)),
            Command::WriteDword(d) => self.write(var, 0, d, true).map(|_| Reply::Dword(d)),
            Command::WriteElementWord { value, .. } => self
                .write(var, i, value as u32, false)
                .map(|_| Reply::ElementWord(value)),
            Command::WriteElementDword { value, .. } => self
                .write(var, i, value, true)
                .map(|_| Reply::ElementDword(value)),
            Command::Describe(_) | Command::Unsupported(_) => Err(E_ACCESS),
        }
    }
}

/// A configuration fault: the Chk_Cfg does not fit the variable table.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ConfigError(pub String);

/// The process images a configuration of a variable table gives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct CfgLayout {
    /// The PKW module comes first.
    pub pkw: bool,
    /// The configured variables by parameter number, in Chk_Cfg order.
    pub used: Vec<usize>,
    /// Input variables with their offsets.
    inputs: Vec<Slot>,
    /// Output variables with their offsets.
    outputs: Vec<Slot>,
    /// Input bytes.
    pub input_len: usize,
    /// Output bytes.
    pub output_len: usize,
}

impl CfgLayout {
    /// Check `cfg` against `table` (module docs: Chk_Cfg) and lay out the
    /// images: the PKW words first if configured, then the variables of
    /// each direction in configuration order.
    pub(crate) fn new(table: &VarTable, cfg: &[u8]) -> Result<CfgLayout, ConfigError> {
        let err = |m: String| ConfigError(m);
        let mut i = 0;
        let pkw = cfg.first() == Some(&PKW_MODULE);
        if pkw {
            i = 1;
        }
        let all = table.all_modules_cfg().filter(|_| table.all_modules);
        let mut used: Vec<usize> = vec![];
        let take = |var: usize, used: &mut Vec<usize>| {
            if used.contains(&var) {
                Err(err(format!(
                    "variable {} (`{}`) is configured twice",
                    var, table.vars[var].name
                )))
            } else {
                used.push(var);
                Ok(())
            }
        };
        while i < cfg.len() {
            if let Some((all_cfg, order)) = all.as_ref().filter(|(c, _)| cfg[i..].starts_with(c)) {
                for &v in order {
                    take(v, &mut used)?;
                }
                i += all_cfg.len();
                continue;
            }
            if cfg[i] == PKW_MODULE {
                return Err(err(format!(
                    "the PKW module 0x73 is at byte {i}; it must be the first module"
                )));
            }
            let Some(id) = cfg.get(i..i + 4) else {
                return Err(err(format!(
                    "byte {i} (0x{:02X}) does not start a module of the variable table",
                    cfg[i]
                )));
            };
            let pnu = id[3] as usize;
            if pnu >= table.vars.len() || table.identifier(pnu) != id {
                return Err(err(format!(
                    "identifier {:02X} {:02X} {:02X} {:02X} at byte {i} is no module of the variable table",
                    id[0], id[1], id[2], id[3]
                )));
            }
            take(pnu, &mut used)?;
            i += 4;
        }
        if !pkw && used.is_empty() {
            return Err(err("empty configuration".into()));
        }
        let mut inp = if pkw { PKW_LEN } else { 0 };
        let mut out = inp;
        let (mut inputs, mut outputs) = (vec![], vec![]);
        for &var in &used {
            let v: &Variable = &table.vars[var];
            let (list, at) = match v.module {
                VarModule::Input => (&mut inputs, &mut inp),
                VarModule::Output => (&mut outputs, &mut out),
            };
            list.push(Slot { var, offset: *at });
            *at += v.bytes();
        }
        if inp > 244 || out > 244 {
            return Err(err(format!(
                "{inp} input and {out} output bytes, at most 244 each way"
            )));
        }
        Ok(CfgLayout {
            pkw,
            used,
            inputs,
            outputs,
            input_len: inp,
            output_len: out,
        })
    }

    /// The variables of one direction with their offsets: (parameter
    /// number, byte offset).
    pub(crate) fn slots(&self, module: VarModule) -> impl Iterator<Item = (usize, usize)> + '_ {
        let list = match module {
            VarModule::Input => &self.inputs,
            VarModule::Output => &self.outputs,
        };
        list.iter().map(|s| (s.var, s.offset))
    }
}

/// The BM4-O-PRO-01 emulation; see the module docs.
#[derive(Debug)]
pub struct Bm4 {
    vars: Vars,
    gsd: Gsd,
    default_config: bool,
    /// Get_Cfg before a Chk_Cfg: the PKW module and every variable.
    full_cfg: Vec<u8>,
    cfg: Option<Vec<u8>>,
    inputs: Vec<Slot>,
    outputs: Vec<Slot>,
    pkw: bool,
    engine: PkwEngine,
    addressing: Addressing,
    sdiag: Option<Sdiag>,
    /// The module's internal error the next SDIAG fails with
    /// (`sdiag-fail`, B44).
    sdiag_fail: Option<SdiagError>,
    new_diag: bool,
    led: Led,
    /// u_LOCAL_NODE_ID: the station address in use (L1399-1411).
    node_id: u8,
    /// u_BAUDRATE: the rate the auto-baud found (L691), once known.
    baud: Option<Baud>,
    /// The b maXX PLC configured the module (its variables exist).
    plc_configured: bool,
    /// Leave data exchange (a module fault).
    restart: bool,
    events: EventQueue,
    inbox: InboxSchedule,
}

impl Bm4 {
    /// A module with the variable table `table` (use
    /// [`VarTable::default_table`] for the default configuration) at the
    /// address `addressing` gives.
    pub fn new(table: VarTable, addressing: Addressing) -> Bm4 {
        let default_config = table == VarTable::default_table();
        let default = default_gsd();
        let gsd = if default_config {
            default
        } else {
            table.gsd(&default)
        };
        let node_id = addressing.address;
        let mut full_cfg = vec![PKW_MODULE];
        for i in 0..table.vars.len() {
            full_cfg.extend_from_slice(&table.identifier(i));
        }
        Bm4 {
            vars: Vars::new(table),
            gsd,
            default_config,
            full_cfg,
            cfg: None,
            inputs: vec![],
            outputs: vec![],
            pkw: false,
            engine: PkwEngine::new(&PKW, Duration::ZERO),
            addressing,
            sdiag: None,
            sdiag_fail: None,
            new_diag: false,
            node_id,
            baud: None,
            led: Led::ParameteriseConfigure,
            plc_configured: true,
            restart: false,
            events: EventQueue::default(),
            inbox: InboxSchedule::default(),
        }
    }

    /// The manual's example (MyGSDFile.gsd) at a fixed address: what
    /// `dpctl demo` runs.
    pub fn example(address: u8) -> Bm4 {
        Bm4::new(VarTable::example(), Addressing::fixed(address))
    }

    /// Read control commands from `inbox` (see [`Bm4::control`]).
    pub fn with_inbox(mut self, inbox: ControlInbox) -> Bm4 {
        self.inbox.set(inbox);
        self
    }

    /// The variable table.
    pub fn table(&self) -> &VarTable {
        &self.vars.table
    }

    /// The station address at start and its mode.
    pub fn addressing(&self) -> &Addressing {
        &self.addressing
    }

    /// The GSD of this configuration.
    pub fn gsd(&self) -> &Gsd {
        &self.gsd
    }

    /// The GSD file as bytes (Latin-1): `BM4OPRO1.GSD` itself for the
    /// default configuration, else the generated file.
    pub fn gsd_file(&self) -> Vec<u8> {
        if self.default_config {
            DEFAULT_GSD.to_vec()
        } else {
            self.gsd.write_latin1()
        }
    }

    /// The GSD file as text.
    pub fn gsd_text(&self) -> String {
        decode_latin1(&self.gsd_file())
    }

    /// The LED state.
    pub fn led(&self) -> Led {
        self.led
    }

    /// The PKW module is configured.
    pub fn pkw_configured(&self) -> bool {
        self.pkw
    }

    /// The variable named `name`: its parameter number.
    pub fn pnu(&self, name: &str) -> Option<usize> {
        self.vars.table.vars.iter().position(|v| v.name == name)
    }

    /// Element `index` of variable `pnu` as the PLC sees it (sign-extended
    /// for signed types; REAL as its bit pattern).
    pub fn value(&self, pnu: usize, index: usize) -> Option<i64> {
        let v = self.vars.table.vars.get(pnu)?;
        if index >= v.length {
            return None;
        }
        let raw = self.vars.element(pnu, index);
        Some(match (v.ty.size(), v.ty.signed()) {
            (1, true) | (2, true) => raw as u16 as i16 as i64,
            (4, true) => raw as i32 as i64,
            _ => raw as i64,
        })
    }

    /// The PLC writes element `index` of variable `pnu` (an actual value
    /// going to the master, or overwriting a setpoint). `Err` when the
    /// variable or element does not exist or the value is out of range.
    pub fn set_value(&mut self, pnu: usize, index: usize, value: i64) -> Result<(), ValueError> {
        let v = self
            .vars
            .table
            .vars
            .get(pnu)
            .ok_or(ValueError::NoVariable(pnu))?;
        if index >= v.length {
            return Err(ValueError::NoElement {
                name: v.name.clone(),
                length: v.length,
            });
        }
        let (lo, hi) = v.ty.range();
        if value < lo || value > hi {
            return Err(ValueError::OutOfRange {
                value,
                ty: v.ty.name(),
                lo,
                hi,
            });
        }
        self.vars.set_element(pnu, index, value as u32);
        Ok(())
    }

    /// FB SDIAG: send a user diagnosis of 3..=60 bytes (a_ED_DATA,
    /// i_LEN = `data.len()`), with x_ED_FLAG and x_ED_OV. It is announced
    /// to the master with the next Data_Exchange response.
    pub fn sdiag(&mut self, data: &[u8], ed_flag: bool, overflow: bool) -> Result<(), SdiagError> {
        if !ed_flag {
            return Err(SdiagError::EdFlag);
        }
        if data.len() < SDIAG_MIN {
            return Err(SdiagError::TooShort);
        }
        if data.len() > SDIAG_MAX {
            return Err(SdiagError::TooLong);
        }
        if self.sdiag.as_ref().is_some_and(|s| !s.fetched) {
            return Err(SdiagError::Busy);
        }
        if let Some(e) = self.sdiag_fail.take() {
            return Err(e);
        }
        self.sdiag = Some(Sdiag {
            data: data.to_vec(),
            overflow,
            fetched: false,
        });
        self.new_diag = true;
        Ok(())
    }

    /// Make the next SDIAG fail with the module's internal error `error`
    /// ([`SdiagError::OutOfRange`] or [`SdiagError::NoMemory`]). The
    /// manual lists these d_STATUS codes (L1977-1978) without saying
    /// when the module raises them, so the emulation raises them on
    /// demand, once, to test a PLC program's error handling.
    pub fn sdiag_fail_next(&mut self, error: SdiagError) {
        self.sdiag_fail = Some(error);
    }

    /// u_LOCAL_NODE_ID (L1399-1411): the station address in use, the
    /// one a master set by Set_Slave_Add included (126 while a set-once
    /// or every-start module waits for it).
    pub fn local_node_id(&self) -> u8 {
        self.node_id
    }

    /// u_BAUDRATE (L691): the rate the module's auto-baud found; `None`
    /// until the program running the slave reports it with
    /// [`Bm4::set_baud`].
    pub fn baud(&self) -> Option<Baud> {
        self.baud
    }

    /// Enter the rate the auto-baud found into u_BAUDRATE.
    pub fn set_baud(&mut self, baud: Baud) {
        self.baud = Some(baud);
    }

    /// x_OK of the last SDIAG: a master fetched it.
    pub fn sdiag_ok(&self) -> bool {
        self.sdiag.as_ref().is_some_and(|s| s.fetched)
    }

    /// Remove the user diagnosis (announced as a change).
    pub fn sdiag_clear(&mut self) {
        if self.sdiag.take().is_some() {
            self.new_diag = true;
        }
    }

    /// Execute one control command (what a PLC program would do), in
    /// words; returns the answer in words:
    ///
    /// - `sdiag HEX… [overflow] [no-ed-flag]`: FB SDIAG with these bytes
    ///   (`a_ED_DATA[0]` first); e.g. the manual's example
    ///   16#1234_5678_90AB_CDEF is `sdiag EF CD AB 90 78 56 34 12`.
    /// - `sdiag-clear`: remove the user diagnosis.
    /// - `set NAME[INDEX] VALUE` / `set NAME VALUE`: the PLC writes a
    ///   variable.
    /// - `get NAME[INDEX]` / `get NAME`: a variable's value.
    /// - `sdiag-fail range|no-memory`: the next SDIAG fails with the
    ///   module's internal error 16#80 B7 00 or 16#80 C3 02.
    /// - `status`: the LED state, then u_LOCAL_NODE_ID and u_BAUDRATE,
    ///   e.g. `data exchange (H1 green); u_LOCAL_NODE_ID 6; u_BAUDRATE
    ///   1500000` (`u_BAUDRATE auto` while no rate was found).
    pub fn control(&mut self, line: &str) -> Result<String, ControlError> {
        let arg = |m: String| ControlError::Argument(m);
        let mut words = line.split_whitespace();
        let cmd = words.next().unwrap_or("");
        let rest: Vec<&str> = words.collect();
        match cmd {
            "sdiag" => {
                let mut data = vec![];
                let (mut ovf, mut flag) = (false, true);
                for w in &rest {
                    match *w {
                        "overflow" => ovf = true,
                        "no-ed-flag" => flag = false,
                        hex => {
                            let bad = || arg(format!("`{hex}` is not hex bytes"));
                            let h = hex.trim_start_matches("16#").replace('_', "");
                            if h.len() % 2 != 0 {
                                return Err(bad());
                            }
                            for i in (0..h.len()).step_by(2) {
                                data.push(u8::from_str_radix(&h[i..i + 2], 16).map_err(|_| bad())?);
                            }
                        }
                    }
                }
                self.sdiag(&data, flag, ovf)
                    .map(|_| format!("SDIAG: {} bytes of diagnosis announced", data.len()))
                    .map_err(|e| ControlError::Refused(format!("SDIAG refused: {e}")))
            }
            "sdiag-clear" => {
                self.sdiag_clear();
                Ok("user diagnosis removed".into())
            }
            "set" | "get" => {
                let name = rest
                    .first()
                    .ok_or_else(|| arg("give a variable name".into()))?;
                let (name, index) = match name.split_once('[') {
                    Some((n, i)) => (
                        n,
                        i.trim_end_matches(']')
                            .parse::<usize>()
                            .map_err(|_| arg(format!("bad index in `{name}`")))?,
                    ),
                    None => (*name, 0),
                };
                let pnu = self
                    .pnu(name)
                    .ok_or_else(|| arg(format!("no variable `{name}`")))?;
                if cmd == "set" {
                    let v = rest.get(1).ok_or_else(|| arg("give a value".into()))?;
                    let value =
                        parse_int(v).ok_or_else(|| arg(format!("`{v}` is not a number")))?;
                    self.set_value(pnu, index, value)
                        .map_err(|e| ControlError::Refused(e.to_string()))?;
                    Ok(format!("{name}[{index}] := {value}"))
                } else {
                    let v = self
                        .value(pnu, index)
                        .ok_or_else(|| arg(format!("{name} has no element {index}")))?;
                    Ok(format!("{name}[{index}] = {v}"))
                }
            }
            "sdiag-fail" => {
                let e = match rest.as_slice() {
                    ["range"] => SdiagError::OutOfRange,
                    ["no-memory"] => SdiagError::NoMemory,
                    _ => return Err(arg("sdiag-fail range|no-memory".into())),
                };
                self.sdiag_fail_next(e);
                Ok(format!(
                    "the next SDIAG fails with d_STATUS 16#{:08X}",
                    e.d_status()
                ))
            }
            "status" => {
                let baud = self
                    .baud
                    .map_or_else(|| "auto".to_string(), |b| b.bps().to_string());
                Ok(format!(
                    "{}; u_LOCAL_NODE_ID {}; u_BAUDRATE {baud}",
                    self.led.as_str(),
                    self.node_id
                ))
            }
            // The PLC side: `plc unconfigured` (the configurator's
            // variables are missing), `plc configured`.
            "plc" => {
                match rest.first().copied() {
                    Some("unconfigured") => {
                        self.plc_configured = false;
                        self.set_led(Led::ConfigurationError);
                    }
                    Some("configured") => {
                        self.plc_configured = true;
                        if self.led == Led::ConfigurationError {
                            self.set_led(Led::ParameteriseConfigure);
                        }
                    }
                    _ => return Err(arg("plc configured|unconfigured".into())),
                }
                Ok(self.led.as_str().to_string())
            }
            // Module faults: `fault software-watchdog`, `fault blink N`
            // (1..4), `fault none` (the b maXX switched off and on).
            "fault" => {
                let led = match rest.as_slice() {
                    ["software-watchdog"] => Led::SoftwareWatchdog,
                    ["blink", n] => match n.parse::<u8>() {
                        Ok(n @ 1..=4) => Led::Blink(n),
                        _ => return Err(arg(format!("blink `{n}`: give 1..4"))),
                    },
                    ["none"] => {
                        if self.led.is_fatal() {
                            self.set_led(Led::ParameteriseConfigure);
                        }
                        return Ok(self.led.as_str().to_string());
                    }
                    _ => return Err(arg("fault software-watchdog | blink 1..4 | none".into())),
                };
                self.set_led(led);
                self.restart = true;
                Ok(led.as_str().to_string())
            }
            _ => Err(ControlError::Unknown {
                command: cmd.into(),
                known: "sdiag, sdiag-clear, sdiag-fail, set, get, status, plc, fault",
            }),
        }
    }

    fn set_led(&mut self, led: Led) {
        if self.led != led {
            self.led = led;
            self.events.note("led", led.as_str().to_string());
        }
    }
}

fn parse_int(s: &str) -> Option<i64> {
    if let Some(h) = s.strip_prefix("0x").or_else(|| s.strip_prefix("16#")) {
        i64::from_str_radix(&h.replace('_', ""), 16).ok()
    } else {
        s.parse().ok()
    }
}

impl Device for Bm4 {
    fn ident_number(&self) -> u16 {
        IDENT
    }

    fn real_cfg(&self) -> &[u8] {
        self.cfg.as_deref().unwrap_or(&self.full_cfg)
    }

    fn features(&self) -> Features {
        Features {
            set_slave_add: self.addressing.accepts_set_slave_add(),
            max_diag_len: 244,
            ..Features::default()
        }
    }

    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        if self.led.is_fatal() {
            return Err(format!("the module does not work: {}", self.led.as_str()).into());
        }
        expect_user_prm_len(prm, USER_PRM_LEN)?;
        if self.led != Led::ConfigurationError {
            self.set_led(Led::ParameteriseConfigure);
        }
        Ok(())
    }

    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        if self.led.is_fatal() {
            return Err(format!("the module does not work: {}", self.led.as_str()).into());
        }
        // "Configuration error" is the PLC's (L2057-2059): without its
        // variables the module has no configuration to check against.
        if !self.plc_configured {
            return Err("configuration error: the b maXX PLC did not configure the module (no bmaXX_Variables)".into());
        }
        // A master's configuration that does not fit: Cfg_Fault, and
        // the module stays in parameterise / configure mode (the manual
        // gives no LED for it).
        let l = CfgLayout::new(&self.vars.table, cfg).map_err(|e| Reason::from(e.0))?;
        self.vars.cyclic.iter_mut().for_each(|c| *c = false);
        for &v in &l.used {
            self.vars.cyclic[v] = true;
        }
        self.pkw = l.pkw;
        self.inputs = l.inputs;
        self.outputs = l.outputs;
        self.cfg = Some(cfg.to_vec());
        self.engine.reset();
        if self.led != Led::ConfigurationError {
            self.set_led(Led::ParameteriseConfigure);
        }
        Ok(IoLayout {
            inputs: l.input_len,
            outputs: l.output_len,
        })
    }

    fn write_outputs(&mut self, now: Instant, outputs: &[u8]) {
        if self.led.is_fatal() {
            return;
        }
        self.set_led(Led::DataExchange);
        if self.pkw {
            if let Some(req) = Pkw::parse(outputs) {
                if let Some(job) = self.engine.on_request(now, req, &mut self.vars) {
                    self.events
                        .note("pkw", format!("PKW {} -> {}", job.request, job.response));
                }
            }
        }
        for s in &self.outputs {
            let n = self.vars.data[s.var].len();
            if let Some(src) = outputs.get(s.offset..s.offset + n) {
                self.vars.data[s.var].copy_from_slice(src);
            }
        }
    }

    fn read_inputs(&mut self, now: Instant, inputs: &mut [u8]) {
        if self.pkw {
            self.engine.response(now).emit(inputs);
        }
        for s in &self.inputs {
            let d = &self.vars.data[s.var];
            if let Some(dst) = inputs.get_mut(s.offset..s.offset + d.len()) {
                dst.copy_from_slice(d);
            }
        }
    }

    fn clear_outputs(&mut self, _now: Instant, why: ClearReason) {
        // Setpoints keep their last value in the PLC's variables; the PKW
        // channel starts afresh.
        self.engine.reset();
        match why {
            _ if self.led.is_fatal() => {}
            ClearReason::Watchdog => self.set_led(Led::BusError),
            ClearReason::LeftDataExchange => {
                if self.led == Led::DataExchange {
                    self.set_led(Led::ParameteriseConfigure)
                }
            }
            ClearReason::ClearData | ClearReason::FailSafe => {}
        }
    }

    fn diagnosis(&mut self, _now: Instant, diag: &mut DiagWriter<'_>) {
        let mut fetched_now = false;
        if let Some(s) = &mut self.sdiag {
            diag.device(&s.data);
            diag.set_ext_diag();
            if s.overflow {
                diag.set_overflow();
            }
            fetched_now = !s.fetched;
            s.fetched = true;
        }
        if fetched_now {
            self.events
                .note("diag", "user diagnosis fetched by the master (x_OK)".into());
        }
    }

    fn take_new_diag(&mut self) -> bool {
        std::mem::take(&mut self.new_diag)
    }

    fn set_address(
        &mut self,
        new_address: u8,
        _no_add_chg: bool,
        _rem_slave_data: &[u8],
    ) -> Result<(), Reason> {
        match self.addressing.mode {
            AddressMode::Fixed => Err("the address is fixed (us_DEVICE 1..125)".into()),
            AddressMode::SetOnce if self.addressing.stored => {
                Err("the address was set once already (us_DEVICE 126)".into())
            }
            AddressMode::SetOnce => {
                // The program running the slave keeps it in the state
                // file (SlaveEvent::AddressChanged); no file I/O here.
                let text = match &self.addressing.store {
                    Some(p) => format!("address {new_address} set once, kept in {}", p.display()),
                    None => format!("address {new_address} set once"),
                };
                self.events.note("address", text);
                self.addressing.stored = true;
                self.node_id = new_address;
                Ok(())
            }
            AddressMode::EveryStart => {
                self.events.note(
                    "address",
                    format!("address {new_address} set for this start (not stored)"),
                );
                self.node_id = new_address;
                Ok(())
            }
        }
    }

    fn take_restart(&mut self) -> bool {
        std::mem::take(&mut self.restart)
    }

    fn poll_event(&mut self) -> Option<DeviceEvent> {
        self.events.pop()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.inbox.deadline()
    }

    fn handle_timeout(&mut self, now: Instant) {
        for line in self.inbox.due(now) {
            match self.control(&line) {
                Ok(t) => self.events.note("control", t),
                Err(e) => self.events.note("control_error", format!("`{line}`: {e}")),
            }
        }
    }
}

#[cfg(test)]
mod tests;
