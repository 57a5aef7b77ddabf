//! The `bk3000` entry of the profile registry: `dpctl slave --device
//! bk3000 --terminals KL1104,KL2134,KL3102,KL4002,KL9010`.

use super::image::Strip;
use super::Bk3000;
use crate::{BoxedDevice, Profile, ProfileOptions};

/// The registry entry.
pub const PROFILE: Profile = Profile {
    name: "bk3000",
    summary: "Beckhoff BK3000 PROFIBUS-DP bus coupler (ident 0xBECF) with a K-bus terminal strip",
    options_help:
        "--terminals KL1104,KL2134,KL3102:complete,...,KL9010 (plug order, end terminal last) or \
--device-opt terminals-file=FILE (one terminal per line or comma-separated, # comments), \
--switch-ones N --switch-tens N (rotary switches, instead of --addr), \
--device-opt programmed-cfg=HEX (table 70 for programmed configuration), \
--control FILE|- (commands: status, outputs, set NAME VALUE, release NAME|all, pull N, plug N, run)",
    build,
};

fn digit(opts: &ProfileOptions, key: &str) -> Result<Option<u8>, String> {
    opts.get(key)
        .map(|v| {
            v.trim()
                .parse::<u8>()
                .ok()
                .filter(|d| *d <= 9)
                .ok_or_else(|| format!("--{key} `{v}`: a decimal rotary switch is 0..9"))
        })
        .transpose()
}

/// The station address from the rotary switches (`switch-ones`,
/// `switch-tens`; p. 31: upper switch ones, lower switch tens), if either
/// is given; `Ok(None)` takes `--addr`.
pub fn address(opts: &ProfileOptions) -> Result<Option<u8>, String> {
    match (digit(opts, "switch-ones")?, digit(opts, "switch-tens")?) {
        (None, None) => Ok(None),
        (ones, tens) => Ok(Some(tens.unwrap_or(0) * 10 + ones.unwrap_or(0))),
    }
}

/// The strip the options name (`terminals` or `terminals-file`).
pub fn strip(opts: &ProfileOptions) -> Result<Strip, String> {
    let list = match (opts.get("terminals"), opts.get("terminals-file")) {
        (Some(_), Some(_)) => return Err("give --terminals or a terminals file, not both".into()),
        (Some(l), None) => l.to_string(),
        (None, Some(path)) => std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?,
        (None, None) => {
            return Err(
                "give the terminal strip: --terminals KL1104,KL2134,...,KL9010 (plug order, end terminal last)"
                    .into(),
            )
        }
    };
    Strip::parse(&list).map_err(|e| e.to_string())
}

/// The coupler the options describe.
pub fn build_device(opts: &ProfileOptions) -> Result<Bk3000, String> {
    let mut dev = Bk3000::new(strip(opts)?);
    if let Some(h) = opts.get("programmed-cfg") {
        let bytes = parse_hex(h)?;
        dev = dev.with_programmed_cfg(bytes)?;
    }
    if let Some(inbox) = &opts.control {
        dev = dev.with_inbox(inbox.clone());
    }
    Ok(dev)
}

fn build(opts: &ProfileOptions) -> Result<BoxedDevice, String> {
    address(opts)?;
    Ok(Box::new(build_device(opts)?))
}

fn parse_hex(s: &str) -> Result<Vec<u8>, String> {
    let digits: String = s
        .split(|c: char| c.is_whitespace() || c == ',')
        .map(|t| t.trim_start_matches("0x").trim_start_matches("0X"))
        .collect();
    if digits.is_empty() || !digits.len().is_multiple_of(2) {
        return Err(format!("programmed-cfg `{s}` is not hex bytes"));
    }
    (0..digits.len())
        .step_by(2)
        .map(|i| {
            u8::from_str_radix(&digits[i..i + 2], 16)
                .map_err(|_| format!("programmed-cfg `{s}` is not hex bytes"))
        })
        .collect()
}
