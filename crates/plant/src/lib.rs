//! `profibus-plant`: simulated plants: a DP master and emulated slaves on
//! the in-process simulated bus ([`SimBus`], virtual time), sans-IO.
//!
//! One builder wires every plant of the project: the demo plant of
//! `dpctl demo` ([`demo`]), the fault soak of `dpctl soak` ([`soak`]), a
//! bus file's slaves for `dpctl gateway --sim` ([`PlantBuilder::bus`]),
//! and the tests and benchmarks that need a master with slaves.
//!
//! ```
//! use profibus_devices::generic::InputPattern;
//! use profibus_devices::gsd_files;
//! use profibus_fdl::Baud;
//! use profibus_plant::Plant;
//! use std::time::Duration;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let gsd = gsd_files::parse(gsd_files::DPCTL_GEN)?;
//! let mut plant = Plant::builder()
//!     .baud(Baud::B1500000)
//!     .generic(3, "echo", &gsd, &["2 words in/out"], InputPattern::Echo)?
//!     .profile(6, "drive", "bm4", &["example=true"], None)?
//!     .build()?;
//! plant.run_for(Duration::from_millis(300));
//! assert!(plant.all_in_data_exchange());
//! # Ok(())
//! # }
//! ```
//!
//! The plant runs only when told to ([`Plant::run_until`]); a program that
//! paces it on the wall clock does so from outside (the gateway's
//! `Pacer`).

#![forbid(unsafe_code)]

pub mod demo;
pub mod soak;

use profibus_devices::channels::ChannelMap;
use profibus_devices::generic::{GenericDevice, GenericError, InputPattern};
use profibus_devices::{BoxedDevice, Configured, ControlInbox, DeviceOptions, ProfileError};
use profibus_dp::config::gsd::{Gsd, LookupError, SelectionError};
use profibus_dp::config::layout::{ModuleLayout, SlaveLayout};
use profibus_dp::master::{
    DpMaster, MasterConfig, MasterConfigError, MasterOptions, SlaveParams, SlaveState,
};
use profibus_dp::slave::DpSlave;
use profibus_fdl::line::medium::MediumConfig;
use profibus_fdl::sim::{SimBus, StationId};
use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
use profibus_fdl::station::passive::PassiveStation;
use profibus_fdl::{Baud, BusParams, Instant};
use std::time::Duration;

/// The FDL station of a plant's master.
pub type MasterStation = ActiveStation<DpMaster>;

/// The FDL station of a plant's slave.
pub type SlaveStation = PassiveStation<DpSlave<BoxedDevice>>;

/// The station address of a plant's master unless the builder is told
/// otherwise.
pub const MASTER_ADDRESS: u8 = 1;

/// A slave of a plant as its master and a view see it.
#[derive(Debug, Clone)]
pub struct PlantSlave {
    /// Station address.
    pub address: u8,
    /// Its name for people.
    pub name: String,
    /// Its GSD, if it was given one.
    pub gsd: Option<Gsd>,
    /// The GSD modules it is configured with, in slot order.
    pub modules: Vec<String>,
    /// Named channels of its process images, where a profile gives them.
    pub channels: Option<ChannelMap>,
    /// The device profile it runs, if any.
    pub profile: Option<&'static str>,
}

impl PlantSlave {
    /// Its layout as a view sees it: address, name, GSD and the GSD
    /// modules with their spans; the ident number from its GSD; DP-V1 and
    /// capabilities are left unset.
    pub fn layout(&self) -> SlaveLayout {
        SlaveLayout {
            address: self.address,
            name: self.name.clone(),
            ident_number: self.gsd.as_ref().map_or(0, |g| g.ident_number),
            modules: (self.gsd.as_ref())
                .map(|g| ModuleLayout::of_gsd(g, &self.modules))
                .unwrap_or_default(),
            gsd: self.gsd.clone(),
            ..SlaveLayout::default()
        }
    }
}

