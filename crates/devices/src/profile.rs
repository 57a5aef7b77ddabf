//! The one shape of every device profile: the [`Profile`] trait, its
//! options ([`DeviceOptions`]), the object-safe [`Configured`] view the
//! programs use, and the registry rows ([`ProfileEntry`]) of
//! [`crate::PROFILES`].
//!
//! A profile is configured once from its typed options (a serde struct
//! per profile; the keys of a bus file's `[[slave]]` table or of
//! `dpctl slave --device-opt KEY=VALUE`) and then answers everything the
//! programs need about that product in that configuration: its GSD, the
//! slave [`Device`](profibus_dp::slave::Device) that emulates it, the
//! station address it chooses, and the master side: the GSD modules (and
//! so Chk_Cfg and User_Prm_Data) a master configures it with, the named
//! channels of its process images, and its PKW dialect.

use crate::channels::ChannelMap;
use crate::pkw::Dialect;
use crate::BoxedDevice;
use profibus_dp::config::gsd::Gsd;
use profibus_dp::config::layout::Capabilities;
use profibus_dp::config::names::{field_names, DidYouMean};
use serde::de::DeserializeOwned;
use serde::Deserializer;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

/// Why a profile cannot be configured or used.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// No profile has that name.
    #[error("no device profile `{name}`{suggestions} (available: {available})")]
    Unknown {
        /// The name asked for.
        name: String,
        /// The closest profile names.
        suggestions: DidYouMean,
        /// The registered names.
        available: String,
    },
    /// The profile has no option of that name.
    #[error("unknown option `{key}`{}", hint(key, valid))]
    UnknownOption {
        /// The key given.
        key: String,
        /// The profile's options.
        valid: &'static [&'static str],
    },
    /// The value of an option is refused.
    #[error("option `{key}`: {message}")]
    BadOption {
        /// The option.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The options do not fit the profile's options struct.
    #[error("options: {0}")]
    Options(String),
    /// A file named in the options cannot be read or written.
    #[error("{}: {error}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// The cause (in the message; not also `source()`, so that a
        /// printed error chain names it once).
        error: std::io::Error,
    },
    /// A table file (variables, parameters) named in the options is
    /// invalid.
    #[error("{}: {message}", path.display())]
    Table {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The stored Set_Slave_Add address cannot be read.
    #[error(transparent)]
    AddressFile(#[from] crate::address::AddressFileError),
    /// The GSD cannot give the configuration.
    #[error(transparent)]
    Selection(#[from] profibus_dp::config::gsd::SelectionError),
    /// A module name matches no module of the GSD, or several.
    #[error(transparent)]
    Module(#[from] profibus_dp::config::gsd::LookupError),
    /// A GSD file cannot be read.
    #[error(transparent)]
    Gsd(#[from] profibus_dp::config::gsd::GsdError),
    /// The device cannot be built from this configuration (the
    /// device's own error).
    #[error(transparent)]
    Device(Box<dyn std::error::Error + Send + Sync>),
    /// A configuration (Chk_Cfg) the profile does not know.
    #[error("configuration: {0}")]
    Config(String),
    /// The options contradict each other or the product.
    #[error("{0}")]
    Invalid(String),
}

/// `; did you mean …?` for `key` among `valid`, else the valid keys.
fn hint(key: &str, valid: &[&str]) -> String {
    let near = DidYouMean::new(key, valid.iter().copied());
    if near.is_empty() {
        format!(" (options: {})", valid.join(", "))
    } else {
        near.to_string()
    }
}

impl ProfileError {
    /// The option the error is about, if it is about one.
    pub fn option(&self) -> Option<&str> {
        match self {
            ProfileError::UnknownOption { key, .. } => Some(key),
            ProfileError::BadOption { key, .. } => Some(key),
            _ => None,
        }
    }
}

/// Why a control command (a line of text for a running device, see
/// [`ControlInbox`]) was not executed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ControlError {
    /// No such command.
    #[error("unknown command `{command}` ({known})")]
    Unknown {
        /// The command word given.
        command: String,
        /// The commands the device knows.
        known: &'static str,
    },
    /// An argument is missing or malformed.
    #[error("{0}")]
    Argument(String),
    /// The device refuses (what the emulated product would report).
    #[error("{0}")]
    Refused(String),
}

/// Control commands (lines of text) for a running device, e.g. a user
/// diagnosis the emulated PLC sends. The command line puts lines in; the
/// device takes them out while it runs. Clones share the queue.
#[derive(Debug, Clone, Default)]
pub struct ControlInbox(Arc<Mutex<VecDeque<String>>>);

impl ControlInbox {
    /// An empty inbox.
    pub fn new() -> ControlInbox {
        ControlInbox::default()
    }

    /// Queue a command line.
    pub fn push(&self, line: impl Into<String>) {
        if let Ok(mut q) = self.0.lock() {
            q.push_back(line.into());
        }
    }

    /// The oldest queued line.
    pub fn take(&self) -> Option<String> {
        self.0.lock().ok()?.pop_front()
    }
}

impl PartialEq for ControlInbox {
    fn eq(&self, other: &ControlInbox) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl Eq for ControlInbox {}

/// A profile's options before they are decoded into its options struct:
/// a TOML table with `snake_case` keys (`-` in keys is read as `_`, so
/// `--device-opt us-device=126` and a bus file's `us_device = 126` are
/// the same option).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DeviceOptions(toml::Table);

impl DeviceOptions {
    /// No options.
    pub fn new() -> DeviceOptions {
        DeviceOptions::default()
    }

    /// The options of a table (e.g. the rest of a bus file's `[[slave]]`).
    pub fn from_table(table: toml::Table) -> DeviceOptions {
        let mut o = DeviceOptions::new();
        for (k, v) in table {
            o.set(&k, v);
        }
        o
    }

    /// Set `key` to `value`.
    pub fn set(&mut self, key: &str, value: impl Into<toml::Value>) {
        self.0.insert(key.trim().replace('-', "_"), value.into());
    }

    /// Set `key` from command-line text: a TOML value when the text is
    /// one (`126`, `0x19`, `true`, `[1, 2]`, `"x"`), else the text itself
    /// (a path, a name).
    pub fn set_text(&mut self, key: &str, text: &str) {
        let text = text.trim();
        let value = format!("v = {text}")
            .parse::<toml::Table>()
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(text.to_string()));
        self.set(key, value);
    }

    /// Set an option from `KEY=VALUE` (see [`DeviceOptions::set_text`]).
    pub fn set_pair(&mut self, pair: &str) -> Result<(), ProfileError> {
        let (k, v) = pair
            .split_once('=')
            .ok_or_else(|| ProfileError::Options(format!("`{pair}` is not KEY=VALUE")))?;
        self.set_text(k, v);
        Ok(())
    }

    /// Make the relative paths among `keys` relative to `dir`.
    pub fn paths_relative_to(&mut self, dir: &std::path::Path, keys: &[&str]) {
        for key in keys {
            if let Some(toml::Value::String(p)) = self.0.get_mut(*key) {
                if std::path::Path::new(p.as_str()).is_relative() {
                    *p = dir.join(&*p).display().to_string();
                }
            }
        }
    }

    /// The value of `key`.
    pub fn get(&self, key: &str) -> Option<&toml::Value> {
        self.0.get(&key.replace('-', "_"))
    }

    /// The table.
    pub fn table(&self) -> &toml::Table {
        &self.0
    }

    /// Decode into a profile's options struct: a key that is none of
    /// its fields is [`ProfileError::UnknownOption`] with the closest.
    pub fn decode<T: DeserializeOwned>(&self) -> Result<T, ProfileError> {
        let valid = field_names::<T>();
        if let Some(key) = self.0.keys().find(|k| !valid.contains(&k.as_str())) {
            if !valid.is_empty() {
                return Err(ProfileError::UnknownOption {
                    key: key.clone(),
                    valid,
                });
            }
        }
        let decode = |t: toml::Table| toml::Value::Table(t).try_into::<T>();
        decode(self.0.clone()).map_err(|e| {
            let message = e.message().to_string();
            // The option at fault: the one that alone does not decode
            // (every other option has its default).
            let key = self.0.iter().map(|(k, _)| k).find(|k| {
                let one = self.0.iter().filter(|(o, _)| o == k);
                decode(one.map(|(o, v)| (o.clone(), v.clone())).collect()).is_err()
            });
            match key {
                Some(key) => ProfileError::BadOption {
                    key: key.clone(),
                    message,
                },
                None => ProfileError::Options(message),
            }
        })
    }
}

/// The most a file named in a profile's options (a table, a terminals,
/// tags or script file) may have, in bytes (1 MiB: such files are a few
/// KB; parsing TOML costs up to some 50 times the text's size).
pub const MAX_OPTION_FILE: u64 = 1 << 20;

/// The UTF-8 text of a file named in a profile's options, at most
/// [`MAX_OPTION_FILE`] bytes: a file that cannot be read is
/// [`ProfileError::File`], one too large or not UTF-8
/// [`ProfileError::Table`].
pub fn read_option_file(path: &std::path::Path) -> Result<String, ProfileError> {
    use profibus_dp::config::file::{read_text, ReadFileError};
    read_text(path, MAX_OPTION_FILE, "a device option file").map_err(|e| match e {
        ReadFileError::Io(error) => ProfileError::File {
            path: path.into(),
            error,
        },
        e => ProfileError::Table {
            path: path.into(),
            message: e.to_string(),
        },
    })
}

/// Read the table file `path` (a profile option) and parse it with
/// `parse`: a missing file is [`ProfileError::File`], a bad one
/// [`ProfileError::Table`].
pub fn read_table<T, E: std::fmt::Display>(
    path: &std::path::Path,
    parse: impl FnOnce(&str) -> Result<T, E>,
) -> Result<T, ProfileError> {
    let text = read_option_file(path)?;
    parse(&text).map_err(|e| ProfileError::Table {
        path: path.into(),
        message: e.to_string(),
    })
}

/// Serde helper for options structs: an integer given as a number or as
/// text (`25`, `"0x19"`, `"16#19"`), range-checked for the field's type.
pub fn int<'de, D, T>(d: D) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: TryFrom<i64>,
{
    opt_int(d)?.ok_or_else(|| serde::de::Error::custom("a number is required"))
}

/// [`int`] for an `Option` field (use with `#[serde(default)]`).
pub fn opt_int<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: Deserializer<'de>,
    T: TryFrom<i64>,
{
    use serde::de::Error;
    use serde::Deserialize;
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Raw {
        Int(i64),
        Text(String),
    }
    let v = match Raw::deserialize(d)? {
        Raw::Int(i) => i,
        Raw::Text(t) => {
            let t = t.trim().replace('_', "");
            let hex = t
                .strip_prefix("0x")
                .or_else(|| t.strip_prefix("0X"))
                .or_else(|| t.strip_prefix("16#"));
            match hex {
                Some(h) => i64::from_str_radix(h, 16),
                None => t.parse(),
            }
            .map_err(|_| D::Error::custom(format!("`{t}` is not a number")))?
        }
    };
    T::try_from(v)
        .map(Some)
        .map_err(|_| D::Error::custom(format!("{v} is out of range")))
}

/// The kind of a [`DeviceEvent`](profibus_dp::slave::DeviceEvent) whose
/// text is the whole new content of the device's state file
/// ([`Profile::state_file`]); the program running the slave writes it
/// there (the device does no file I/O).
pub const STATE_EVENT: &str = "state";

/// A device profile: one product, configured from its options. Every
/// product module implements it the same way and registers with one line
/// in [`crate::PROFILES`] (`ProfileEntry::of::<MyProfile>()`).
///
/// # Example
///
/// The Omega Drive-Line II board as a bus file's `device = "omega"` with
/// `setpoints = 2` and `actual_values = 2` configures it: the GSD modules
/// and the Chk_Cfg a master sends, the slave the DP slave core runs, and
/// the named channels of its process images.
///
/// ```
/// use profibus_devices::channels::{Direction, Value};
/// use profibus_devices::omega::profile::{OmegaProfile, Options};
/// use profibus_devices::Profile;
///
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let options = Options {
///     setpoints: Some(2),
///     actual_values: Some(2),
///     ..Options::default()
/// };
/// let drive = OmegaProfile::configure(options, Some(25))?;
/// let gsd = drive.gsd();
/// let cfg = gsd.chk_cfg(&gsd.select(&drive.modules())?)?;
/// let _slave = drive.device(None)?; // a `profibus_dp::slave::Device`
///
/// // The master side: write a setpoint by name, read it back.
/// let channels = drive.channels(&cfg)?;
/// let mut outputs = vec![0u8; profibus_dp::pdu::cfg::totals(&cfg)?.output_bytes];
/// channels.write_output("setpoint1", Value::Int(1500), &mut outputs)?;
/// let setpoint = channels
///     .decode(Direction::Output, &outputs)
///     .find(|(c, _)| c.name == "setpoint1");
/// assert_eq!(setpoint.map(|(_, v)| v), Some(Value::Int(1500)));
/// # Ok(())
/// # }
/// ```
pub trait Profile: std::fmt::Debug + Sized + Send + Sync + 'static {
    /// The options, decoded from [`DeviceOptions`] (use
    /// `#[serde(default, deny_unknown_fields)]` so that a typo is an
    /// error).
    type Options: DeserializeOwned;
    /// The name (`dpctl slave --device NAME`, a bus file's `device = "NAME"`).
    const NAME: &'static str;
    /// One line about the product.
    const SUMMARY: &'static str;
    /// The options in words (for `dpctl slave --list-devices`).
    const OPTIONS_HELP: &'static str;
    /// The ident number the product always reports, if fixed (finds the
    /// profile of a slave configured from plain GSD modules, e.g. for its
    /// PKW dialect).
    const IDENT: Option<u16>;

    /// The profile configured with `options`; `address` is the station
    /// address the caller has for it (`--addr`, a bus file's `address`),
    /// if any. May read files the options name; nothing else.
    fn configure(options: Self::Options, address: Option<u8>) -> Result<Self, ProfileError>;

    /// The GSD of this configuration.
    fn gsd(&self) -> &Gsd;

    /// The GSD file as bytes (Latin-1). Default: the GSD written out.
    fn gsd_file(&self) -> Vec<u8> {
        self.gsd().write_latin1()
    }

    /// The GSD module names a master configures this device with, in slot
    /// order (they give Chk_Cfg and User_Prm_Data).
    fn modules(&self) -> Vec<String>;

    /// The station address the device chooses itself (a rotary switch, a
    /// stored Set_Slave_Add address), overriding the caller's; `None`:
    /// the caller's address.
    fn address(&self) -> Option<u8> {
        None
    }

    /// The file in which the program running the slave keeps an address
    /// set by Set_Slave_Add ([`crate::address::StoredAddress`]), if the
    /// device keeps one.
    fn address_file(&self) -> Option<PathBuf> {
        None
    }

    /// The file in which the program running the slave keeps the device's
    /// state (e.g. the RFID reader's tags), if it keeps one: the device
    /// reports each new content as a [`DeviceEvent`] of kind
    /// [`STATE_EVENT`], and the program writes it there.
    ///
    /// [`DeviceEvent`]: profibus_dp::slave::DeviceEvent
    fn state_file(&self) -> Option<PathBuf> {
        None
    }

    /// The slave device that emulates the product; `control` is where
    /// control commands arrive, for profiles that take them.
    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError>;

    /// The named channels of the process images the configuration `cfg`
    /// (Chk_Cfg bytes) gives.
    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError>;

    /// The options that name files or directories: in a bus file they
    /// are relative to the bus file's directory.
    const PATH_OPTIONS: &'static [&'static str] = &[];

    /// The product's PKW dialect, if it has a PKW channel (the [`pkw`](crate::pkw)
    /// module knows no device: each owns its dialect).
    const PKW: Option<&'static Dialect> = None;

    /// The PKW dialect of a slave of this product configured with `cfg`
    /// (Chk_Cfg bytes): [`Profile::PKW`] when the configuration has the
    /// PKW module. Default: the PKW module 0x73 first.
    fn pkw_dialect(cfg: &[u8]) -> Option<&'static Dialect> {
        Self::PKW.filter(|_| cfg.first() == Some(&crate::pkw::PKW_MODULE))
    }

    /// What a slave of this product configured with `cfg` (Chk_Cfg
    /// bytes) can do beyond cyclic data, for the master side (the
    /// gateway's PKW and RFID requests). Default: [`Capabilities::PKW`]
    /// when [`Profile::pkw_dialect`] finds the PKW module.
    fn capabilities(cfg: &[u8]) -> Capabilities {
        if Self::pkw_dialect(cfg).is_some() {
            Capabilities::PKW
        } else {
            Capabilities::empty()
        }
    }

    /// The PKW parameter number the product gives a parameter named
    /// `name` in its GSD `gsd` (e.g. a BM4-O-PRO-01 variable module),
    /// for clients that take names; `None`: names are not parameters.
    fn pkw_parameter(_gsd: &Gsd, _name: &str) -> Option<u16> {
        None
    }

    /// The PKW parameters the product names, for `dpctl pkw list` (the
    /// BM4-O-PRO-01's variable modules of `gsd`, the Omega's
    /// V-controller parameter table). Default: none.
    fn pkw_parameters(_gsd: &Gsd) -> Vec<crate::pkw::PkwParameter> {
        vec![]
    }

    /// Warnings found while configuring (e.g. GSD vendor quirks).
    fn warnings(&self) -> Vec<String> {
        vec![]
    }

    /// Commissioning (`dpctl scan --write-config`): option sets that may
    /// give a slave of this product the configuration `cfg` (its Get_Cfg
    /// answer), most likely first. The caller configures each and keeps
    /// the first whose Chk_Cfg is `cfg`, so a guess costs nothing but
    /// time. Default: the profile's default options only. A product
    /// whose options the configuration tells (the JX2's word counts, a
    /// coupler's terminal strip) derives them from `cfg`.
    fn options_for_cfg(_cfg: &[u8]) -> Vec<DeviceOptions> {
        vec![DeviceOptions::new()]
    }

    /// Commissioning: what the configuration `cfg` does not tell about
    /// the options found for it (e.g. terminals that send the same
    /// bytes), one line each, for the written bus file's comments.
    /// Default: nothing.
    fn commission_notes(_cfg: &[u8], _options: &DeviceOptions) -> Vec<String> {
        vec![]
    }
}

/// A configured profile, object-safe: what programs hold
/// (`Box<dyn Configured>`). Every [`Profile`] is one.
pub trait Configured: std::fmt::Debug + Send + Sync {
    /// The profile's name.
    fn name(&self) -> &'static str;
    /// See [`Profile::gsd`].
    fn gsd(&self) -> &Gsd;
    /// See [`Profile::gsd_file`].
    fn gsd_file(&self) -> Vec<u8>;
    /// See [`Profile::modules`].
    fn modules(&self) -> Vec<String>;
    /// See [`Profile::address`].
    fn address(&self) -> Option<u8>;
    /// See [`Profile::address_file`].
    fn address_file(&self) -> Option<PathBuf>;
    /// See [`Profile::state_file`].
    fn state_file(&self) -> Option<PathBuf>;
    /// See [`Profile::device`].
    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError>;
    /// See [`Profile::channels`].
    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError>;
    /// See [`Profile::warnings`].
    fn warnings(&self) -> Vec<String>;

    /// The Chk_Cfg bytes of [`Configured::modules`].
    fn chk_cfg(&self) -> Result<Vec<u8>, ProfileError> {
        let gsd = self.gsd();
        Ok(gsd.chk_cfg(&gsd.select(&self.modules())?)?)
    }

    /// The User_Prm_Data of [`Configured::modules`] with the GSD's
    /// default parameter values.
    fn user_prm_data(&self) -> Result<Vec<u8>, ProfileError> {
        let gsd = self.gsd();
        Ok(gsd.user_prm_data(&gsd.select(&self.modules())?, &[])?)
    }
}

impl<P: Profile> Configured for P {
    fn name(&self) -> &'static str {
        P::NAME
    }
    fn gsd(&self) -> &Gsd {
        Profile::gsd(self)
    }
    fn gsd_file(&self) -> Vec<u8> {
        Profile::gsd_file(self)
    }
    fn modules(&self) -> Vec<String> {
        Profile::modules(self)
    }
    fn address(&self) -> Option<u8> {
        Profile::address(self)
    }
    fn address_file(&self) -> Option<PathBuf> {
        Profile::address_file(self)
    }
    fn state_file(&self) -> Option<PathBuf> {
        Profile::state_file(self)
    }
    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError> {
        Profile::device(self, control)
    }
    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError> {
        Profile::channels(self, cfg)
    }
    fn warnings(&self) -> Vec<String> {
        Profile::warnings(self)
    }
}

