//! The `omega` profile: `dpctl slave --device omega`, `device = "omega"`
//! in a bus file.

use super::params::ParamTable;
use super::{check_configuration, Omega, IDENT, MAX_VALUES, PKW};
use crate::channels::{ChannelMap, ChannelType, Direction};
use crate::pkw::{Dialect, PKW_LEN};
use crate::profile::{opt_int, read_table, ControlInbox, DeviceOptions, Profile, ProfileError};
use crate::BoxedDevice;
use profibus_dp::config::gsd::Gsd;
use serde::Deserialize;
use std::path::PathBuf;
use std::time::Duration;

/// The options of the `omega` profile.
#[derive(Debug, Default, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Options {
    /// The V controller's parameter set (TOML); default: the shipped one.
    pub params: Option<PathBuf>,
    /// si_NR_WR_VALUE: setpoints the drive expects (1..8, with
    /// `actual_values`); default: any valid configuration (the master
    /// side: 2).
    #[serde(deserialize_with = "opt_int")]
    pub setpoints: Option<u8>,
    /// si_NR_RD_VALUE: actual values (1..8).
    #[serde(deserialize_with = "opt_int")]
    pub actual_values: Option<u8>,
    /// The rotary switches S40/S41 (hex allowed), instead of the caller's
    /// address.
    #[serde(deserialize_with = "opt_int")]
    pub switch: Option<u16>,
    /// PKW processing delay in ms (default 5).
    #[serde(deserialize_with = "opt_int")]
    pub pkw_delay_ms: Option<u64>,
    /// t_TIMEOUT_SD_DATA in ms (default 5000, 0: off).
    #[serde(deserialize_with = "opt_int")]
    pub sd_timeout_ms: Option<u64>,
    /// Who enables the drive: `master` (control word 1 drives the device
    /// control state machine; the default) or `auto` (the Omega's own
    /// program enables it; the drive follows its setpoints at once).
    pub drive_enable: Option<String>,
    /// Master side: configure the service data (PKW) module (default:
    /// true).
    pub pkw: Option<bool>,
}

/// The Omega Drive-Line II option board with a parameter set.
#[derive(Debug)]
pub struct OmegaProfile {
    options: Options,
    table: ParamTable,
    gsd: Gsd,
}

