//! The gateway's settings: the bus file's `[mqtt]` table, parsed into
//! [`MqttSettings`] ([`MqttSettings::from_table`],
//! [`MqttSettings::for_bus_file`]). Every key, its default and meaning:
//! `docs/gateway.md` in the repository.

use crate::field::Field;
use crate::topics::SparkplugId;
use profibus_dp::config::busfile::BusFileError;
use profibus_dp::monitor::alert::AlertRule;
use serde::de::IgnoredAny;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// When process images are published.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PublishMode {
    /// As soon as an image differs from the last one published.
    OnChange,
    /// Every `interval`, changed or not.
    Interval,
    /// On change and every `interval`.
    Both,
}

/// The MQTT protocol version the gateway speaks (`[mqtt] version`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MqttVersion {
    /// MQTT 3.1.1 (`version = 4`, the protocol level of its CONNECT), the
    /// default.
    #[default]
    V311,
    /// MQTT 5.0 (`version = 5`): request/response through the Response
    /// Topic and Correlation Data properties, units as user properties,
    /// message expiry.
    V5,
}

impl MqttVersion {
    /// The version from the number of `version` (the CONNECT's protocol
    /// level): 4 or 5.
    pub fn from_level(level: i64) -> Option<MqttVersion> {
        match level {
            4 => Some(MqttVersion::V311),
            5 => Some(MqttVersion::V5),
            _ => None,
        }
    }
}

/// `3.1.1` or `5`, as in log lines.
impl std::fmt::Display for MqttVersion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            MqttVersion::V311 => "3.1.1",
            MqttVersion::V5 => "5",
        })
    }
}

/// The default of `[mqtt] message_expiry_s`: a non-retained value
/// message older than this is of no use to a client that was away.
pub const DEFAULT_MESSAGE_EXPIRY_S: u32 = 10;

/// What the outputs do after `outputs_timeout` without a broker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SafeState {
    /// Keep the last values.
    Keep,
    /// Zero the output images of the writable slaves.
    Zero,
    /// Put the master into Clear until the broker is back.
    Clear,
}

impl SafeState {
    /// The name in the bus file and in payloads.
    pub fn as_str(self) -> &'static str {
        match self {
            SafeState::Keep => "keep",
            SafeState::Zero => "zero",
            SafeState::Clear => "clear",
        }
    }
}

/// What MQTT may change on one slave (`[mqtt] writable`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriteAccess {
    /// Station address.
    pub address: u8,
    /// `None`: everything (whole image, channels, DP-V1 and PKW writes,
    /// RFID commands); `Some(names)`: only these named output channels.
    pub channels: Option<Vec<String>>,
}

impl WriteAccess {
    /// Full access to the slave.
    pub fn full(address: u8) -> WriteAccess {
        WriteAccess {
            address,
            channels: None,
        }
    }
}

/// The MQTT side of a gateway.
#[derive(Debug, Clone, PartialEq)]
pub struct MqttSettings {
    /// Broker URL, `mqtt://HOST[:PORT]` (port 1883 by default).
    pub broker: Option<String>,
    /// MQTT client identifier.
    pub client_id: String,
    /// First topic level.
    pub prefix: String,
    /// Second topic level: the bus (segment) name.
    pub bus: String,
    /// Quality of service of every publish and subscription (0..=2).
    pub qos: u8,
    /// When images are published.
    pub publish: PublishMode,
    /// The period of [`PublishMode::Interval`] and [`PublishMode::Both`].
    pub interval: Duration,
    /// What may be written over MQTT, per slave.
    pub writable: Vec<WriteAccess>,
    /// Time without a broker after which the outputs go to
    /// [`MqttSettings::safe_state`] (`None`: never).
    pub outputs_timeout: Option<Duration>,
    /// The outputs' safe state.
    pub safe_state: SafeState,
    /// How long DP-V1, PKW and RFID requests may take.
    pub job_timeout: Duration,
    /// MQTT user name.
    pub username: Option<String>,
    /// Where the password is.
    pub password: Option<PasswordSource>,
    /// CA certificates (PEM) for `mqtts://`; `None`: the system's.
    pub ca_file: Option<PathBuf>,
    /// Sparkplug B mode with this group and edge node id (`None`: plain
    /// JSON topics).
    pub sparkplug: Option<SparkplugId>,
    /// Report by exception: the least time between two publishes of a
    /// slave's image (`[mqtt] min_interval_ms`; zero: no limit).
    pub min_interval: Duration,
    /// Report by exception: the deadband of the analog channels
    /// (`[mqtt] deadband`).
    pub deadband: Deadband,
    /// Per-slave overrides of `min_interval` and `deadband`
    /// (`[[mqtt.slave]]`).
    pub slave_traffic: Vec<SlaveTraffic>,
    /// Sparkplug B: the host id of the primary host application whose
    /// `spBv1.0/STATE/<id>` the edge node follows (`None`: none).
    pub primary_host: Option<String>,
    /// Sparkplug B: each device's named channels as an instance of a
    /// template defined in the NBIRTH, one definition per device type
    /// (`[mqtt] sparkplug_templates`, default false: flat metrics).
    pub sparkplug_templates: bool,
    /// The protocol version (`[mqtt] version`).
    pub version: MqttVersion,
    /// MQTT 5: the Message Expiry Interval of every message published
    /// without retain, in seconds (`[mqtt] message_expiry_s`; `None`:
    /// none).
    pub message_expiry_s: Option<u32>,
    /// Whether the images (`inputs`, `outputs`) are retained
    /// (`[mqtt] retain_values`, default true).
    pub retain_values: bool,
    /// Alert rules on the master's per-slave statistics (`[mqtt] alerts`
    /// and `dpctl gateway --alert`), the syntax of
    /// [`profibus_dp::monitor::alert`].
    pub alerts: Vec<AlertRule>,
    /// The interval the alert rules are checked over (`[mqtt]
    /// alert_interval_ms`, default 1 s).
    pub alert_interval: Duration,
}

