//! `profibus-dp`: DP services (layer 7 of PROFIBUS-DP) on top of
//! `profibus-fdl`.
//!
//! - [`sap`]: the service access points of the DP services.

pub mod sap;
