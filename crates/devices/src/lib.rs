//! `profibus-devices`: device profiles: slave emulations of specific
//! PROFIBUS-DP products (and master-side helpers for them), plus the
//! [`generic`] device any GSD file describes.
//!
//! Every profile implements [`profibus_dp::slave::Device`] and is listed
//! in [`PROFILES`], which `dpctl slave --list-devices` prints and
//! `dpctl slave --device NAME` builds from.

pub mod generic;
pub mod gsd_files;

use profibus_dp::slave::Device;

/// A device as `dpctl slave` runs it.
pub type BoxedDevice = Box<dyn Device + Send>;

/// Options of a device profile from the command line
/// (`--device-opt KEY=VALUE`, repeatable).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ProfileOptions {
    /// The options in the order given.
    pub options: Vec<(String, String)>,
}

impl ProfileOptions {
    /// The value of `key`, if given (the last one wins).
    pub fn get(&self, key: &str) -> Option<&str> {
        self.options
            .iter()
            .rev()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// A device profile: a named product the slave can emulate.
#[derive(Debug, Clone, Copy)]
pub struct Profile {
    /// The name given to `--device`.
    pub name: &'static str,
    /// One line about the product.
    pub summary: &'static str,
    /// The options it takes, in words (for `--list-devices`).
    pub options_help: &'static str,
    /// Build the device; `Err` says what is wrong with the options.
    pub build: fn(&ProfileOptions) -> Result<BoxedDevice, String>,
}

/// Every device profile (the device issues add theirs here).
pub const PROFILES: &[Profile] = &[];

/// The profile named `name`.
pub fn profile(name: &str) -> Option<&'static Profile> {
    PROFILES.iter().find(|p| p.name.eq_ignore_ascii_case(name))
}
