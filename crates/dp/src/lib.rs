//! `profibus-dp`: DP services (layer 7 of PROFIBUS-DP) on top of
//! `profibus-fdl`.
//!
//! The path names the layer:
//!
//! - [`pdu`]: the data units of the DP services and their decoding —
//!   SAPs, Set_Prm, Chk_Cfg identifiers, Slave_Diag, Global_Control,
//!   DP-V1, a telegram's DP layer decoded and described.
//! - the protocol cores, sans-IO (events and time in; bytes, deadline and
//!   events out):
//!   - [`master`]: the DP master core (start-up sequence, poll cycle,
//!     Global_Control, class-2 services, DP-V1 read/write), the
//!     application of an FDL active station.
//!   - [`slave`]: the DP slave core (state machine, every slave service)
//!     and the [`slave::Device`] trait device profiles implement.
//!   - [`monitor`]: a passive observer of another master's traffic: every
//!     slave's state, data, diagnosis, cycle times, retries and errors,
//!     and the masters in the token ring (`dpctl monitor`).
//!   - [`scan`]: the live-list scanner behind `dpctl scan`.
//! - [`fms`]: PROFIBUS-FMS PDUs (the BK3000's DP/FMS mixed mode).
//! - [`config`]: configuration files — GSD files, the TOML bus file of a
//!   master, and the helpers they share (file reading, closest names).

#![forbid(unsafe_code)]

pub mod class2;
pub mod config;
pub mod fms;
pub mod master;
pub mod monitor;
pub mod pdu;
pub mod scan;
pub mod slave;
