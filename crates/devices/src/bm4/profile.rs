//! The `bm4` entry of the profile registry: `dpctl slave --device bm4`.

use super::vars::VarTable;
use super::{Addressing, Bm4};
use crate::{BoxedDevice, Profile, ProfileOptions};
use std::path::Path;

/// The registry entry.
pub const PROFILE: Profile = Profile {
    name: "bm4",
    summary: "Baumüller b maXX PLC module BM4-O-PRO-01 (ident 0x0008): PLC variables as modules, PKW channel, SDIAG user diagnosis",
    options_help: "--vars FILE.toml (variable table; default: BM4OPRO1.GSD's configuration), \
--us-device N (1..125 fixed, 126 set once by the master and kept in --state-dir, 127 set after every start, \
128 rotary switch; default: --addr), --switch N (rotary switch for us_DEVICE 128), --state-dir DIR, \
--write-gsd FILE (write the generated GSD), --control FILE|- (commands: sdiag HEX..., sdiag-clear, set NAME VALUE, get NAME, status)",
    build,
};

fn num(opts: &ProfileOptions, key: &str) -> Result<Option<u8>, String> {
    opts.get(key)
        .map(|v| {
            let v = v.trim();
            let parsed = match v.strip_prefix("0x").or_else(|| v.strip_prefix("0X")) {
                Some(h) => u8::from_str_radix(h, 16),
                None => v.parse::<u8>(),
            };
            parsed.map_err(|_| format!("--{key} `{v}` is not a number 0..=255"))
        })
        .transpose()
}

/// The addressing the options give: `us-device` (default: `addr`),
/// `switch`, `state-dir`.
pub fn addressing(opts: &ProfileOptions) -> Result<Addressing, String> {
    let switch = num(opts, "switch")?;
    let us = match (num(opts, "us-device")?, switch) {
        (Some(u), _) => u,
        (None, Some(_)) => 128,
        (None, None) => num(opts, "addr")?
            .ok_or("give --us-device N, --switch N (us_DEVICE 128) or --addr N")?,
    };
    Addressing::from_us_device(us, switch, opts.get("state-dir").map(Path::new))
}

/// The station address at start.
pub fn address(opts: &ProfileOptions) -> Result<u8, String> {
    addressing(opts).map(|a| a.address)
}

fn build(opts: &ProfileOptions) -> Result<BoxedDevice, String> {
    let table = match opts.get("vars") {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
            VarTable::parse(&text).map_err(|e| format!("{path}: {e}"))?
        }
        None => VarTable::default_table(),
    };
    let mut dev = Bm4::new(table, addressing(opts)?);
    if let Some(path) = opts.get("write-gsd") {
        std::fs::write(path, dev.gsd_file()).map_err(|e| format!("{path}: {e}"))?;
    }
    if let Some(inbox) = &opts.control {
        dev = dev.with_inbox(inbox.clone());
    }
    Ok(Box::new(dev))
}
