//! Bus files: a DP master's configuration in TOML, built on the slaves'
//! GSD files.
//!
//! ```toml
//! [master]
//! address = 1            # the master's station address
//! baud = "1.5M"          # 9600 … 12M
//!
//! [bus]                  # optional: bus parameters in bit times
//! slot_time = 300        # TSL; default from the baud rate
//! ttr = 32436            # target rotation time
//! # also: min_tsdr, max_tsdr, tset, tqui, gap_factor, hsa, max_retry
//!
//! [options]              # optional: poll-cycle behaviour
//! lost_after = 3         # cycles without answer before a slave is lost
//! reprobe_ms = 100       # how often a lost slave is probed
//! diag_interval_ms = 0   # periodic diagnosis (0 = only on DH)
//! global_control_ms = 100  # repeat operate/clear Global_Control (default 100; 0 = only on change)
//! alone_hold_bits = 3000  # alone in the ring: poll cycles per token visit for at most
//!                         # this many bit times, within the token hold time (default:
//!                         # 10 ms a visit; 0: the token to itself after every cycle)
//!
//! [[slave]]
//! address = 8
//! name = "coupler"                       # optional
//! gsd = "../gsd/BK30BECF.GSD"            # relative to this file
//! modules = ["KL1002 2 digital inputs"]  # GSD module names
//! params = { "Diagnosis" = "on" }        # ExtUserPrmData by name ("2:Name" for module 2)
//! watchdog_ms = 1000                     # 0 switches it off
//! group = 1                              # Group_Ident bits
//! sync = false
//! freeze = false
//! initial_outputs = [0, 0]               # optional
//! alarms = ["diagnostic", "process"]     # DP-V1 alarms to enable (default: all the
//!                                        # GSD declares; false: none)
//!
//! [mqtt]                 # optional: settings of `dpctl gateway`, kept raw
//! prefix = "profibus"    # (see the `profibus-gateway` crate)
//!
//! [opcua]                # optional: the OPC UA server of `dpctl gateway`,
//! endpoint = "opc.tcp://0.0.0.0:4840"  # kept raw (see `profibus-opcua`)
//!
//! [[slave]]
//! address = 25
//! device = "omega"                       # a device profile instead of gsd/modules
//! setpoints = 2                          # … with its options
//! actual_values = 2
//! omega.params = "omega-params.toml"     # an option named like a slave key
//! ```
//!
//! A slave names either a GSD file and its modules, or a device profile
//! (`device = "NAME"`) with the profile's options as further keys. An
//! option named like a slave key (see [`SLAVE_KEYS`]: the `omega`
//! profile's `params` file, the `generic` profile's `gsd` and `modules`)
//! goes into the sub-table named after the profile, `omega.params =
//! "params.toml"` (any option may); `params` or `modules` at the top of a
//! `device` slave's table stay slave keys and are refused where a device
//! slave cannot take them, naming where the option goes. `gsd` next to
//! `device` is the GSD file the profile takes its identity from (a
//! vendor's file: ident number, modules, parameters; for the generic
//! profile its GSD), passed as the profile's option `gsd`. This
//! crate knows no profile: [`BusFile::load_with`] takes a
//! [`DeviceResolver`] (the `profibus-devices` registry is one) that turns
//! the name and options into the profile's GSD and modules; from there
//! the slave is built like any other (`params`, `watchdog_ms`, … apply),
//! and [`BusSlave::device`] keeps the name and options for the layer
//! above (named channels, PKW).
//!
//! [`BusFile::load`] parses the file, reads every GSD, selects the modules,
//! builds Chk_Cfg and User_Prm_Data, checks the selection against the
//! GSD's limits, and derives the bus parameters: defaults from
//! [`BusParams::defaults`], raised to the largest `MaxTsdr` of the slaves
//! for the baud rate (with TSL = max TSDR + 15 at least) unless the file
//! sets them. Every error names the file and line and says what is wrong.
//! A file over [`MAX_BUS_FILE`] bytes or not UTF-8 is refused before it is
//! parsed.

