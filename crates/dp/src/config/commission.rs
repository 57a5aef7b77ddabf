//! Commissioning: from what a scan read on the live bus (each DP slave's
//! Slave_Diag and Get_Cfg) to a bus file that `dpctl master --config`
//! accepts unchanged (`dpctl scan --write-config`).
//!
//! For each slave: the GSD files of its ident number in the
//! [`GsdLibrary`], in library order;
//! the first whose modules give exactly the Get_Cfg bytes
//! ([`modules_for_cfg`]) configures it, the simplest fit first, the
//! others listed as comments. A slave whose ident number a device profile
//! knows is written as `device = "NAME"` with the options that give the
//! same Chk_Cfg, when the [`ProfileMatcher`] of the layer above finds
//! them. A slave is never guessed: with no GSD for its ident, no Get_Cfg
//! answer or no module combination of its files that gives the bytes, it
//! is left out of the file and reported ([`NotConfigured`]).

use crate::config::discover::{modules_for_cfg, CfgMatch, Fit};
use crate::config::gsd::Gsd;
use crate::config::library::{GsdLibrary, GsdSource, LibraryEntry};
use crate::pdu::diag::{SlaveDiag, NO_MASTER};
use crate::pdu::im::Im0;
use profibus_fdl::timing::Baud;
use profibus_fdl::wire::Hex;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What the scan read from one DP slave.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScannedSlave {
    /// Its station address.
    pub address: u8,
    /// Its Slave_Diag answer, if any.
    pub diag: Option<Vec<u8>>,
    /// Its Get_Cfg answer, if any.
    pub cfg: Option<Vec<u8>>,
    /// Its I&M0 over a class-2 connection; `None`: not asked (`--no-im`).
    pub im0: Option<Im0Scan>,
}

/// What the scan made of a slave's I&M0 (read through a class-2
/// connection: the call on index 255 of slot 0,
/// [`crate::master::records::ImReader`]). Never a reason to leave a
/// slave out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Im0Scan {
    /// Not asked, and why (its GSD offers no class-2 services).
    Skipped(String),
    /// Read.
    Read(Im0),
    /// Asked and not read: why (refused, no answer, not valid).
    Failed(String),
}

impl Im0Scan {
    /// One line for the bus file's comments and the scan's words:
    /// `I&M0: order 6ES7 …, serial …, V1.2.3 (hardware revision 3,
    /// manufacturer 0x001A)`, or why it is not there.
    pub fn describe(&self) -> String {
        match self {
            Im0Scan::Read(im) => {
                let or_blank = |s: String| if s.is_empty() { "(blank)".into() } else { s };
                format!(
                    "I&M0: order {}, serial {}, {} (hardware revision {}, manufacturer 0x{:04X})",
                    or_blank(im.order_id()),
                    or_blank(im.serial_number()),
                    im.software_revision,
                    im.hardware_revision,
                    im.manufacturer_id
                )
            }
            Im0Scan::Skipped(why) => format!("I&M0 not asked: {why}"),
            Im0Scan::Failed(why) => format!("I&M0 not read: {why}"),
        }
    }
}

impl ScannedSlave {
    fn diag(&self) -> Option<SlaveDiag<'_>> {
        SlaveDiag::parse(self.diag.as_deref()?).ok()
    }

    /// The ident number from its Slave_Diag.
    pub fn ident(&self) -> Option<u16> {
        self.diag().map(|d| d.ident_number)
    }

    /// The master that parameterised it (`None`: none, or no diagnosis).
    pub fn owner(&self) -> Option<u8> {
        self.diag()
            .map(|d| d.master_address)
            .filter(|m| *m != NO_MASTER)
    }
}

/// A device profile that fits a slave: its name and the options that
/// give the slave's Chk_Cfg.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceMatch {
    /// The profile's name (`device = "NAME"`).
    pub name: String,
    /// The options to write next to it.
    pub options: toml::Table,
    /// What the configuration does not tell (e.g. terminals that send
    /// the same bytes), written as comments.
    pub notes: Vec<String>,
}

