//! `profibus-dp`: DP services (layer 7 of PROFIBUS-DP) on top of
//! `profibus-fdl`.
//!
//! - [`busfile`]: the TOML bus file of a master, built on GSD files.
//! - [`sap`]: the service access points of the DP services.
//! - [`cfg`]: configuration identifiers (Chk_Cfg / Get_Cfg / GSD modules)
//!   decoded into I/O lengths.
//! - [`prm`]: the Set_Prm data unit.
//! - [`decode`]: the DP layer of a telegram decoded (service and data
//!   unit; responses read by the request they answer): `dpctl sniff --json`.
//! - [`describe`]: telegrams described for people and scripts
//!   ([`describe::TelegramSummary`]: `dpctl decode`, `dpctl sniff`).
//! - [`diag`]: Slave_Diag, the station status bytes and extended
//!   diagnosis blocks, with words for people.
//! - [`control`]: Global_Control and Set_Slave_Add.
//! - [`dpv1`]: DP-V1 class-1 read/write/alarm PDUs and error decoding.
//! - [`master`]: the DP master core (start-up sequence, poll cycle,
//!   Global_Control, class-2 services, DP-V1 read/write), the application
//!   of an FDL active station.
//! - [`monitor`]: a passive observer of another master's traffic: every
//!   slave's state, data, diagnosis, cycle times, retries and errors, and
//!   the masters in the token ring (`dpctl monitor`).
//! - [`scan`]: the live-list scanner behind `dpctl scan`.
//! - [`names`]: the closest valid names to a misspelt one ("did you
//!   mean …?") and the keys of a serde struct.
//! - [`gsd`]: GSD files: parser (strict and lenient), typed model,
//!   module selection → Chk_Cfg / User_Prm_Data, writer.
//! - [`slave`]: the DP slave core (state machine, every slave service)
//!   and the [`slave::Device`] trait device profiles implement.

#![forbid(unsafe_code)]

pub mod busfile;
pub mod cfg;
pub mod control;
pub mod decode;
pub mod describe;
pub mod diag;
pub mod dpv1;
pub mod file;
pub mod gsd;
pub mod master;
pub mod monitor;
pub mod names;
pub mod prm;
pub mod sap;
pub mod scan;
pub mod slave;