/// How far an analog channel must move from the value last published
/// before its image is published again.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Deadband {
    /// In the channel's unit (`deadband = 0.05`); `0`: every change.
    Absolute(f64),
    /// In percent of the channel's range (`deadband = "1%"`); only for
    /// channels whose range the gateway knows (those in engineering
    /// units); other channels are compared exactly.
    Percent(f64),
}

impl Deadband {
    /// The default: 1 % of the range.
    pub const DEFAULT: Deadband = Deadband::Percent(1.0);
}

/// The traffic settings of one slave (`[[mqtt.slave]]`).
#[derive(Debug, Clone, PartialEq)]
pub struct SlaveTraffic {
    /// Station address.
    pub address: u8,
    /// Overrides `[mqtt] min_interval_ms`.
    pub min_interval: Option<Duration>,
    /// Overrides `[mqtt] deadband` for the slave's analog channels.
    pub deadband: Option<Deadband>,
    /// Deadbands of single channels, by name.
    pub channels: Vec<(String, Deadband)>,
}

/// The default of `[mqtt] min_interval_ms`.
pub const DEFAULT_MIN_INTERVAL: Duration = Duration::from_millis(250);

/// Where the MQTT password comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PasswordSource {
    /// The first line of this file.
    File(PathBuf),
    /// This environment variable.
    Env(String),
}

/// A broker's address from its URL.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Broker {
    /// Host name or IP address.
    pub host: String,
    /// TCP port.
    pub port: u16,
    /// TLS (`mqtts://`).
    pub tls: bool,
}

/// The broker as a URL: `mqtt://HOST:PORT` or `mqtts://HOST:PORT`.
impl std::fmt::Display for Broker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let scheme = if self.tls { "mqtts" } else { "mqtt" };
        write!(f, "{scheme}://{}:{}", self.host, self.port)
    }
}

impl MqttSettings {
    /// The write access to slave `address`, if any.
    pub fn access(&self, address: u8) -> Option<&WriteAccess> {
        self.writable.iter().find(|w| w.address == address)
    }
}

/// A bad `[mqtt]` setting.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SettingsError {
    /// A key this version does not know (the message names the closest
    /// keys).
    #[error("[mqtt]: unknown key `{0}`{hint}", hint = did_you_mean(.0, KEYS.iter().copied()))]
    UnknownKey(String),
    /// A key with a value of the wrong type or range.
    #[error("[mqtt]: `{key}` {problem}")]
    Bad {
        /// The key.
        key: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// Sparkplug B with MQTT 5.
    #[error(
        "[mqtt]: Sparkplug B needs MQTT 3.1.1 (`version = 4`, the default), not `version = 5`"
    )]
    SparkplugNeedsV311,
    /// A broker URL that is not `mqtt://HOST[:PORT]` or `mqtts://HOST[:PORT]`.
    #[error("broker URL `{0}` is not mqtt://HOST[:PORT] or mqtts://HOST[:PORT]")]
    BadUrl(String),
    /// `error` inside the table, at the dotted `path` (an entry of an
    /// array by its 1-based number: `mqtt.slave.2.channels.ai1`); the
    /// message is `error`'s.
    #[error("{error}")]
    At {
        /// Where, from the bus file's root.
        path: String,
        /// What is wrong.
        error: Box<SettingsError>,
    },
}

impl SettingsError {
    /// `self` at the dotted `path` (see [`SettingsError::At`]).
    pub fn at(self, path: impl Into<String>) -> SettingsError {
        SettingsError::At {
            path: path.into(),
            error: Box::new(self),
        }
    }

    /// The dotted path of the key this error is about (`mqtt.qos`), for
    /// its position in the bus file.
    pub fn key_path(&self) -> String {
        match self {
            SettingsError::UnknownKey(k) => format!("mqtt.{k}"),
            SettingsError::Bad { key, .. } => format!("mqtt.{key}"),
            SettingsError::BadUrl(_) => "mqtt.broker".into(),
            SettingsError::SparkplugNeedsV311 => "mqtt.version".into(),
            SettingsError::At { path, .. } => path.clone(),
        }
    }

    /// This error as a bus-file error of `file`: `FILE:LINE:COL: …` at
    /// the key it is about.
    pub fn in_bus_file(&self, file: &profibus_dp::config::busfile::BusFile) -> BusFileError {
        file.error_at(&self.key_path(), self.to_string())
    }
}

/// The `[mqtt]` table as written.
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct RawSettings {
    broker: Field<String>,
    client_id: Field<String>,
    prefix: Field<String>,
    bus: Field<String>,
    qos: Field<u8>,
    publish: Field<String>,
    interval_ms: Field<u64>,
    writable: Field<Vec<RawAccess>>,
    outputs_timeout_ms: Field<u64>,
    safe_state: Field<String>,
    job_timeout_ms: Field<u64>,
    username: Field<String>,
    password_file: Field<String>,
    password_env: Field<String>,
    ca_file: Field<String>,
    sparkplug: Field<String>,
    min_interval_ms: Field<u64>,
    deadband: Field<toml::Value>,
    slave: Field<Vec<toml::Table>>,
    primary_host: Field<String>,
    sparkplug_templates: Field<bool>,
    version: Field<toml::Value>,
    message_expiry_s: Field<u64>,
    retain_values: Field<bool>,
    alerts: Field<Vec<String>>,
    alert_interval_ms: Field<u64>,
}

