//! Bus files whose slaves may name a device profile (`device = "bm4"`
//! plus its options instead of `gsd` and `modules`): the profile registry
//! as the bus file's [`DeviceResolver`], and the named channels of those
//! slaves for the master.

use crate::channels::{ChannelError, ChannelMap, OutputWrite, OutputWriteError, Value};
use crate::profile::{Configured, DeviceOptions, ProfileError};
use crate::rfid::jobs::{MasterJobs, QueueError};
use profibus_dp::config::busfile::{
    BusFile, BusFileError, DeviceEntry, DeviceError, DeviceResolver, ResolvedDevice,
};
use profibus_dp::config::layout::SlaveLayout;
use profibus_dp::master::{CommandError, DpMaster};
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::Path;

/// A loaded bus file with the configured profiles of its `device`
/// slaves.
#[derive(Debug)]
pub struct ProfiledBus {
    /// The bus file.
    pub file: BusFile,
    profiles: Vec<(u8, Box<dyn Configured>)>,
}

/// The registry as a [`DeviceResolver`], keeping what it configured.
#[derive(Default)]
struct Registry {
    configured: RefCell<Vec<(u8, Box<dyn Configured>)>>,
}

impl DeviceResolver for Registry {
    fn resolve(&self, entry: &DeviceEntry, address: u8) -> Result<ResolvedDevice, DeviceError> {
        let p = crate::profile(&entry.name).map_err(DeviceError::new)?;
        let mut options = DeviceOptions::from_table(entry.options.clone());
        options.paths_relative_to(&entry.dir, p.path_options);
        // A vendor's GSD next to `device` (crate::identity).
        if !p.path_options.contains(&"gsd") {
            options.paths_relative_to(&entry.dir, &["gsd"]);
        }
        let profile = p.configure(&options, Some(address)).map_err(|e| {
            let message = format!("device `{}`: {e}", p.name);
            // A module the GSD lacks is about the option naming modules.
            let option = match &e {
                ProfileError::Module(_) if options.get("modules").is_some() => Some("modules"),
                e => e.option(),
            };
            match option {
                Some(key) => DeviceError::at_option(key, message),
                None => DeviceError::new(message),
            }
        })?;
        let resolved = ResolvedDevice {
            gsd: profile.gsd().clone(),
            modules: profile.modules(),
        };
        self.configured.borrow_mut().push((address, profile));
        Ok(resolved)
    }
}

impl ProfiledBus {
    /// Read and check a bus file (see `profibus_dp::config::busfile`), resolving
    /// `device = "NAME"` slaves with the profile registry.
    pub fn load(path: impl AsRef<Path>) -> Result<ProfiledBus, BusFileError> {
        Self::with_registry(|r| BusFile::load_with(path, r))
    }

    /// [`ProfiledBus::load`] from text; GSD paths are relative to `path`'s
    /// directory.
    pub fn parse(path: &Path, text: &str) -> Result<ProfiledBus, BusFileError> {
        Self::with_registry(|r| BusFile::parse_with(path, text, r))
    }

    fn with_registry(
        load: impl FnOnce(&Registry) -> Result<BusFile, BusFileError>,
    ) -> Result<ProfiledBus, BusFileError> {
        let registry = Registry::default();
        let file = load(&registry)?;
        Ok(ProfiledBus {
            file,
            profiles: registry.configured.into_inner(),
        })
    }

    /// The configured profile of the slave at `address`, if it was given
    /// as one.
    pub fn profile(&self, address: u8) -> Option<&dyn Configured> {
        self.profiles
            .iter()
            .find(|(a, _)| *a == address)
            .map(|(_, p)| p.as_ref())
    }

    /// The configured-slave layouts of the bus file's slaves, in bus
    /// order: modules with their byte spans, and capabilities from each
    /// slave's profile ([`crate::capabilities`]).
    pub fn layouts(&self) -> Vec<SlaveLayout> {
        (self.file.slaves.iter())
            .map(|s| SlaveLayout {
                capabilities: crate::capabilities(s.params.ident_number, &s.params.cfg),
                ..SlaveLayout::of_slave(s)
            })
            .collect()
    }