/// Finds the device profile of a slave from its ident number and its
/// configuration (the layer above implements it with its registry).
pub trait ProfileMatcher {
    /// A profile with ident number `ident` and options that give exactly
    /// `cfg` for the slave at `address`; `Err` with the words of why a profile of that ident does
    /// not fit (written as a comment), `Ok(None)` when no profile has
    /// the ident.
    fn device_for(
        &self,
        address: u8,
        ident: u16,
        cfg: &[u8],
    ) -> Result<Option<DeviceMatch>, String>;
}

/// No device profiles.
pub struct NoProfiles;

impl ProfileMatcher for NoProfiles {
    fn device_for(&self, _: u8, _ident: u16, _cfg: &[u8]) -> Result<Option<DeviceMatch>, String> {
        Ok(None)
    }
}

/// Why a slave was left out of the bus file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NotConfigured {
    /// It did not answer Slave_Diag.
    NoDiag,
    /// No GSD file of the library has its ident number.
    NoGsd {
        /// Its ident number.
        ident: u16,
        /// The places searched, in words.
        places: String,
    },
    /// It did not answer Get_Cfg.
    NoCfg,
    /// No module combination of any file of its ident gives the bytes.
    NoFit {
        /// The Get_Cfg bytes.
        cfg: Vec<u8>,
        /// Per file: the file and the nearest fit in words
        /// ([`crate::config::discover::Nearest::describe`]).
        files: Vec<(String, String)>,
    },
}

impl NotConfigured {
    /// A short key for programs (`no_diag`, `no_gsd`, `no_cfg`, `no_fit`).
    pub fn kind(&self) -> &'static str {
        match self {
            NotConfigured::NoDiag => "no_diag",
            NotConfigured::NoGsd { .. } => "no_gsd",
            NotConfigured::NoCfg => "no_cfg",
            NotConfigured::NoFit { .. } => "no_fit",
        }
    }
}

impl std::fmt::Display for NotConfigured {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotConfigured::NoDiag => f.write_str("no answer to Slave_Diag"),
            NotConfigured::NoGsd { ident, places } => {
                write!(f, "no GSD for ident 0x{ident:04X} (searched {places})")
            }
            NotConfigured::NoCfg => f.write_str("no answer to Get_Cfg"),
            NotConfigured::NoFit { cfg, files } => {
                for (i, (file, nearest)) in files.iter().enumerate() {
                    if i > 0 {
                        f.write_str("; ")?;
                    }
                    write!(
                        f,
                        "Get_Cfg `{}` matches no module combination of {file}: {nearest}",
                        Hex(cfg)
                    )?;
                }
                Ok(())
            }
        }
    }
}

/// How a slave is configured in the written file.
#[derive(Debug, Clone, PartialEq)]
pub enum Configuration {
    /// From a GSD file and its modules.
    Gsd {
        /// Where the file is.
        source: GsdSource,
        /// The modules of the simplest fit, in slot order.
        modules: Vec<String>,
        /// Other fits (module names), simplest first.
        others: Vec<Vec<String>>,
        /// Slots where other modules send the same bytes: (slot, the
        /// other modules' names).
        same_bytes: Vec<(usize, Vec<String>)>,
        /// The station and module parameters with their GSD defaults:
        /// (bus-file name, value as TOML).
        params: Vec<(String, toml::Value)>,
        /// A device profile knows the ident but none of its options give
        /// the configuration: why (a comment).
        profile_note: Option<String>,
    },
    /// As a device profile.
    Device(DeviceMatch),
}

/// What commissioning made of one scanned slave.
#[derive(Debug, Clone, PartialEq)]
pub struct SlavePlan {
    /// What was read.
    pub scanned: ScannedSlave,
    /// The model name of its GSD, where found.
    pub model: Option<String>,
    /// Its configuration, or why it has none.
    pub result: Result<Configuration, NotConfigured>,
}