/// The keys of the `[mqtt]` table (closest names of an unknown one).
const KEYS: &[&str] = &[
    "broker",
    "client_id",
    "prefix",
    "bus",
    "qos",
    "publish",
    "interval_ms",
    "writable",
    "outputs_timeout_ms",
    "safe_state",
    "job_timeout_ms",
    "username",
    "password_file",
    "password_env",
    "ca_file",
    "sparkplug",
    "min_interval_ms",
    "deadband",
    "slave",
    "primary_host",
    "sparkplug_templates",
    "version",
    "message_expiry_s",
    "retain_values",
    "alerts",
    "alert_interval_ms",
];

/// The keys of a `[[mqtt.slave]]` entry.
const SLAVE_KEYS: &[&str] = &["address", "min_interval_ms", "deadband", "channels"];

/// `; did you mean `a` or `b`?` for the names closest to `name`, or
/// nothing.
fn did_you_mean<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> String {
    let close = profibus_dp::config::names::closest(name, candidates);
    match close.split_last() {
        None => String::new(),
        Some((last, [])) => format!("; did you mean `{last}`?"),
        Some((last, rest)) => {
            let rest: Vec<String> = rest.iter().map(|n| format!("`{n}`")).collect();
            format!("; did you mean {} or `{last}`?", rest.join(", "))
        }
    }
}

/// A deadband as written: a number ≥ 0 (absolute) or `"N%"` (0..=100).
fn deadband(v: &toml::Value, key: &'static str, what: &str) -> Result<Deadband, SettingsError> {
    let problem = || {
        bad(
            key,
            format!(
                "{what}must be a number >= 0 (in the channel's unit) or a percentage of its range like \"1%\""
            ),
        )
    };
    let number = |x: f64| (x.is_finite() && x >= 0.0).then_some(x);
    match v {
        toml::Value::Integer(i) => number(*i as f64).map(Deadband::Absolute),
        toml::Value::Float(x) => number(*x).map(Deadband::Absolute),
        toml::Value::String(s) => s
            .strip_suffix('%')
            .and_then(|n| n.trim().parse::<f64>().ok())
            .and_then(number)
            .filter(|p| *p <= 100.0)
            .map(Deadband::Percent),
        _ => None,
    }
    .ok_or_else(problem)
}

/// A minimum interval in ms: 0 (no limit) to a day.
fn min_interval(v: Field<u64>, key: &'static str) -> Result<Option<Duration>, SettingsError> {
    match v.given() {
        None => Ok(None),
        Some(Ok(ms @ 0..=86_400_000)) => Ok(Some(Duration::from_millis(ms))),
        Some(_) => Err(bad(key, "must be 0..=86400000")),
    }
}

/// One `[[mqtt.slave]]` entry (the `i`th, from 1); its errors are at
/// `mqtt.slave.I.KEY`.
fn slave_traffic(i: usize, t: toml::Table) -> Result<SlaveTraffic, SettingsError> {
    let at = format!("entry {i}: ");
    let err =
        |key: &str, problem: String| bad("slave", problem).at(format!("mqtt.slave.{i}.{key}"));
    if let Some(k) = t.keys().find(|k| !SLAVE_KEYS.contains(&k.as_str())) {
        let hint = did_you_mean(k, SLAVE_KEYS.iter().copied());
        return Err(err(k, format!("{at}unknown key `{k}`{hint}")));
    }
    let address = match t.get("address") {
        Some(toml::Value::Integer(a @ 0..=125)) => *a as u8,
        _ => {
            return Err(err(
                "address",
                format!("{at}needs `address`, a station address 0..=125"),
            ))
        }
    };
    let min_interval = match t.get("min_interval_ms") {
        None => None,
        Some(toml::Value::Integer(ms @ 0..=86_400_000)) => Some(Duration::from_millis(*ms as u64)),
        Some(_) => {
            return Err(err(
                "min_interval_ms",
                format!("{at}`min_interval_ms` must be 0..=86400000"),
            ))
        }
    };
    let deadband_of = |v: &toml::Value, what: String, key: String| {
        deadband(v, "slave", &what).map_err(|e| e.at(format!("mqtt.slave.{i}.{key}")))
    };
    let deadband = t
        .get("deadband")
        .map(|v| deadband_of(v, format!("{at}`deadband` "), "deadband".into()))
        .transpose()?;
    let channels = match t.get("channels") {
        None => vec![],
        Some(toml::Value::Table(c)) => c
            .iter()
            .map(|(name, v)| {
                Ok((
                    name.clone(),
                    deadband_of(
                        v,
                        format!("{at}channel `{name}` "),
                        format!("channels.{name}"),
                    )?,
                ))
            })
            .collect::<Result<_, SettingsError>>()?,
        Some(_) => {
            return Err(err(
                "channels",
                format!("{at}`channels` must be a table of deadbands by channel name"),
            ))
        }
    };
    Ok(SlaveTraffic {
        address,
        min_interval,
        deadband,
        channels,
    })
}

/// One entry of `writable` as written: `3` or `{ address = 3, channels = ["a"] }`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum RawAccess {
    Entry(RawEntry),
    Address(Field<u8>),
}

/// A table entry of `writable`.
#[derive(Debug, Default, Deserialize)]
#[serde(default)]
struct RawEntry {
    address: Field<u8>,
    channels: Field<Vec<Field<String>>>,
    /// Keys other than these two (refused, by name).
    #[serde(flatten)]
    unknown: BTreeMap<String, IgnoredAny>,
}