/// How a registry row configures its profile.
type ConfigureFn = fn(&DeviceOptions, Option<u8>) -> Result<Box<dyn Configured>, ProfileError>;

/// One row of the registry: a profile's name and words, and how to
/// configure it.
#[derive(Debug, Clone, Copy)]
pub struct ProfileEntry {
    /// See [`Profile::NAME`].
    pub name: &'static str,
    /// See [`Profile::SUMMARY`].
    pub summary: &'static str,
    /// See [`Profile::OPTIONS_HELP`].
    pub options_help: &'static str,
    /// See [`Profile::IDENT`].
    pub ident: Option<u16>,
    /// See [`Profile::PKW`].
    pub pkw: Option<&'static Dialect>,
    /// See [`Profile::PATH_OPTIONS`].
    pub path_options: &'static [&'static str],
    configure: ConfigureFn,
    pkw_dialect: fn(&[u8]) -> Option<&'static Dialect>,
    pkw_parameter: fn(&Gsd, &str) -> Option<u16>,
    pkw_parameters: fn(&Gsd) -> Vec<crate::pkw::PkwParameter>,
    capabilities: fn(&[u8]) -> Capabilities,
    options_for_cfg: fn(&[u8]) -> Vec<DeviceOptions>,
    commission_notes: fn(&[u8], &DeviceOptions) -> Vec<String>,
}

