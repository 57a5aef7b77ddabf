//! PROFIBUS-DP to MQTT: a DP master's slaves as JSON topics on a broker.
//!
//! A library for gateway makers, used by `dpctl gateway`. The core,
//! [`Gateway`], is sans-IO: it reads a running [`DpMaster`] at a cycle
//! boundary and queues [`Publish`]es, and it turns messages into output
//! writes; [`MqttLink`] is the thin driver on the `rumqttc` client.
//!
//! # Topics (plain JSON mode)
//!
//! Under `<prefix>/<bus>/` (from the bus file's `[mqtt]` table, see
//! [`settings`]):
//!
//! | topic | retained | payload |
//! |---|---|---|
//! | `status` | yes | `{"state": "online", "ts", "slaves", "writable"}`; the last will sets `{"state": "offline"}` |
//! | `<addr>/state` | yes | `{"address", "name", "state", "ts", "cycle"}` (+ `"fault"` after a parameterisation/configuration fault) |
//! | `<addr>/inputs` | yes | `{"address", "hex", "values", "ts", "cycle"}`; `values` (named channels) for profiled slaves |
//! | `<addr>/outputs` | yes | the output image sent, same form |
//! | `<addr>/diag` | yes | `{"address", "hex", "text", "ts", "cycle"}`: the last diagnosis, decoded |
//! | `<addr>/outputs/set` | — | written by clients: see below |
//! | `<addr>/outputs/response` | no | `{"ok", "error"?, "correlation_id"?, "ts"}` |
//!
//! `ts` is the wall-clock time in ms since the Unix epoch, `cycle` the
//! master's poll cycle counter.
//!
//! # Writes
//!
//! A payload on `<addr>/outputs/set` is a bare hex string (the whole
//! output image), or a JSON object with `"hex"` (the whole image, exactly
//! the slave's output length) or `"channels"` (`{"name": value}` for a
//! profiled slave's named output channels), and optionally
//! `"correlation_id"` (repeated in the reply; MQTT 3.1.1 has no
//! correlation data of its own). Only slaves listed in `[mqtt] writable`
//! may be written. A write is checked as a whole and applied to the
//! slave's image at once between two polls, so one Data_Exchange carries
//! all of it; a malformed, unknown or unauthorised write changes nothing,
//! is logged, and gets `{"ok": false, "error": …}` on
//! `<addr>/outputs/response`.
//!
//! # Broker faults
//!
//! The bus keeps running while the broker is away. The link reconnects
//! with a growing pause; on every connection the status and every
//! retained topic are published again.
//!
//! [`DpMaster`]: profibus_dp::master::DpMaster

pub mod core;
pub mod link;
pub mod settings;
pub mod sim;
pub mod sparkplug;

pub use crate::core::{Gateway, Publish, SlaveInfo, Topics};
pub use link::{LinkEvent, MqttLink, Session};
pub use settings::{MqttSettings, PublishMode, SettingsError};
pub use sparkplug::{EdgeNode, SparkplugId};