/// Work out every slave's configuration; see the module docs.
pub fn plan(
    slaves: &[ScannedSlave],
    library: &GsdLibrary,
    profiles: &dyn ProfileMatcher,
) -> Vec<SlavePlan> {
    slaves
        .iter()
        .map(|s| plan_one(s, library, profiles))
        .collect()
}

fn plan_one(s: &ScannedSlave, library: &GsdLibrary, profiles: &dyn ProfileMatcher) -> SlavePlan {
    let mut plan = SlavePlan {
        scanned: s.clone(),
        model: None,
        result: Err(NotConfigured::NoDiag),
    };
    let Some(ident) = s.ident() else {
        return plan;
    };
    let entries = library.find(ident);
    plan.model = entries.first().and_then(|e| e.gsd.model_name.clone());
    let Some(cfg) = s.cfg.as_deref() else {
        plan.result = Err(NotConfigured::NoCfg);
        return plan;
    };
    let profile_note = match profiles.device_for(s.address, ident, cfg) {
        Ok(Some(m)) => {
            plan.result = Ok(Configuration::Device(m));
            return plan;
        }
        Ok(None) => None,
        Err(why) => Some(why),
    };
    if entries.is_empty() {
        plan.result = Err(NotConfigured::NoGsd {
            ident,
            places: library.places(),
        });
        return plan;
    }
    let mut misses = Vec::new();
    for e in entries {
        match modules_for_cfg(&e.gsd, cfg) {
            CfgMatch::Found { best, others } => {
                plan.model = e.gsd.model_name.clone();
                plan.result = Ok(configuration(e, &best, &others, profile_note));
                return plan;
            }
            CfgMatch::NoFit(n) => misses.push((e.source.to_string(), n.describe(&e.gsd))),
        }
    }
    plan.result = Err(NotConfigured::NoFit {
        cfg: cfg.to_vec(),
        files: misses,
    });
    plan
}

fn configuration(
    e: &LibraryEntry,
    best: &Fit,
    others: &[Fit],
    profile_note: Option<String>,
) -> Configuration {
    let g = &e.gsd;
    let names = |f: &Fit| f.names(g).into_iter().map(str::to_string).collect();
    let same_bytes = best
        .alternatives
        .iter()
        .enumerate()
        .filter(|(_, a)| a.len() > 1)
        .map(|(slot, a)| {
            let rest = a[1..].iter().map(|i| g.modules[*i].name.clone()).collect();
            (slot, rest)
        })
        .collect();
    Configuration::Gsd {
        source: e.source.clone(),
        modules: names(best),
        others: others.iter().map(names).collect(),
        same_bytes,
        params: default_params(g, &best.modules),
        profile_note,
    }
}

/// The parameters of a selection at their defaults, as a bus file's
/// `params` names them (`N:Name` for module N's, 0-based, where a name is
/// not unique), with the value's text where the GSD names it.
pub fn default_params(g: &Gsd, selection: &[usize]) -> Vec<(String, toml::Value)> {
    let Ok(params) = g.parameters(selection) else {
        return vec![];
    };
    let mut out: Vec<(String, toml::Value)> = Vec::new();
    for p in &params {
        let d = p.definition;
        let unique = params
            .iter()
            .filter(|q| q.definition.name.trim() == d.name.trim())
            .count()
            == 1;
        let key = match (p.position, unique) {
            (Some(pos), false) => format!("{pos}:{}", d.name.trim()),
            _ => d.name.trim().to_string(),
        };
        let text = d
            .prm_text_ref
            .and_then(|r| g.prm_text(r))
            .and_then(|t| t.texts.iter().find(|x| x.value == d.default))
            .map(|x| x.text.clone())
            // A text the bus file reads back as this value only: not a
            // number, no `=`.
            .filter(|t| !t.trim().is_empty() && t.trim().parse::<i64>().is_err());
        let value = match text {
            Some(t) => toml::Value::String(t),
            None => toml::Value::Integer(d.default),
        };
        if !out.iter().any(|(k, _)| *k == key) {
            out.push((key, value));
        }
    }
    out
}

