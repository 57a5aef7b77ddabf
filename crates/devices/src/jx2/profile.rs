//! The `jx2` profile: `dpctl slave --device jx2`, `device = "jx2"` in a
//! bus file.
//!
//! The module's layout is whatever its PLC program writes into the
//! registers, so the master side takes it from options: `input_words`,
//! `output_words` (default 4 each, the reset values) and the consistent
//! windows (`consistent_inputs` words at word `consistent_input_offset`,
//! likewise for outputs). [`Jx2Profile::modules`] turns them into the
//! modules of `JX2P0DC3.GSD` that the module's Chk_Cfg rule accepts.

use super::script::Interpreter;
use super::{Plc, ScriptedJx2, IDENT};
use crate::channels::{ChannelMap, ChannelType, Direction};
use crate::profile::{ControlInbox, DeviceOptions, Profile, ProfileError};
use crate::BoxedDevice;
use profibus_dp::config::gsd::Gsd;
use serde::Deserialize;
use std::path::PathBuf;

/// The profile's name.
pub const NAME: &str = "jx2";

/// The options of the `jx2` profile.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Options {
    /// The module number x of the registers 1x100..1x999 (1..=9).
    #[serde(deserialize_with = "crate::profile::int")]
    pub module_number: u32,
    /// Register commands run as the PLC program (see [`super::script`]).
    pub script: Option<PathBuf>,
    /// Master side: input words (1x102).
    #[serde(deserialize_with = "crate::profile::int")]
    pub input_words: u16,
    /// Master side: output words (1x103).
    #[serde(deserialize_with = "crate::profile::int")]
    pub output_words: u16,
    /// Master side: consistent input words (1x124).
    #[serde(deserialize_with = "crate::profile::int")]
    pub consistent_inputs: u16,
    /// Master side: their word offset (1x128).
    #[serde(deserialize_with = "crate::profile::int")]
    pub consistent_input_offset: u16,
    /// Master side: consistent output words (1x125).
    #[serde(deserialize_with = "crate::profile::int")]
    pub consistent_outputs: u16,
    /// Master side: their word offset (1x129).
    #[serde(deserialize_with = "crate::profile::int")]
    pub consistent_output_offset: u16,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            module_number: 2,
            script: None,
            input_words: 4,
            output_words: 4,
            consistent_inputs: 0,
            consistent_input_offset: 0,
            consistent_outputs: 0,
            consistent_output_offset: 0,
        }
    }
}

/// The JX2-PROFI1 with its options.
#[derive(Debug)]
pub struct Jx2Profile {
    options: Options,
    script: Option<String>,
    gsd: Gsd,
}

