//! The `bk3000` profile: `dpctl slave --device bk3000 --terminals
//! KL1104,KL2134,KL3102,KL4002,KL9010`, `device = "bk3000"` with
//! `terminals = [...]` in a bus file.

use super::catalogue::Role;
use super::catalogue::TerminalType;
use super::image::{self, CfgReject, Dir, Image, Options as ImageOptions, Owner, Strip};
use super::{user, Bk3000, IDENT};
use crate::channels::{Channel, ChannelMap, ChannelType, Direction, Scale};
use crate::profile::{opt_int, ControlInbox, DeviceOptions, Profile, ProfileError};
use crate::BoxedDevice;
use profibus_dp::config::gsd::Gsd;
use serde::Deserialize;
use std::path::PathBuf;

/// A terminal list: `["KL1104", "KL2134"]` (bus file) or
/// `"KL1104,KL2134"` (command line).
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum TerminalList {
    /// One name per element.
    List(Vec<String>),
    /// Names separated by commas or blanks.
    Text(String),
}

/// The options of the `bk3000` profile.
#[derive(Debug, Default, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Options {
    /// The strip in plug order, end terminal last; a name may carry
    /// `:compact`, `:complete`, `:standard` or `:status`. Default:
    /// [`DEFAULT_STRIP`], the manual's appendix example.
    pub terminals: Option<TerminalList>,
    /// The strip from a file (one name per line or comma-separated, `#`
    /// comments).
    pub terminals_file: Option<PathBuf>,
    /// Rotary switch for the ones of the address (0..9).
    #[serde(deserialize_with = "opt_int")]
    pub switch_ones: Option<u8>,
    /// Rotary switch for the tens of the address (0..9).
    #[serde(deserialize_with = "opt_int")]
    pub switch_tens: Option<u8>,
    /// Table 70: the programmed configuration (hex bytes).
    pub programmed_cfg: Option<String>,
    /// Free placement in the programmed configuration (p. 51):
    /// `POS@IN/OUT, …` ([`image::Placement::parse_list`]); needs
    /// `programmed_cfg`.
    pub placement: Option<String>,
    /// Terminal types the catalogue lacks ([`super::user`]): a table of
    /// tables, `[slave.terminal_types.KL3404]` in a bus file.
    pub terminal_types: Option<toml::Table>,
    /// The same from a TOML file (`--device-opt terminal-types-file=FILE`).
    pub terminal_types_file: Option<PathBuf>,
    /// Delay the process data by the modelled K-bus cycle time (manual
    /// p. 23; [`Bk3000::with_kbus_timing`]).
    pub kbus_timing: bool,
    /// DP/FMS mode, table 0 register 16 (p. 66): `dp` (default), `mixed`
    /// (DP and FMS at once), `fms` (FMS only, the whole KBL); see
    /// docs/fms.md.
    pub fms: Option<String>,
}

/// A BK3000 with its strip.
#[derive(Debug)]
pub struct Bk3000Profile {
    strip: Strip,
    address: Option<u8>,
    programmed: Option<Vec<u8>>,
    placement: Vec<image::Placement>,
    kbus_timing: bool,
    fms: super::fms::FmsMode,
    gsd: Gsd,
}

impl Bk3000Profile {
    /// The strip.
    pub fn strip(&self) -> &Strip {
        &self.strip
    }
}

fn invalid(e: impl ToString) -> ProfileError {
    ProfileError::Invalid(e.to_string())
}

/// The strip without `terminals`: the manual's appendix example
/// ("Beispiel: Prozeßabbild im Buskoppler", p. 38-40, manual line 76-78),
/// digital and analog terminals in and out, a power feed and the end
/// terminal.
pub const DEFAULT_STRIP: &str = "KL1002,KL1002,KL1002,KL1002,KL1002,KL2012,KL2012,KL2012,KL3002,\
KL4002,KL4002,KL3002,KL9100,KL1002,KL1002,KL1002,KL2012,KL2012,KL4002,KL9010";

/// The terminal types the options describe (`terminal_types` and
/// `terminal_types_file`).
pub fn user_types(o: &Options) -> Result<Vec<&'static TerminalType>, ProfileError> {
    let mut out = vec![];
    if let Some(t) = &o.terminal_types {
        out.extend(user::parse_table(t).map_err(|e| ProfileError::BadOption {
            key: "terminal_types".into(),
            message: e.to_string(),
        })?);
    }
    if let Some(path) = &o.terminal_types_file {
        let text = crate::profile::read_option_file(path)?;
        out.extend(
            user::parse_text(&text).map_err(|message| ProfileError::Table {
                path: path.clone(),
                message,
            })?,
        );
    }
    Ok(out)
}