impl std::fmt::Display for ProfileEntry {
    /// The row of a profile list (`dpctl slave --list-devices`): name and
    /// summary, then its options on a second line where it has any.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:<8} {}", self.name, self.summary)?;
        if !self.options_help.is_empty() {
            write!(f, "\n         options: {}", self.options_help)?;
        }
        Ok(())
    }
}

fn configure_boxed<P: Profile>(
    options: &DeviceOptions,
    address: Option<u8>,
) -> Result<Box<dyn Configured>, ProfileError> {
    // `ident` and `gsd` (a vendor's GSD) for every profile:
    // crate::identity.
    let own = field_names::<P::Options>();
    let (rest, ident, gsd) = crate::identity::take(options, own)?;
    let p: Box<dyn Configured> = Box::new(P::configure(rest.decode()?, address)?);
    if ident.is_none() && gsd.is_none() {
        return Ok(p);
    }
    Ok(Box::new(crate::identity::Identified::new(p, ident, gsd)?))
}

impl ProfileEntry {
    /// The row of profile `P`.
    pub const fn of<P: Profile>() -> ProfileEntry {
        ProfileEntry {
            name: P::NAME,
            summary: P::SUMMARY,
            options_help: P::OPTIONS_HELP,
            ident: P::IDENT,
            pkw: P::PKW,
            path_options: P::PATH_OPTIONS,
            configure: configure_boxed::<P>,
            pkw_dialect: P::pkw_dialect,
            pkw_parameter: P::pkw_parameter,
            pkw_parameters: P::pkw_parameters,
            capabilities: P::capabilities,
            options_for_cfg: P::options_for_cfg,
            commission_notes: P::commission_notes,
        }
    }

