//! The `omega` entry of the profile registry: `dpctl slave --device omega`.

use super::params::ParamTable;
use super::Omega;
use crate::{BoxedDevice, Profile, ProfileOptions};
use std::time::Duration;

/// The registry entry.
pub const PROFILE: Profile = Profile {
    name: "omega",
    summary: "Baumüller Omega Drive-Line II option board PBDP-01 (ident 0x00D0): setpoints/actual values, PKW to a V-controller parameter set",
    options_help: "--params FILE.toml (V-controller parameter set; default: the shipped table), \
--setpoints N / --actual-values N (si_NR_WR_VALUE / si_NR_RD_VALUE, 1..8; default: any valid configuration), \
--switch N (rotary switches S40/S41, hex allowed, instead of --addr), --device-opt pkw-delay-ms=MS (PKW processing delay, default 5), \
--control FILE|- (commands: status, quit, get P)",
    build,
};

fn number(opts: &ProfileOptions, key: &str) -> Result<Option<u64>, String> {
    opts.get(key)
        .map(|v| {
            let v = v.trim();
            match v.strip_prefix("0x").or_else(|| v.strip_prefix("0X")) {
                Some(h) => u64::from_str_radix(h, 16),
                None => v.parse(),
            }
            .map_err(|_| format!("--{key} `{v}` is not a number"))
        })
        .transpose()
}

/// The address from the rotary switches (`switch`), if given: S40 is the
/// high nibble, S41 the low one (L498-511); DP addresses stop at 125.
pub fn address(opts: &ProfileOptions) -> Result<Option<u8>, String> {
    match number(opts, "switch")? {
        None => Ok(None),
        Some(s) if s <= 125 => Ok(Some(s as u8)),
        Some(s) => Err(format!(
            "rotary switches S40/S41 at 0x{s:02X}: station addresses are 0..=125"
        )),
    }
}

fn build(opts: &ProfileOptions) -> Result<BoxedDevice, String> {
    let table = match opts.get("params") {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
            ParamTable::parse(&text).map_err(|e| format!("{path}: {e}"))?
        }
        None => ParamTable::default_table(),
    };
    let mut dev = Omega::new(table);
    match (number(opts, "setpoints")?, number(opts, "actual-values")?) {
        (None, None) => {}
        (Some(sp), Some(av)) => dev = dev.with_counts(sp as usize, av as usize)?,
        _ => return Err("give both --setpoints and --actual-values, or neither".into()),
    }
    if let Some(ms) = number(opts, "pkw-delay-ms")? {
        dev = dev.with_pkw_delay(Duration::from_millis(ms));
    }
    if let Some(inbox) = &opts.control {
        dev = dev.with_inbox(inbox.clone());
    }
    Ok(Box::new(dev))
}