/// How the written file names GSD files.
#[derive(Debug, Clone)]
pub struct WriteOptions {
    /// The master's address.
    pub master: u8,
    /// The bus rate.
    pub baud: Baud,
    /// The bus file's directory: GSD paths under it are written
    /// relative to it.
    pub dir: PathBuf,
    /// Folder (relative to `dir`) for built-in GSD files, which the
    /// caller writes there ([`built_in_files`]).
    pub built_in_dir: PathBuf,
}

/// The built-in GSD files the plans use: (file name, bytes), to write
/// into [`WriteOptions::built_in_dir`].
pub fn built_in_files(plans: &[SlavePlan], library: &GsdLibrary) -> Vec<(String, &'static [u8])> {
    let mut out: Vec<(String, &'static [u8])> = Vec::new();
    for p in plans {
        if let Ok(Configuration::Gsd {
            source: GsdSource::BuiltIn(name),
            ..
        }) = &p.result
        {
            let bytes = library
                .entries()
                .iter()
                .find(|e| e.source == GsdSource::BuiltIn(name))
                .and_then(|e| e.bytes);
            if let Some(b) = bytes {
                if !out.iter().any(|(n, _)| n == name) {
                    out.push((name.to_string(), b));
                }
            }
        }
    }
    out
}

/// The watchdog written for each slave: three target rotation times
/// (TTR of [`BusParams::defaults`], which the bus file keeps unless its
/// `[bus]` table says otherwise), at least 1 s, in whole 100 ms. A
/// master shares the token with other masters (a second master scanning
/// the bus holds it up to one TTR), and a slave whose watchdog runs out
/// between two polls leaves Data_Exchange: 1 s is short at 19.2 kbit/s,
/// where one TTR of 32436 bit times is 1.7 s.
///
/// [`BusParams::defaults`]: profibus_fdl::timing::BusParams::defaults
pub fn watchdog_ms(baud: Baud) -> u64 {
    let p = profibus_fdl::timing::BusParams::defaults(baud);
    let ttr = baud.bits_to_duration(u64::from(p.ttr)).as_millis() as u64;
    (3 * ttr).div_ceil(100).max(10) * 100
}

/// A TOML string (quoted and escaped).
fn quote(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// A TOML key (bare where it can be).
fn key(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        s.to_string()
    } else {
        quote(s)
    }
}

fn gsd_path(source: &GsdSource, o: &WriteOptions) -> String {
    match source {
        GsdSource::File(p) => {
            let rel = p.strip_prefix(&o.dir).unwrap_or(p);
            rel.display().to_string()
        }
        GsdSource::BuiltIn(name) => o.built_in_dir.join(name).display().to_string(),
    }
}

fn owner_words(s: &ScannedSlave) -> String {
    match s.owner() {
        Some(m) => format!("parameterised by master {m}"),
        None => "not parameterised".to_string(),
    }
}

/// The bus file text for `plans`: `[master]`, then one `[[slave]]` per
/// configured slave with comments naming what was read, then the slaves
/// left out as comments with the reason.
pub fn bus_file_text(plans: &[SlavePlan], o: &WriteOptions) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "# Written by `dpctl scan --write-config` from the live bus: each slave's\n\
         # Slave_Diag (ident, owner) and Get_Cfg (its real configuration).\n\
         # Parameters are the GSD's defaults: check them before running."
    );
    let _ = writeln!(
        t,
        "\n[master]\naddress = {}\nbaud = {}  # {}",
        o.master,
        o.baud.bps(),
        o.baud
    );
    for p in plans {
        let s = &p.scanned;
        let Ok(c) = &p.result else { continue };
        let ident = s.ident().unwrap_or(0);
        let cfg = s.cfg.as_deref().unwrap_or(&[]);
        let _ = writeln!(t, "\n[[slave]]");
        let _ = writeln!(
            t,
            "# ident 0x{ident:04X}{}, {}; Get_Cfg {}",
            p.model
                .as_deref()
                .map(|m| format!(" ({})", m.trim()))
                .unwrap_or_default(),
            owner_words(s),
            Hex(cfg)
        );
        if let Some(im) = &s.im0 {
            let _ = writeln!(t, "# {}", im.describe());
        }
        let _ = writeln!(t, "address = {}", s.address);
        if let Some(m) = &p.model {
            let _ = writeln!(t, "name = {}", quote(m.trim()));
        }
        match c {
            Configuration::Device(d) => {
                for n in &d.notes {
                    let _ = writeln!(t, "# {n}");
                }
                let _ = writeln!(t, "device = {}", quote(&d.name));
                for (k, v) in &d.options {
                    if crate::config::busfile::SLAVE_KEYS.contains(&k.as_str()) {
                        let _ = writeln!(t, "{}.{} = {v}", key(&d.name), key(k));
                    } else {
                        let _ = writeln!(t, "{} = {v}", key(k));
                    }
                }
            }
            Configuration::Gsd {
                source,
                modules,
                others,
                same_bytes,
                params,
                profile_note,
            } => {
                if let Some(n) = profile_note {
                    let _ = writeln!(t, "# {n}");
                }
                let _ = writeln!(t, "gsd = {}", quote(&gsd_path(source, o)));
                let list: Vec<String> = modules.iter().map(|m| quote(m)).collect();
                let _ = writeln!(t, "modules = [{}]", list.join(", "));
                for (slot, alt) in same_bytes {
                    let alt: Vec<String> = alt.iter().map(|m| quote(m.trim())).collect();
                    let _ = writeln!(
                        t,
                        "# slot {}: {} send(s) the same bytes as {}",
                        slot + 1,
                        alt.join(", "),
                        quote(modules[*slot].trim())
                    );
                }
                for other in others {
                    let list: Vec<String> = other.iter().map(|m| quote(m)).collect();
                    let _ = writeln!(t, "# also fits: modules = [{}]", list.join(", "));
                }
                if !params.is_empty() {
                    let list: Vec<String> = params
                        .iter()
                        .map(|(k, v)| format!("{} = {v}", quote(k)))
                        .collect();
                    let _ = writeln!(t, "params = {{ {} }}", list.join(", "));
                }
            }
        }
        let _ = writeln!(t, "watchdog_ms = {}", watchdog_ms(o.baud));
    }
    let left: Vec<&SlavePlan> = plans.iter().filter(|p| p.result.is_err()).collect();
    if !left.is_empty() {
        let _ = writeln!(t, "\n# Not configured (add them by hand):");
        for p in left {
            if let Err(why) = &p.result {
                let ident = p
                    .scanned
                    .ident()
                    .map(|i| format!(" (ident 0x{i:04X})"))
                    .unwrap_or_default();
                let _ = writeln!(t, "# slave {}{ident}: {why}", p.scanned.address);
            }
        }
    }
    t
}