/// Why a plant cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    /// A device profile refused its options or its configuration.
    #[error("slave {address}: {error}")]
    Profile {
        /// Station address.
        address: u8,
        /// Why (in the message, not also `source()`).
        error: ProfileError,
    },
    /// A generic device cannot be built from its GSD.
    #[error("slave {address}: {error}")]
    Generic {
        /// Station address.
        address: u8,
        /// Why.
        error: GenericError,
    },
    /// A module name matches no module of a slave's GSD.
    #[error(transparent)]
    Module(#[from] LookupError),
    /// A slave's GSD cannot give a configuration.
    #[error(transparent)]
    Selection(#[from] SelectionError),
    /// The master refused its configuration.
    #[error(transparent)]
    Master(#[from] MasterConfigError),
}

/// A slave waiting to be put on the line.
struct Entry {
    slave: PlantSlave,
    /// What the master sends it, when given rather than derived from
    /// the GSD and modules.
    params: Option<SlaveParams>,
    device: BoxedDevice,
}

/// Builds a [`Plant`]: see the crate docs. Defaults: 1.5 Mbit/s with the
/// default bus parameters, an ideal line paced at the baud rate, the
/// master at [`MASTER_ADDRESS`] with default options.
pub struct PlantBuilder {
    params: BusParams,
    medium: Option<MediumConfig>,
    master: u8,
    options: MasterOptions,
    watchdog: Option<Duration>,
    slaves: Vec<Entry>,
}

impl Default for PlantBuilder {
    fn default() -> PlantBuilder {
        PlantBuilder {
            params: BusParams::defaults(Baud::B1500000),
            medium: None,
            master: MASTER_ADDRESS,
            options: MasterOptions::default(),
            watchdog: None,
            slaves: Vec::new(),
        }
    }
}

impl PlantBuilder {
    /// The line rate, with the default bus parameters of that rate.
    pub fn baud(mut self, baud: Baud) -> Self {
        self.params = BusParams::defaults(baud);
        self
    }

    /// The bus parameters every station uses.
    pub fn params(mut self, params: BusParams) -> Self {
        self.params = params;
        self
    }

    /// The line model (faults, seed); default: an ideal line paced at
    /// the baud rate.
    pub fn medium(mut self, medium: MediumConfig) -> Self {
        self.medium = Some(medium);
        self
    }

    /// The master's station address.
    pub fn master(mut self, address: u8) -> Self {
        self.master = address;
        self
    }

    /// The master's poll-cycle options.
    pub fn options(mut self, options: MasterOptions) -> Self {
        self.options = options;
        self
    }

    /// The watchdog time the master gives the slaves whose parameters it
    /// derives from their GSD.
    pub fn watchdog(mut self, watchdog: Duration) -> Self {
        self.watchdog = Some(watchdog);
        self
    }

    /// A slave described by `slave` (the master configures it from its
    /// GSD and modules) running `device`.
    pub fn slave(mut self, slave: PlantSlave, device: BoxedDevice) -> Self {
        self.slaves.push(Entry {
            slave,
            params: None,
            device,
        });
        self
    }

    /// A slave the master configures with `params` as given (Chk_Cfg,
    /// User_Prm_Data and the rest), running `device`.
    pub fn slave_params(mut self, params: SlaveParams, device: BoxedDevice) -> Self {
        let slave = PlantSlave {
            address: params.address,
            name: params.name.clone(),
            gsd: None,
            modules: vec![],
            channels: None,
            profile: None,
        };
        self.slaves.push(Entry {
            slave,
            params: Some(params),
            device,
        });
        self
    }

    /// A slave of the profile called `name` in the registry, as a bus
    /// file with `device = "NAME"` and `options` (`KEY=VALUE`) configures
    /// it, named `label`; its commands arrive in `control`. A profile
    /// that chooses its own address (a rotary switch) keeps it.
    pub fn profile(
        self,
        address: u8,
        label: &str,
        name: &str,
        options: &[&str],
        control: Option<ControlInbox>,
    ) -> Result<Self, PlantError> {
        let e = |error| PlantError::Profile { address, error };
        let mut o = DeviceOptions::new();
        for kv in options {
            o.set_pair(kv).map_err(e)?;
        }
        let p = profibus_devices::profile(name)
            .and_then(|p| p.configure(&o, Some(address)))
            .map_err(e)?;
        let device = p.device(control).map_err(e)?;
        self.configured(address, label, &*p, device)
    }

    /// A slave of a configured profile `profile`, named `label`, running
    /// `device` (e.g. the profile's device prepared by hand).
    pub fn configured(
        self,
        address: u8,
        label: &str,
        profile: &dyn Configured,
        device: BoxedDevice,
    ) -> Result<Self, PlantError> {
        let address = profile.address().unwrap_or(address);
        let e = |error| PlantError::Profile { address, error };
        let channels = profile.channels(&profile.chk_cfg().map_err(e)?).ok();
        let slave = PlantSlave {
            address,
            name: label.into(),
            gsd: Some(profile.gsd().clone()),
            modules: profile.modules(),
            channels,
            profile: Some(profile.name()),
        };
        Ok(self.slave(slave, device))
    }

    /// A generic device of `gsd` with `modules` whose inputs follow
    /// `inputs`.
    pub fn generic(
        self,
        address: u8,
        name: &str,
        gsd: &Gsd,
        modules: &[&str],
        inputs: InputPattern,
    ) -> Result<Self, PlantError> {
        let device = GenericDevice::from_gsd(gsd, modules)
            .map_err(|error| PlantError::Generic { address, error })?
            .with_inputs(inputs);
        let slave = PlantSlave {
            address,
            name: name.into(),
            gsd: Some(gsd.clone()),
            modules: modules.iter().map(|m| m.to_string()).collect(),
            channels: None,
            profile: Some("generic"),
        };
        Ok(self.slave(slave, Box::new(device)))
    }

    /// The master and slaves of a bus file: its master's address, bus
    /// parameters and options, and each slave with the parameters the
    /// file gives, running its device profile's device (without a
    /// control inbox) or, for a slave given by GSD modules, the generic
    /// device whose inputs echo its outputs.
    pub fn bus(
        mut self,
        profiled: &profibus_devices::bus::ProfiledBus,
    ) -> Result<Self, PlantError> {
        let file = &profiled.file;
        self.params = file.master.params;
        self.master = file.master.address;
        self.options = file.master.options.clone();
        for s in &file.slaves {
            let address = s.params.address;
            let profile = profiled.profile(address);
            let device: BoxedDevice = match profile {
                Some(p) => p
                    .device(None)
                    .map_err(|error| PlantError::Profile { address, error })?,
                None => Box::new(
                    GenericDevice::from_gsd(&s.gsd, &s.modules)
                        .map_err(|error| PlantError::Generic { address, error })?,
                ),
            };
            let slave = PlantSlave {
                address,
                name: s.params.name.clone(),
                gsd: Some(s.gsd.clone()),
                modules: s.modules.clone(),
                channels: profiled.channels(address).and_then(Result::ok),
                profile: profile.map(|p| p.name()),
            };
            self.slaves.push(Entry {
                slave,
                params: Some(s.params.clone()),
                device,
            });
        }
        Ok(self)
    }

    /// The master's configuration: each slave's parameters as given, or
    /// from its GSD and modules with the builder's watchdog.
    fn master_config(&self) -> Result<MasterConfig, PlantError> {
        let mut slaves = Vec::with_capacity(self.slaves.len());
        for e in &self.slaves {
            let p = match (&e.params, &e.slave.gsd) {
                (Some(p), _) => p.clone(),
                (None, Some(gsd)) => {
                    let s = &e.slave;
                    let sel = gsd.select(&s.modules)?;
                    let mut p = SlaveParams::new(s.address, gsd.ident_number, gsd.chk_cfg(&sel)?);
                    p.name = s.name.clone();
                    p.user_prm_data = gsd.user_prm_data(&sel, &[])?;
                    p.dpv1 = gsd.dpv1_slave;
                    if self.watchdog.is_some() {
                        p.watchdog = self.watchdog;
                    }
                    p
                }
                (None, None) => unreachable!("slave_params gives the parameters"),
            };
            slaves.push(p);
        }
        Ok(MasterConfig {
            address: self.master,
            params: self.params,
            slaves,
            options: self.options.clone(),
        })
    }

    /// The stations, not yet on a line: for a program that wraps them
    /// (e.g. the soak's recorders) before it adds them to its own
    /// [`SimBus`].
    pub fn stations(self) -> Result<Stations, PlantError> {
        let cfg = self.master_config()?;
        let master = ActiveStation::new(
            ActiveConfig::new(self.master, self.params),
            DpMaster::new(&cfg)?,
        );
        let params = self.params;
        let slaves = (self.slaves.into_iter())
            .map(|e| {
                let station = PassiveStation::new(DpSlave::new(e.device, e.slave.address), params);
                (e.slave, station)
            })
            .collect();
        Ok(Stations {
            medium: self.medium.unwrap_or(MediumConfig::paced(params.baud)),
            params,
            master,
            slaves,
        })
    }

    /// The plant: the master, then the slaves in the order given, on one
    /// simulated line.
    pub fn build(self) -> Result<Plant, PlantError> {
        let s = self.stations()?;
        let mut bus = SimBus::new(s.medium);
        let master = bus.add(s.master);
        let mut slaves = Vec::with_capacity(s.slaves.len());
        let mut ids = Vec::with_capacity(s.slaves.len());
        for (slave, station) in s.slaves {
            ids.push(bus.add(station));
            slaves.push(slave);
        }
        Ok(Plant {
            bus,
            master,
            slaves,
            ids,
            params: s.params,
        })
    }
}

/// A plant's stations before they are on a line
/// ([`PlantBuilder::stations`]).
pub struct Stations {
    /// The line model.
    pub medium: MediumConfig,
    /// The bus parameters of every station.
    pub params: BusParams,
    /// The master.
    pub master: MasterStation,
    /// The slaves with their descriptions, in bus order.
    pub slaves: Vec<(PlantSlave, SlaveStation)>,
}

/// A DP master and its slaves on one simulated line; see the crate docs.
pub struct Plant {
    bus: SimBus,
    master: StationId,
    slaves: Vec<PlantSlave>,
    ids: Vec<StationId>,
    params: BusParams,
}

impl Plant {
    /// A builder with the defaults of [`PlantBuilder`].
    pub fn builder() -> PlantBuilder {
        PlantBuilder::default()
    }

    /// The plant of a bus file ([`PlantBuilder::bus`]).
    pub fn from_bus(profiled: &profibus_devices::bus::ProfiledBus) -> Result<Plant, PlantError> {
        Plant::builder().bus(profiled)?.build()
    }

    /// The slaves, in bus order.
    pub fn slaves(&self) -> &[PlantSlave] {
        &self.slaves
    }

    /// The bus parameters of the stations.
    pub fn params(&self) -> BusParams {
        self.params
    }

    /// The master's DP application.
    pub fn master(&mut self) -> &mut DpMaster {
        self.bus.station_mut::<MasterStation>(self.master).app_mut()
    }

    /// The master's DP application, read-only.
    pub fn master_ref(&self) -> &DpMaster {
        self.bus.station::<MasterStation>(self.master).app()
    }

    /// The master's FDL station.
    pub fn master_station(&mut self) -> &mut MasterStation {
        self.bus.station_mut::<MasterStation>(self.master)
    }

    /// The station of the slave at `address`.
    pub fn slave_station(&mut self, address: u8) -> Option<&mut SlaveStation> {
        let i = self.slaves.iter().position(|s| s.address == address)?;
        Some(self.bus.station_mut::<SlaveStation>(self.ids[i]))
    }

    /// Switch the slave at `address` off (a pulled plug) or on again.
    pub fn set_online(&mut self, address: u8, online: bool) {
        if let Some(i) = self.slaves.iter().position(|s| s.address == address) {
            self.bus.set_online(self.ids[i], online);
        }
    }

    /// The simulated line, e.g. for a tap or stations of a test's own.
    pub fn bus(&mut self) -> &mut SimBus {
        &mut self.bus
    }

    /// Virtual time of the line.
    pub fn now(&self) -> Instant {
        self.bus.now()
    }

    /// Run the line up to `t` (virtual time since the start).
    pub fn run_until(&mut self, t: Instant) {
        self.bus.run_until(t);
    }

    /// Run the line for `d` of virtual time.
    pub fn run_for(&mut self, d: Duration) {
        self.bus.run_for(d);
    }

    /// Whether the master has every slave in Data_Exchange.
    pub fn all_in_data_exchange(&self) -> bool {
        let m = self.master_ref();
        (self.slaves.iter()).all(|s| m.slave_state(s.address) == Some(SlaveState::DataExchange))
    }

    /// Run until `done` holds for the master (checked after every event)
    /// or `limit` of virtual time passed; returns whether it held.
    pub fn run_while(&mut self, limit: Duration, mut done: impl FnMut(&DpMaster) -> bool) -> bool {
        let id = self.master;
        self.bus
            .run_while(limit, |b| done(b.station::<MasterStation>(id).app()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_devices::gsd_files;

    #[test]
    fn a_builder_plant_reaches_data_exchange_and_echoes() {
        let gsd = gsd_files::parse(gsd_files::DPCTL_GEN).unwrap();
        let mut plant = Plant::builder()
            .watchdog(Duration::from_millis(200))
            .generic(3, "echo", &gsd, &["2 words in/out"], InputPattern::Echo)
            .unwrap()
            .profile(25, "omega", "omega", &[], None)
            .unwrap()
            .build()
            .unwrap();
        assert_eq!(plant.slaves()[1].profile, Some("omega"));
        assert!(plant.slaves()[1].channels.is_some());
        plant.run_for(Duration::from_millis(500));
        assert!(plant.all_in_data_exchange());
        plant.master().set_outputs(3, &[1, 2, 3, 4]);
        assert!(plant.run_while(Duration::from_secs(1), |m| {
            m.inputs(3).is_some_and(|i| i.starts_with(&[1, 2, 3, 4]))
        }));
    }

    #[test]
    fn a_bad_profile_option_names_the_slave() {
        let e = Plant::builder()
            .profile(6, "bm4", "bm4", &["nope=1"], None)
            .err()
            .unwrap();
        assert!(e.to_string().starts_with("slave 6: "), "{e}");
        assert!(std::error::Error::source(&e).is_none());
    }
}
