//! `profibus-devices`: device profiles: slave emulations of specific
//! PROFIBUS-DP products (and master-side helpers for them), plus the
//! [`generic`] device any GSD file describes.
//!
//! Every profile implements [`profibus_dp::slave::Device`] and is listed
//! in [`PROFILES`], which `dpctl slave --list-devices` prints and
//! `dpctl slave --device NAME` builds from.

pub mod bk3000;
pub mod bm4;
pub mod generic;
pub mod gsd_files;
pub mod omega;
pub mod pkw;

use profibus_dp::slave::Device;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

/// A device as `dpctl slave` runs it.
pub type BoxedDevice = Box<dyn Device + Send>;

/// Options of a device profile from the command line
/// (`--device-opt KEY=VALUE`, repeatable).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ProfileOptions {
    /// The options in the order given.
    pub options: Vec<(String, String)>,
    /// Where control commands for the device arrive (e.g. `dpctl slave
    /// --control -`: lines from stdin), for profiles that take them.
    pub control: Option<ControlInbox>,
}

/// Control commands (lines of text) for a running device, e.g. a user
/// diagnosis the emulated PLC sends. The command line puts lines in; the
/// device takes them out while it runs. Clones share the queue.
#[derive(Debug, Clone, Default)]
pub struct ControlInbox(Arc<Mutex<VecDeque<String>>>);

impl ControlInbox {
    /// An empty inbox.
    pub fn new() -> ControlInbox {
        ControlInbox::default()
    }

    /// Queue a command line.
    pub fn push(&self, line: impl Into<String>) {
        if let Ok(mut q) = self.0.lock() {
            q.push_back(line.into());
        }
    }

    /// The oldest queued line.
    pub fn take(&self) -> Option<String> {
        self.0.lock().ok()?.pop_front()
    }
}

impl PartialEq for ControlInbox {
    fn eq(&self, other: &ControlInbox) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl Eq for ControlInbox {}

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
pub const PROFILES: &[Profile] = &[bm4::profile::PROFILE, omega::profile::PROFILE];

/// The station address a profile chooses itself from its options (the
/// BM4-O-PRO-01's us_DEVICE and rotary switch, a stored Set_Slave_Add
/// address), overriding the command line's `--addr`; `Ok(None)` when the
/// profile takes `--addr` as it is.
pub fn profile_address(name: &str, opts: &ProfileOptions) -> Result<Option<u8>, String> {
    if name.eq_ignore_ascii_case(bm4::profile::PROFILE.name) {
        bm4::profile::address(opts).map(Some)
    } else if name.eq_ignore_ascii_case(omega::profile::PROFILE.name) {
        omega::profile::address(opts)
    } else {
        Ok(None)
    }
}

/// The profile named `name`.
pub fn profile(name: &str) -> Option<&'static Profile> {
    PROFILES.iter().find(|p| p.name.eq_ignore_ascii_case(name))
}