/// A plan in words, one line: `  8  ident 0x0DCE dpctl generic slave:
/// modules "2 words in/out" (GSD FILE)`, or the reason it was left out.
pub fn describe(p: &SlavePlan, dir: &Path) -> String {
    let s = &p.scanned;
    let ident = s
        .ident()
        .map(|i| format!("ident 0x{i:04X}"))
        .unwrap_or_else(|| "no ident".into());
    let model = p
        .model
        .as_deref()
        .map(|m| format!(" {}", m.trim()))
        .unwrap_or_default();
    let what = match &p.result {
        Ok(Configuration::Device(d)) => {
            let opts: Vec<String> = d
                .options
                .iter()
                .map(|(k, v)| format!("{k} = {v}"))
                .collect();
            if opts.is_empty() {
                format!("device `{}`", d.name)
            } else {
                format!("device `{}` ({})", d.name, opts.join(", "))
            }
        }
        Ok(Configuration::Gsd {
            source,
            modules,
            others,
            ..
        }) => {
            let list: Vec<String> = modules.iter().map(|m| quote(m.trim())).collect();
            let src = match source {
                GsdSource::File(f) => f.strip_prefix(dir).unwrap_or(f).display().to_string(),
                b => b.to_string(),
            };
            let more = match others.len() {
                0 => String::new(),
                n => format!("; {n} other fit(s) in the file's comments"),
            };
            format!("modules {} from {src}{more}", list.join(", "))
        }
        Err(why) => format!("not configured: {why}"),
    };
    let im = match &s.im0 {
        Some(i @ Im0Scan::Read(_)) => format!("; {}", i.describe()),
        _ => String::new(),
    };
    format!(
        "{:3}  {ident}{model}, {}: {what}{im}",
        s.address,
        owner_words(s)
    )
}