impl Profile for Jx2Profile {
    type Options = Options;
    const NAME: &'static str = NAME;
    const SUMMARY: &'static str = "Jetter JX2-PROFI1 (ident 0x0DC3, ours): a PLC's PROFIBUS module driven through registers 1x100..1x999, DP-V1 data records";
    const OPTIONS_HELP: &'static str = "--module-number N (1..9, default 2: registers 12100...), \
--script FILE (register commands run as the PLC program), --control SOCKET (register commands on a Unix socket; \
stdin always takes them); bus file: input_words, output_words (default 4), consistent_inputs, consistent_input_offset, \
consistent_outputs, consistent_output_offset";
    const PATH_OPTIONS: &'static [&'static str] = &["script"];
    const IDENT: Option<u16> = Some(IDENT);

    fn configure(options: Options, _address: Option<u8>) -> Result<Self, ProfileError> {
        Plc::new(options.module_number).map_err(|e| ProfileError::Invalid(e.to_string()))?;
        let script = match &options.script {
            Some(path) => {
                let text = crate::profile::read_option_file(path)?;
                Interpreter::script(&text).map_err(|e| ProfileError::Table {
                    path: path.clone(),
                    message: e.to_string(),
                })?;
                Some(text)
            }
            None => None,
        };
        let o = &options;
        for (words, cw, off, what) in [
            (
                o.input_words,
                o.consistent_inputs,
                o.consistent_input_offset,
                "input",
            ),
            (
                o.output_words,
                o.consistent_outputs,
                o.consistent_output_offset,
                "output",
            ),
        ] {
            if words > 122 || cw + off > words {
                return Err(ProfileError::Invalid(format!(
                    "{words} {what} words with {cw} consistent at word {off}: at most 122 words, the window inside them"
                )));
            }
        }
        Ok(Jx2Profile {
            options,
            script,
            gsd: crate::gsd_files::parse(super::GSD).expect("JX2P0DC3.GSD parses"),
        })
    }

    fn gsd(&self) -> &Gsd {
        &self.gsd
    }

    fn gsd_file(&self) -> Vec<u8> {
        super::GSD.to_vec()
    }

    fn modules(&self) -> Vec<String> {
        let o = &self.options;
        let mut names = vec![];
        for (words, cw, off, dir) in [
            (
                o.input_words,
                o.consistent_inputs,
                o.consistent_input_offset,
                "INPUT",
            ),
            (
                o.output_words,
                o.consistent_outputs,
                o.consistent_output_offset,
                "OUTPUT",
            ),
        ] {
            let (cw, off) = if cw > 0 { (cw, off) } else { (0, words) };
            for (n, consistent) in [(off, false), (cw, true), (words - off - cw, false)] {
                if consistent {
                    if n > 0 {
                        names.push(format!("{dir} (consistent) : {n} words"));
                    }
                    continue;
                }
                // Plain words: the GSD's sizes 64, 32, …, 1.
                let mut left = n;
                for size in [64, 32, 16, 8, 4, 2, 1] {
                    while left >= size {
                        names.push(format!("{dir} : {size} words"));
                        left -= size;
                    }
                }
            }
        }
        names
    }

    /// The word counts and the consistent block of each direction, as
    /// the configuration's identifiers give them (manual: 1x102/1x103
    /// words, 1x124/1x125 consistent words at offsets 1x128/1x129); the
    /// module number is not on the bus (default 2).
    fn options_for_cfg(cfg: &[u8]) -> Vec<DeviceOptions> {
        // (words, consistent words, their offset) per direction.
        let mut dirs = [(0u16, 0u16, 0u16); 2];
        for id in profibus_dp::pdu::cfg::identifiers(cfg) {
            let Ok(id) = id else { return vec![] };
            for (k, len) in [(0, id.input), (1, id.output)] {
                let Some(len) = len else { continue };
                let words = (len.bytes() / 2) as u16;
                let d = &mut dirs[k];
                if len.consistent && d.1 == 0 {
                    (d.1, d.2) = (words, d.0);
                }
                d.0 += words;
            }
        }
        let mut o = DeviceOptions::new();
        for (k, (words, cw, off)) in ["input", "output"].into_iter().zip(dirs) {
            o.set(&format!("{k}_words"), i64::from(words));
            if cw > 0 {
                o.set(&format!("consistent_{k}s"), i64::from(cw));
                o.set(&format!("consistent_{k}_offset"), i64::from(off));
            }
        }
        vec![o]
    }

    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError> {
        let plc = Plc::new(self.options.module_number)
            .map_err(|e| ProfileError::Invalid(e.to_string()))?;
        let program = match &self.script {
            Some(text) => {
                Interpreter::script(text).map_err(|e| ProfileError::Invalid(e.to_string()))?
            }
            None => Interpreter::new(),
        };
        Ok(Box::new(ScriptedJx2::new(plc, program, control)))
    }

    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError> {
        let t =
            profibus_dp::pdu::cfg::totals(cfg).map_err(|e| ProfileError::Config(e.to_string()))?;
        let mut m = ChannelMap::new();
        // Word n of an image is register (1x112) + n or (1x113) + n on
        // the PLC side; named by position.
        for i in 0..t.input_bytes / 2 {
            m.push(format!("in{i}"), Direction::Input, 2 * i, ChannelType::U16);
        }
        for i in 0..t.output_bytes / 2 {
            m.push(
                format!("out{i}"),
                Direction::Output,
                2 * i,
                ChannelType::U16,
            );
        }
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DeviceOptions;

    #[test]
    fn modules_of_the_manual_examples() {
        let entry = crate::profile("jx2").unwrap();
        let mut o = DeviceOptions::new();
        for kv in [
            "input_words=16",
            "consistent_inputs=4",
            "consistent_input_offset=8",
            "output_words=12",
            "consistent_outputs=8",
            "consistent_output_offset=4",
        ] {
            o.set_pair(kv).unwrap();
        }
        let p = entry.configure(&o, Some(3)).unwrap();
        assert_eq!(
            p.modules(),
            [
                "INPUT : 8 words",
                "INPUT (consistent) : 4 words",
                "INPUT : 4 words",
                "OUTPUT : 4 words",
                "OUTPUT (consistent) : 8 words"
            ]
        );
        let cfg = p.chk_cfg().unwrap();
        assert_eq!(cfg, [0x57, 0xD3, 0x53, 0x63, 0xE7]);
        assert_eq!(p.user_prm_data().unwrap(), [0x80, 0, 0]);
        let ch = p.channels(&cfg).unwrap();
        assert_eq!(ch.of(Direction::Input).count(), 16);
        // Defaults: 4/4 words.
        let p = entry.configure(&DeviceOptions::new(), None).unwrap();
        assert_eq!(p.modules(), ["INPUT : 4 words", "OUTPUT : 4 words"]);
        let mut o = DeviceOptions::new();
        o.set_pair("input_words=123").unwrap();
        assert!(entry.configure(&o, None).is_err());
        o.set_pair("module_number=0").unwrap();
        assert!(entry.configure(&o, None).is_err());
    }
}
