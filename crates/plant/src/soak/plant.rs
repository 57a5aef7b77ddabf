//! The soak's plant: a master and one slave of every profile of the
//! registry ([`profibus_devices::PROFILES`]), from the plant builder.

use super::{SoakConfig, SoakError, MASTER_ADDRESS};
use crate::{Plant, PlantSlave, Stations};
use profibus_devices::generic::InputPattern;
use profibus_devices::jx2::{self, script::Interpreter};
use profibus_devices::{BoxedDevice, DeviceOptions, ProfileError, PROFILES};
use profibus_fdl::Instant;

pub(super) use crate::{MasterStation, SlaveStation};

/// Options per profile: (name, station address, KEY=VALUE options).
/// Every profile of the registry must have a row (checked).
const SLAVES: &[(&str, u8, &[&str])] = &[
    ("generic", 3, &[]),
    ("bm4", 4, &[]),
    ("omega", 5, &["drive-enable=auto"]),
    ("jx2", 6, &[]),
    ("rfid", 8, &[]),
    (
        "bk3000",
        9,
        &[
            "terminals=KL1104,KL2134,KL3102,KL4002,KL9010",
            "switch-ones=9",
        ],
    ),
];

fn err(name: &'static str) -> impl Fn(ProfileError) -> SoakError {
    move |error| SoakError::Profile { name, error }
}

/// The plant's stations: the master, then one slave per registry
/// profile, named by its profile.
pub(super) fn stations(cfg: &SoakConfig) -> Result<Stations, SoakError> {
    let mut b = Plant::builder()
        .baud(cfg.baud)
        .medium(cfg.medium())
        .master(MASTER_ADDRESS)
        // The token to itself after every poll cycle: the soak puts the
        // token path (SD4 telegrams without FCS, forged by bit errors)
        // under load, which a lone master holding the token would spare.
        .options(profibus_dp::master::MasterOptions {
            alone_hold_bits: Some(0),
            ..Default::default()
        })
        .watchdog(cfg.watchdog);
    for entry in PROFILES {
        let name = entry.name;
        let (_, address, options) =
            SLAVES.iter().find(|(n, _, _)| *n == name).ok_or_else(|| {
                err(name)(ProfileError::Invalid(
                    "the soak has no slave of this profile".into(),
                ))
            })?;
        b = match name {
            // The generic profile reads a GSD file; the soak uses the
            // built-in test slave's GSD so that it needs no files.
            "generic" => {
                let gsd =
                    profibus_devices::gsd_files::parse(profibus_devices::gsd_files::DPCTL_GEN)
                        .map_err(|e| err(name)(e.into()))?;
                b.generic(
                    *address,
                    name,
                    &gsd,
                    &["2 words in/out"],
                    InputPattern::Echo,
                )?
            }
            _ => {
                let mut o = DeviceOptions::new();
                for kv in *options {
                    o.set_pair(kv).map_err(err(name))?;
                }
                let p = entry.configure(&o, Some(*address)).map_err(err(name))?;
                let device = if name == jx2::profile::NAME {
                    jx2_plc(*address)?
                } else {
                    p.device(None).map_err(err(name))?
                };
                b.configured(*address, name, &*p, device)?
            }
        };
    }
    Ok(b.stations()?)
}

/// The profile of a slave of the plant.
pub(super) fn profile(s: &PlantSlave) -> &'static str {
    s.profile.unwrap_or("generic")
}

/// The JX2-PROFI1 as its PLC configured it before the bus started: 4
/// input and 4 output words, station `address` (the profile's default
/// master-side configuration).
fn jx2_plc(address: u8) -> Result<BoxedDevice, SoakError> {
    let e = |e: &dyn std::fmt::Display| SoakError::Jx2(e.to_string());
    let mut plc = jx2::Plc::new(2).map_err(|x| e(&x))?;
    let init = format!("write 12102 4\nwrite 12103 4\nwrite 12107 {address}\n");
    Interpreter::script(&init)
        .map_err(|x| e(&x))?
        .run(&mut plc, Instant::ZERO);
    plc.module.settle(Instant::ZERO + jx2::INIT_TIME);
    if plc.module.station_address() != Some(address) {
        return Err(SoakError::Jx2(
            "the PLC did not configure its module".into(),
        ));
    }
    Ok(Box::new(jx2::ScriptedJx2::new(
        plc,
        Interpreter::new(),
        None,
    )))
}
