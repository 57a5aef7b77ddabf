//! The master side of a BK3000: from a terminal list, the Chk_Cfg and
//! User_Prm_Data a master sends, and the coupler's process image as named
//! channels (terminal position, type, channel, value with unit where the
//! terminal's range is known), both ways.

use super::catalogue::Role;
use super::image::{Dir, Entry, Image, Owner, Strip, StripError};
use super::prm::{CouplerDiag, UserPrm, USER_PRM_LEN};
use std::fmt;

/// A BK3000 as a master sees it: its strip, its settings, its image.
#[derive(Debug, Clone, PartialEq)]
pub struct Bk3000Master {
    strip: Strip,
    prm: UserPrm,
    image: Image,
}

/// One channel's value.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelValue {
    /// `3.KL3102.1`, `3.KL3102.1.status`, `plc.data`, `kbus.counter`.
    pub name: String,
    /// Terminal position (1-based), `None` for the coupler's own fields.
    pub position: Option<usize>,
    /// Terminal type (`BK3000` for the coupler's fields).
    pub terminal: &'static str,
    /// Channel 1.. (0 for the coupler's fields).
    pub channel: u8,
    /// What the field carries.
    pub role: Role,
    /// Input or output.
    pub dir: Dir,
    /// The raw value (bit, byte, signed word, unsigned double word).
    pub raw: i64,
    /// The value in `unit` (or the raw value).
    pub value: f64,
    /// Unit of `value`, where the terminal's range is known.
    pub unit: Option<&'static str>,
}

impl fmt::Display for ChannelValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.unit {
            Some(u) => write!(f, "{} = {:.3} {u}", self.name, self.value),
            None if self.role == Role::Value => write!(f, "{} = {}", self.name, self.raw),
            None => write!(f, "{} = 0x{:02X}", self.name, self.raw as u8),
        }
    }
}

/// Why an output cannot be written by name.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChannelError {
    /// No channel of that name.
    #[error("no channel `{0}` on this BK3000 (names look like 2.KL2134.1 or 2.1)")]
    Unknown(String),
    /// The channel is an input.
    #[error("channel `{0}` is an input")]
    NotOutput(String),
    /// The value does not fit.
    #[error("value {value} out of range for `{name}`")]
    Range {
        /// The channel.
        name: String,
        /// The value given.
        value: f64,
    },
}

impl Bk3000Master {
    /// A coupler with `strip` and settings `prm` (the terminals' mappings
    /// as the list gives them).
    pub fn new(strip: Strip, prm: UserPrm) -> Bk3000Master {
        let image = strip.default_image(super::image::Options {
            plc_interface: prm.plc_interface,
            cycle_counter: prm.cycle_counter,
        });
        Bk3000Master { strip, prm, image }
    }

    /// From terminal names (`["KL1104", "KL3102:complete", "KL9010"]`)
    /// with default settings.
    pub fn from_names<S: AsRef<str>>(names: &[S]) -> Result<Bk3000Master, StripError> {
        Ok(Bk3000Master::new(
            Strip::from_names(names)?,
            UserPrm::default(),
        ))
    }

    /// The strip.
    pub fn strip(&self) -> &Strip {
        &self.strip
    }

    /// The settings.
    pub fn user_prm(&self) -> UserPrm {
        self.prm
    }

    /// The Chk_Cfg bytes.
    pub fn chk_cfg(&self) -> &[u8] {
        &self.image.cfg
    }

    /// The User_Prm_Data bytes.
    pub fn user_prm_data(&self) -> [u8; USER_PRM_LEN] {
        self.prm.emit()
    }

    /// The process image.
    pub fn image(&self) -> &Image {
        &self.image
    }

    fn value(&self, e: &Entry, raw: i64) -> ChannelValue {
        let (position, scale) = match e.owner {
            Owner::Terminal(p) => (Some(p), Some(self.strip.slots()[p - 1].ty.scale)),
            _ => (None, None),
        };
        let scale = scale.filter(|_| e.role == Role::Value);
        ChannelValue {
            name: e.name.clone(),
            position,
            terminal: e.terminal,
            channel: e.channel,
            role: e.role,
            dir: e.dir,
            raw,
            value: scale.map_or(raw as f64, |s| s.to_engineering(raw)),
            unit: scale.and_then(|s| s.unit()),
        }
    }

    /// The channels of `data` (inputs or outputs as `dir` says), unused
    /// bytes left out.
    pub fn decode(&self, dir: Dir, data: &[u8]) -> Vec<ChannelValue> {
        self.image
            .entries
            .iter()
            .filter(|e| e.dir == dir && e.role != Role::Reserved)
            .map(|e| self.value(e, Image::get(e, data)))
            .collect()
    }

    /// Write output channel `name` (full or short name) with the value
    /// `value` in the channel's unit (digital 0/1; control bytes raw).
    pub fn encode(
        &self,
        name: &str,
        value: f64,
        outputs: &mut [u8],
    ) -> Result<ChannelValue, ChannelError> {
        let e = match self.image.find(name, Some(Dir::Out)) {
            Some(e) => e,
            None if self.image.find(name, Some(Dir::In)).is_some() => {
                return Err(ChannelError::NotOutput(name.to_string()))
            }
            None => return Err(ChannelError::Unknown(name.to_string())),
        };
        let raw = match e.owner {
            Owner::Terminal(p) if e.role == Role::Value => {
                let sc = self.strip.slots()[p - 1].ty.scale;
                let (lo, hi) = sc.range();
                if !(lo..=hi).contains(&value) {
                    return Err(ChannelError::Range {
                        name: e.name.clone(),
                        value,
                    });
                }
                sc.from_engineering(value)
            }
            _ => {
                if !(0.0..=255.0).contains(&value) {
                    return Err(ChannelError::Range {
                        name: e.name.clone(),
                        value,
                    });
                }
                value.round() as i64
            }
        };
        Image::put(e, outputs, raw);
        Ok(self.value(e, raw))
    }

    /// The coupler's manufacturer diagnosis (the Ext_Diag_Data from its
    /// length byte on) in words.
    pub fn describe_diag(ext_diag: &[u8]) -> Vec<String> {
        CouplerDiag::parse(ext_diag).map_or_else(Vec::new, |d| d.describe())
    }
}