/// The strip the options name; [`DEFAULT_STRIP`] without `terminals`.
pub fn strip(o: &Options) -> Result<Strip, ProfileError> {
    let list = match (&o.terminals, &o.terminals_file) {
        (Some(_), Some(_)) => {
            return Err(invalid("give --terminals or a terminals file, not both"))
        }
        (Some(TerminalList::List(v)), None) => v.join(","),
        (Some(TerminalList::Text(t)), None) => t.clone(),
        (None, Some(path)) => crate::profile::read_option_file(path)?,
        (None, None) => DEFAULT_STRIP.to_string(),
    };
    let extra = user_types(o)?;
    let s = Strip::parse_with(&list, &extra).map_err(|e| match &o.terminals_file {
        Some(path) => ProfileError::Table {
            path: path.clone(),
            message: e.to_string(),
        },
        None => ProfileError::BadOption {
            key: "terminals".into(),
            message: e.to_string(),
        },
    })?;
    Ok(s)
}

/// The station address of the rotary switches (p. 31: upper switch =
/// ones, lower switch = tens), if either is given.
pub fn switch_address(o: &Options) -> Result<Option<u8>, ProfileError> {
    for (k, v) in [
        ("switch-ones", o.switch_ones),
        ("switch-tens", o.switch_tens),
    ] {
        if let Some(d) = v.filter(|d| *d > 9) {
            return Err(invalid(format!(
                "--{k} {d}: a decimal rotary switch is 0..9"
            )));
        }
    }
    Ok(match (o.switch_ones, o.switch_tens) {
        (None, None) => None,
        (ones, tens) => Some(tens.unwrap_or(0) * 10 + ones.unwrap_or(0)),
    })
}

fn parse_hex(s: &str) -> Result<Vec<u8>, ProfileError> {
    let bad = || invalid(format!("programmed-cfg `{s}` is not hex bytes"));
    let digits: String = s
        .split(|c: char| c.is_whitespace() || c == ',')
        .map(|t| t.trim_start_matches("0x").trim_start_matches("0X"))
        .collect();
    if digits.is_empty() || !digits.len().is_multiple_of(2) {
        return Err(bad());
    }
    (0..digits.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&digits[i..i + 2], 16).map_err(|_| bad()))
        .collect()
}

impl Profile for Bk3000Profile {
    type Options = Options;
    const NAME: &'static str = "bk3000";
    const SUMMARY: &'static str =
        "Beckhoff BK3000 PROFIBUS-DP bus coupler (ident 0xBECF) with a K-bus terminal strip";
    const OPTIONS_HELP: &'static str = "--terminals KL1104,KL2134,KL3102:complete,...,KL9010 (plug order, end terminal last; \
bus file: terminals = [...]) or --device-opt terminals-file=FILE (default: the manual's appendix example strip), \
--switch-ones N --switch-tens N (rotary switches, instead of --addr), \
--device-opt programmed-cfg=HEX (table 70), --device-opt placement=POS@IN/OUT,... (free placement in it), \
--device-opt terminal-types-file=FILE.toml (terminals the catalogue lacks; bus file: [slave.terminal_types.NAME]), \
--device-opt kbus-timing=true (process data delayed by the K-bus cycle time), \
--device-opt fms=dp|mixed|fms (DP/FMS mode, table 0 register 16: FMS server on the KBL's LSAPs), \
--control FILE|- (commands: status, outputs, set NAME VALUE, release NAME|all, pull N, plug N, run)";
    const PATH_OPTIONS: &'static [&'static str] = &["terminals_file", "terminal_types_file"];
    const IDENT: Option<u16> = Some(IDENT);

    fn configure(options: Options, _address: Option<u8>) -> Result<Self, ProfileError> {
        let strip = strip(&options)?;
        let address = switch_address(&options)?;
        let programmed = options
            .programmed_cfg
            .as_deref()
            .map(parse_hex)
            .transpose()?;
        let placement = match &options.placement {
            Some(text) => {
                image::Placement::parse_list(text).map_err(|message| ProfileError::BadOption {
                    key: "placement".into(),
                    message,
                })?
            }
            None => vec![],
        };
        match (&programmed, placement.is_empty()) {
            (None, false) => {
                return Err(invalid("placement needs programmed-cfg (table 70)"));
            }
            (Some(p), true) => {
                Bk3000::new(strip.clone())
                    .with_programmed_cfg(p.clone())
                    .map_err(invalid)?;
            }
            (Some(p), false) => {
                Bk3000::new(strip.clone())
                    .with_placement(p.clone(), placement.clone())
                    .map_err(|message| ProfileError::BadOption {
                        key: "placement".into(),
                        message,
                    })?;
            }
            (None, true) => {}
        }
        let fms = match options.fms.as_deref() {
            None | Some("dp") => super::fms::FmsMode::DpOnly,
            Some("mixed") => super::fms::FmsMode::Mixed,
            Some("fms") => super::fms::FmsMode::FmsOnly,
            Some(other) => {
                return Err(ProfileError::BadOption {
                    key: "fms".into(),
                    message: format!("{other:?} is no FMS mode; use dp, mixed or fms"),
                })
            }
        };
        Ok(Bk3000Profile {
            strip,
            address,
            programmed,
            placement,
            kbus_timing: options.kbus_timing,
            fms,
            gsd: crate::gsd_files::parse(crate::gsd_files::BK30BECF).expect("BK30BECF.GSD parses"),
        })
    }

    fn gsd(&self) -> &Gsd {
        &self.gsd
    }

    fn gsd_file(&self) -> Vec<u8> {
        crate::gsd_files::BK30BECF.to_vec()
    }

    fn modules(&self) -> Vec<String> {
        gsd_modules(&self.gsd, &self.strip)
    }

    fn address(&self) -> Option<u8> {
        self.address
    }

    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError> {
        let mut dev = Bk3000::new(self.strip.clone())
            .with_kbus_timing(self.kbus_timing)
            .with_fms_mode(self.fms);
        match &self.programmed {
            Some(p) if !self.placement.is_empty() => {
                dev = dev
                    .with_placement(p.clone(), self.placement.clone())
                    .map_err(invalid)?;
            }
            Some(p) => dev = dev.with_programmed_cfg(p.clone()).map_err(invalid)?,
            None => {}
        }
        if let Some(inbox) = control {
            dev = dev.with_inbox(inbox);
        }
        Ok(Box::new(dev))
    }

    /// The strips of [`super::commission::strips_for_cfg`].
    fn options_for_cfg(cfg: &[u8]) -> Vec<DeviceOptions> {
        super::commission::strips_for_cfg(cfg)
            .into_iter()
            .map(|strip| {
                let mut o = DeviceOptions::new();
                o.set("terminals", strip);
                o
            })
            .collect()
    }

    fn commission_notes(_cfg: &[u8], options: &DeviceOptions) -> Vec<String> {
        let names: Vec<String> = options
            .get("terminals")
            .and_then(|v| v.as_array())
            .map(|a| {
                a.iter()
                    .filter_map(|t| t.as_str().map(str::to_string))
                    .collect()
            })
            .unwrap_or_default();
        super::commission::notes(&names)
    }

    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError> {
        let img = image_of(&self.strip, cfg).map_err(|e| ProfileError::Config(e.to_string()))?;
        Ok(channel_map(&self.strip, &img))
    }
}