impl Profile for OmegaProfile {
    type Options = Options;
    const NAME: &'static str = "omega";
    const SUMMARY: &'static str = "Baumüller Omega Drive-Line II option board PBDP-01 (ident 0x00D0): setpoints/actual values, PKW to a V-controller parameter set";
    const OPTIONS_HELP: &'static str = "--params FILE.toml (V-controller parameter set; default: the shipped table), \
--setpoints N / --actual-values N (si_NR_WR_VALUE / si_NR_RD_VALUE, 1..8; default: any valid configuration), \
--switch N (rotary switches S40/S41, hex allowed, instead of --addr), --device-opt pkw-delay-ms=MS (PKW processing delay, default 5), \
--device-opt sd-timeout-ms=MS (t_TIMEOUT_SD_DATA, default 5000, 0 off), --device-opt drive-enable=master|auto (control word 1 drives the \
DRIVECOM state machine, default; or the drive enables itself), \
--control FILE|- (commands: status, quit, get P, fault [CODE], plc on|off, cyclic P…|none, sd-delay MS); \
bus file: setpoints, actual_values (default 2 each), pkw = true|false, drive_enable, sd_timeout_ms";
    const IDENT: Option<u16> = Some(IDENT);
    const PATH_OPTIONS: &'static [&'static str] = &["params"];
    const PKW: Option<&'static Dialect> = Some(&PKW);

    fn configure(options: Options, _address: Option<u8>) -> Result<Self, ProfileError> {
        let table = match &options.params {
            Some(path) => read_table(path, ParamTable::parse)?,
            None => ParamTable::default_table(),
        };
        match (options.setpoints, options.actual_values) {
            (None, None) => {}
            (Some(sp), Some(av)) => {
                Omega::new(ParamTable::default_table())
                    .with_counts(sp as usize, av as usize)
                    .map_err(|e| ProfileError::Invalid(e.to_string()))?;
            }
            _ => {
                return Err(ProfileError::Invalid(
                    "give both --setpoints and --actual-values, or neither".into(),
                ))
            }
        }
        if let Some(e) = options
            .drive_enable
            .as_deref()
            .filter(|e| !matches!(*e, "master" | "auto"))
        {
            return Err(ProfileError::BadOption {
                key: "drive_enable".into(),
                message: format!("`{e}`: give master or auto"),
            });
        }
        if let Some(s) = options.switch.filter(|s| *s > 125) {
            return Err(ProfileError::Invalid(format!(
                "rotary switches S40/S41 at 0x{s:02X}: station addresses are 0..=125"
            )));
        }
        Ok(OmegaProfile {
            options,
            table,
            gsd: crate::gsd_files::parse(super::GSD).expect("BNF_00D0.GSD parses leniently"),
        })
    }

    fn gsd(&self) -> &Gsd {
        &self.gsd
    }

    fn gsd_file(&self) -> Vec<u8> {
        super::GSD.to_vec()
    }

    fn modules(&self) -> Vec<String> {
        let sp = self
            .options
            .setpoints
            .unwrap_or(2)
            .clamp(1, MAX_VALUES as u8);
        let av = self
            .options
            .actual_values
            .unwrap_or(2)
            .clamp(1, MAX_VALUES as u8);
        // By identifier (BNF_00D0.GSD L1462-1547): the first 0x73 is the
        // service data module, 0x71 status / control, 0x51.. actual
        // values, 0x61.. setpoints (both in steps of 2).
        let mut ids = vec![];
        if self.options.pkw.unwrap_or(true) {
            ids.push(0x73);
        }
        ids.extend([0x71, 0x51 + 2 * (av - 1), 0x61 + 2 * (sp - 1)]);
        ids.into_iter()
            .filter_map(|id| {
                let m = self.gsd.modules.iter().find(|m| m.cfg == [id])?;
                Some(m.name.clone())
            })
            .collect()
    }

    fn address(&self) -> Option<u8> {
        self.options.switch.map(|s| s as u8)
    }

    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError> {
        let o = &self.options;
        let mut dev = Omega::new(self.table.clone());
        if let (Some(sp), Some(av)) = (o.setpoints, o.actual_values) {
            dev = dev
                .with_counts(sp as usize, av as usize)
                .map_err(|e| ProfileError::Invalid(e.to_string()))?;
        }
        if let Some(ms) = o.pkw_delay_ms {
            dev = dev.with_pkw_delay(Duration::from_millis(ms));
        }
        if let Some(ms) = o.sd_timeout_ms {
            dev = dev.with_sd_timeout(Duration::from_millis(ms));
        }
        if o.drive_enable.as_deref() == Some("auto") {
            dev = dev.with_auto_enable();
        }
        if let Some(inbox) = control {
            dev = dev.with_inbox(inbox);
        }
        Ok(Box::new(dev))
    }

    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError> {
        let l = check_configuration(cfg).map_err(|e| ProfileError::Config(e.to_string()))?;
        let mut m = ChannelMap::new();
        let at = if l.pkw {
            crate::pkw::channels(&mut m);
            PKW_LEN
        } else {
            0
        };
        for (dir, words, values, n) in [
            (
                Direction::Input,
                ["status1", "status2"],
                "actual",
                l.actual_values,
            ),
            (
                Direction::Output,
                ["control1", "control2"],
                "setpoint",
                l.setpoints,
            ),
        ] {
            m.push(words[0], dir, at, ChannelType::U16);
            m.push(words[1], dir, at + 2, ChannelType::U16);
            for i in 0..n {
                m.push(
                    format!("{values}{}", i + 1),
                    dir,
                    at + 4 + 4 * i,
                    ChannelType::I32,
                );
            }
        }
        Ok(m)
    }

    /// A parameter of the shipped V-controller table by name: case and
    /// `_` / `-` for spaces do not matter (`L_rev_actual_value` is P218).
    /// The counts and the PKW module from the identifiers (BNF_00D0.GSD
    /// L1462-1547): `0x73` (service data) first where configured, `0x71`,
    /// then actual values `0x51 + 2 (n - 1)` and setpoints `0x61 + 2 (n -
    /// 1)`.
    fn options_for_cfg(cfg: &[u8]) -> Vec<DeviceOptions> {
        let (pkw, rest) = match cfg.split_first() {
            Some((0x73, rest)) => (true, rest),
            _ => (false, cfg),
        };
        let count = |b: u8, high: u8| {
            (b & 0xF0 == high && b & 1 == 1).then_some(i64::from(b & 0x0F) / 2 + 1)
        };
        let [0x71, av, sp] = rest else {
            return vec![DeviceOptions::new()];
        };
        let (Some(av), Some(sp)) = (count(*av, 0x50), count(*sp, 0x60)) else {
            return vec![DeviceOptions::new()];
        };
        let mut o = DeviceOptions::new();
        o.set("setpoints", sp);
        o.set("actual_values", av);
        if !pkw {
            o.set("pkw", false);
        }
        vec![o]
    }

    fn pkw_parameter(_gsd: &Gsd, name: &str) -> Option<u16> {
        let norm = |s: &str| s.to_lowercase().replace(['_', '-'], " ");
        let want = norm(name);
        (ParamTable::default_table().params.iter())
            .find(|p| norm(&p.name) == want)
            .map(|p| p.pnu)
    }

    fn pkw_parameters(_gsd: &Gsd) -> Vec<crate::pkw::PkwParameter> {
        let mut v: Vec<crate::pkw::PkwParameter> = (ParamTable::default_table().params)
            .into_iter()
            .map(|p| crate::pkw::PkwParameter {
                pnu: p.pnu,
                details: format!(
                    "{}, {}{}..{}",
                    if p.dword { "dword" } else { "word" },
                    if p.protected { "read only, " } else { "" },
                    p.min,
                    p.max
                ),
                name: p.name,
            })
            .collect();
        v.push(crate::pkw::PkwParameter {
            pnu: super::OMEGA_ARRAY_FIRST,
            name: "Omega DINT array P1000..P2047 (P1000[i] = P1000+i)".into(),
            details: "dword, read and write (commands 1 and 3)".into(),
        });
        v
    }

    fn pkw_dialect(cfg: &[u8]) -> Option<&'static Dialect> {
        check_configuration(cfg)
            .is_ok_and(|l| l.pkw)
            .then_some(&PKW)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::channels::Value;
    use crate::DeviceOptions;

    #[test]
    fn master_side_follows_the_counts() {
        let entry = crate::profile("omega").unwrap();
        let mut o = DeviceOptions::new();
        o.set_pair("setpoints=8").unwrap();
        o.set_pair("actual-values=1").unwrap();
        o.set_pair("switch=0x19").unwrap();
        let p = entry.configure(&o, None).unwrap();
        assert_eq!(p.address(), Some(25));
        let cfg = p.chk_cfg().unwrap();
        assert_eq!(check_configuration(&cfg).unwrap().setpoints, 8);
        let ch = p.channels(&cfg).unwrap();
        let names: Vec<&str> = ch.of(Direction::Input).map(|c| c.name.as_str()).collect();
        assert_eq!(
            names,
            ["pke", "ind", "pwe1", "pwe2", "status1", "status2", "actual1"]
        );
        let mut out = vec![0u8; 44];
        ch.write_output("setpoint8", Value::Int(-1), &mut out)
            .unwrap();
        assert_eq!(&out[40..44], &[0xFF; 4]);
        let p = entry.configure(&DeviceOptions::new(), Some(25)).unwrap();
        assert_eq!(p.address(), None, "the caller's address");
        assert_eq!(p.chk_cfg().unwrap(), [0x73, 0x71, 0x53, 0x63]);
        let mut o = DeviceOptions::new();
        o.set_pair("setpoints=2").unwrap();
        assert!(entry.configure(&o, None).is_err(), "both counts or neither");
    }
}