use crate::config::gsd::{Gsd, ParseOptions, PrmValue};
use crate::config::names::{field_names, DidYouMean};
use crate::master::{MasterConfig, MasterOptions, SlaveParams};
use crate::pdu::alarm::{AlarmEnable, AlarmMode};
use crate::pdu::prm::Dpv1Status2;
use profibus_fdl::timing::{Baud, BusParams};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Duration;
use toml::Spanned;
use toml_edit::{Item, TableLike};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    master: Spanned<RawMaster>,
    #[serde(default)]
    bus: Option<Spanned<RawBus>>,
    #[serde(default)]
    options: Option<RawOptions>,
    #[serde(default)]
    slave: Vec<Spanned<RawSlave>>,
    /// The gateway's settings, kept raw: `profibus-gateway` reads them.
    #[serde(default)]
    mqtt: Option<toml::Table>,
    /// The OPC UA server's settings, kept raw: `profibus-opcua` reads them.
    #[serde(default)]
    opcua: Option<toml::Table>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaster {
    address: Spanned<u8>,
    baud: Spanned<BaudValue>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum BaudValue {
    Number(u32),
    Text(String),
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawBus {
    slot_time: Option<u32>,
    min_tsdr: Option<u32>,
    max_tsdr: Option<u32>,
    tset: Option<u32>,
    tqui: Option<u32>,
    gap_factor: Option<u8>,
    hsa: Option<u8>,
    max_retry: Option<u8>,
    ttr: Option<u32>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawOptions {
    lost_after: Option<u8>,
    reprobe_ms: Option<u64>,
    diag_interval_ms: Option<u64>,
    global_control_ms: Option<u64>,
    alone_hold_bits: Option<u32>,
}

/// The keys of a `[[slave]]` table; any other key is a profile option
/// (only with `device`). A profile option with the name of a slave key
/// (the Omega profile's `params` file, the generic profile's `gsd` and
/// `modules`) goes into the sub-table named after the profile:
/// `omega.params = "params.toml"`.
pub const SLAVE_KEYS: &[&str] = &[
    "address",
    "name",
    "gsd",
    "device",
    "modules",
    "params",
    "watchdog_ms",
    "group",
    "sync",
    "freeze",
    "initial_outputs",
    "dpv1",
    "alarms",
];

/// The `[[slave]]` tables as plain tables, for the profile options.
#[derive(Deserialize)]
struct SlaveTables {
    #[serde(default)]
    slave: Vec<Spanned<toml::Table>>,
}

#[derive(Deserialize)]
struct RawSlave {
    address: Spanned<u8>,
    name: Option<String>,
    gsd: Option<Spanned<String>>,
    device: Option<Spanned<String>>,
    #[serde(default)]
    modules: Vec<Spanned<String>>,
    #[serde(default)]
    params: BTreeMap<String, Spanned<toml::Value>>,
    watchdog_ms: Option<u64>,
    group: Option<u8>,
    sync: Option<Spanned<bool>>,
    freeze: Option<Spanned<bool>>,
    initial_outputs: Option<Spanned<Vec<u8>>>,
    dpv1: Option<bool>,
    /// `alarms = ["diagnostic", …]`, `alarms = false` or `alarms = true`.
    alarms: Option<Spanned<toml::Value>>,
}

/// A slave given as a device profile: `device = "NAME"` and the other
/// keys of its table.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceEntry {
    /// The profile's name.
    pub name: String,
    /// The bus file's directory: relative file names in the options are
    /// relative to it (as `gsd` is).
    pub dir: PathBuf,
    /// The profile's options: the table's keys that are not slave keys,
    /// and the entries of its sub-table named after the profile
    /// (`omega.params = …`, for an option named like a slave key).
    pub options: toml::Table,
}

/// What a [`DeviceResolver`] makes of a [`DeviceEntry`].
#[derive(Debug, Clone)]
pub struct ResolvedDevice {
    /// The profile's GSD for these options.
    pub gsd: Gsd,
    /// The GSD module names to configure, in slot order.
    pub modules: Vec<String>,
}

/// Why a [`DeviceResolver`] cannot resolve a [`DeviceEntry`]: its
/// message (which names the profile or option at fault) and, when one
/// option is at fault, that option's key, where the error is shown.
#[derive(Debug, thiserror::Error)]
#[error("{error}")]
pub struct DeviceError {
    /// The option at fault, if the error is about one.
    pub option: Option<String>,
    /// What is wrong (shown as the error's message, not as a source, so
    /// that a printed chain says it once).
    pub error: Box<dyn std::error::Error + Send + Sync>,
}

impl DeviceError {
    /// An error about the entry as a whole (shown at `device = …`).
    pub fn new(error: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> DeviceError {
        DeviceError {
            option: None,
            error: error.into(),
        }
    }

    /// An error about the option `key` (shown at its key).
    pub fn at_option(
        key: impl Into<String>,
        error: impl Into<Box<dyn std::error::Error + Send + Sync>>,
    ) -> DeviceError {
        DeviceError {
            option: Some(key.into()),
            error: error.into(),
        }
    }
}

/// Turns `device = "NAME"` plus options into a GSD and modules (the
/// layer above implements it with its profile registry).
pub trait DeviceResolver {
    /// Resolve the profile entry of the slave at `address`. The error's
    /// message is shown after `slave N: `: it names the profile.
    fn resolve(&self, entry: &DeviceEntry, address: u8) -> Result<ResolvedDevice, DeviceError>;
}

/// No device profiles: a `device =` entry is an error.
struct NoProfiles;

impl DeviceResolver for NoProfiles {
    fn resolve(&self, entry: &DeviceEntry, _address: u8) -> Result<ResolvedDevice, DeviceError> {
        Err(DeviceError::new(format!(
            "device `{}`: device profiles need a loader with the device registry \
             (`profibus_devices::bus::ProfiledBus`)",
            entry.name
        )))
    }
}

/// One configured slave with its GSD.
#[derive(Debug, Clone)]
pub struct BusSlave {
    /// What the master sends it.
    pub params: SlaveParams,
    /// The GSD file it was built from (for a device profile, the words
    /// ``the GSD of device `NAME` ``: its GSD is built in).
    pub gsd_path: PathBuf,
    /// The device profile it was given as, if any.
    pub device: Option<DeviceEntry>,
    /// The parsed GSD (for diagnosis texts and `dpctl gsd`).
    pub gsd: Gsd,
    /// The selected module names, in order.
    pub modules: Vec<String>,
}

/// A loaded bus file.
#[derive(Debug, Clone)]
pub struct BusFile {
    /// The file.
    pub path: PathBuf,
    /// The master's configuration.
    pub master: MasterConfig,
    /// The slaves with their GSD data, in the order of `master.slaves`.
    pub slaves: Vec<BusSlave>,
    /// Warnings (GSD quirks, adjusted bus parameters).
    pub warnings: Vec<String>,
    /// The `[mqtt]` table as written, for the gateway (`profibus-gateway`
    /// parses and checks it; this crate only carries it).
    pub mqtt: Option<toml::Table>,
    /// The `[opcua]` table as written, for the OPC UA server
    /// (`profibus-opcua` parses and checks it; this crate only carries it).
    pub opcua: Option<toml::Table>,
    /// Where the keys of `[mqtt]` and `[opcua]` are, for the errors of
    /// the crates that read those tables ([`BusFile::error_at`]).
    pub positions: KeyPositions,
}

/// Where the keys of the tables a bus file carries raw (`[mqtt]`,
/// `[opcua]`) are written: 1-based line and column by dotted path
/// (`mqtt.deadband`; the entries of an array by their 1-based number,
/// `mqtt.slave.2.channels.ai1`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct KeyPositions(BTreeMap<String, (usize, usize)>);

impl KeyPositions {
    /// The position of `path`, else of its closest enclosing key that
    /// has one.
    pub fn at(&self, path: &str) -> Option<(usize, usize)> {
        let mut p = path;
        loop {
            if let Some(at) = self.0.get(p) {
                return Some(*at);
            }
            p = &p[..p.rfind('.')?];
        }
    }
}

impl BusFile {
    /// An error about the key at dotted `path` of a table the bus file
    /// carries raw (`mqtt.slave.2.deadband`; see [`KeyPositions`]),
    /// shown at the key (or its closest enclosing key) like every other
    /// bus-file error: `FILE:LINE:COL: MESSAGE`.
    pub fn error_at(&self, path: &str, message: impl Into<String>) -> BusFileError {
        let (line, column) = self.positions.at(path).unwrap_or((0, 0));
        BusFileError {
            path: self.path.clone(),
            line,
            column,
            message: message.into(),
        }
    }
}

/// What is wrong with a bus file, with its position.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusFileError {
    /// The file.
    pub path: PathBuf,
    /// 1-based line (0 when unknown).
    pub line: usize,
    /// 1-based column (0 when unknown).
    pub column: usize,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for BusFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line > 0 {
            write!(
                f,
                "{}:{}:{}: {}",
                self.path.display(),
                self.line,
                self.column,
                self.message
            )
        } else {
            write!(f, "{}: {}", self.path.display(), self.message)
        }
    }
}

impl std::error::Error for BusFileError {}

struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Ctx<'_> {
    /// The 1-based line and column of byte `at` of the file.
    fn line_col(&self, at: usize) -> (usize, usize) {
        let upto = &self.text[..at.min(self.text.len())];
        let line = upto.matches('\n').count() + 1;
        let column = upto.len() - upto.rfind('\n').map_or(0, |i| i + 1) + 1;
        (line, column)
    }

    fn err(
        &self,
        span: Option<std::ops::Range<usize>>,
        message: impl Into<String>,
    ) -> BusFileError {
        let (line, column) = span.map_or((0, 0), |r| self.line_col(r.start));
        BusFileError {
            path: self.path.to_path_buf(),
            line,
            column,
            message: message.into(),
        }
    }

    /// The profile options of a `[[slave]]` table: its keys that are not
    /// slave keys and, with `device = "NAME"`, the entries of its sub-table
    /// `NAME` (where an option named like a slave key goes). A slave key
    /// that a `device` slave cannot take as such (`gsd`, `modules`, or a
    /// `params` that is not a table) is refused with a message that says
    /// where the profile's option of that name goes.
    fn profile_options(&self, t: &Spanned<toml::Table>) -> Result<toml::Table, BusFileError> {
        let table = t.get_ref();
        let at = |key: &str| key_span(self.text, t.span(), key);
        let addr = table
            .get("address")
            .and_then(|v| v.as_integer())
            .map_or_else(|| "?".to_string(), |a| a.to_string());
        let mut options: toml::Table = table
            .iter()
            .filter(|(k, _)| !SLAVE_KEYS.contains(&k.as_str()))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        let Some(name) = table.get("device").and_then(|v| v.as_str()) else {
            return Ok(options);
        };
        if SLAVE_KEYS.contains(&name) {
            // No profile has a slave key's name; the resolver says so.
            return Ok(options);
        }
        let under = |key: &str| {
            format!("an option `{key}` of the `{name}` profile goes under `{name}.{key} = …`")
        };
        // `gsd` next to `device`: the GSD file the profile takes its
        // identity from (a vendor's file; the generic profile's own GSD),
        // passed as the profile's option `gsd`.
        match table.get("gsd") {
            Some(toml::Value::String(g)) => {
                if let Some(toml::Value::Table(sub)) = table.get(name) {
                    if sub.contains_key("gsd") {
                        return Err(self.err(
                            at("gsd"),
                            format!("slave {addr}: `gsd` and `{name}.gsd` both given"),
                        ));
                    }
                }
                options.insert("gsd".into(), toml::Value::String(g.clone()));
            }
            Some(_) => {
                return Err(self.err(
                    at("gsd"),
                    format!("slave {addr}: `gsd` is the path of a GSD file"),
                ))
            }
            None => {}
        }
        if table.contains_key("modules") {
            return Err(self.err(
                at("modules"),
                format!(
                    "slave {addr}: a device profile chooses its modules; {}",
                    under("modules")
                ),
            ));
        }
        if table.get("params").is_some_and(|v| !v.is_table()) {
            return Err(self.err(
                at("params"),
                format!(
                    "slave {addr}: `params` is the slave's User_Prm_Data by name \
                     (`params = {{ NAME = VALUE }}`); {}",
                    under("params")
                ),
            ));
        }
        if let Some(ns) = options.remove(name) {
            let toml::Value::Table(ns) = ns else {
                return Err(self.err(
                    at(name),
                    format!(
                        "slave {addr}: `{name}` must be a table of the `{name}` profile's options \
                         (`{name}.KEY = VALUE`)"
                    ),
                ));
            };
            for (k, v) in ns {
                if options.contains_key(&k) {
                    return Err(self.err(
                        at(name),
                        format!(
                            "slave {addr}: option `{k}` given twice, as `{k}` and as `{name}.{k}`"
                        ),
                    ));
                }
                options.insert(k, v);
            }
        }
        Ok(options)
    }
}