    /// The named channels of the slave at `address` for the configuration
    /// the master sends it; `None` for a slave given by GSD modules.
    pub fn channels(&self, address: u8) -> Option<Result<ChannelMap, ProfileError>> {
        let profile = self.profile(address)?;
        let slave = self
            .file
            .slaves
            .iter()
            .find(|s| s.params.address == address)?;
        Some(profile.channels(&slave.params.cfg))
    }
}

/// `{"slave": N, "set": {"NAME": VALUE, …}}`: a master command (`dpctl
/// master --input`) that writes outputs by channel name, for slaves with
/// named channels (given as `device = …` in the bus file).
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetChannels {
    /// Station address of the slave.
    pub slave: u8,
    /// The values, by channel name.
    pub set: BTreeMap<String, Value>,
}

/// Why a [`SetChannels`] command was refused.
#[derive(Debug, thiserror::Error)]
pub enum SetChannelsError {
    /// The line is not a valid command.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The slave has no named channels.
    #[error("slave {0} has no named channels (give it as `device = …` in the bus file)")]
    NoChannels(u8),
    /// The master has no such slave.
    #[error("slave not in the bus file")]
    UnknownSlave,
    /// A name or value does not fit the channels.
    #[error(transparent)]
    Channel(#[from] ChannelError),
}

impl SetChannels {
    /// The command in `line`; `None` when `line` is not a channel command
    /// (not a JSON object with `"set"`).
    pub fn from_json(line: &str) -> Option<Result<SetChannels, SetChannelsError>> {
        let v: serde_json::Value = serde_json::from_str(line).ok()?;
        v.get("set")?;
        Some(serde_json::from_value(v).map_err(Into::into))
    }

