//! The `rfid` profile: `dpctl slave --device rfid [--tags FILE.toml]`,
//! `device = "rfid"` in a bus file.

use super::tags::TagField;
use super::{Rfid, CFG, IDENT, PAYLOAD_MAX};
use crate::channels::{ChannelMap, ChannelType, Direction};
use crate::profile::{ControlInbox, Profile, ProfileError};
use crate::BoxedDevice;
use profibus_dp::config::gsd::Gsd;
use profibus_dp::config::layout::Capabilities;
use serde::Deserialize;
use std::path::PathBuf;

/// The options of the `rfid` profile.
#[derive(Debug, Default, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Options {
    /// The tags file ([`super::tags`]): the tags, which one is in the
    /// field, the reader's timing. The program running the slave rewrites
    /// it when the field changes ([`Profile::state_file`]). Default: no
    /// tags, default timing, nothing kept.
    pub tags: Option<PathBuf>,
    /// The reader's own command set (TOML, [`super::custom`]): commands,
    /// answers, delays. Default: `VER` (the manual's) and the modelled
    /// GT, RD, WD, TOR.
    pub commands: Option<PathBuf>,
}

/// The reader with its antenna field.
#[derive(Debug)]
pub struct RfidProfile {
    options: Options,
    commands: Option<super::custom::CommandSet>,
    field: TagField,
    gsd: Gsd,
}

impl RfidProfile {
    /// The antenna field the reader starts with.
    pub fn field(&self) -> &TagField {
        &self.field
    }
}

impl Profile for RfidProfile {
    type Options = Options;
    const NAME: &'static str = "rfid";
    const SUMMARY: &'static str = "AEG ID RFID reader ARE I2 / K1 PFB (ident 0x0DC4, ours): 16-byte handshake carrying reader commands (VER from the manual; GT, RD, WD, TOR modelled)";

    /// The reader's 16-byte command handshake.
    fn capabilities(_cfg: &[u8]) -> Capabilities {
        Capabilities::RFID
    }
    const OPTIONS_HELP: &'static str = "--tags FILE.toml (tags with UID and memory, which one is in the field, \
the reader's timing; rewritten when a tag's memory changes or a tag enters or leaves; default: no tags), \
--device-opt commands=FILE.toml (the reader's own command set: commands, answers, delays), \
--control SOCKET|FILE|- (commands: enter UID, leave, tags, status); bus file: tags, commands";
    const PATH_OPTIONS: &'static [&'static str] = &["tags", "commands"];
    const IDENT: Option<u16> = Some(IDENT);

    fn configure(options: Options, _address: Option<u8>) -> Result<Self, ProfileError> {
        let field = match &options.tags {
            Some(path) => {
                let text = crate::profile::read_option_file(path)?;
                TagField::parse(&text).map_err(|e| ProfileError::Table {
                    path: path.clone(),
                    message: e.to_string(),
                })?
            }
            None => TagField::new(),
        };
        let commands = match &options.commands {
            Some(path) => Some(crate::profile::read_table(
                path,
                super::custom::CommandSet::parse,
            )?),
            None => None,
        };
        Ok(RfidProfile {
            options,
            commands,
            field,
            gsd: crate::gsd_files::parse(super::GSD).expect("AEGI0DC4.GSD parses"),
        })
    }

    fn gsd(&self) -> &Gsd {
        &self.gsd
    }

    fn gsd_file(&self) -> Vec<u8> {
        super::GSD.to_vec()
    }

    fn modules(&self) -> Vec<String> {
        self.gsd
            .modules
            .iter()
            .filter(|m| m.cfg == CFG)
            .map(|m| m.name.clone())
            .collect()
    }

    fn state_file(&self) -> Option<PathBuf> {
        self.options.tags.clone()
    }

    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError> {
        let mut dev = Rfid::new(self.field.clone()).with_state_events(self.options.tags.is_some());
        if let Some(set) = &self.commands {
            dev = dev.with_commands(set.clone());
        }
        if let Some(inbox) = control {
            dev = dev.with_inbox(inbox);
        }
        Ok(Box::new(dev))
    }

    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError> {
        if cfg != CFG {
            return Err(ProfileError::Config(format!(
                "the reader has the one module 3F, not {}",
                profibus_fdl::wire::Hex(cfg)
            )));
        }
        let mut m = ChannelMap::new();
        m.push("status", Direction::Input, 0, ChannelType::U8);
        m.push(
            "data_flag",
            Direction::Input,
            0,
            ChannelType::Bool { bit: 3 },
        );
        m.push("receive_ack", Direction::Input, 1, ChannelType::U8);
        m.push("length", Direction::Input, 2, ChannelType::U8);
        m.push("receive_request", Direction::Output, 0, ChannelType::U8);
        m.push("send_job", Direction::Output, 1, ChannelType::U8);
        m.push("length", Direction::Output, 2, ChannelType::U8);
        for dir in [Direction::Input, Direction::Output] {
            for i in 0..PAYLOAD_MAX {
                m.push(format!("payload{}", i + 1), dir, 3 + i, ChannelType::U8);
            }
        }
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DeviceOptions;

    #[test]
    fn registry_gsd_and_channels() {
        let entry = crate::profile("rfid").unwrap();
        let p = entry.configure(&DeviceOptions::new(), Some(9)).unwrap();
        assert_eq!(p.chk_cfg().unwrap(), CFG);
        assert_eq!(p.user_prm_data().unwrap(), Vec::<u8>::new());
        assert_eq!(p.gsd().ident_number, IDENT);
        assert_eq!(p.state_file(), None);
        let ch = p.channels(&CFG).unwrap();
        assert_eq!(ch.of(Direction::Input).count(), 4 + 13);
        assert_eq!(ch.of(Direction::Output).count(), 3 + 13);
        let inputs = [0x08, 4, 10, b'P', 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0];
        let flag = ch.find(Direction::Input, "data_flag").unwrap();
        assert_eq!(flag.read(&inputs), Some(crate::channels::Value::Bool(true)));
        assert!(p.channels(&[0x2F, 0x1F]).is_err());
        let mut o = DeviceOptions::new();
        o.set_pair("tags=/nonexistent/tags.toml").unwrap();
        assert!(matches!(
            entry.configure(&o, None),
            Err(ProfileError::File { .. })
        ));
        let mut o = DeviceOptions::new();
        o.set_pair("speed=3").unwrap();
        assert!(matches!(
            entry.configure(&o, None),
            Err(ProfileError::UnknownOption { .. })
        ));
    }
}