/// The position of `key` in `table`, where the parser knows it.
fn key_at(table: &dyn TableLike, key: &str) -> Option<std::ops::Range<usize>> {
    table.key(key).and_then(|k| k.span())
}

/// The `[[slave]]` tables of a parsed bus file (array of tables or an
/// array of inline tables).
fn slave_tables(root: &toml_edit::Table) -> Vec<&dyn TableLike> {
    match root.get("slave") {
        Some(Item::ArrayOfTables(a)) => a.iter().map(|t| t as &dyn TableLike).collect(),
        Some(Item::Value(toml_edit::Value::Array(a))) => a
            .iter()
            .filter_map(|v| v.as_inline_table().map(|t| t as &dyn TableLike))
            .collect(),
        _ => vec![],
    }
}

/// Where the option `key` of the device `name` of slave table `n` is:
/// `key = …` in the table, else `name.key = …`.
fn option_at(
    root: &toml_edit::Table,
    n: usize,
    name: &str,
    key: &str,
) -> Option<std::ops::Range<usize>> {
    let t = *slave_tables(root).get(n)?;
    key_at(t, key).or_else(|| {
        let ns = t.get(name)?.as_table_like()?;
        key_at(ns, key).or_else(|| key_at(t, name))
    })
}

/// `; did you mean …?` for `key` among `known`, else the valid keys.
fn key_hint(key: &str, known: &[&str]) -> String {
    let near = DidYouMean::new(key, known.iter().copied());
    if near.is_empty() {
        format!(" (valid: {})", known.join(", "))
    } else {
        near.to_string()
    }
}

impl Ctx<'_> {
    /// Every key of the file is one the bus file knows: the tables'
    /// keys, and a `[[slave]]` table's keys other than profile options
    /// (a key of a `device` slave that is none of [`SLAVE_KEYS`] is an
    /// option, checked by the profile, unless it is a misspelt slave key
    /// whose right spelling is missing).
    fn check_keys(&self, root: &toml_edit::Table) -> Result<(), BusFileError> {
        for (k, item) in root.iter() {
            let (table, known) = match k {
                "master" => ("[master]", field_names::<RawMaster>()),
                "bus" => ("[bus]", field_names::<RawBus>()),
                "options" => ("[options]", field_names::<RawOptions>()),
                "slave" => {
                    for t in slave_tables(root) {
                        self.check_slave_keys(t)?;
                    }
                    continue;
                }
                "mqtt" | "opcua" => continue,
                other => {
                    return Err(self.err(
                        key_at(root, other),
                        format!(
                            "unknown table `{other}`{}",
                            key_hint(other, field_names::<RawFile>())
                        ),
                    ))
                }
            };
            let Some(t) = item.as_table_like() else {
                continue;
            };
            for (key, _) in t.iter() {
                if !known.contains(&key) {
                    return Err(self.err(
                        key_at(t, key),
                        format!("unknown key `{key}` in {table}{}", key_hint(key, known)),
                    ));
                }
            }
        }
        Ok(())
    }

    fn check_slave_keys(&self, t: &dyn TableLike) -> Result<(), BusFileError> {
        let slave = match t.get("address").and_then(|a| a.as_integer()) {
            Some(a) => format!("slave {a}: "),
            None => String::new(),
        };
        let device = t.contains_key("device");
        for (k, _) in t.iter() {
            if SLAVE_KEYS.contains(&k) {
                continue;
            }
            let near = DidYouMean::new(k, SLAVE_KEYS.iter().copied());
            let misspelt = near.0.iter().any(|n| !t.contains_key(n));
            let message = if !device {
                let hint = if near.is_empty() {
                    " (profile options need `device = \"NAME\"`)".to_string()
                } else {
                    near.to_string()
                };
                format!("{slave}unknown key `{k}` in [[slave]]{hint}")
            } else if misspelt {
                format!("{slave}unknown key `{k}` in [[slave]]{near}")
            } else {
                continue;
            };
            return Err(self.err(key_at(t, k), message));
        }
        Ok(())
    }
}

/// The largest bus file read, in bytes (1 MiB; a bus file of 125 slaves
/// is some 20 KB). Parsing costs up to some 50 times the file's size.
pub const MAX_BUS_FILE: u64 = 1 << 20;

impl BusFile {
    /// Read and check a bus file without device profiles; see the module
    /// docs.
    pub fn load(path: impl AsRef<Path>) -> Result<BusFile, BusFileError> {
        Self::load_with(path, &NoProfiles)
    }

    /// Read and check a bus file whose `device = "NAME"` entries
    /// `resolver` resolves.
    pub fn load_with(
        path: impl AsRef<Path>,
        resolver: &dyn DeviceResolver,
    ) -> Result<BusFile, BusFileError> {
        let path = path.as_ref();
        let io = |m: String| BusFileError {
            path: path.to_path_buf(),
            line: 0,
            column: 0,
            message: m,
        };
        let text = crate::config::file::read_text(path, MAX_BUS_FILE, "a bus file").map_err(
            |e| match e {
                crate::config::file::ReadFileError::NotUtf8 { line, column, .. } => BusFileError {
                    line,
                    column,
                    ..io(e.to_string())
                },
                e => io(e.to_string()),
            },
        )?;
        Self::parse_with(path, &text, resolver)
    }

    /// Check the text of a bus file without device profiles; GSD paths
    /// are relative to `path`'s directory.
    pub fn parse(path: &Path, text: &str) -> Result<BusFile, BusFileError> {
        Self::parse_with(path, text, &NoProfiles)
    }

    /// Check the text of a bus file whose `device = "NAME"` entries
    /// `resolver` resolves.
    ///
    /// The steps, each a function: every key checked where it is (which
    /// also yields the profile options), the `[master]` table, each
    /// `[[slave]]` (its GSD or device profile, its modules, its
    /// User_Prm_Data, its parameters), then the `[bus]` table against the
    /// slaves' needs and the `[options]`. The first error found is
    /// returned.
    pub fn parse_with(
        path: &Path,
        text: &str,
        resolver: &dyn DeviceResolver,
    ) -> Result<BusFile, BusFileError> {
        let cx = Ctx { path, text };
        let (profile_options, positions) = cx.read_keys()?;
        let raw: RawFile = toml::from_str(text).map_err(|e| cx.err(e.span(), e.message()))?;
        let mut warnings = Vec::new();
        let (address, baud) = cx.master(&raw.master)?;
        let master = Master { address, baud };

        let dir = path.parent().unwrap_or(Path::new("."));
        let mut slaves = Vec::new();
        let mut seen = [false; 128];
        let mut max_tsdr_needed = 0u32;
        for (n, rs) in raw.slave.iter().enumerate() {
            let options = profile_options.get(n).cloned().unwrap_or_default();
            let site = SlaveSite {
                n,
                dir,
                options,
                resolver,
            };
            let (slave, max_tsdr) = cx.slave(master, rs, site, &mut seen, &mut warnings)?;
            max_tsdr_needed = max_tsdr_needed.max(max_tsdr.unwrap_or(0));
            slaves.push(slave);
        }

        let params = cx.bus_params(raw.bus.as_ref(), baud, max_tsdr_needed, &mut warnings)?;
        let options = master_options(raw.options.unwrap_or_default());
        Ok(BusFile {
            path: path.to_path_buf(),
            master: MasterConfig {
                address,
                params,
                slaves: slaves.iter().map(|s| s.params.clone()).collect(),
                options,
            },
            slaves,
            warnings,
            mqtt: raw.mqtt,
            opcua: raw.opcua,
            positions,
        })
    }
}

