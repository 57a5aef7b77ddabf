//! The gateway's settings: the bus file's `[mqtt]` table.
//!
//! ```toml
//! [mqtt]
//! broker = "mqtt://localhost:1883"   # `dpctl gateway --mqtt` overrides it
//! client_id = "dpctl-gateway-line1"  # default: dpctl-gateway-<bus>
//! prefix = "profibus"                # first topic level
//! bus = "line1"                      # second topic level; default: the file's stem
//! qos = 1                            # 0, 1 or 2
//! publish = "change"                 # "change", "interval" or "both"
//! interval_ms = 1000                 # period of "interval" / "both"
//! writable = [3, 6]                  # slaves whose outputs MQTT may set (default: none)
//! sparkplug = "plant/line1"          # Sparkplug B mode, GROUP/EDGE (see crate::sparkplug)
//! ```

use crate::sparkplug::SparkplugId;
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
    /// Station addresses whose outputs may be written over MQTT.
    pub writable: Vec<u8>,
    /// Sparkplug B mode with this group and edge node id (`None`: plain
    /// JSON topics).
    pub sparkplug: Option<SparkplugId>,
}

/// A bad `[mqtt]` setting.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SettingsError {
    /// A key this version does not know.
    #[error("[mqtt]: unknown key `{0}`")]
    UnknownKey(String),
    /// A key with a value of the wrong type or range.
    #[error("[mqtt]: `{key}` {problem}")]
    Bad {
        /// The key.
        key: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// A broker URL that is not `mqtt://HOST[:PORT]`.
    #[error("broker URL `{0}` is not mqtt://HOST[:PORT]")]
    BadUrl(String),
}

const KEYS: &[&str] = &[
    "broker",
    "client_id",
    "prefix",
    "bus",
    "qos",
    "publish",
    "interval_ms",
    "writable",
    "sparkplug",
];

fn bad(key: &'static str, problem: impl Into<String>) -> SettingsError {
    SettingsError::Bad {
        key,
        problem: problem.into(),
    }
}

fn string(t: &toml::Table, key: &'static str) -> Result<Option<String>, SettingsError> {
    match t.get(key) {
        None => Ok(None),
        Some(toml::Value::String(s)) if !s.is_empty() => Ok(Some(s.clone())),
        Some(_) => Err(bad(key, "must be a non-empty string")),
    }
}

/// Whether `s` is usable as one topic level (no wildcards, no `/`).
fn topic_level(s: &str) -> bool {
    !s.is_empty() && !s.contains(['/', '+', '#', '\0'])
}

