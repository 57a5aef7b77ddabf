//! Configuration files: what a master or slave is told before it runs.
//!
//! - [`gsd`]: GSD files: parser (strict and lenient), typed model,
//!   module selection → Chk_Cfg / User_Prm_Data, writer.
//! - [`busfile`]: the TOML bus file of a master, built on GSD files.
//! - [`discover`]: from a slave's Get_Cfg bytes back to the GSD modules
//!   that give them (scan to bus file).
//! - [`file`](mod@file): reading an input file (bus file, profile table, script)
//!   with a size limit.
//! - [`layout`]: a configured slave's modules with their byte spans and
//!   its capabilities, worked out once from the bus file.
//! - [`names`]: the closest valid names to a misspelt one ("did you
//!   mean …?") and the keys of a serde struct.

pub mod busfile;
pub mod discover;
pub mod file;
pub mod gsd;
pub mod layout;
pub mod names;
