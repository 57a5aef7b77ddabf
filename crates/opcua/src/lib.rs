//! PROFIBUS-DP over OPC UA: a DP master's slaves as an address space
//! that SCADA and MES clients browse, subscribe to and write, beside (or
//! instead of) the MQTT gateway of `profibus-gateway`. Used by `dpctl
//! gateway --opcua`.
//!
//! The server runs on `async-opcua` (pure-Rust cryptography, no
//! OpenSSL). The crate stands apart from `profibus-gateway` so that
//! only programs with an OPC UA server pay for that library's ~100
//! extra crates.
//!
//! - [`settings`]: the `[opcua]` table and the users file.
//! - [`space`]: the nodes under `Objects/PROFIBUS/<bus>/` and the values
//!   sampled from the master at each cycle boundary.
//! - [`face`]: [`Face`], the gateway core ([`profibus_gateway::Gateway`])
//!   with this face: writes and method calls become the core's requests,
//!   with the same checks and permissions as MQTT's.
//! - [`server`]: [`OpcuaServer`], endpoints, security, users, callbacks.
//! - [`events`]: DP-V1 alarms as events of `DpAlarmEventType`.
//! - [`identity`]: I&M0 of DP-V1 slaves in their identity properties.
//! - [`sim`]: the simulated plant of `dpctl gateway --sim --opcua`.
//!
//! The address space, security and the certificate's path are
//! described in `docs/opcua.md` in the repository.

pub mod events;
pub mod face;
pub mod identity;
pub mod server;
pub mod settings;
pub mod sim;
pub mod space;

pub use face::Face;
pub use server::{OpcuaServer, ServerError};
pub use settings::{OpcuaSettings, Security, SettingsError};
pub use space::NAMESPACE_URI;
