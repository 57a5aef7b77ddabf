//! The data units of the DP services (IEC 61158-6-3 / EN 50170 part 3):
//! what DP carries inside an FDL telegram, as typed values with `parse`
//! and `emit`, and a telegram's DP layer decoded for people and scripts.
//!
//! - [`sap`]: the service access points of the DP services.
//! - [`prm`]: the Set_Prm data unit.
//! - [`cfg`](mod@cfg): configuration identifiers (Chk_Cfg / Get_Cfg / GSD modules)
//!   decoded into I/O lengths.
//! - [`diag`]: Slave_Diag, the station status bytes and extended
//!   diagnosis blocks, with words for people.
//! - [`control`]: Global_Control and Set_Slave_Add.
//! - [`dpv1`]: DP-V1 class-1 read/write/alarm PDUs and error decoding.
//! - [`c2`]: DP-V1 class-2 (MSAC_C2) connection PDUs: Initiate, RM,
//!   Read/Write/Data_Transport, Idle, Abort.
//! - [`alarm`]: DP-V1 alarm and status blocks in Slave_Diag, Alarm_Mode
//!   and the alarm enables of Set_Prm.
//! - [`im`]: I&M0..I&M4 records and the call header on index 255.
//! - [`decode`]: the DP layer of a telegram decoded (service and data
//!   unit; responses read by the request they answer): `dpctl sniff --json`.
//! - [`describe`]: telegrams described for people and scripts
//!   ([`describe::TelegramSummary`]: `dpctl decode`, `dpctl sniff`).

pub mod alarm;
pub mod c2;
pub mod cfg;
pub mod control;
pub mod decode;
pub mod describe;
pub mod diag;
pub mod dpv1;
pub mod im;
pub mod prm;
pub mod sap;
