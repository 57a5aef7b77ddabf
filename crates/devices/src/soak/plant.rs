//! The soak's plant: a master and one slave of every profile of the
//! registry ([`crate::PROFILES`]).

use super::{SoakConfig, SoakError, MASTER_ADDRESS};
use crate::jx2::{self, script::Interpreter};
use crate::{BoxedDevice, Configured, DeviceOptions, PROFILES};
use profibus_dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams};
use profibus_dp::slave::DpSlave;
use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
use profibus_fdl::station::passive::PassiveStation;
use profibus_fdl::{BusParams, Instant};

pub(super) type MasterStation = ActiveStation<DpMaster>;
pub(super) type SlaveStation = PassiveStation<DpSlave<BoxedDevice>>;

/// A slave of the plant.
pub(super) struct PlantSlave {
    pub(super) profile: &'static str,
    pub(super) address: u8,
    /// The master side: GSD and modules.
    pub(super) configured: Box<dyn Configured>,
    pub(super) device: BoxedDevice,
}

/// Options per profile: (name, station address, KEY=VALUE options).
/// Every profile of the registry must have a row (checked).
const SLAVES: &[(&str, u8, &[&str])] = &[
    ("generic", 3, &[]),
    ("bm4", 4, &[]),
    ("omega", 5, &[]),
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

fn err(name: &'static str) -> impl Fn(crate::ProfileError) -> SoakError {
    move |error| SoakError::Profile { name, error }
}

/// One slave per registry profile.
pub(super) fn slaves(_cfg: &SoakConfig) -> Result<Vec<PlantSlave>, SoakError> {
    let mut out = Vec::new();
    for entry in PROFILES {
        let name = entry.name;
        let (_, address, options) =
            SLAVES.iter().find(|(n, _, _)| *n == name).ok_or_else(|| {
                err(name)(crate::ProfileError::Invalid(
                    "the soak has no slave of this profile".into(),
                ))
            })?;
        let mut o = DeviceOptions::new();
        let (configured, device): (Box<dyn Configured>, BoxedDevice) = match name {
            // The generic profile reads a GSD file; the soak uses the
            // built-in test slave's GSD so that it needs no files.
            "generic" => {
                let gsd = crate::gsd_files::parse(crate::gsd_files::DPCTL_GEN)
                    .map_err(|e| err(name)(e.into()))?;
                let modules = ["2 words in/out"];
                let dev = crate::generic::GenericDevice::from_gsd(&gsd, &modules)
                    .map_err(|e| err(name)(crate::ProfileError::Device(Box::new(e))))?;
                (
                    Box::new(BuiltIn {
                        gsd,
                        modules: modules.iter().map(|m| m.to_string()).collect(),
                    }),
                    Box::new(dev),
                )
            }
            _ => {
                for kv in *options {
                    o.set_pair(kv).map_err(err(name))?;
                }
                let p = entry.configure(&o, Some(*address)).map_err(err(name))?;
                let device = if name == jx2::profile::NAME {
                    jx2_plc(*address)?
                } else {
                    p.device(None).map_err(err(name))?
                };
                (p, device)
            }
        };
        let address = configured.address().unwrap_or(*address);
        out.push(PlantSlave {
            profile: name,
            address,
            configured,
            device,
        });
    }
    Ok(out)
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

/// The master's side of the built-in generic slave.
#[derive(Debug)]
struct BuiltIn {
    gsd: profibus_dp::config::gsd::Gsd,
    modules: Vec<String>,
}

impl Configured for BuiltIn {
    fn name(&self) -> &'static str {
        "generic"
    }
    fn gsd(&self) -> &profibus_dp::config::gsd::Gsd {
        &self.gsd
    }
    fn gsd_file(&self) -> Vec<u8> {
        self.gsd.write_latin1()
    }
    fn modules(&self) -> Vec<String> {
        self.modules.clone()
    }
    fn address(&self) -> Option<u8> {
        None
    }
    fn address_file(&self) -> Option<std::path::PathBuf> {
        None
    }
    fn state_file(&self) -> Option<std::path::PathBuf> {
        None
    }
    fn device(
        &self,
        _control: Option<crate::ControlInbox>,
    ) -> Result<BoxedDevice, crate::ProfileError> {
        Ok(Box::new(
            crate::generic::GenericDevice::from_gsd(&self.gsd, &self.modules)
                .map_err(|e| crate::ProfileError::Device(Box::new(e)))?,
        ))
    }
    fn channels(&self, _cfg: &[u8]) -> Result<crate::channels::ChannelMap, crate::ProfileError> {
        Err(crate::ProfileError::Invalid("no named channels".into()))
    }
    fn warnings(&self) -> Vec<String> {
        vec![]
    }
}

fn params(cfg: &SoakConfig) -> BusParams {
    BusParams::defaults(cfg.baud)
}

/// The master's configuration of the plant.
pub(super) fn master_config(
    cfg: &SoakConfig,
    slaves: &[PlantSlave],
) -> Result<MasterConfig, SoakError> {
    let mut out = Vec::new();
    for s in slaves {
        let c = &s.configured;
        let cfg_bytes = c.chk_cfg().map_err(err(s.profile))?;
        let mut p = SlaveParams::new(s.address, c.gsd().ident_number, cfg_bytes);
        p.name = s.profile.into();
        p.user_prm_data = c.user_prm_data().map_err(err(s.profile))?;
        p.dpv1 = c.gsd().dpv1_slave;
        p.watchdog = Some(cfg.watchdog);
        out.push(p);
    }
    Ok(MasterConfig {
        address: MASTER_ADDRESS,
        params: params(cfg),
        slaves: out,
        options: MasterOptions::default(),
    })
}

pub(super) fn master_station(
    cfg: &SoakConfig,
    master: &MasterConfig,
) -> Result<MasterStation, SoakError> {
    Ok(ActiveStation::new(
        ActiveConfig::new(MASTER_ADDRESS, params(cfg)),
        DpMaster::new(master)?,
    ))
}

pub(super) fn slave_station(cfg: &SoakConfig, device: BoxedDevice, address: u8) -> SlaveStation {
    PassiveStation::new(DpSlave::new(device, address), params(cfg))
}
