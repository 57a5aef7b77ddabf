//! Configuration files: what a master or slave is told before it runs.
//!
//! - [`gsd`]: GSD files: parser (strict and lenient), typed model,
//!   module selection → Chk_Cfg / User_Prm_Data, writer.
//! - [`busfile`]: the TOML bus file of a master, built on GSD files.
//! - [`discover`]: from a slave's Get_Cfg bytes back to the GSD modules
//!   that give them (scan to bus file).
//! - [`library`]: the GSD files a slave's file is found in by ident
//!   number (folders, built-in files, the user library).
//! - [`commission`]: from a scan's Slave_Diag and Get_Cfg answers to a
//!   bus file (`dpctl scan --write-config`).
//! - [`file`](mod@file): reading an input file (bus file, profile table, script)
//!   with a size limit.
//! - [`layout`]: a configured slave's modules with their byte spans and
//!   its capabilities, worked out once from the bus file.
//! - [`names`]: the closest valid names to a misspelt one ("did you
//!   mean …?") and the keys of a serde struct.

pub mod busfile;
pub mod commission;
pub mod discover;
pub mod file;
pub mod gsd;
pub mod layout;
pub mod library;
pub mod names;