    /// Configure the profile from `options`; `address` is the caller's
    /// station address for it, if any.
    pub fn configure(
        &self,
        options: &DeviceOptions,
        address: Option<u8>,
    ) -> Result<Box<dyn Configured>, ProfileError> {
        (self.configure)(options, address)
    }

    /// See [`Profile::pkw_dialect`].
    pub fn pkw_dialect(&self, cfg: &[u8]) -> Option<&'static Dialect> {
        (self.pkw_dialect)(cfg)
    }

    /// See [`Profile::capabilities`].
    pub fn capabilities(&self, cfg: &[u8]) -> Capabilities {
        (self.capabilities)(cfg)
    }

    /// See [`Profile::pkw_parameter`].
    pub fn pkw_parameter(&self, gsd: &Gsd, name: &str) -> Option<u16> {
        (self.pkw_parameter)(gsd, name)
    }

    /// See [`Profile::pkw_parameters`].
    pub fn pkw_parameters(&self, gsd: &Gsd) -> Vec<crate::pkw::PkwParameter> {
        (self.pkw_parameters)(gsd)
    }

    /// See [`Profile::commission_notes`].
    pub fn commission_notes(&self, cfg: &[u8], options: &DeviceOptions) -> Vec<String> {
        (self.commission_notes)(cfg, options)
    }

    /// The options of this profile, among [`Profile::options_for_cfg`],
    /// whose Chk_Cfg is exactly `cfg`; `address` as for
    /// [`ProfileEntry::configure`].
    pub fn options_giving(&self, cfg: &[u8], address: Option<u8>) -> Option<DeviceOptions> {
        (self.options_for_cfg)(cfg).into_iter().find(|o| {
            self.configure(o, address)
                .and_then(|p| p.chk_cfg())
                .is_ok_and(|c| c == cfg)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_option_file_is_named_once() {
        let e = read_option_file(std::path::Path::new("/nonexistent/params.toml")).unwrap_err();
        assert!(matches!(e, ProfileError::File { .. }), "{e}");
        assert!(
            e.to_string().starts_with("/nonexistent/params.toml: "),
            "{e}"
        );
        // The cause is in the message and not also the source, so that a
        // printed chain (`dpctl: {e:#}`) names it once.
        assert!(std::error::Error::source(&e).is_none());
    }
}