#[cfg(feature = "serde")]
impl serde::Serialize for SlavePlan {
    /// `{address, ident, owner, status, cfg, model, configured, device,
    /// options, gsd, modules, others, reason, why}`.
    fn serialize<S: serde::Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let s = &self.scanned;
        let mut m = ser.serialize_map(None)?;
        m.serialize_entry("address", &s.address)?;
        m.serialize_entry("ident", &s.ident().map(|i| format!("0x{i:04X}")))?;
        m.serialize_entry("owner", &s.owner())?;
        if let Some(d) = s.diag() {
            m.serialize_entry("status", &d.status_words())?;
        }
        m.serialize_entry("cfg", &s.cfg.as_deref().map(|c| Hex(c).to_string()))?;
        m.serialize_entry("model", &self.model.as_deref().map(str::trim))?;
        m.serialize_entry("configured", &self.result.is_ok())?;
        match &self.result {
            Ok(Configuration::Device(d)) => {
                m.serialize_entry("device", &d.name)?;
                m.serialize_entry("options", &d.options)?;
            }
            Ok(Configuration::Gsd {
                source,
                modules,
                others,
                ..
            }) => {
                m.serialize_entry("gsd", &source.to_string())?;
                let trim = |v: &Vec<String>| v.iter().map(|x| x.trim().to_string()).collect();
                let modules: Vec<String> = trim(modules);
                m.serialize_entry("modules", &modules)?;
                let others: Vec<Vec<String>> = others.iter().map(trim).collect();
                m.serialize_entry("others", &others)?;
            }
            Err(why) => {
                m.serialize_entry("reason", why.kind())?;
                m.serialize_entry("why", &why.to_string())?;
            }
        }
        m.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::busfile::BusFile;

    const GSD: &str = "#Profibus_DP\nGSD_Revision=3\nVendor_Name=\"T\"\nModel_Name=\"Test IO\"\n\
        Ident_Number=0x4711\nProtocol_Ident=0\nStation_Type=0\n19.2_supp=1\n1.5M_supp=1\n\
        MaxTsdr_19.2=60\nMaxTsdr_1.5M=150\n\
        Modular_Station=1\nMax_Module=4\nMax_Input_Len=32\nMax_Output_Len=32\nMax_Data_Len=64\n\
        PrmText=1\nText(0)=\"off\"\nText(1)=\"on\"\nEndPrmText\n\
        ExtUserPrmData=1 \"Diagnosis\"\nUnsigned8 1 0-1\nPrm_Text_Ref=1\nEndExtUserPrmData\n\
        Max_User_Prm_Data_Len=4\nExt_User_Prm_Data_Const(0)=0x00\nExt_User_Prm_Data_Ref(0)=1\n\
        Module=\"8 DI\" 0x10\nEndModule\nModule=\"8 DO\" 0x20\nEndModule\n\
        Module=\"2x8 DI\" 0x10,0x10\nEndModule\n";

    fn slave(address: u8, ident: u16, cfg: Option<&[u8]>) -> ScannedSlave {
        let id = ident.to_be_bytes();
        ScannedSlave {
            address,
            diag: Some(vec![0x02, 0x05, 0, 255, id[0], id[1]]),
            cfg: cfg.map(<[u8]>::to_vec),
            im0: None,
        }
    }