fn bad(key: &'static str, problem: impl Into<String>) -> SettingsError {
    SettingsError::Bad {
        key,
        problem: problem.into(),
    }
}

/// A non-empty string key, when given.
fn string(v: Field<String>, key: &'static str) -> Result<Option<String>, SettingsError> {
    match v.given() {
        None => Ok(None),
        Some(Ok(s)) if !s.is_empty() => Ok(Some(s)),
        Some(_) => Err(bad(key, "must be a non-empty string")),
    }
}

/// A string key naming one of `choices` (absent: the first).
fn choice<T: Copy>(
    v: Field<String>,
    key: &'static str,
    choices: &[(&str, T)],
) -> Result<T, SettingsError> {
    let Some(name) = string(v, key)? else {
        return Ok(choices[0].1);
    };
    match choices.iter().find(|(n, _)| *n == name) {
        Some(&(_, v)) => Ok(v),
        None => {
            let names: Vec<&str> = choices.iter().map(|c| c.0).collect();
            let (last, rest) = names.split_last().expect("choices");
            let list = format!("{} or {last}", rest.join(", "));
            Err(bad(key, format!("`{name}` is not {list}")))
        }
    }
}

/// A time in ms (1 ms to a day), when given.
fn millis(v: Field<u64>, key: &'static str) -> Result<Option<Duration>, SettingsError> {
    match v.given() {
        None => Ok(None),
        Some(Ok(ms @ 1..=86_400_000)) => Ok(Some(Duration::from_millis(ms))),
        Some(_) => Err(bad(key, "must be 1..=86400000")),
    }
}

/// What `version` may be.
const VERSION_VALUES: &str = "must be 4 (MQTT 3.1.1, the default) or 5 (MQTT 5)";

/// Whether `s` is usable as one topic level (no wildcards, no `/`).
fn topic_level(s: &str) -> bool {
    !s.is_empty() && !s.contains(['/', '+', '#', '\0'])
}

/// A settings table as written, read into `T` whose fields all take
/// any TOML value (`None`: `T::default()`); the error is the key this
/// version does not know (else serde's message), the only one left.
/// `[mqtt]` here and `[opcua]` in `profibus-opcua` are read this way.
pub fn raw_table<T: serde::de::DeserializeOwned + Default>(
    table: Option<&toml::Table>,
) -> Result<T, String> {
    let Some(t) = table else {
        return Ok(T::default());
    };
    toml::Value::Table(t.clone()).try_into::<T>().map_err(|e| {
        let m = e.message();
        let key = m
            .split('`')
            .nth(1)
            .filter(|_| m.starts_with("unknown field"));
        key.unwrap_or(m).to_string()
    })
}

