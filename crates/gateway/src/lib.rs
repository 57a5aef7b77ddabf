//! PROFIBUS-DP to MQTT: a DP master's slaves as JSON topics or a Sparkplug B edge node on a broker.
//!
//! A library for gateway makers, used by `dpctl gateway`. The core,
//! [`Gateway`], is sans-IO: it reads a running [`DpMaster`] at a cycle
//! boundary and queues [`Publish`]es, and it turns messages into output
//! writes; [`MqttLink`] is the thin driver on the `rumqttc` client.
//!
//! # Sparkplug B mode
//!
//! With `--sparkplug GROUP/EDGE` (or `sparkplug` in `[mqtt]`) the
//! master is a Sparkplug B edge node instead, [`EdgeNode`]: protobuf
//! payloads under `spBv1.0/…`, births and deaths, DCMD writes. Topics,
//! metrics, datatypes and what is not supported: [`sparkplug`]. Both
//! cores implement [`Session`], the interface the link and drivers use.
//!
//! # Topics (plain JSON mode)
//!
//! Under `<prefix>/<bus>/` (from the bus file's `[mqtt]` table, see
//! [`settings`]):
//!
//! | topic | retained | payload |
//! |---|---|---|
//! | `status` | yes | `{"state": "online", "master", "ts", "slaves", "writable"}` (+ `"outputs_timeout"` after an outage that reached it); `master` is the master's operating state (`operate`, `clear`, `stop`), republished at once when it changes; the last will sets `{"state": "offline"}` |
//! | `<addr>/state` | yes | `{"address", "name", "state", "ts", "cycle"}` (+ `"fault"` after a parameterisation/configuration fault); published in the step after any change (slave lost, back) |
//! | `<addr>/inputs` | yes | `{"address", "hex", "values", "units", "ts", "cycle"}`; `values` (`{"name": value}`, named channels) for slaves with a device profile or GSD modules, scaled channels in their unit; `units` (`{"name": "V"}`) only when some channel is scaled |
//! | `<addr>/outputs` | yes | the output image sent, same form |
//! | `<addr>/diag` | yes | `{"address", "hex", "station_status", "master", "ident_number", "text", "ts", "cycle"}`: the last Slave_Diag, published in the step after it changes; `station_status` (the status bits in words, `"OK"` when none is set), `master` (the parameterising master, `null` for none) and `ident_number` when it has its 6 standard bytes; `text` the whole diagnosis in words (GSD texts where known) |
//! | `<addr>/outputs/set`, `<addr>/dpv1/request`, `<addr>/pkw/request`, `<addr>/rfid/request` | — | requests from clients: see below |
//! | `<addr>/outputs/response`, `…/dpv1/response`, `…/pkw/response`, `…/rfid/response` | no | `{"ok", "error"?, "id"?, "ts", …}`: the answers |
//!
//! `ts` is the wall-clock time in ms since the Unix epoch, `cycle` the
//! master's poll cycle counter. The payloads are the typed values of
//! [`payload`].
//!
//! # Requests and answers
//!
//! The client is MQTT 3.1.1 (one link for both modes; rumqttc's MQTT 5
//! client is a separate API), so a request carries its correlation in
//! the payload: every request is a JSON object that may have `"id"` (any
//! JSON value, repeated in the answer) and `"reply_to"` (a topic without
//! wildcards for the answer; default: the service's response topic of the
//! slave). Each request gets exactly one answer: `{"ok": true, …}` with
//! the result, or `{"ok": false, "error": "…"}`; a malformed, unknown or
//! unauthorised request changes nothing and is logged.
//!
//! | topic | payload | answer fields |
//! |---|---|---|
//! | `outputs/set` | a bare hex string (the whole image), `{"hex"}` (the whole image, exactly the output length) or `{"channels": {"name": value}}` (named output channels of a profiled slave) | — |
//! | `dpv1/request` | `{"op": "read", "slot", "index", "length"?}` (length 1..=240, default 240) or `{"op": "write", "slot", "index", "hex"}` | `"hex"` (read) |
//! | `pkw/request` | `{"op": "read", "pnu", "index"?}`, `{"op": "write", "pnu", "value", "index"?, "dword"?}` (a word unless the value needs a double word or `"dword": true`; negative values two's complement) or `{"op": "describe", "pnu", "element"}`; `"pnu"` is a number 0..=2047 or the name the device gives the parameter (a BM4 variable module of its GSD, e.g. `"di_MyReadVar3"`) | `"value"`, `"dword"`, `"request"`, `"response"` (the PKW words, hex) |
//! | `rfid/request` | `{"command": "RD 00 01"}` (one command line) | `"answer"` (text), `"hex"` |
//!
//! Permissions come from `[mqtt] writable` (see [`settings`]): output
//! writes, DP-V1 writes, PKW writes and RFID commands need the slave
//! listed; a slave listed with `channels` takes only writes of those
//! channels. Reads are open for every configured slave. DP-V1 requests
//! need a DP-V1 slave, PKW requests a slave with a PKW channel (BM4,
//! Omega), RFID requests a reader; they run through the master's MSAC_C1
//! jobs and the device crate's `PkwClient` and `RfidClient`, one PKW or
//! RFID job per slave at a time, each within `[mqtt] job_timeout_ms`.
//!
//! Queues are bounded per slave: at most [`request::QUEUE_LIMIT`] (8) output
//! writes and DP-V1 requests wait for the next cycle boundary, and 8 PKW
//! or RFID jobs for the slave's client; one more is answered
//! `{"ok": false, "error": "slave N: too many requests waiting (at most 8)"}`
//! on its response topic and changes nothing.
//!
//! An output write is checked as a whole and applied to the slave's
//! image at once between two polls, so one Data_Exchange carries all of
//! it. (A PKW or RFID job writes its words into the same image: a whole
//! image written during such a job overwrites them.)
//!
//! # Connection
//!
//! `mqtt://HOST[:PORT]` is plain TCP, `mqtts://HOST[:PORT]` TLS with
//! rustls (CA certificates from `[mqtt] ca_file`, else the system's); a
//! user name and a password from a file or an environment variable (see
//! [`settings`]); [`Connection::from_settings`] reads them.
//!
//! # Broker faults
//!
//! The bus keeps running while the broker is away. The link reconnects
//! with a growing pause (100 ms doubling to 5 s); on every connection the
//! status and every retained topic are published again. The link logs
//! one line each for its start, the connection, a loss and the
//! reconnection, with the broker's URL ([`link`]). After
//! `[mqtt] outputs_timeout_ms` without a broker the outputs go to
//! `[mqtt] safe_state` once (default `keep`: the last values stay), which
//! is logged and, once the broker is back, reported in the status.
//!
//! # Modules
//!
//! In layers: each module uses only the modules before it in this list
//! (the test `layers` checks it), so the cores know no connection and
//! nothing below the driver knows the simulated plant.
//!
//! 1. [`field`]: a field parsed leniently, checked afterwards.
//! 2. [`topics`]: the topic names, plain and Sparkplug B.
//! 3. [`slave`]: what the gateway knows of a configured slave.
//! 4. [`settings`]: the `[mqtt]` table.
//! 5. [`request`]: requests from clients, parsed from their payloads.
//! 6. [`payload`]: the JSON payloads the plain mode publishes.
//! 7. [`session`]: the [`Session`] interface of the cores, [`Publish`].
//! 8. [`outage`]: the outputs while the broker is away.
//! 9. [`json`]: the plain JSON core, [`Gateway`].
//! 10. [`sparkplug`]: the Sparkplug B core, [`EdgeNode`].
//! 11. [`link`]: the MQTT connection on `rumqttc` and tokio, [`MqttLink`].
//! 12. [`sim`]: the simulated plant of `dpctl gateway --sim`.
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
//!      [[slave]]\naddress = 25\ndevice = \"omega\"\n\
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

pub use json::Gateway;
pub use link::{Connection, ConnectionError, LinkEvent, MqttLink};
pub use session::{LinkSetup, Publish, Session};
pub use settings::{Broker, MqttSettings, PublishMode, SafeState, SettingsError, WriteAccess};
pub use slave::{slave_infos, SlaveInfo, SlaveInfoError};
pub use sparkplug::EdgeNode;
pub use topics::{Service, SparkplugId, Topics};

/// The module order of the crate documentation's layers.
#[cfg(test)]
const LAYERS: [&str; 12] = [
    "field",
    "topics",
    "slave",
    "settings",
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