/// The image a configuration gives on `strip`: the coupler functions
/// (PLC interface, cycle counter) as the configuration shows them.
pub fn image_of(strip: &Strip, cfg: &[u8]) -> Result<Image, CfgReject> {
    let mut first = None;
    for (plc_interface, cycle_counter) in
        [(false, false), (true, false), (false, true), (true, true)]
    {
        match image::check_cfg(
            strip,
            ImageOptions {
                plc_interface,
                cycle_counter,
            },
            cfg,
        ) {
            Ok(img) => return Ok(img),
            Err(e) => {
                first.get_or_insert(e);
            }
        }
    }
    Err(first.expect("tried"))
}

/// The named channels of an image on `strip`: bits, bytes (status and
/// control), signed words in the terminal's unit where its range is
/// known (V, °C, %), unsigned double words (counters, positions).
pub fn channel_map(strip: &Strip, img: &Image) -> ChannelMap {
    let mut m = ChannelMap::new();
    for e in img.entries.iter().filter(|e| e.role != Role::Reserved) {
        let dir = match e.dir {
            Dir::In => Direction::Input,
            Dir::Out => Direction::Output,
        };
        let ty = match (e.bit, e.bytes) {
            (Some(bit), _) => ChannelType::Bool { bit },
            (None, 2) => ChannelType::I16,
            (None, 4) => ChannelType::U32,
            _ => ChannelType::U8,
        };
        let mut c = Channel::new(e.name.clone(), dir, e.byte, ty);
        if let (Owner::Terminal(p), Role::Value, None) = (e.owner, e.role, e.bit) {
            if let Some((num, den, unit)) = strip.slots()[p - 1].ty.scale.rational() {
                c = c.scaled(Scale {
                    num,
                    den,
                    unit: unit.to_string(),
                });
            }
        }
        m.channels.push(c);
    }
    m
}

/// The GSD modules of `strip` in its default mappings: the complex
/// terminals in plug order, then the digital bytes (inputs, outputs) in
/// modules of at most 4 bytes.
pub fn gsd_modules(gsd: &Gsd, strip: &Strip) -> Vec<String> {
    let mut names = vec![];
    for (slot, v) in strip.slots().iter().zip(strip.default_variants()) {
        let Some(v) = v else { continue };
        let family = &slot.ty.name[..3];
        let m = gsd
            .modules
            .iter()
            .filter(|m| m.cfg == v.cfg)
            .find(|m| m.name.starts_with(family))
            .or_else(|| gsd.modules.iter().find(|m| m.cfg == v.cfg));
        if let Some(m) = m {
            names.push(m.name.clone());
        }
    }
    let img = strip.default_image(ImageOptions::default());
    for (kind, mut bytes) in [(0x10u8, img.digital.0), (0x20, img.digital.1)] {
        while bytes > 0 {
            let n = bytes.min(4);
            if let Some(m) = gsd
                .modules
                .iter()
                .find(|m| m.cfg == [kind | (n as u8 - 1)] && m.name.contains("digital"))
            {
                names.push(m.name.clone());
            }
            bytes -= n;
        }
    }
    names
}