impl MqttSettings {
    /// Settings from a bus file's `[mqtt]` table (`None`: all defaults);
    /// `default_bus` names the bus when the table does not.
    pub fn from_table(
        table: Option<&toml::Table>,
        default_bus: &str,
    ) -> Result<MqttSettings, SettingsError> {
        let empty = toml::Table::new();
        let t = table.unwrap_or(&empty);
        if let Some(k) = t.keys().find(|k| !KEYS.contains(&k.as_str())) {
            return Err(SettingsError::UnknownKey(k.clone()));
        }
        let bus = string(t, "bus")?.unwrap_or_else(|| default_bus.to_string());
        if !topic_level(&bus) {
            return Err(bad("bus", format!("`{bus}` is not one topic level")));
        }
        let prefix = string(t, "prefix")?.unwrap_or_else(|| "profibus".into());
        if prefix.split('/').any(|l| !topic_level(l)) {
            return Err(bad("prefix", format!("`{prefix}` is not a topic prefix")));
        }
        let qos = match t.get("qos") {
            None => 1,
            Some(toml::Value::Integer(q @ 0..=2)) => *q as u8,
            Some(_) => return Err(bad("qos", "must be 0, 1 or 2")),
        };
        let publish = match string(t, "publish")?.as_deref() {
            None | Some("change") => PublishMode::OnChange,
            Some("interval") => PublishMode::Interval,
            Some("both") => PublishMode::Both,
            Some(o) => {
                return Err(bad(
                    "publish",
                    format!("`{o}` is not change, interval or both"),
                ))
            }
        };
        let interval = match t.get("interval_ms") {
            None => Duration::from_secs(1),
            Some(toml::Value::Integer(ms @ 1..=86_400_000)) => Duration::from_millis(*ms as u64),
            Some(_) => return Err(bad("interval_ms", "must be 1..=86400000")),
        };
        let writable = match t.get("writable") {
            None => vec![],
            Some(toml::Value::Array(a)) => a
                .iter()
                .map(|v| match v {
                    toml::Value::Integer(n @ 0..=125) => Ok(*n as u8),
                    _ => Err(bad("writable", "takes station addresses 0..=125")),
                })
                .collect::<Result<_, _>>()?,
            Some(_) => return Err(bad("writable", "must be a list of station addresses")),
        };
        let broker = string(t, "broker")?;
        if let Some(b) = &broker {
            parse_broker(b)?;
        }
        let sparkplug = string(t, "sparkplug")?
            .map(|s| SparkplugId::parse(&s).map_err(|e| bad("sparkplug", e.to_string())))
            .transpose()?;
        Ok(MqttSettings {
            broker,
            client_id: string(t, "client_id")?.unwrap_or_else(|| format!("dpctl-gateway-{bus}")),
            prefix,
            bus,
            qos,
            publish,
            interval,
            writable,
            sparkplug,
        })
    }
}

/// Host and port of an `mqtt://HOST[:PORT]` URL (`tcp://` is taken too).
pub fn parse_broker(url: &str) -> Result<(String, u16), SettingsError> {
    let bad = || SettingsError::BadUrl(url.to_string());
    let rest = url
        .strip_prefix("mqtt://")
        .or_else(|| url.strip_prefix("tcp://"))
        .ok_or_else(bad)?;
    let rest = rest.trim_end_matches('/');
    let (host, port) = match rest.rsplit_once(':') {
        Some((h, p)) => (h, p.parse::<u16>().map_err(|_| bad())?),
        None => (rest, 1883),
    };
    if host.is_empty() || host.contains(['/', '@']) {
        return Err(bad());
    }
    Ok((host.trim_matches(['[', ']']).to_string(), port))
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
        let s = parse(
            "broker = \"mqtt://h:1884\"\nprefix = \"plant/a\"\nbus = \"seg7\"\nqos = 0\npublish = \"both\"\ninterval_ms = 250\nwritable = [3, 6]",
        )
        .unwrap();
        assert_eq!(s.prefix, "plant/a");
        assert_eq!(s.bus, "seg7");
        assert_eq!(s.publish, PublishMode::Both);
        assert_eq!(s.interval, Duration::from_millis(250));
        assert_eq!(s.writable, [3, 6]);
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
        assert!(parse("broker = \"http://x\"").is_err());
    }

    #[test]
    fn from_a_bus_file() {
        let text = "[master]\naddress = 1\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 25\ndevice = \"omega\"\n\n[mqtt]\nbus = \"seg2\"\nwritable = [25]\n";
        let path = std::path::Path::new("/nonexistent/plant.toml");
        let bus = profibus_devices::bus::ProfiledBus::parse(path, text).unwrap();
        let s = MqttSettings::from_table(bus.file.mqtt.as_ref(), "plant").unwrap();
        assert_eq!(
            (s.bus.as_str(), s.writable.as_slice()),
            ("seg2", &[25u8][..])
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
    fn broker_urls() {
        assert_eq!(
            parse_broker("mqtt://127.0.0.1:1884").unwrap(),
            ("127.0.0.1".into(), 1884)
        );
        assert_eq!(
            parse_broker("mqtt://broker").unwrap(),
            ("broker".into(), 1883)
        );
        assert!(parse_broker("mqtt://:1").is_err());
        assert!(parse_broker("mqtt://h:99999").is_err());
    }
}