impl MqttSettings {
    /// Settings from a bus file's `[mqtt]` table (`None`: all defaults);
    /// `default_bus` names the bus when the table does not.
    pub fn from_table(
        table: Option<&toml::Table>,
        default_bus: &str,
    ) -> Result<MqttSettings, SettingsError> {
        let t: RawSettings = raw_table(table).map_err(SettingsError::UnknownKey)?;
        let bus = string(t.bus, "bus")?.unwrap_or_else(|| default_bus.to_string());
        if !topic_level(&bus) {
            return Err(bad("bus", format!("`{bus}` is not one topic level")));
        }
        let prefix = string(t.prefix, "prefix")?.unwrap_or_else(|| "profibus".into());
        if prefix.split('/').any(|l| !topic_level(l)) {
            return Err(bad("prefix", format!("`{prefix}` is not a topic prefix")));
        }
        let qos = match t.qos.given() {
            None => 1,
            Some(Ok(q @ 0..=2)) => q,
            Some(_) => return Err(bad("qos", "must be 0, 1 or 2")),
        };
        let publish = choice(
            t.publish,
            "publish",
            &[
                ("change", PublishMode::OnChange),
                ("interval", PublishMode::Interval),
                ("both", PublishMode::Both),
            ],
        )?;
        let interval = millis(t.interval_ms, "interval_ms")?.unwrap_or(Duration::from_secs(1));
        let writable: Vec<WriteAccess> = match t.writable.given() {
            None => vec![],
            Some(Ok(a)) => a.into_iter().map(access).collect::<Result<_, _>>()?,
            Some(Err(())) => return Err(bad("writable", "must be a list of station addresses")),
        };
        if let Some(w) = writable
            .iter()
            .enumerate()
            .find(|(i, w)| writable[..*i].iter().any(|o| o.address == w.address))
        {
            return Err(bad(
                "writable",
                format!("lists slave {} twice", w.1.address),
            ));
        }
        let outputs_timeout = millis(t.outputs_timeout_ms, "outputs_timeout_ms")?;
        let job_timeout =
            millis(t.job_timeout_ms, "job_timeout_ms")?.unwrap_or(Duration::from_secs(2));
        let safe_state = choice(
            t.safe_state,
            "safe_state",
            &[
                ("keep", SafeState::Keep),
                ("zero", SafeState::Zero),
                ("clear", SafeState::Clear),
            ],
        )?;
        let password = match (
            string(t.password_file, "password_file")?,
            string(t.password_env, "password_env")?,
        ) {
            (Some(_), Some(_)) => {
                return Err(bad(
                    "password_file",
                    "and `password_env` exclude each other",
                ))
            }
            (Some(f), None) => Some(PasswordSource::File(f.into())),
            (None, Some(v)) => Some(PasswordSource::Env(v)),
            (None, None) => None,
        };
        let username = string(t.username, "username")?;
        if password.is_some() && username.is_none() {
            return Err(bad("username", "is needed with a password"));
        }
        let ca_file = string(t.ca_file, "ca_file")?.map(PathBuf::from);
        let broker = string(t.broker, "broker")?;
        if let Some(b) = &broker {
            parse_broker(b)?;
        }
        let sparkplug = string(t.sparkplug, "sparkplug")?
            .map(|s| SparkplugId::parse(&s).map_err(|e| bad("sparkplug", e.to_string())))
            .transpose()?;
        let client_id = string(t.client_id, "client_id")?;
        let min_interval =
            min_interval(t.min_interval_ms, "min_interval_ms")?.unwrap_or(DEFAULT_MIN_INTERVAL);
        let deadband = match t.deadband.given() {
            None => Deadband::DEFAULT,
            Some(Ok(v)) => deadband(&v, "deadband", "")?,
            Some(Err(())) => {
                return Err(deadband(&toml::Value::Boolean(false), "deadband", "")
                    .expect_err("not a deadband"))
            }
        };
        let slave_traffic: Vec<SlaveTraffic> = match t.slave.given() {
            None => vec![],
            Some(Ok(v)) => v
                .into_iter()
                .enumerate()
                .map(|(i, t)| slave_traffic(i + 1, t))
                .collect::<Result<_, _>>()?,
            Some(Err(())) => {
                return Err(bad(
                    "slave",
                    "must be tables `[[mqtt.slave]]` with `address`",
                ))
            }
        };
        if let Some(s) = slave_traffic
            .iter()
            .enumerate()
            .find(|(i, s)| slave_traffic[..*i].iter().any(|o| o.address == s.address))
        {
            return Err(bad("slave", format!("lists slave {} twice", s.1.address))
                .at(format!("mqtt.slave.{}", s.0 + 1)));
        }
        let primary_host = string(t.primary_host, "primary_host")?;
        if let Some(h) = primary_host.as_deref().filter(|h| !topic_level(h)) {
            return Err(bad("primary_host", format!("`{h}` is not one topic level")));
        }
        let sparkplug_templates = match t.sparkplug_templates.given() {
            None => false,
            Some(Ok(b)) => b,
            Some(Err(())) => return Err(bad("sparkplug_templates", "must be true or false")),
        };
        let version = match t.version.given() {
            None => MqttVersion::default(),
            Some(Ok(toml::Value::Integer(n))) => {
                MqttVersion::from_level(n).ok_or_else(|| bad("version", VERSION_VALUES))?
            }
            Some(_) => return Err(bad("version", VERSION_VALUES)),
        };
        if sparkplug.is_some() && version == MqttVersion::V5 {
            return Err(SettingsError::SparkplugNeedsV311);
        }
        let message_expiry_s = match t.message_expiry_s.given() {
            None => Some(DEFAULT_MESSAGE_EXPIRY_S),
            Some(Ok(0)) => None,
            Some(Ok(s @ 1..=86_400)) => Some(s as u32),
            Some(_) => return Err(bad("message_expiry_s", "must be 0 (none) to 86400 seconds")),
        };
        let retain_values = match t.retain_values.given() {
            None => true,
            Some(Ok(b)) => b,
            Some(Err(())) => return Err(bad("retain_values", "must be true or false")),
        };
        let alerts = match t.alerts.given() {
            None => vec![],
            Some(Ok(v)) => v
                .iter()
                .map(|r| AlertRule::parse(r).map_err(|e| bad("alerts", e.to_string())))
                .collect::<Result<_, _>>()?,
            Some(Err(())) => {
                return Err(bad("alerts", "must be a list of rules like \"retries>1%\""))
            }
        };
        let alert_interval =
            millis(t.alert_interval_ms, "alert_interval_ms")?.unwrap_or(Duration::from_secs(1));
        Ok(MqttSettings {
            broker,
            client_id: client_id.unwrap_or_else(|| format!("dpctl-gateway-{bus}")),
            prefix,
            bus,
            qos,
            publish,
            interval,
            writable,
            outputs_timeout,
            safe_state,
            job_timeout,
            username,
            password,
            ca_file,
            sparkplug,
            min_interval,
            deadband,
            slave_traffic,
            primary_host,
            sparkplug_templates,
            version,
            message_expiry_s,
            retain_values,
            alerts,
            alert_interval,
        })
    }

    /// Relative file paths (`password_file`, `ca_file`) taken relative to
    /// `dir` (the bus file's directory).
    pub fn relative_to(&mut self, dir: &Path) {
        if let Some(PasswordSource::File(f)) = &mut self.password {
            *f = dir.join(&*f);
        }
        if let Some(f) = &mut self.ca_file {
            *f = dir.join(&*f);
        }
    }

    /// The settings of the bus file at `path` from its `[mqtt]` table:
    /// the bus named after the file's stem (wildcards and `/` replaced by
    /// `_`) unless the table names it, files relative to the bus file's
    /// directory.
    pub fn for_bus_file(
        table: Option<&toml::Table>,
        path: &Path,
    ) -> Result<MqttSettings, SettingsError> {
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("bus")
            .replace(['/', '+', '#'], "_");
        let mut s = MqttSettings::from_table(table, &stem)?;
        if let Some(dir) = path.parent() {
            s.relative_to(dir);
        }
        Ok(s)
    }
}