    /// Write the slave's outputs in `m` through `map`, its channels: all
    /// values or none.
    pub fn apply(
        &self,
        m: &mut DpMaster,
        map: Option<&ChannelMap>,
    ) -> Result<(), SetChannelsError> {
        let map = map.ok_or(SetChannelsError::NoChannels(self.slave))?;
        let h = m.handle(self.slave).ok_or(SetChannelsError::UnknownSlave)?;
        // The rule every output write follows (`OutputWrite`).
        let values = self.set.iter().map(|(k, v)| (k.clone(), *v)).collect();
        let image = OutputWrite::Channels(values)
            .apply(self.slave, m.outputs_mut(h), Some(map), None)
            .map_err(|e| match e {
                OutputWriteError::Channel { error, .. } => SetChannelsError::Channel(error),
                _ => SetChannelsError::NoChannels(self.slave),
            })?;
        m.outputs_mut(h).copy_from_slice(&image);
        Ok(())
    }
}

/// Why a command line of `dpctl master --input` was refused.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// A channel write ([`SetChannels`]).
    #[error(transparent)]
    Channels(#[from] SetChannelsError),
    /// An RFID reader command ([`MasterJobs::command`]).
    #[error(transparent)]
    Rfid(#[from] QueueError),
    /// A command of the master itself ([`MasterCommand`]).
    ///
    /// [`MasterCommand`]: profibus_dp::master::MasterCommand
    #[error(transparent)]
    Master(#[from] CommandError),
}

/// Run one command line of `dpctl master --input` on `m`: a channel
/// write by name (the slave's channels from `channels`), a command for
/// the RFID readers of `rfid`, else a command of the master itself. The
/// reply to show, if any.
pub fn execute_input<'a>(
    m: &mut DpMaster,
    channels: impl Fn(u8) -> Option<&'a ChannelMap>,
    rfid: &mut MasterJobs,
    line: &str,
) -> Result<Option<String>, InputError> {
    if let Some(c) = SetChannels::from_json(line) {
        let c = c?;
        c.apply(m, channels(c.slave))?;
        return Ok(None);
    }
    match rfid.command(m, line) {
        Some(r) => Ok(Some(r?)),
        None => Ok(m.execute_json(line)?),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::channels::{Direction, Value};

    /// A bus file of master 2 at 1.5 Mbit/s with the `[[slave]]` tables
    /// `$slaves`.
    macro_rules! bus_text {
        ($slaves:literal) => {
            concat!("[master]\naddress = 2\nbaud = \"1.5M\"\n\n", $slaves)
        };
    }

    #[test]
    fn layouts_give_module_spans_and_the_profiles_capabilities() {
        use profibus_dp::config::layout::{Capabilities, Span};
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("gsd/bus.toml");
        let text = bus_text!(
            "[[slave]]\naddress = 25\ndevice = \"omega\"\n\n[[slave]]\naddress = 30\ndevice = \"rfid\"\n"
        );
        let bus = ProfiledBus::parse(&dir, text).unwrap();
        let l = bus.layouts();
        assert_eq!((l[0].address, l[1].address), (25, 30));
        assert_eq!(l[0].capabilities, Capabilities::PKW);
        assert_eq!(l[1].capabilities, Capabilities::RFID);
        // The Omega's PKW module first: 8 bytes each way, then the rest.
        let m = &l[0].modules;
        assert_eq!(m[0].inputs, Span { offset: 0, len: 8 });
        assert_eq!(m[1].inputs.offset, 8);
    }

    #[test]
    fn set_channels_commands_write_named_outputs_all_or_none() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("gsd/bus.toml");
        let text = bus_text!(
            "[[slave]]\naddress = 25\ndevice = \"omega\"\nsetpoints = 1\nactual_values = 1\npkw = false\n"
        );
        let bus = ProfiledBus::parse(&dir, text).unwrap();
        let map = bus.channels(25).unwrap().unwrap();
        let mut m = DpMaster::new(&bus.file.master).unwrap();
        assert!(SetChannels::from_json(r#"{"operating": "clear"}"#).is_none());
        assert!(SetChannels::from_json("not json").is_none());
        let parse = |line: &str| SetChannels::from_json(line).unwrap();
        let set = parse(r#"{"slave": 25, "set": {"setpoint1": 1500}}"#).unwrap();
        set.apply(&mut m, Some(&map)).unwrap();
        let written: Vec<(String, Value)> = map
            .decode(Direction::Output, m.outputs(25).unwrap())
            .map(|(c, v)| (c.name.clone(), v))
            .collect();
        assert!(
            written.contains(&("setpoint1".into(), Value::Int(1500))),
            "{written:?}"
        );
        // Refused: nothing changes.
        let before = m.outputs(25).unwrap().to_vec();
        let bad = parse(r#"{"slave": 25, "set": {"setpoint1": 1, "nope": 2}}"#).unwrap();
        assert!(matches!(
            bad.apply(&mut m, Some(&map)),
            Err(SetChannelsError::Channel(_))
        ));
        assert_eq!(m.outputs(25).unwrap(), before);
        let e = set.apply(&mut m, None).unwrap_err().to_string();
        assert!(e.starts_with("slave 25 has no named channels"), "{e}");
        assert!(parse(r#"{"slave": 25, "set": {}, "x": 1}"#).is_err());
        let other = parse(r#"{"slave": 9, "set": {"setpoint1": 1}}"#).unwrap();
        assert!(matches!(
            other.apply(&mut m, Some(&map)),
            Err(SetChannelsError::UnknownSlave)
        ));
    }

    #[test]
    fn bm4_and_omega_from_a_bus_file() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("gsd/bus.toml");
        let text = bus_text!(
            r#"[[slave]]
address = 6
device = "bm4"
vars = "../data/bm4_example_vars.toml"
modules = ["ud_MyReadVar1", "ud_MyWriteVar1"]
"#
        );
        // `modules` is a slave key: a profile chooses its own.
        assert!(ProfiledBus::parse(&dir, text).is_err());
        let text = text.replace("modules", "varz");
        let e = ProfiledBus::parse(&dir, &text).unwrap_err();
        assert!(e.message.contains("varz"), "{e}");
        let bus = ProfiledBus::parse(&dir, &text.replace("varz", "variables")).unwrap();
        assert_eq!(
            bus.file.slaves[0].modules[1..],
            ["ud_MyReadVar1", "ud_MyWriteVar1"]
        );
        let text = bus_text!(
            r#"[[slave]]
address = 6
device = "bm4"
vars = "BM4_VARS"

[[slave]]
address = 25
device = "omega"
setpoints = 1
actual_values = 1
pkw = false
"#
        )
        .replace(
            "BM4_VARS",
            concat!(env!("CARGO_MANIFEST_DIR"), "/data/bm4_example_vars.toml"),
        );
        let bus = ProfiledBus::parse(&dir, &text).unwrap();
        let bm4 = &bus.file.slaves[0];
        assert_eq!(bm4.params.ident_number, crate::bm4::IDENT);
        assert_eq!(bm4.params.cfg[0], crate::pkw::PKW_MODULE);
        assert_eq!(bm4.device.as_ref().unwrap().name, "bm4");
        let dialect = crate::pkw_dialect(bm4.params.ident_number, &bm4.params.cfg).unwrap();
        assert_eq!(dialect.name, crate::bm4::PKW.name);
        let ch = bus.channels(6).unwrap().unwrap();
        assert!(ch.find(Direction::Output, "ud_MyWriteVar1").is_some());
        let omega = &bus.file.slaves[1];
        assert_eq!(omega.params.cfg, [0x71, 0x51, 0x61]);
        let ch = bus.channels(25).unwrap().unwrap();
        let mut inputs = [0u8; 8];
        inputs[0] = 0x02; // status word 1: Remote
        inputs[4..8].copy_from_slice(&1234i32.to_be_bytes());
        let values: Vec<(String, Value)> = ch
            .decode(Direction::Input, &inputs)
            .map(|(c, v)| (c.name.clone(), v))
            .collect();
        assert_eq!(
            values,
            [
                ("status1".to_string(), Value::Int(0x0200)),
                ("status2".to_string(), Value::Int(0)),
                ("actual1".to_string(), Value::Int(1234)),
            ]
        );
        assert!(bus.profile(25).is_some() && bus.channels(7).is_none());
        // Profile options are checked by the profile.
        let e =
            ProfiledBus::parse(&dir, &text.replace("setpoints = 1", "setpoints = 9")).unwrap_err();
        assert!(e.message.contains("si_NR_WR_VALUE"), "{e}");
    }

    #[test]
    fn file_options_are_relative_to_the_bus_file() {
        // Every profile whose options name a file declares them.
        for (name, key) in [
            ("bk3000", "terminals_file"),
            ("jx2", "script"),
            ("rfid", "tags"),
            ("bm4", "vars"),
            ("omega", "params"),
            ("generic", "gsd"),
        ] {
            let p = crate::profile(name).unwrap();
            assert!(p.path_options.contains(&key), "{name}: {key}");
        }
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().to_path_buf();
        std::fs::write(dir.join("strip.txt"), "KL1104,KL2134,KL9010").unwrap();
        let text = bus_text!(
            r#"[[slave]]
address = 11
device = "bk3000"
terminals_file = "strip.txt"
"#
        );
        // Read from elsewhere: the file is found next to the bus file.
        let bus = ProfiledBus::parse(&dir.join("bus.toml"), text);
        let bus = bus.unwrap();
        assert_eq!(bus.file.slaves[0].params.address, 11);
    }

    #[test]
    fn profile_options_named_like_slave_keys_go_under_the_profile_name() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("gsd/bus.toml");
        // Omega's `params` (a parameter file) and generic's `gsd` and
        // `modules`: under the profile's name, relative to the bus file.
        let text = bus_text!(
            r#"[[slave]]
address = 25
device = "omega"
pkw = false
omega.params = "../data/omega_vparams.toml"

[[slave]]
address = 7
device = "generic"
generic.gsd = "BNF_00D0.GSD"
generic.modules = ["Status / control module", "1 actual value, 1 setpoint"]
lenient = true
"#
        );
        let bus = ProfiledBus::parse(&dir, text).unwrap();
        let omega = &bus.file.slaves[0];
        let params = omega.device.as_ref().unwrap().options.get("params");
        assert_eq!(
            params.and_then(|v| v.as_str()),
            Some("../data/omega_vparams.toml")
        );
        let generic = &bus.file.slaves[1];
        assert_eq!(generic.modules.len(), 2, "{:?}", generic.modules);
        assert_eq!(bus.profile(7).unwrap().name(), "generic");
        // The file is read by the profile: a wrong name says so.
        let e = ProfiledBus::parse(&dir, &text.replace("omega_vparams", "nope")).unwrap_err();
        assert!(e.message.contains("nope"), "{e}");
        // At the top of the table they are slave keys, refused with the
        // place the option goes.
        let e = ProfiledBus::parse(&dir, &text.replace("omega.params", "params")).unwrap_err();
        assert_eq!(e.line, 9, "{e}");
        assert!(e.message.contains("`omega.params = …`"), "{e}");
        // `gsd` next to `device` is the profile's `gsd` (for the generic
        // profile its own GSD file; crate::identity for the others).
        let bus = ProfiledBus::parse(&dir, &text.replace("generic.gsd", "gsd")).unwrap();
        assert_eq!(bus.profile(7).unwrap().gsd().ident_number, 0x00D0);
        let both = text.replace(
            "generic.gsd = \"BNF_00D0.GSD\"\n",
            "gsd = \"BNF_00D0.GSD\"\ngeneric.gsd = \"BNF_00D0.GSD\"\n",
        );
        let e = ProfiledBus::parse(&dir, &both).unwrap_err();
        assert!(e.message.contains("both given"), "{e}");
    }
}

/// Every profile's defaults reach Data_Exchange: a bus file with only
/// `address` and `device` (the generic profile needs its GSD file, and
/// modules where the GSD names none by default) configures the master, and the
/// profile's own slave emulation, configured with no options, accepts
/// that configuration on the simulated bus.
#[cfg(test)]
mod defaults {
    use super::*;
    use crate::jx2::script::Interpreter;
    use profibus_dp::master::{DpMaster, SlaveState};
    use profibus_dp::slave::DpSlave;
    use profibus_fdl::line::medium::MediumConfig;
    use profibus_fdl::sim::SimBus;
    use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
    use profibus_fdl::station::passive::PassiveStation;
    use profibus_fdl::time::Instant;
    use std::time::Duration;

    /// The options a profile cannot do without, as bus-file lines: the
    /// generic device needs its GSD file and, for a modular station
    /// without `Preset` modules (DPCTL_GEN.GSD), its modules.
    fn required(name: &str) -> &'static str {
        match name {
            "generic" => {
                "generic.gsd = \"DPCTL_GEN.GSD\"\ngeneric.modules = [\"2 words in/out\"]\n"
            }
            _ => "",
        }
    }

    #[test]
    fn every_profile_reaches_data_exchange_with_its_defaults() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("gsd/bus.toml");
        for p in crate::PROFILES {
            let text = format!(
                "[master]\naddress = 2\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 7\ndevice = \"{}\"\n{}",
                p.name,
                required(p.name)
            );
            let bus = ProfiledBus::parse(&dir, &text)
                .unwrap_or_else(|e| panic!("{}: the bus file is refused: {e}", p.name));
            let cfg = &bus.file.master;
            let params = cfg.params;
            let mut sim = SimBus::new(MediumConfig::paced(params.baud));
            let m = sim.add(ActiveStation::new(
                ActiveConfig::new(cfg.address, params),
                DpMaster::new(cfg).unwrap(),
            ));
            // The slave side: the same profile with the same options, as
            // `dpctl slave --device NAME --addr 7` runs it.
            let mut options =
                DeviceOptions::from_table(bus.file.slaves[0].device.clone().unwrap().options);
            options.paths_relative_to(dir.parent().unwrap(), p.path_options);
            let slave = p
                .configure(&options, Some(7))
                .unwrap_or_else(|e| panic!("{}: {e}", p.name));
            let address = slave.address().unwrap_or(7);
            assert_eq!(address, 7, "{}", p.name);
            let device = match p.name {
                // The JX2-PROFI1 joins the bus once its PLC writes the
                // station address to 1x107 (docs/devices/jx2.md): here
                // the PLC program that does, as on a real installation.
                "jx2" => {
                    let mut plc = crate::jx2::Plc::new(2).unwrap();
                    let mut init = Interpreter::script("write 12107 7\n").unwrap();
                    init.run(&mut plc, Instant::ZERO);
                    plc.module.settle(Instant::ZERO + crate::jx2::INIT_TIME);
                    Box::new(crate::jx2::ScriptedJx2::new(plc, Interpreter::new(), None))
                }
                _ => slave.device(None).unwrap(),
            };
            sim.add(PassiveStation::new(DpSlave::new(device, address), params));
            let state = |sim: &SimBus| {
                sim.station::<ActiveStation<DpMaster>>(m)
                    .app()
                    .slave_state(7)
            };
            for _ in 0..200 {
                sim.run_for(Duration::from_millis(10));
                if state(&sim) == Some(SlaveState::DataExchange) {
                    break;
                }
            }
            assert_eq!(
                state(&sim),
                Some(SlaveState::DataExchange),
                "{}: {text}",
                p.name
            );
        }
    }
}

/// A master set up from a vendor's GSD file (another ident number, other
/// module names, User_Prm_Data the emulation does not know) reaches
/// Data_Exchange with the profile given that file (`gsd = "…"` next to
/// `device`, crate::identity), and an `ident` alone changes the ident
/// number both sides use.
#[cfg(test)]
mod vendor_identity {
    use super::*;
    use profibus_dp::master::{DpMaster, SlaveState};
    use profibus_dp::slave::DpSlave;
    use profibus_fdl::line::medium::MediumConfig;
    use profibus_fdl::sim::SimBus;
    use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
    use profibus_fdl::station::passive::PassiveStation;
    use std::time::Duration;

    /// The bus file `text` in `dir`: the master from it and the slave at
    /// 7 as `dpctl slave --device NAME` runs it with the same options; the
    /// slave's state after at most 2 s and the ident number the master
    /// sent.
    fn run(dir: &Path, text: &str) -> (Option<SlaveState>, u16) {
        run_with(dir, text, None)
    }

    /// [`run`] with the slave configured from `slave` (name, options)
    /// instead of the bus file's entry.
    fn run_with(
        dir: &Path,
        text: &str,
        slave: Option<(&str, DeviceOptions)>,
    ) -> (Option<SlaveState>, u16) {
        let bus = ProfiledBus::parse(&dir.join("bus.toml"), text).unwrap_or_else(|e| panic!("{e}"));
        let cfg = &bus.file.master;
        let params = cfg.params;
        let mut sim = SimBus::new(MediumConfig::paced(params.baud));
        let m = sim.add(ActiveStation::new(
            ActiveConfig::new(cfg.address, params),
            DpMaster::new(cfg).unwrap(),
        ));
        let (p, mut options) = match slave {
            Some((name, o)) => (crate::profile(name).unwrap(), o),
            None => {
                let entry = bus.file.slaves[0].device.clone().unwrap();
                let o = DeviceOptions::from_table(entry.options);
                (crate::profile(&entry.name).unwrap(), o)
            }
        };
        options.paths_relative_to(dir, &["gsd"]);
        let slave = p
            .configure(&options, Some(7))
            .unwrap_or_else(|e| panic!("{e}"));
        let device = slave.device(None).unwrap();
        sim.add(PassiveStation::new(DpSlave::new(device, 7), params));
        let state = |sim: &SimBus| {
            sim.station::<ActiveStation<DpMaster>>(m)
                .app()
                .slave_state(7)
        };
        for _ in 0..200 {
            sim.run_for(Duration::from_millis(10));
            if state(&sim) == Some(SlaveState::DataExchange) {
                break;
            }
        }
        (state(&sim), bus.file.slaves[0].params.ident_number)
    }

    const MASTER: &str = "[master]\naddress = 2\nbaud = \"1.5M\"\n\n";

    #[test]
    fn a_master_from_the_vendors_gsd_reaches_data_exchange() {
        let dir = tempfile::tempdir().unwrap();
        // "AEG's" file: its own ident number, module name and two bytes of
        // User_Prm_Data the reader's manual does not describe.
        let ours = String::from_utf8_lossy(crate::gsd_files::AEGI0DC4).to_string();
        let vendor = ours
            .replace("Ident_Number=0x0DC4", "Ident_Number=0x08AE")
            .replace(
                "User_Prm_Data_Len=0",
                "User_Prm_Data_Len=2\nUser_Prm_Data=0x12,0x34",
            );
        let vendor = vendor.replacen("Module=\"", "Module=\"AEG ", 1);
        assert_ne!(vendor, ours);
        std::fs::write(dir.path().join("AEG.GSD"), &vendor).unwrap();
        let text =
            format!("{MASTER}[[slave]]\naddress = 7\ndevice = \"rfid\"\ngsd = \"AEG.GSD\"\n");
        let bus = ProfiledBus::parse(&dir.path().join("bus.toml"), &text).unwrap();
        let s = &bus.file.slaves[0];
        assert_eq!(s.params.ident_number, 0x08AE, "the vendor's ident");
        assert!(
            s.modules.iter().all(|m| m.starts_with("AEG ")),
            "{:?}",
            s.modules
        );
        assert_eq!(
            s.params.user_prm_data,
            [0x12, 0x34],
            "the vendor's parameters"
        );
        assert_eq!(
            run(dir.path(), &text),
            (Some(SlaveState::DataExchange), 0x08AE)
        );
        // Without the vendor's file the emulation refuses that master
        // (Prm_Fault: another ident number).
        let (state, _) = run_with(dir.path(), &text, Some(("rfid", DeviceOptions::new())));
        assert_ne!(state, Some(SlaveState::DataExchange));
        // Jetter's file for the JX2-PROFI1: another ident number and
        // module names (the PLC program writes the station address).
        let ours = String::from_utf8_lossy(crate::jx2::GSD).to_string();
        let vendor = ours
            .replace("Ident_Number=0x0DC3", "Ident_Number=0x0815")
            .replace("Module=\"", "Module=\"Jetter ");
        std::fs::write(dir.path().join("JETTER.GSD"), vendor).unwrap();
        let script = dir.path().join("plc.txt");
        std::fs::write(&script, "write 12107 7\n").unwrap();
        let jx2 = format!(
            "{MASTER}[[slave]]\naddress = 7\ndevice = \"jx2\"\ngsd = \"JETTER.GSD\"\nscript = {:?}\n",
            script.display().to_string()
        );
        let bus = ProfiledBus::parse(&dir.path().join("bus.toml"), &jx2).unwrap();
        assert!(bus.file.slaves[0]
            .modules
            .iter()
            .all(|m| m.starts_with("Jetter ")));
        assert_eq!(
            run(dir.path(), &jx2),
            (Some(SlaveState::DataExchange), 0x0815)
        );
        // With the vendor's file and `ident`: `ident` wins.
        let both = format!("{text}ident = 0x0ABC\n");
        assert_eq!(
            run(dir.path(), &both),
            (Some(SlaveState::DataExchange), 0x0ABC)
        );
    }

    #[test]
    fn ident_alone_changes_the_ident_number_of_every_profile() {
        let dir = tempfile::tempdir().unwrap();
        for (name, extra) in [("omega", ""), ("bm4", ""), ("rfid", ""), ("bk3000", "")] {
            let text = format!(
                "{MASTER}[[slave]]\naddress = 7\ndevice = \"{name}\"\nident = \"0x1234\"\n{extra}"
            );
            assert_eq!(
                run(dir.path(), &text),
                (Some(SlaveState::DataExchange), 0x1234),
                "{name}"
            );
        }
        let text = format!("{MASTER}[[slave]]\naddress = 7\ndevice = \"omega\"\nident = 0x10000\n");
        let e = ProfiledBus::parse(&dir.path().join("bus.toml"), &text).unwrap_err();
        assert!(e.message.contains("option `ident`"), "{e}");
    }
}