/// The master's address and baud rate, which every slave is checked
/// against.
#[derive(Clone, Copy)]
struct Master {
    address: u8,
    baud: Baud,
}

/// Where a `[[slave]]` table stands: its index among the slave tables,
/// the bus file's directory (GSD paths are relative to it), its profile
/// options and the resolver of `device = "NAME"`.
struct SlaveSite<'r> {
    n: usize,
    dir: &'r Path,
    options: toml::Table,
    resolver: &'r dyn DeviceResolver,
}

/// Where a slave's GSD came from: a file or a device profile.
struct GsdSource {
    /// The GSD file, or the words ``the GSD of device `NAME` ``.
    gsd_path: PathBuf,
    gsd: Gsd,
    device: Option<DeviceEntry>,
    /// `gsd = …` or `device = …`: where errors about the GSD are shown.
    span: std::ops::Range<usize>,
    /// The module names to configure, with their position in the file
    /// (`None`: chosen by the device profile).
    modules: Vec<(String, Option<std::ops::Range<usize>>)>,
}

impl GsdSource {
    /// The GSD for people: the file, or the device profile's.
    fn describe(&self) -> String {
        match &self.device {
            Some(d) => format!("device `{}`", d.name),
            None => self.gsd_path.display().to_string(),
        }
    }
}

