//! PROFIBUS-DP to MQTT: a DP master's slaves as JSON topics or a Sparkplug B edge node on a broker.
//!
//! A library for gateway makers, used by `dpctl gateway`. The core,
//! [`Gateway`], is sans-IO: it reads a running [`DpMaster`] at a cycle
//! boundary and queues [`Publish`]es, and it turns messages into output
//! writes; [`MqttLink`] is the thin driver on the `rumqttc` client.
//!
//! With `--sparkplug GROUP/EDGE` (or `sparkplug` in `[mqtt]`) the master
//! is a Sparkplug B edge node instead, [`EdgeNode`]. Both cores
//! implement [`Session`], the interface the link and drivers use.
//!
//! The protocol (topics, payloads, requests and answers, the `[mqtt]`
//! settings, the Sparkplug B mapping, QoS and retain, what happens while
//! the broker is away) is described in one place: `docs/gateway.md` in
//! the repository.
//!
//! # Modules
//!
//! In layers: each module uses only the modules before it in this list
//! (the test `layers` checks it), so the cores know no connection and
//! nothing below the driver knows the simulated plant.
//!
//! 1. [`url`]: broker and endpoint URLs split into host, port and path.
//! 2. [`field`]: a field parsed leniently, checked afterwards.
//! 3. [`topics`]: the topic names, plain and Sparkplug B.
//! 4. [`slave`]: what the gateway knows of a configured slave.
//! 5. [`settings`]: the `[mqtt]` table.
//! 6. [`alerts`]: alert rules on the master's per-slave statistics.
//! 7. [`traffic`]: report by exception (deadbands, minimum interval).
//! 8. [`request`]: requests from clients, parsed from their payloads.
//! 9. [`payload`]: the JSON payloads the plain mode publishes.
//! 10. [`session`]: the [`Session`] interface of the cores, [`Publish`].
//! 11. [`outage`]: the outputs while the broker is away.
//! 12. [`json`]: the plain JSON core, [`Gateway`].
//! 13. [`sparkplug`]: the Sparkplug B core, [`EdgeNode`].
//! 14. [`link`]: the MQTT connection on `rumqttc` and tokio, [`MqttLink`].
//! 15. [`sim`]: the simulated plant of `dpctl gateway --sim`.
//!
//! # Example
//!
//! The core without a broker, on the simulated plant of `dpctl gateway
//! --sim`: the bus file's slaves are emulated on virtual time, the
//! gateway reads the master at every step and queues its publishes, and
//! a client's write of a named channel reaches the drive, whose actual
//! value follows.
//!
//! ```
//! use profibus_devices::bus::ProfiledBus;
//! use profibus_fdl::Instant;
//! use profibus_gateway::sim::slave_infos;
//! use profibus_plant::Plant;
//! use profibus_gateway::{Gateway, MqttSettings};
//! use std::path::Path;
//! use std::time::Duration;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let bus = ProfiledBus::parse(
//!     Path::new("line.toml"),
//!     "[master]\naddress = 2\nbaud = \"1.5M\"\n\
//!      [[slave]]\naddress = 25\ndevice = \"omega\"\ndrive_enable = \"auto\"\n\
//!      [mqtt]\nwritable = [25]\n",
//! )?;
//! let settings = MqttSettings::from_table(bus.file.mqtt.as_ref(), "line")?;
//! let mut gateway = Gateway::new(settings, slave_infos(&bus)?);
//! let mut plant = Plant::from_bus(&bus)?;
//! gateway.connected(0);
//! gateway.handle_message(
//!     "profibus/line/25/outputs/set",
//!     br#"{"channels": {"setpoint1": 1500}}"#,
//!     0,
//! );
//! let mut actual = None;
//! for ms in 1..=300u64 {
//!     let now = Instant::ZERO + Duration::from_millis(ms);
//!     plant.run_until(now);
//!     gateway.step(plant.master(), now, ms);
//!     while let Some(p) = gateway.poll_publish() {
//!         if p.topic == "profibus/line/25/inputs" {
//!             let v: serde_json::Value = serde_json::from_slice(&p.payload)?;
//!             actual = v["values"]["actual1"].as_i64();
//!         }
//!     }
//! }
//! assert_eq!(actual, Some(1500));
//! # Ok(())
//! # }
//! ```
//!
//! [`DpMaster`]: profibus_dp::master::DpMaster

pub mod alerts;
pub mod field;
pub mod json;
pub mod link;
pub mod outage;
pub mod payload;
pub mod request;
pub mod session;
pub mod settings;
pub mod sim;
pub mod slave;
pub mod sparkplug;
pub mod topics;
pub mod traffic;
pub mod url;

pub use json::Gateway;
pub use link::{Connection, ConnectionError, LinkEvent, MqttLink};
pub use session::{LinkSetup, Properties, Publish, Session};
pub use settings::{
    Broker, Deadband, MqttSettings, MqttVersion, PublishMode, SafeState, SettingsError,
    SlaveTraffic, WriteAccess,
};
pub use slave::{slave_infos, SlaveInfo, SlaveInfoError};
pub use sparkplug::EdgeNode;
pub use topics::{Service, SparkplugId, Topics};

/// The module order of the crate documentation's layers.
#[cfg(test)]
const LAYERS: [&str; 15] = [
    "url",
    "field",
    "topics",
    "slave",
    "settings",
    "alerts",
    "traffic",
    "request",
    "payload",
    "session",
    "outage",
    "json",
    "sparkplug",
    "link",
    "sim",
];

#[cfg(test)]
mod layers {
    use super::LAYERS;
    use std::path::Path;

    /// The `crate::` paths a source file's code (not its comments or
    /// tests) names.
    fn uses(text: &str) -> Vec<String> {
        let code = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
        code.lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .flat_map(|l| l.split("crate::").skip(1))
            .map(|rest| {
                rest.chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect()
            })
            .collect()
    }

    #[test]
    fn every_module_uses_only_the_layers_before_it() {
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        for (rank, module) in LAYERS.iter().enumerate() {
            let file = src.join(format!("{module}.rs"));
            let files = if file.exists() {
                vec![file]
            } else {
                std::fs::read_dir(src.join(module))
                    .unwrap()
                    .map(|e| e.unwrap().path())
                    .collect()
            };
            for f in files {
                let text = std::fs::read_to_string(&f).unwrap();
                for used in uses(&text) {
                    let at = LAYERS.iter().position(|m| *m == used);
                    assert!(
                        used == *module || at.is_some_and(|at| at < rank),
                        "{}: uses crate::{used}, not a layer before `{module}`",
                        f.display()
                    );
                }
            }
        }
        let files = std::fs::read_dir(&src).unwrap().count();
        assert_eq!(
            files,
            LAYERS.len() + 1,
            "every module in LAYERS, and lib.rs"
        );
    }
}