/// One entry of `writable`: `3` or `{ address = 3, channels = ["a"] }`.
fn access(v: RawAccess) -> Result<WriteAccess, SettingsError> {
    let address = |v: Field<u8>| match v {
        Field::Valid(n @ 0..=125) => Ok(n),
        _ => Err(bad("writable", "takes station addresses 0..=125")),
    };
    match v {
        RawAccess::Entry(e) => {
            if let Some(k) = e.unknown.keys().next() {
                return Err(bad("writable", format!("entry has an unknown key `{k}`")));
            }
            let channels = match e.channels.given() {
                Some(Ok(a)) => a
                    .into_iter()
                    .map(|c| match c {
                        Field::Valid(s) if !s.is_empty() => Ok(s),
                        _ => Err(bad("writable", "`channels` takes channel names")),
                    })
                    .collect::<Result<_, _>>()?,
                _ => return Err(bad("writable", "an entry table needs `channels = [..]`")),
            };
            Ok(WriteAccess {
                address: address(e.address)?,
                channels: Some(channels),
            })
        }
        RawAccess::Address(a) => Ok(WriteAccess::full(address(a)?)),
    }
}

/// The broker of an `mqtt://HOST[:PORT]` (`tcp://` is taken too) or
/// `mqtts://HOST[:PORT]` (`ssl://`) URL.
pub fn parse_broker(url: &str) -> Result<Broker, SettingsError> {
    let bad = || SettingsError::BadUrl(url.to_string());
    let u = crate::url::split_url(url, &["mqtt://", "tcp://", "mqtts://", "ssl://"])
        .filter(|u| u.path.is_empty())
        .ok_or_else(bad)?;
    let tls = matches!(u.scheme, "mqtts://" | "ssl://");
    Ok(Broker {
        host: u.host.to_string(),
        port: u.port.unwrap_or(if tls { 8883 } else { 1883 }),
        tls,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<MqttSettings, SettingsError> {
        let t: toml::Table = toml::from_str(text).unwrap();
        MqttSettings::from_table(Some(&t), "line1")
    }

    #[test]
    fn defaults_and_keys() {
        let s = MqttSettings::from_table(None, "line1").unwrap();
        assert_eq!(s.prefix, "profibus");
        assert_eq!(s.client_id, "dpctl-gateway-line1");
        assert_eq!((s.qos, s.publish), (1, PublishMode::OnChange));
        assert!(s.writable.is_empty());
        assert_eq!((s.outputs_timeout, s.safe_state), (None, SafeState::Keep));
        let s = parse(
            "broker = \"mqtt://h:1884\"\nprefix = \"plant/a\"\nbus = \"seg7\"\nqos = 0\npublish = \"both\"\ninterval_ms = 250\nwritable = [3, { address = 6, channels = [\"speed\"] }]\noutputs_timeout_ms = 1500\nsafe_state = \"zero\"",
        )
        .unwrap();
        assert_eq!(s.outputs_timeout, Some(Duration::from_millis(1500)));
        assert_eq!(s.safe_state, SafeState::Zero);
        assert_eq!(
            s.access(6).unwrap().channels.as_deref(),
            Some(&["speed".to_string()][..])
        );
        assert_eq!(s.access(3), Some(&WriteAccess::full(3)));
        assert_eq!(s.access(4), None);
        assert_eq!(s.prefix, "plant/a");
        assert_eq!(s.bus, "seg7");
        assert_eq!(s.publish, PublishMode::Both);
        assert_eq!(s.interval, Duration::from_millis(250));
    }

    #[test]
    fn mqtt5_keys() {
        let s = MqttSettings::from_table(None, "l").unwrap();
        assert_eq!(s.version, MqttVersion::V311);
        assert_eq!(s.message_expiry_s, Some(DEFAULT_MESSAGE_EXPIRY_S));
        assert!(s.retain_values);
        let s = parse("version = 5\nmessage_expiry_s = 0\nretain_values = false").unwrap();
        assert_eq!(
            (s.version, s.message_expiry_s, s.retain_values),
            (MqttVersion::V5, None, false)
        );
        let s = parse("version = 4\nmessage_expiry_s = 30").unwrap();
        assert_eq!(
            (s.version, s.message_expiry_s),
            (MqttVersion::V311, Some(30))
        );
    }

    #[test]
    fn sparkplug_templates_key() {
        let s = MqttSettings::from_table(None, "l").unwrap();
        assert!(!s.sparkplug_templates, "flat metrics by default");
        assert!(
            parse("sparkplug_templates = true")
                .unwrap()
                .sparkplug_templates
        );
        assert_eq!(
            parse("sparkplug_templates = \"yes\"")
                .unwrap_err()
                .to_string(),
            "[mqtt]: `sparkplug_templates` must be true or false"
        );
    }

    #[test]
    fn traffic_keys() {
        let s = MqttSettings::from_table(None, "l").unwrap();
        assert_eq!(
            (s.min_interval, s.deadband),
            (DEFAULT_MIN_INTERVAL, Deadband::Percent(1.0))
        );
        let s = parse(
            "min_interval_ms = 0\ndeadband = 0.5\n[[slave]]\naddress = 7\nmin_interval_ms = 1000\ndeadband = \"2.5%\"\nchannels = { \"1.KL3102.1\" = 0.01, speed = 3 }",
        )
        .unwrap();
        assert_eq!(
            (s.min_interval, s.deadband),
            (Duration::ZERO, Deadband::Absolute(0.5))
        );
        assert_eq!(
            s.slave_traffic,
            [SlaveTraffic {
                address: 7,
                min_interval: Some(Duration::from_secs(1)),
                deadband: Some(Deadband::Percent(2.5)),
                channels: vec![
                    ("1.KL3102.1".into(), Deadband::Absolute(0.01)),
                    ("speed".into(), Deadband::Absolute(3.0)),
                ],
            }]
        );
    }

    /// Each error knows the key it is about (for its line and column in
    /// the bus file); the message stays the key's.
    #[test]
    fn errors_name_their_key_path() {
        let path = |text: &str| parse(text).unwrap_err().key_path();
        assert_eq!(path("qos = 3"), "mqtt.qos");
        assert_eq!(path("retain = 1"), "mqtt.retain");
        assert_eq!(
            path("[[slave]]\naddress = 3\naddres = 4"),
            "mqtt.slave.1.addres"
        );
        assert_eq!(path("[[slave]]\nchannels = {}"), "mqtt.slave.1.address");
        let e = parse("[[slave]]\naddress = 3\n[[slave]]\naddress = 4\nchannels = { ai = \"x\" }")
            .unwrap_err();
        assert_eq!(e.key_path(), "mqtt.slave.2.channels.ai");
        assert!(
            e.to_string()
                .starts_with("[mqtt]: `slave` entry 2: channel `ai` must"),
            "{e}"
        );
        assert_eq!(
            path("[[slave]]\naddress = 3\n[[slave]]\naddress = 3"),
            "mqtt.slave.2"
        );
    }

    #[test]
    fn alert_keys() {
        let s = MqttSettings::from_table(None, "l").unwrap();
        assert_eq!(
            (s.alerts.len(), s.alert_interval),
            (0, Duration::from_secs(1))
        );
        let s = parse("alerts = [\"retries>1%\", \"restart\"]\nalert_interval_ms = 5000").unwrap();
        let rules: Vec<String> = s.alerts.iter().map(|r| r.to_string()).collect();
        assert_eq!(rules, ["retries>1%", "restart"]);
        assert_eq!(s.alert_interval, Duration::from_secs(5));
        for (text, message) in [
            (
                "alerts = [\"retrys>1%\"]",
                "[mqtt]: `alerts` alert rule `retrys>1%`, column 1: unknown statistic `retrys` (did you mean `retries`?)",
            ),
            ("alerts = \"restart\"", "[mqtt]: `alerts` must be a list of rules like \"retries>1%\""),
            ("alert_interval_ms = 0", "[mqtt]: `alert_interval_ms` must be 1..=86400000"),
        ] {
            assert_eq!(parse(text).unwrap_err().to_string(), message, "{text}");
        }
    }

    #[test]
    fn bad_settings_are_refused() {
        assert_eq!(
            parse("qos = 3").unwrap_err().to_string(),
            "[mqtt]: `qos` must be 0, 1 or 2"
        );
        assert!(
            matches!(parse("retain = true"), Err(SettingsError::UnknownKey(k)) if k == "retain")
        );
        assert!(parse("bus = \"a/b\"").is_err());
        assert!(parse("prefix = \"a/#\"").is_err());
        assert!(parse("publish = \"sometimes\"").is_err());
        assert!(parse("writable = [200]").is_err());
        assert!(parse("writable = [3, 3]").is_err());
        assert!(parse("writable = [{ address = 3 }]").is_err());
        assert!(parse("writable = [{ address = 3, channels = [1] }]").is_err());
        assert!(parse("safe_state = \"off\"").is_err());
        assert!(parse("outputs_timeout_ms = 0").is_err());
        assert!(parse("broker = \"http://x\"").is_err());
    }

    #[test]
    fn each_bad_setting_has_its_message() {
        for (text, message) in [
            (
                "retain = true",
                "[mqtt]: unknown key `retain`; did you mean `retain_values`?",
            ),
            ("bus = 3", "[mqtt]: `bus` must be a non-empty string"),
            ("bus = \"a/b\"", "[mqtt]: `bus` `a/b` is not one topic level"),
            ("prefix = \"a/#\"", "[mqtt]: `prefix` `a/#` is not a topic prefix"),
            ("qos = \"1\"", "[mqtt]: `qos` must be 0, 1 or 2"),
            (
                "publish = \"sometimes\"",
                "[mqtt]: `publish` `sometimes` is not change, interval or both",
            ),
            ("interval_ms = 0", "[mqtt]: `interval_ms` must be 1..=86400000"),
            ("job_timeout_ms = 1.5", "[mqtt]: `job_timeout_ms` must be 1..=86400000"),
            (
                "writable = 3",
                "[mqtt]: `writable` must be a list of station addresses",
            ),
            (
                "writable = [\"3\"]",
                "[mqtt]: `writable` takes station addresses 0..=125",
            ),
            (
                "writable = [{ address = 3, channels = [\"a\"], x = 1 }]",
                "[mqtt]: `writable` entry has an unknown key `x`",
            ),
            (
                "writable = [{ address = 3, channels = \"a\" }]",
                "[mqtt]: `writable` an entry table needs `channels = [..]`",
            ),
            (
                "writable = [{ address = 3, channels = [\"\"] }]",
                "[mqtt]: `writable` `channels` takes channel names",
            ),
            (
                "writable = [{ address = 3 }]",
                "[mqtt]: `writable` an entry table needs `channels = [..]`",
            ),
            (
                "writable = [{ channels = [\"a\"] }]",
                "[mqtt]: `writable` takes station addresses 0..=125",
            ),
            ("writable = [4, 4]", "[mqtt]: `writable` lists slave 4 twice"),
            ("safe_state = \"off\"", "[mqtt]: `safe_state` `off` is not keep, zero or clear"),
            (
                "username = \"u\"\npassword_file = \"f\"\npassword_env = \"E\"",
                "[mqtt]: `password_file` and `password_env` exclude each other",
            ),
            ("password_env = \"E\"", "[mqtt]: `username` is needed with a password"),
            (
                "broker = \"http://x\"",
                "broker URL `http://x` is not mqtt://HOST[:PORT] or mqtts://HOST[:PORT]",
            ),
            ("retian = true", "[mqtt]: unknown key `retian`"),
            (
                "qso = 1",
                "[mqtt]: unknown key `qso`; did you mean `qos`?",
            ),
            ("min_interval_ms = -1", "[mqtt]: `min_interval_ms` must be 0..=86400000"),
            (
                "deadband = \"1\"",
                "[mqtt]: `deadband` must be a number >= 0 (in the channel's unit) or a percentage of its range like \"1%\"",
            ),
            (
                "deadband = -0.5",
                "[mqtt]: `deadband` must be a number >= 0 (in the channel's unit) or a percentage of its range like \"1%\"",
            ),
            (
                "deadband = \"101%\"",
                "[mqtt]: `deadband` must be a number >= 0 (in the channel's unit) or a percentage of its range like \"1%\"",
            ),
            ("slave = 3", "[mqtt]: `slave` must be tables `[[mqtt.slave]]` with `address`"),
            (
                "[[slave]]\naddres = 3",
                "[mqtt]: `slave` entry 1: unknown key `addres`; did you mean `address`?",
            ),
            (
                "[[slave]]\nmin_interval_ms = 3",
                "[mqtt]: `slave` entry 1: needs `address`, a station address 0..=125",
            ),
            (
                "[[slave]]\naddress = 3\n[[slave]]\naddress = 4\nchannels = { ai = \"x\" }",
                "[mqtt]: `slave` entry 2: channel `ai` must be a number >= 0 (in the channel's unit) or a percentage of its range like \"1%\"",
            ),
            (
                "[[slave]]\naddress = 3\nchannels = [1]",
                "[mqtt]: `slave` entry 1: `channels` must be a table of deadbands by channel name",
            ),
            (
                "[[slave]]\naddress = 3\n[[slave]]\naddress = 3",
                "[mqtt]: `slave` lists slave 3 twice",
            ),
            (
                "sparkplug = \"g\"",
                "[mqtt]: `sparkplug` `g` is not GROUP/EDGE (two non-empty ids without `/`, `+` or `#`)",
            ),
            (
                "version = 3",
                "[mqtt]: `version` must be 4 (MQTT 3.1.1, the default) or 5 (MQTT 5)",
            ),
            (
                "version = \"5.0\"",
                "[mqtt]: `version` must be 4 (MQTT 3.1.1, the default) or 5 (MQTT 5)",
            ),
            (
                "version = 5\nsparkplug = \"g/e\"",
                "[mqtt]: Sparkplug B needs MQTT 3.1.1 (`version = 4`, the default), not `version = 5`",
            ),
            (
                "message_expiry_s = 86401",
                "[mqtt]: `message_expiry_s` must be 0 (none) to 86400 seconds",
            ),
            ("retain_values = 1", "[mqtt]: `retain_values` must be true or false"),
        ] {
            assert_eq!(parse(text).unwrap_err().to_string(), message, "{text}");
        }
    }

    #[test]
    fn from_a_bus_file() {
        let text = "[master]\naddress = 1\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 25\ndevice = \"omega\"\n\n[mqtt]\nbus = \"seg2\"\nwritable = [25]\n";
        let path = std::path::Path::new("/nonexistent/plant.toml");
        let bus = profibus_devices::bus::ProfiledBus::parse(path, text).unwrap();
        let s = MqttSettings::from_table(bus.file.mqtt.as_ref(), "plant").unwrap();
        assert_eq!(
            (s.bus.as_str(), s.writable.as_slice()),
            ("seg2", &[WriteAccess::full(25)][..])
        );
        let bus =
            profibus_devices::bus::ProfiledBus::parse(path, &text[..text.find("[mqtt]").unwrap()])
                .unwrap();
        assert!(bus.file.mqtt.is_none());
        assert_eq!(
            MqttSettings::from_table(None, "plant").unwrap().bus,
            "plant"
        );
    }

    #[test]
    fn credentials_and_tls() {
        let mut s =
            parse("username = \"gw\"\npassword_file = \"pw\"\nca_file = \"/etc/ca.pem\"").unwrap();
        s.relative_to(Path::new("/plant"));
        assert_eq!(s.password, Some(PasswordSource::File("/plant/pw".into())));
        assert_eq!(s.ca_file, Some("/etc/ca.pem".into()));
        let s = parse("username = \"gw\"\npassword_env = \"PW\"").unwrap();
        assert_eq!(s.password, Some(PasswordSource::Env("PW".into())));
        assert!(parse("password_env = \"PW\"").is_err());
        assert!(parse("username = \"gw\"\npassword_env = \"PW\"\npassword_file = \"f\"").is_err());
        assert!(parse("password = \"plain\"").is_err());
    }

    #[test]
    fn broker_urls() {
        let b = |h: &str, port, tls| Broker {
            host: h.into(),
            port,
            tls,
        };
        assert_eq!(
            parse_broker("mqtt://127.0.0.1:1884").unwrap(),
            b("127.0.0.1", 1884, false)
        );
        assert_eq!(
            parse_broker("mqtt://broker").unwrap(),
            b("broker", 1883, false)
        );
        assert_eq!(
            parse_broker("mqtts://broker").unwrap(),
            b("broker", 8883, true)
        );
        assert_eq!(
            parse_broker("ssl://broker:9000").unwrap(),
            b("broker", 9000, true)
        );
        assert!(parse_broker("mqtt://:1").is_err());
        assert!(parse_broker("mqtt://h:99999").is_err());
    }
}