    #[test]
    fn written_file_loads_and_gives_the_read_configuration() {
        let dir = tempfile::tempdir().unwrap();
        let gsd_dir = dir.path().join("gsd");
        std::fs::create_dir(&gsd_dir).unwrap();
        std::fs::write(gsd_dir.join("TEST4711.GSD"), GSD).unwrap();
        let mut lib = GsdLibrary::new();
        lib.add_dir(&gsd_dir).unwrap();
        let slaves = [
            slave(5, 0x4711, Some(&[0x10, 0x10, 0x20])),
            slave(6, 0x4712, Some(&[0x10])),
            slave(7, 0x4711, Some(&[0x30])),
            slave(8, 0x4711, None),
        ];
        let plans = plan(&slaves, &lib, &NoProfiles);
        let o = WriteOptions {
            master: 1,
            baud: Baud::B1500000,
            dir: dir.path().to_path_buf(),
            built_in_dir: "gsd".into(),
        };
        let text = bus_file_text(&plans, &o);
        let path = dir.path().join("bus.toml");
        std::fs::write(&path, &text).unwrap();
        let bus = BusFile::load(&path).unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(bus.slaves.len(), 1, "{text}");
        assert_eq!(bus.slaves[0].params.cfg, [0x10, 0x10, 0x20]);
        assert_eq!(bus.slaves[0].modules, ["2x8 DI", "8 DO"]);
        assert!(text.contains("gsd = \"gsd/TEST4711.GSD\""), "{text}");
        assert!(
            text.contains("# also fits: modules = [\"8 DI\", \"8 DI\", \"8 DO\"]"),
            "{text}"
        );
        assert!(
            text.contains("params = { \"Diagnosis\" = \"on\" }"),
            "{text}"
        );
        assert!(
            text.contains("# slave 6 (ident 0x4712): no GSD for ident 0x4712"),
            "{text}"
        );
        assert!(
            text.contains(
                "# slave 7 (ident 0x4711): Get_Cfg `30` matches no module combination of"
            ),
            "{text}"
        );
        assert!(
            text.contains("# slave 8 (ident 0x4711): no answer to Get_Cfg"),
            "{text}"
        );
        assert_eq!(plans[1].result.as_ref().unwrap_err().kind(), "no_gsd");
        assert_eq!(plans[2].result.as_ref().unwrap_err().kind(), "no_fit");
        assert!(describe(&plans[0], dir.path()).starts_with(
            "  5  ident 0x4711 Test IO, not parameterised: modules \"2x8 DI\", \"8 DO\" from gsd/TEST4711.GSD; 1 other fit"
        ), "{}", describe(&plans[0], dir.path()));
    }

    #[test]
    fn watchdog_covers_three_token_rotations() {
        assert_eq!(watchdog_ms(Baud::B1500000), 1000);
        // TTR 32436 bit times at 19.2 kbit/s: 1689 ms.
        assert_eq!(watchdog_ms(Baud::B19200), 5100);
    }

    #[test]
    fn a_profile_match_is_written_as_a_device() {
        struct One;
        impl ProfileMatcher for One {
            fn device_for(
                &self,
                _: u8,
                ident: u16,
                _: &[u8],
            ) -> Result<Option<DeviceMatch>, String> {
                let mut options = toml::Table::new();
                options.insert("setpoints".into(), 2.into());
                options.insert("params".into(), "p.toml".into());
                Ok((ident == 0xD0).then(|| DeviceMatch {
                    name: "omega".into(),
                    options,
                    notes: vec!["setpoints from the bytes".into()],
                }))
            }
        }
        let plans = plan(&[slave(25, 0xD0, Some(&[0x71]))], &GsdLibrary::new(), &One);
        let o = WriteOptions {
            master: 1,
            baud: Baud::B19200,
            dir: "/x".into(),
            built_in_dir: "gsd".into(),
        };
        let text = bus_file_text(&plans, &o);
        assert!(
            text.contains(
                "# setpoints from the bytes\ndevice = \"omega\"\nomega.params = \"p.toml\"\nsetpoints = 2\n"
            ),
            "{text}"
        );
    }
}
