//! The `jx2` entry of the profile registry: `dpctl slave --device jx2`.

use super::{Plc, SharedJx2};
use crate::{BoxedDevice, Profile, ProfileOptions};

/// The registry entry.
pub const PROFILE: Profile = Profile {
    name: "jx2",
    summary: "Jetter JX2-PROFI1 (ident 0x0DC3, ours): a PLC's PROFIBUS module driven through registers 1x100..1x999, DP-V1 data records",
    options_help: "--module-number N (1..9, default 2: registers 12100...), --script FILE (register commands run as the PLC program), \
--control SOCKET (register commands on a Unix socket; stdin always takes them)",
    build,
};

/// The module number the options give (default 2).
pub fn module_number(opts: &ProfileOptions) -> Result<u32, String> {
    match opts.get("module-number") {
        None => Ok(2),
        Some(v) => v
            .trim()
            .parse::<u32>()
            .ok()
            .filter(|n| (1..=9).contains(n))
            .ok_or_else(|| format!("--module-number `{v}` is not 1..=9")),
    }
}

fn build(opts: &ProfileOptions) -> Result<BoxedDevice, String> {
    let plc = Plc::new(module_number(opts)?).map_err(|e| e.to_string())?;
    Ok(Box::new(SharedJx2::new(plc)))
}
