//! The `rfid` entry of the profile registry: `dpctl slave --device rfid`.

use super::tags::TagField;
use super::Rfid;
use crate::{BoxedDevice, Profile, ProfileOptions};
use std::path::Path;

/// The registry entry.
pub const PROFILE: Profile = Profile {
    name: "rfid",
    summary: "AEG ID RFID reader ARE I2 / K1 PFB (ident 0x0DC4): 16-byte handshake carrying reader commands (VER, GT, RD, WD, TOR)",
    options_help: "--tags FILE.toml (tags with UID and memory, which one is in the field, the reader's timing; \
rewritten when a tag's memory changes or a tag enters or leaves; default: no tags), \
--control FILE|- (commands: enter UID, leave, tags, status)",
    build,
};

fn build(opts: &ProfileOptions) -> Result<BoxedDevice, String> {
    let mut dev = match opts.get("tags") {
        Some(path) => Rfid::from_tags_file(Path::new(path))?,
        None => Rfid::new(TagField::new()),
    };
    if let Some(inbox) = &opts.control {
        dev = dev.with_inbox(inbox.clone());
    }
    Ok(Box::new(dev))
}
