//! `profibus-dp`: DP services (layer 7 of PROFIBUS-DP) on top of
//! `profibus-fdl`.
//!
//! - [`sap`]: the service access points of the DP services.
//! - [`cfg`]: configuration identifiers (Chk_Cfg / Get_Cfg / GSD modules)
//!   decoded into I/O lengths.

pub mod cfg;
pub mod sap;