impl Ctx<'_> {
    /// Step 1, the keys: every key of the file with its position first,
    /// so that a misspelt key is named where it is with the closest valid
    /// keys; then each `[[slave]]` table's profile options (checked before
    /// the typed read, so that a profile option given where a slave key
    /// of the same name goes gets its own message rather than the slave
    /// key's type error).
    ///
    /// Also returns where the keys of `[mqtt]` and `[opcua]` are.
    fn read_keys(&self) -> Result<(Vec<toml::Table>, KeyPositions), BusFileError> {
        // The parsed document is dropped before the file is read again:
        // a large file costs one parse at a time.
        let mut positions = KeyPositions::default();
        {
            let doc = toml_edit::ImDocument::parse(self.text)
                .map_err(|e| self.err(e.span(), e.message().trim_end()))?;
            self.check_keys(doc.as_table())?;
            let root = doc.as_table();
            for name in ["mqtt", "opcua"] {
                if let Some(item) = root.get(name) {
                    self.record(&mut positions, name, key_at(root, name), item);
                }
            }
        }
        let tables: SlaveTables =
            toml::from_str(self.text).map_err(|e| self.err(e.span(), e.message()))?;
        let options = tables
            .slave
            .iter()
            .map(|t| self.profile_options(t))
            .collect::<Result<_, _>>()?;
        Ok((options, positions))
    }

    /// Record where `path` (at `span`) and everything inside `item` are.
    fn record(
        &self,
        out: &mut KeyPositions,
        path: &str,
        span: Option<std::ops::Range<usize>>,
        item: &Item,
    ) {
        if let Some(r) = span {
            out.0.insert(path.to_string(), self.line_col(r.start));
        }
        match item {
            Item::ArrayOfTables(a) => {
                for (i, t) in a.iter().enumerate() {
                    let p = format!("{path}.{}", i + 1);
                    if let Some(r) = t.span() {
                        out.0.insert(p.clone(), self.line_col(r.start));
                    }
                    self.record_table(out, &p, t);
                }
            }
            Item::Value(toml_edit::Value::Array(a)) => {
                for (i, v) in a.iter().enumerate() {
                    let p = format!("{path}.{}", i + 1);
                    if let Some(r) = v.span() {
                        out.0.insert(p.clone(), self.line_col(r.start));
                    }
                    if let Some(t) = v.as_inline_table() {
                        self.record_table(out, &p, t);
                    }
                }
            }
            _ => {
                if let Some(t) = item.as_table_like() {
                    self.record_table(out, path, t);
                }
            }
        }
    }

    fn record_table(&self, out: &mut KeyPositions, path: &str, t: &dyn TableLike) {
        for (k, item) in t.iter() {
            self.record(out, &format!("{path}.{k}"), key_at(t, k), item);
        }
    }

    /// Step 2, the `[master]` table: its address and baud rate.
    fn master(&self, m: &Spanned<RawMaster>) -> Result<(u8, Baud), BusFileError> {
        let m = m.get_ref();
        let address = *m.address.get_ref();
        if address > 125 {
            return Err(self.err(
                Some(m.address.span()),
                format!("master address {address} is outside 0..=125"),
            ));
        }
        let baud = match m.baud.get_ref() {
            BaudValue::Number(n) => Baud::from_bps(*n).ok_or_else(|| {
                self.err(
                    Some(m.baud.span()),
                    format!("{n} is not a PROFIBUS baud rate"),
                )
            })?,
            BaudValue::Text(s) => s
                .parse::<Baud>()
                .map_err(|e| self.err(Some(m.baud.span()), e.to_string()))?,
        };
        Ok((address, baud))
    }

    /// Step 3, one `[[slave]]` table: its address, its GSD (file or
    /// device profile), its modules, its User_Prm_Data and the master's
    /// parameters for it. Returns the slave and the GSD's `MaxTsdr` at the
    /// baud rate, which the bus parameters must allow.
    fn slave(
        &self,
        master: Master,
        rs: &Spanned<RawSlave>,
        site: SlaveSite<'_>,
        seen: &mut [bool; 128],
        warnings: &mut Vec<String>,
    ) -> Result<(BusSlave, Option<u32>), BusFileError> {
        let s = rs.get_ref();
        let addr = *s.address.get_ref();
        if addr > 125 || addr == master.address {
            return Err(self.err(
                Some(s.address.span()),
                format!(
                    "slave address {addr} is invalid (0..=125 and not the master's {})",
                    master.address
                ),
            ));
        }
        if std::mem::replace(&mut seen[addr as usize], true) {
            return Err(self.err(
                Some(s.address.span()),
                format!("a second slave with address {addr}"),
            ));
        }
        let source = self.gsd_source(rs, site, warnings)?;
        let baud = master.baud;
        if !source.gsd.supports_baud(baud) {
            return Err(self.err(
                Some(source.span.clone()),
                format!(
                    "slave {addr}: {} does not support {baud}",
                    source.describe()
                ),
            ));
        }
        let max_tsdr = source.gsd.max_tsdr(baud);
        let (selection, names) = self.modules(rs, &source)?;
        let gsd = &source.gsd;
        let cfg = gsd
            .chk_cfg(&selection)
            .map_err(|e| self.err(Some(rs.span()), format!("slave {addr}: {e}")))?;
        let user_prm_data = self.user_prm_data(rs, gsd, &selection)?;
        let params = self.slave_params(rs, gsd, cfg, user_prm_data)?;
        let GsdSource {
            gsd_path,
            gsd,
            device,
            ..
        } = source;
        let slave = BusSlave {
            params,
            gsd_path,
            device,
            gsd,
            modules: names,
        };
        Ok((slave, max_tsdr))
    }

    /// The slave's GSD: `gsd = FILE` (read leniently, its quirks added
    /// to `warnings`) with `modules`, or `device = NAME` resolved by the
    /// site's resolver. Exactly one of the two.
    fn gsd_source(
        &self,
        rs: &Spanned<RawSlave>,
        site: SlaveSite<'_>,
        warnings: &mut Vec<String>,
    ) -> Result<GsdSource, BusFileError> {
        let s = rs.get_ref();
        let addr = *s.address.get_ref();
        match (&s.gsd, &s.device) {
            (Some(g), None) => {
                let gsd_path = site.dir.join(g.get_ref());
                let parsed = Gsd::from_file(&gsd_path, ParseOptions { lenient: true })
                    .map_err(|e| self.err(Some(g.span()), format!("GSD file: {e}")))?;
                for w in &parsed.warnings {
                    warnings.push(format!("{}:{w}", gsd_path.display()));
                }
                let modules = s
                    .modules
                    .iter()
                    .map(|m| (m.get_ref().clone(), Some(m.span())))
                    .collect();
                Ok(GsdSource {
                    gsd_path,
                    gsd: parsed.gsd,
                    device: None,
                    span: g.span(),
                    modules,
                })
            }
            (_, Some(d)) => {
                if let Some(m) = s.modules.first() {
                    return Err(self.err(
                        Some(m.span()),
                        format!("slave {addr}: a device profile chooses its modules; give its options instead"),
                    ));
                }
                let entry = DeviceEntry {
                    name: d.get_ref().clone(),
                    dir: site.dir.to_path_buf(),
                    options: site.options,
                };
                let r = site.resolver.resolve(&entry, addr).map_err(|e| {
                    let at = match &e.option {
                        // Parsed again for the key's position: only on
                        // this error.
                        Some(key) => toml_edit::ImDocument::parse(self.text)
                            .ok()
                            .and_then(|doc| option_at(doc.as_table(), site.n, &entry.name, key)),
                        None => None,
                    };
                    let at = at.or(Some(d.span()));
                    self.err(at, format!("slave {addr}: {e}"))
                })?;
                Ok(GsdSource {
                    gsd_path: PathBuf::from(format!("the GSD of device `{}`", entry.name)),
                    gsd: r.gsd,
                    device: Some(entry),
                    span: d.span(),
                    modules: r.modules.into_iter().map(|m| (m, None)).collect(),
                })
            }
            _ => Err(self.err(
                Some(rs.span()),
                format!("slave {addr}: give either `gsd` (with `modules`) or `device`"),
            )),
        }
    }

    /// Step 4, module resolution: each module name found in the GSD (by
    /// exact name), or the GSD's default selection when none is given;
    /// then the selection checked against the GSD's limits. Returns the
    /// module indexes and their names.
    fn modules(
        &self,
        rs: &Spanned<RawSlave>,
        source: &GsdSource,
    ) -> Result<(Vec<usize>, Vec<String>), BusFileError> {
        let s = rs.get_ref();
        let addr = *s.address.get_ref();
        let gsd = &source.gsd;
        let mut selection = Vec::new();
        let mut names = Vec::new();
        for (m, span) in &source.modules {
            let i = gsd.find_module_index(m).map_err(|e| {
                self.err(
                    span.clone().or(Some(source.span.clone())),
                    format!("slave {addr}: {}: {e}", source.describe()),
                )
            })?;
            selection.push(i);
            names.push(gsd.modules[i].name.clone());
        }
        if source.modules.is_empty() {
            selection = gsd.default_selection();
            names = selection
                .iter()
                .map(|&i| gsd.modules[i].name.clone())
                .collect();
        }
        let problems = gsd.check_selection(&selection);
        if !problems.is_empty() {
            let span = s.modules.first().map(|m| m.span()).unwrap_or(rs.span());
            let all: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
            return Err(self.err(Some(span), format!("slave {addr}: {}", all.join("; "))));
        }
        Ok((selection, names))
    }

    /// The slave's User_Prm_Data: the GSD's defaults for the selected
    /// modules with the `params` table's values by name.
    fn user_prm_data(
        &self,
        rs: &Spanned<RawSlave>,
        gsd: &Gsd,
        selection: &[usize],
    ) -> Result<Vec<u8>, BusFileError> {
        let s = rs.get_ref();
        let addr = *s.address.get_ref();
        let mut values = Vec::new();
        for (name, v) in &s.params {
            let text = match v.get_ref() {
                toml::Value::Integer(i) => i.to_string(),
                toml::Value::String(t) => t.clone(),
                toml::Value::Boolean(b) => (*b as u8).to_string(),
                other => {
                    return Err(self.err(
                        Some(v.span()),
                        format!("parameter `{name}`: {other} is neither a number nor a text"),
                    ))
                }
            };
            let pv: PrmValue = format!("{name}={text}").parse().map_err(
                |e: crate::config::gsd::PrmValueParseError| self.err(Some(v.span()), e.to_string()),
            )?;
            values.push(pv);
        }
        gsd.user_prm_data(selection, &values)
            .map_err(|e| self.err(Some(rs.span()), format!("slave {addr}: {e}")))
    }

    /// Step 5, the checks of a slave: sync and freeze only where the GSD
    /// has them, the initial outputs within the output length, Set_Prm
    /// within 244 bytes; and the master's parameters for the slave
    /// (name, watchdog, group, DP-V1, intervals from the GSD).
    fn slave_params(
        &self,
        rs: &Spanned<RawSlave>,
        gsd: &Gsd,
        cfg: Vec<u8>,
        user_prm_data: Vec<u8>,
    ) -> Result<SlaveParams, BusFileError> {
        let s = rs.get_ref();
        let addr = *s.address.get_ref();
        let flag = |f: &Option<Spanned<bool>>| f.as_ref().is_some_and(|v| *v.get_ref());
        let span = |f: &Option<Spanned<bool>>| f.as_ref().map(|v| v.span());
        if flag(&s.sync) && !gsd.sync_mode_supp {
            return Err(self.err(
                span(&s.sync),
                format!("slave {addr}: the GSD says the device has no sync mode"),
            ));
        }
        if flag(&s.freeze) && !gsd.freeze_mode_supp {
            return Err(self.err(
                span(&s.freeze),
                format!("slave {addr}: the GSD says the device has no freeze mode"),
            ));
        }
        let mut p = SlaveParams::new(addr, gsd.ident_number, cfg);
        p.name = s.name.clone().unwrap_or_else(|| {
            gsd.model_name
                .clone()
                .unwrap_or_else(|| format!("slave {addr}"))
        });
        p.watchdog = match s.watchdog_ms {
            Some(0) => None,
            Some(ms) => Some(Duration::from_millis(ms)),
            None => Some(Duration::from_secs(1)),
        };
        p.group = s.group.unwrap_or(0);
        p.sync = flag(&s.sync);
        p.freeze = flag(&s.freeze);
        p.user_prm_data = user_prm_data;
        p.dpv1 = s.dpv1.unwrap_or(gsd.dpv1_slave);
        (p.alarms, p.alarm_mode) = self.alarms(rs, gsd, p.dpv1)?;
        p.fail_safe = gsd.fail_safe;
        p.min_slave_interval =
            Duration::from_micros(100 * gsd.min_slave_intervall.unwrap_or(0) as u64);
        p.dpv1_timeout =
            Duration::from_millis(10 * gsd.c1_response_timeout.map_or(100, |t| t.max(1)) as u64);
        let (_, output_len) = p
            .io_lengths()
            .map_err(|e| self.err(Some(rs.span()), format!("slave {addr}: {e}")))?;
        if let Some(io) = &s.initial_outputs {
            if io.get_ref().len() > output_len {
                return Err(self.err(
                    Some(io.span()),
                    format!(
                        "slave {addr}: {} initial output bytes, the modules have {output_len}",
                        io.get_ref().len()
                    ),
                ));
            }
            p.initial_outputs = io.get_ref().clone();
        }
        if p.set_prm().len() > 244 {
            return Err(self.err(
                Some(rs.span()),
                format!("slave {addr}: Set_Prm would exceed 244 bytes"),
            ));
        }
        Ok(p)
    }

    /// The DP-V1 alarms Set_Prm enables (DPV1_Status_2) and the
    /// Alarm_Mode (DPV1_Status_3): every alarm type the GSD declares
    /// (`Diagnostic_Alarm_supp`, …) unless the slave's `alarms` key
    /// names fewer (`alarms = ["diagnostic", …]`) or none (`alarms =
    /// false`). A name that is no alarm type, or an alarm the GSD does
    /// not declare, is an error at the name. The mode is sequence mode
    /// with the most alarms `Alarm_Sequence_Mode_Count` allows, else
    /// type mode (one per type).
    fn alarms(
        &self,
        rs: &Spanned<RawSlave>,
        gsd: &Gsd,
        dpv1: bool,
    ) -> Result<(Dpv1Status2, AlarmMode), BusFileError> {
        let s = rs.get_ref();
        let addr = *s.address.get_ref();
        let declared = if dpv1 {
            gsd.declared_alarms()
        } else {
            Dpv1Status2::empty()
        };
        let mode = gsd.alarm_mode();
        let Some(raw) = &s.alarms else {
            return Ok((declared, mode));
        };
        let span = raw.span();
        let names: Vec<&str> = match raw.get_ref() {
            toml::Value::Boolean(true) => return Ok((declared, mode)),
            toml::Value::Boolean(false) => return Ok((Dpv1Status2::empty(), mode)),
            toml::Value::Array(a) => a.iter().filter_map(|v| v.as_str()).collect(),
            _ => vec![],
        };
        let list = matches!(raw.get_ref(), toml::Value::Array(a) if a.len() == names.len());
        if !list {
            return Err(self.err(
                Some(span),
                format!(
                    "slave {addr}: `alarms` is a list of alarm types (diagnostic, process, \
                     pull_plug, status, update, manufacturer), or false"
                ),
            ));
        }
        if names.is_empty() {
            return Ok((Dpv1Status2::empty(), mode));
        }
        if !dpv1 {
            return Err(self.err(
                Some(span),
                format!("slave {addr}: alarms need a DP-V1 slave, and the GSD says it is none"),
            ));
        }
        // Where a name is: its quoted text inside the list.
        let at = |name: &str| {
            let inside = self.text.get(span.clone()).unwrap_or("");
            let quoted = format!("\"{name}\"");
            let i = inside.find(&quoted).or_else(|| inside.find(name));
            Some(i.map_or(span.clone(), |i| span.start + i..span.end))
        };
        let valid = AlarmEnable::ALL.map(AlarmEnable::name);
        let mut want = Dpv1Status2::empty();
        for name in names {
            let Some(e) = AlarmEnable::from_name(name) else {
                return Err(self.err(
                    at(name),
                    format!(
                        "slave {addr}: unknown alarm type `{name}`{}",
                        key_hint(name, &valid)
                    ),
                ));
            };
            if !declared.contains(e.bit()) {
                return Err(self.err(
                    at(name),
                    format!(
                        "slave {addr}: {} does not declare {name} alarms (no {} = 1)",
                        gsd.model_name
                            .as_deref()
                            .map_or("the GSD".to_string(), |m| format!("the GSD of {m}")),
                        e.gsd_keyword()
                    ),
                ));
            }
            want |= e.bit();
        }
        Ok((want, mode))
    }

    /// Step 6, the `[bus]` table: the defaults of the baud rate with the
    /// file's values; max TSDR raised to the slaves' largest `MaxTsdr`
    /// and the slot time to max TSDR + 15 unless the file sets them (then
    /// too low a value is an error); the result validated.
    fn bus_params(
        &self,
        bus: Option<&Spanned<RawBus>>,
        baud: Baud,
        max_tsdr_needed: u32,
        warnings: &mut Vec<String>,
    ) -> Result<BusParams, BusFileError> {
        let mut params = BusParams::defaults(baud);
        let b = bus.map(|b| b.get_ref());
        let set = |v: Option<u32>, d: &mut u32| {
            if let Some(v) = v {
                *d = v;
            }
        };
        if let Some(b) = b {
            set(b.slot_time, &mut params.slot_time);
            set(b.min_tsdr, &mut params.min_tsdr);
            set(b.max_tsdr, &mut params.max_tsdr);
            set(b.tset, &mut params.tset);
            set(b.tqui, &mut params.tqui);
            set(b.ttr, &mut params.ttr);
            params.gap_factor = b.gap_factor.unwrap_or(params.gap_factor);
            params.hsa = b.hsa.unwrap_or(params.hsa);
            params.max_retry = b.max_retry.unwrap_or(params.max_retry);
        }
        if max_tsdr_needed > params.max_tsdr {
            if b.is_some_and(|b| b.max_tsdr.is_some()) {
                return Err(self.err(
                    bus.map(|b| b.span()),
                    format!(
                        "max_tsdr {} is below the slaves' MaxTsdr of {max_tsdr_needed} at {baud}",
                        params.max_tsdr
                    ),
                ));
            }
            warnings.push(format!(
                "max TSDR raised from {} to {max_tsdr_needed} bit for the slaves' GSD MaxTsdr",
                params.max_tsdr
            ));
            params.max_tsdr = max_tsdr_needed;
        }
        if params.slot_time < params.max_tsdr + 15 {
            if b.is_some_and(|b| b.slot_time.is_some()) {
                return Err(self.err(
                    bus.map(|b| b.span()),
                    format!(
                        "slot_time {} must be at least max TSDR + 15 = {}",
                        params.slot_time,
                        params.max_tsdr + 15
                    ),
                ));
            }
            params.slot_time = params.max_tsdr + 15;
        }
        params
            .validate()
            .map_err(|e| self.err(bus.map(|b| b.span()), e.to_string()))?;
        Ok(params)
    }
}

