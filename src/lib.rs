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
//! these. This package's `tests/` run the crates together in process (the
//! simulated bus, hostile inputs, allocation counts); the end-to-end tests
//! that drive real `dpctl` processes live in `crates/cli/tests/`.

pub use profibus_devices as devices;
pub use profibus_dp as dp;
pub use profibus_fdl as fdl;
pub use profibus_io as io;
