//! A bus file's slaves as emulated devices on the in-process simulated
//! bus, paced at the bus file's baud rate: a gateway with no hardware
//! (`dpctl gateway --sim`). Slaves given as a device profile run that
//! profile's device; slaves given by GSD modules run the generic device
//! with inputs that echo the outputs.

use crate::core::SlaveInfo;
use profibus_devices::bus::ProfiledBus;
use profibus_devices::generic::{GenericDevice, GenericError};
use profibus_devices::{BoxedDevice, ProfileError};
use profibus_dp::master::{DpMaster, MasterConfigError};
use profibus_dp::slave::DpSlave;
use profibus_fdl::medium::MediumConfig;
use profibus_fdl::sim::{SimBus, StationId};
use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
use profibus_fdl::station::passive::PassiveStation;
use profibus_fdl::Instant;

/// Why a simulated plant could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The master's configuration.
    #[error(transparent)]
    Master(#[from] MasterConfigError),
    /// A device profile.
    #[error("slave {0}: {1}")]
    Profile(u8, ProfileError),
    /// A slave given by GSD modules.
    #[error("slave {0}: {1}")]
    Generic(u8, GenericError),
}

/// The master and the emulated slaves of a bus file on a simulated line.
pub struct SimPlant {
    bus: SimBus,
    master: StationId,
}

impl SimPlant {
    /// Build the plant of `profiled`.
    pub fn new(profiled: &ProfiledBus) -> Result<SimPlant, SimError> {
        let file = &profiled.file;
        let params = file.master.params;
        let mut bus = SimBus::new(MediumConfig::paced(params.baud));
        let master = bus.add(ActiveStation::new(
            ActiveConfig::new(file.master.address, params),
            DpMaster::new(&file.master)?,
        ));
        for s in &file.slaves {
            let a = s.params.address;
            let device: BoxedDevice = match profiled.profile(a) {
                Some(p) => p.device(None).map_err(|e| SimError::Profile(a, e))?,
                None => Box::new(
                    GenericDevice::from_gsd(&s.gsd, &s.modules)
                        .map_err(|e| SimError::Generic(a, e))?,
                ),
            };
            bus.add(PassiveStation::new(DpSlave::new(device, a), params));
        }
        Ok(SimPlant { bus, master })
    }

    /// Run the line up to `t` (virtual time since the start).
    pub fn run_until(&mut self, t: Instant) {
        self.bus.run_until(t);
    }

    /// The virtual time.
    pub fn now(&self) -> Instant {
        self.bus.now()
    }

    /// The DP master.
    pub fn master(&mut self) -> &mut DpMaster {
        self.bus
            .station_mut::<ActiveStation<DpMaster>>(self.master)
            .app_mut()
    }
}

/// The gateway's view of a bus file's slaves: names, named channels of
/// profiled slaves, GSDs, PKW dialects, RFID readers.
pub fn slave_infos(profiled: &ProfiledBus) -> Result<Vec<SlaveInfo>, SimError> {
    profiled
        .file
        .slaves
        .iter()
        .map(|s| {
            let a = s.params.address;
            Ok(SlaveInfo {
                address: a,
                name: s.params.name.clone(),
                channels: profiled
                    .channels(a)
                    .transpose()
                    .map_err(|e| SimError::Profile(a, e))?,
                gsd: Some(s.gsd.clone()),
                dpv1: s.params.dpv1,
                pkw: profibus_devices::pkw_dialect(s.params.ident_number, &s.params.cfg).ok(),
                rfid: s.params.ident_number == profibus_devices::rfid::IDENT,
            })
        })
        .collect()
}