/// Step 7, the `[options]` table: the master's options, defaults where
/// the file gives none (a 0 ms interval is off).
fn master_options(o: RawOptions) -> MasterOptions {
    let d = MasterOptions::default();
    let ms = |v: Option<u64>| v.filter(|&x| x > 0).map(Duration::from_millis);
    MasterOptions {
        lost_after: o.lost_after.unwrap_or(d.lost_after).max(1),
        reprobe_interval: o
            .reprobe_ms
            .map(Duration::from_millis)
            .unwrap_or(d.reprobe_interval),
        diag_interval: ms(o.diag_interval_ms),
        global_control_interval: match o.global_control_ms {
            None => d.global_control_interval,
            Some(v) => ms(Some(v)),
        },
        not_ready_limit: d.not_ready_limit,
        alone_hold_bits: o.alone_hold_bits.or(d.alone_hold_bits),
    }
}

/// Where `key` is set inside the table at `span` (its line), else the
/// table.
fn key_span(text: &str, span: std::ops::Range<usize>, key: &str) -> Option<std::ops::Range<usize>> {
    let body = text.get(span.clone())?;
    let mut at = 0;
    for line in body.split_inclusive('\n') {
        let t = line.trim_start();
        if t.strip_prefix(key)
            .is_some_and(|r| r.trim_start().starts_with('=') || r.starts_with('.'))
        {
            let start = span.start + at + (line.len() - t.len());
            return Some(start..start + key.len());
        }
        at += line.len();
    }
    Some(span)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gsd_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../devices/gsd/bus.toml")
    }

    /// A bus file whose slave 25 is the device profile `omega2`; its
    /// further keys follow.
    const OMEGA2_BUS: &str =
        "[master]\naddress = 2\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 25\ndevice = \"omega2\"\n";

    /// `text` parsed as crates/devices/gsd/bus.toml with the device profile `omega2`.
    fn with_omega2(text: &str) -> Result<BusFile, BusFileError> {
        BusFile::parse_with(&gsd_dir(), text, &OneProfile)
    }

    fn load(text: &str) -> Result<BusFile, BusFileError> {
        BusFile::parse(&gsd_dir(), text)
    }

    /// The keys of the raw tables are found where they are written, in
    /// `[mqtt]`, dotted, in `[[mqtt.slave]]` entries (by number) and in
    /// inline tables; an unknown path falls back to the closest key.
    #[test]
    fn raw_tables_know_where_their_keys_are() {
        let b = load(
            "[master]\naddress = 2\nbaud = \"1.5M\"\n\n[mqtt]\nqos = 3\n  deadband = \"x\"\n\
             [[mqtt.slave]]\naddress = 4\n[[mqtt.slave]]\naddress = 5\n\
             channels = { \"1.KL3102.1\" = 0.5, ai = [] }\n\n[opcua]\nsecurity = 1\n",
        )
        .unwrap();
        let at = |p: &str| b.positions.at(p);
        assert_eq!(at("mqtt"), Some((5, 2)));
        assert_eq!(at("mqtt.qos"), Some((6, 1)));
        assert_eq!(at("mqtt.deadband"), Some((7, 3)));
        assert_eq!(at("mqtt.slave.1"), Some((8, 1)));
        assert_eq!(at("mqtt.slave.2.address"), Some((11, 1)));
        assert_eq!(at("mqtt.slave.2.channels.1.KL3102.1"), Some((12, 14)));
        assert_eq!(at("mqtt.slave.2.channels.ai"), Some((12, 34)));
        assert_eq!(at("mqtt.slave.2.nothing"), Some((10, 1)));
        assert_eq!(at("mqtt.nothing"), Some((5, 2)));
        assert_eq!(at("opcua.security"), Some((15, 1)));
        assert_eq!(at("nothing"), None);
        let e = b.error_at("mqtt.qos", "[mqtt]: `qos` must be 0, 1 or 2");
        assert!(
            e.to_string()
                .ends_with("bus.toml:6:1: [mqtt]: `qos` must be 0, 1 or 2"),
            "{e}"
        );
        let e = b.error_at("nothing", "why");
        assert!(e.to_string().ends_with("bus.toml: why"), "{e}");
        // Dotted keys at the root.
        let b = load("mqtt.qos = 3\n[master]\naddress = 2\nbaud = \"1.5M\"\n").unwrap();
        assert_eq!(b.positions.at("mqtt.qos"), Some((1, 6)));
    }

    #[test]
    fn omega_board_from_its_gsd() {
        let b = load(
            r#"
[master]
address = 2
baud = "1.5M"

[[slave]]
address = 5
gsd = "BNF_00D0.GSD"
modules = ["Service data module", "Status / control module", "8 cycl. actual values (16 AI)", "8 cycl. setpoints (16 AO)"]
watchdog_ms = 300
"#,
        );
        let b = match b {
            Ok(b) => b,
            Err(e) => panic!("{e}"),
        };
        let s = &b.master.slaves[0];
        assert_eq!(s.ident_number, 0x00D0);
        assert_eq!(s.io_lengths().unwrap(), (44, 44));
        assert_eq!(b.master.params.baud, Baud::B1500000);
        assert_eq!(b.master.address, 2);
        // A class-1 master announces Operate/Clear cyclically by default.
        assert_eq!(
            b.master.options.global_control_interval,
            Some(crate::master::DEFAULT_GLOBAL_CONTROL_INTERVAL)
        );
    }

    #[test]
    fn global_control_period_from_the_options() {
        for (line, want) in [
            ("global_control_ms = 0", None),
            ("global_control_ms = 40", Some(Duration::from_millis(40))),
        ] {
            let text = format!(
                "[master]\naddress = 2\nbaud = \"1.5M\"\n[options]\n{line}\n[[slave]]\naddress = 5\ngsd = \"BNF_00D0.GSD\"\nmodules = [\"Service data module\"]\n"
            );
            let b = load(&text).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(b.master.options.global_control_interval, want, "{line}");
        }
    }

    #[test]
    fn errors_name_line_and_what_is_wrong() {
        let e = load(
            r#"[master]
address = 2
baud = "1.5M"

[[slave]]
address = 5
gsd = "BNF_00D0.GSD"
modules = ["no such module"]
"#,
        )
        .unwrap_err();
        assert_eq!(e.line, 8, "{e}");
        assert!(e.to_string().contains("no such module"), "{e}");

        let e = load("[master]\naddress = 2\nbaud = 115200\n").unwrap_err();
        assert_eq!(e.line, 3);
        assert!(e.message.contains("not a PROFIBUS baud rate"));

        let e = load("[master]\naddress = 2\nbaud = \"1.5M\"\nfoo = 1\n").unwrap_err();
        assert_eq!(e.line, 4, "{e}");

        let e = load(
            "[master]\naddress = 2\nbaud = \"1.5M\"\n[[slave]]\naddress = 2\ngsd = \"BNF_00D0.GSD\"\n",
        )
        .unwrap_err();
        assert!(e.message.contains("not the master's"), "{e}");
    }

    /// A resolver with one profile, `omega2`: BNF_00D0.GSD with 2/2
    /// values, `pkw = false` leaves the service data module out.
    struct OneProfile;

    impl DeviceResolver for OneProfile {
        fn resolve(
            &self,
            entry: &DeviceEntry,
            _address: u8,
        ) -> Result<ResolvedDevice, DeviceError> {
            if entry.name != "omega2" {
                return Err(DeviceError::new(format!(
                    "no device profile `{}`",
                    entry.name
                )));
            }
            if let Some(k) = entry.options.keys().find(|k| *k != "pkw" && *k != "gsd") {
                return Err(DeviceError::at_option(
                    k.clone(),
                    format!("device `omega2`: unknown option `{k}`"),
                ));
            }
            let gsd = Gsd::from_file(
                gsd_dir().with_file_name("BNF_00D0.GSD"),
                ParseOptions { lenient: true },
            )
            .map_err(DeviceError::new)?
            .gsd;
            let mut modules = vec![
                "Status / control module",
                "2 cycl. actual values ( 4 AI)",
                "2 cycl. setpoints ( 4 AO)",
            ];
            if entry.options.get("pkw") != Some(&toml::Value::Boolean(false)) {
                modules.insert(0, "Service data module");
            }
            Ok(ResolvedDevice {
                gsd,
                modules: modules.into_iter().map(String::from).collect(),
            })
        }
    }

    /// The error of `text` as crates/devices/gsd/bus.toml with the profile `omega2`:
    /// `line:col: message`.
    fn error_of(text: &str) -> String {
        let e = with_omega2(text).unwrap_err();
        format!("{}:{}: {}", e.line, e.column, e.message)
    }

    /// A bus file of master 2 with one slave at 5 of DPCTL_GEN.GSD whose
    /// `modules` line is `modules`.
    fn gen_bus(modules: &str) -> String {
        format!(
            "[master]\naddress = 2\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 5\ngsd = \"DPCTL_GEN.GSD\"\n{modules}\n"
        )
    }

    #[test]
    fn alarms_default_to_the_gsd_and_the_key_narrows_or_switches_them_off() {
        use crate::pdu::prm::Dpv1Status2 as S2;
        let bus = |line: &str| {
            format!(
                "[master]\naddress = 2\nbaud = \"1.5M\"\n[[slave]]\naddress = 9\n\
                 gsd = \"../../cli/tests/data/DPCTL_ALM.GSD\"\nmodules = [\"1 byte in\"]\n{line}\n"
            )
        };
        let params = |line: &str| {
            load(&bus(line))
                .unwrap_or_else(|e| panic!("{e}"))
                .master
                .slaves[0]
                .clone()
        };
        let p = params("");
        assert_eq!(
            p.alarms,
            S2::DIAGNOSTIC_ALARM | S2::PROCESS_ALARM | S2::PULL_PLUG_ALARM
        );
        assert_eq!(p.alarm_mode.0, 3, "Alarm_Sequence_Mode_Count=8: mode 3");
        // DPV1_Enable, the enables, Alarm_Mode.
        assert_eq!(&p.set_prm()[7..], &[0x80, 0xE0, 0x03]);
        assert_eq!(params("alarms = [\"process\"]").alarms, S2::PROCESS_ALARM);
        let off = params("alarms = false");
        assert!(off.alarms.is_empty());
        assert_eq!(&off.set_prm()[7..], &[0x80, 0x00, 0x00]);
        let e = load(&bus("alarms = [\"prozess\"]")).unwrap_err();
        assert_eq!((e.line, e.column), (8, 11), "{e}");
        assert!(
            e.message
                .ends_with("unknown alarm type `prozess`; did you mean `process`?"),
            "{e}"
        );
        let e = load(&bus("alarms = \"all\"")).unwrap_err();
        assert!(e.message.contains("is a list of alarm types"), "{e}");
        // DPCTL_GEN.GSD is DP-V1 without alarms.
        let e = load(&gen_bus(
            "modules = [\"1 byte in\"]\nalarms = [\"diagnostic\"]",
        ))
        .unwrap_err();
        assert!(
            e.message
                .contains("does not declare diagnostic alarms (no Diagnostic_Alarm_supp = 1)"),
            "{e}"
        );
    }

    #[test]
    fn module_names_match_exactly_or_not_at_all() {
        let b = load(&gen_bus("modules = [\"2 words in/out\"]")).unwrap();
        assert_eq!(b.slaves[0].modules, ["2 words in/out"]);
        // Not in the GSD: an error at the name, with the closest names,
        // never the nearest module instead.
        assert_eq!(
            error_of(&gen_bus("modules = [\"1 byte in\", \"3 words in/out\"]")),
            format!(
                "8:25: slave 5: {}: no module named `3 words in/out`; \
                 did you mean `2 words in/out`?",
                gsd_dir().with_file_name("DPCTL_GEN.GSD").display()
            )
        );
        for near in ["2 Words in/out", "2 words"] {
            let e = error_of(&gen_bus(&format!("modules = [\"{near}\"]")));
            assert!(e.starts_with("8:12: slave 5: "), "{e}");
            assert!(e.contains(": no module named"), "{e}");
            assert!(e.contains("did you mean `2 words in/out`"), "{e}");
        }
    }

    #[test]
    fn unknown_keys_are_named_where_they_are_with_the_closest() {
        let master = "[master]\naddress = 2\nbaud = \"1.5M\"\n";
        for (text, want) in [
            (
                "[master]\nadress = 2\nbaud = \"1.5M\"\n".to_string(),
                "2:1: unknown key `adress` in [master]; did you mean `address`?",
            ),
            (
                format!("{master}[bus]\nslot_tim = 300\n"),
                "5:1: unknown key `slot_tim` in [bus]; did you mean `slot_time`?",
            ),
            (
                format!("{master}[options]\nlost_afterr = 3\n"),
                "5:1: unknown key `lost_afterr` in [options]; did you mean `lost_after`?",
            ),
            (
                format!("{master}[optoins]\nlost_after = 3\n"),
                "4:2: unknown table `optoins`; did you mean `options`?",
            ),
            (
                format!("{master}[[slave]]\nadress = 5\ngsd = \"DPCTL_GEN.GSD\"\n"),
                "5:1: unknown key `adress` in [[slave]]; did you mean `address`?",
            ),
            (
                format!("{master}[[slave]]\naddress = 5\ngsd = \"DPCTL_GEN.GSD\"\nmodule = [\"1 byte in\"]\n"),
                "7:1: slave 5: unknown key `module` in [[slave]]; did you mean `modules`?",
            ),
            (
                format!("{master}[[slave]]\naddress = 5\ngsd = \"DPCTL_GEN.GSD\"\nfoo = 1\n"),
                "7:1: slave 5: unknown key `foo` in [[slave]] (profile options need `device = \"NAME\"`)",
            ),
            // A device slave: a misspelt slave key, then the profile's
            // own options, at their keys.
            (
                format!("{master}[[slave]]\nadress = 25\ndevice = \"omega2\"\n"),
                "5:1: unknown key `adress` in [[slave]]; did you mean `address`?",
            ),
            (
                format!("{OMEGA2_BUS}pkw = false\nsetpoint = 2\n"),
                "9:1: slave 25: device `omega2`: unknown option `setpoint`",
            ),
            (
                format!("{OMEGA2_BUS}omega2.setpoint = 2\n"),
                "8:8: slave 25: device `omega2`: unknown option `setpoint`",
            ),
        ] {
            assert_eq!(error_of(&text), want, "{text}");
        }
        // Without a suggestion: the valid keys.
        let e = error_of("[master]\naddress = 2\nbaud = \"1.5M\"\nspeed = 1\n");
        assert_eq!(
            e,
            "4:1: unknown key `speed` in [master] (valid: address, baud)"
        );
    }

    #[test]
    fn a_slave_may_name_a_device_profile() {
        let text = &format!("{OMEGA2_BUS}pkw = false\nwatchdog_ms = 300\n");
        let b = with_omega2(text).unwrap();
        let s = &b.slaves[0];
        assert_eq!(s.params.cfg, [0x71, 0x53, 0x63]);
        assert_eq!(s.params.user_prm_data.len(), 5);
        assert_eq!(s.params.watchdog, Some(Duration::from_millis(300)));
        let d = s.device.as_ref().unwrap();
        assert_eq!(d.name, "omega2");
        assert_eq!(d.options.get("pkw"), Some(&toml::Value::Boolean(false)));
        assert!(!d.options.contains_key("watchdog_ms"));

        // Without a registry, or with an unknown name: an error at `device`.
        let e = BusFile::parse(&gsd_dir(), text).unwrap_err();
        assert_eq!(e.line, 7, "{e}");
        let e = with_omega2(&text.replace("omega2", "nope")).unwrap_err();
        assert_eq!(e.message, "slave 25: no device profile `nope`", "{e}");
        // Profile options without a profile: the key's line.
        let e = with_omega2(&text.replace("device = \"omega2\"", "gsd = \"BNF_00D0.GSD\""))
            .unwrap_err();
        assert_eq!(e.line, 8, "{e}");
        assert!(e.message.contains("unknown key `pkw`"), "{e}");
        // `gsd` next to `device`: the profile's option `gsd` (a vendor's
        // GSD file the profile takes its identity from).
        let b = with_omega2(&text.replace("pkw = false", "gsd = \"VENDOR.GSD\"")).unwrap();
        let d = b.slaves[0].device.as_ref().unwrap();
        assert_eq!(
            d.options.get("gsd").and_then(|v| v.as_str()),
            Some("VENDOR.GSD")
        );
        let e = with_omega2(&text.replace("pkw = false", "gsd = 1")).unwrap_err();
        assert!(e.message.contains("path of a GSD file"), "{e}");
        // Neither.
        let e = with_omega2(
            OMEGA2_BUS
                .replace("device = \"omega2\"", "name = \"x\"")
                .as_str(),
        )
        .unwrap_err();
        assert!(e.message.contains("either"), "{e}");
    }

    #[test]
    fn profile_options_named_like_slave_keys_go_under_the_profile_name() {
        let text = &format!("{OMEGA2_BUS}watchdog_ms = 300\nomega2.pkw = false\n");
        let b = with_omega2(text).unwrap();
        let d = b.slaves[0].device.as_ref().unwrap();
        assert_eq!(d.options.get("pkw"), Some(&toml::Value::Boolean(false)));
        assert!(!d.options.contains_key("omega2"));
        assert_eq!(
            b.slaves[0].params.cfg,
            [0x71, 0x53, 0x63],
            "the option took"
        );
        let with = |line: &str| with_omega2(&text.replace("watchdog_ms = 300", line)).unwrap_err();
        // A slave key the device slave cannot take: the key's line and
        // where the profile's option of that name goes.
        for (line, says) in [
            (
                "params = \"omega-params.toml\"",
                "`params` is the slave's User_Prm_Data",
            ),
            ("modules = [\"x\"]", "chooses its modules"),
        ] {
            let e = with(line);
            let key = line.split(' ').next().unwrap();
            assert_eq!(e.line, 8, "{line}: {e}");
            assert!(e.message.contains(says), "{line}: {e}");
            assert!(
                e.message
                    .contains(&format!("goes under `omega2.{key} = …`")),
                "{line}: {e}"
            );
        }
        // The same option twice; the namespace not a table.
        let e = with("pkw = true");
        assert!(e.message.contains("option `pkw` given twice"), "{e}");
        let e = with_omega2(&text.replace("omega2.pkw = false", "omega2 = 1")).unwrap_err();
        assert_eq!(e.line, 9, "{e}");
        assert!(e.message.contains("must be a table"), "{e}");
        // `params` as a table stays the slave's User_Prm_Data.
        let e = with("params = { \"No such parameter\" = 1 }");
        assert!(!e.message.contains("omega2.params"), "{e}");
    }
}
