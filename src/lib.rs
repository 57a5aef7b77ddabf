//! `profibus`: a PROFIBUS-DP master and slave stack.
//!
//! This facade re-exports the layered crates of the workspace:
//!
//! - [`fdl`] (`profibus-fdl`): layer 2 — telegrams, FCS, streaming codec, bus
//!   timing, stations (token ring, requester, responder) and transports.
//! - [`dp`] (`profibus-dp`): layer 7 of DP — services, configuration,
//!   parameter and diagnosis types, the DP master and slave cores, GSD files.
//! - [`devices`] (`profibus-devices`): one module per emulated product,
//!   with slave emulation and master-side helpers.
//!
//! The command line tool `dpctl` (crate `crates/cli`) is built on top of
//! these. The end-to-end tests in this package's `tests/` drive real `dpctl`
//! processes.

pub use profibus_devices as devices;
pub use profibus_dp as dp;
pub use profibus_fdl as fdl;
