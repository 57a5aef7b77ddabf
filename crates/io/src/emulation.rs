//! Running a device as a DP slave on a port: what `dpctl slave` does, for
//! any program that emulates a device.
//!
//! - [`DeviceChoice`]: the device to emulate and its options; it
//!   configures the profile from the [registry](profibus_devices::PROFILES).
//! - [`BaudChoice`]: a fixed rate, or the search of a slave with
//!   `Auto_Baud_supp` (on a pty or a serial server the rate is nominal).
//! - [`SlaveShell`]: runs a [`DpSlave`] with
//!   [`PassiveRunner`] (search again
//!   after a watchdog expiry), keeps what the device reports outside its
//!   request path (an accepted Set_Slave_Add in the profile's address
//!   file, [`STATE_EVENT`] state in its state file) and reports
//!   everything as [`Emitted`] events (`Display` for text, `Serialize`
//!   for JSON lines).

use crate::driver::Clock;
use crate::runner::{PassiveRunner, RunnerError, RunnerEvent, Step};
use crate::transport::Port;
use profibus_devices::address::StoredAddress;
use profibus_devices::{Configured, DeviceOptions, ProfileEntry, ProfileError, STATE_EVENT};
use profibus_dp::slave::{Device, DpSlave, OwnAddress, SlaveEvent, SlaveState, SlaveStats};
use profibus_fdl::station::autobaud::BaudSet;
use profibus_fdl::wire::Hex;
use profibus_fdl::{Baud, Instant};
use std::fmt;
use std::future::Future;
use std::path::PathBuf;

/// The device a slave emulates: a profile of the
/// [registry](profibus_devices::PROFILES) by name, or (`device: None`) the
/// generic device of a GSD file named in the options (`gsd`, with
/// `modules`, `lenient`, `inputs`). `dpctl slave` fills it from its flags.
#[derive(Debug, Clone, Default)]
pub struct DeviceChoice {
    /// The profile's name; `None`: the generic device of a GSD file.
    pub device: Option<String>,
    /// The profile's options (the keys its options struct decodes).
    pub options: DeviceOptions,
}

/// Why a [`DeviceChoice`] gives no device.
#[derive(Debug, thiserror::Error)]
pub enum EmulationError {
    /// Neither a profile nor a GSD file.
    #[error("give --gsd FILE (with --module NAME …) or --device NAME")]
    NoDevice,
    /// The profile named is not in the registry.
    #[error("{0}; or use --gsd FILE")]
    UnknownProfile(ProfileError),
    /// The profile refused its options.
    #[error("device `{name}`: {error}")]
    Profile {
        /// The profile.
        name: &'static str,
        /// Why (in the message, not also the error's source, so that a
        /// printed chain says it once).
        error: ProfileError,
    },
    /// The generic device or the options are refused.
    #[error(transparent)]
    Plain(#[from] ProfileError),
}

/// A configured profile with its name for people.
#[derive(Debug)]
pub struct Emulated {
    /// The registry row.
    pub entry: &'static ProfileEntry,
    /// The configured profile.
    pub profile: Box<dyn Configured>,
    /// The device's name for people: the profile's, or the GSD's model.
    pub name: String,
}

impl DeviceChoice {
    fn in_words(&self, e: ProfileError) -> EmulationError {
        match &self.device {
            Some(_) => EmulationError::Profile {
                name: self.entry().map_or("", |e| e.name),
                error: e,
            },
            None => EmulationError::Plain(e),
        }
    }

    fn entry(&self) -> Result<&'static ProfileEntry, EmulationError> {
        match &self.device {
            Some(name) => profibus_devices::profile(name).map_err(EmulationError::UnknownProfile),
            None => Ok(profibus_devices::profile("generic")?),
        }
    }

    /// Configure the profile; `address` is the caller's station address
    /// for it, if any.
    pub fn configure(&self, address: Option<u8>) -> Result<Emulated, EmulationError> {
        if self.device.is_none() && self.options.get("gsd").is_none() {
            return Err(EmulationError::NoDevice);
        }
        let entry = self.entry()?;
        let profile = entry
            .configure(&self.options, address)
            .map_err(|e| self.in_words(e))?;
        let name = match &self.device {
            Some(_) => entry.name.to_string(),
            None => {
                let gsd = profile.gsd();
                (gsd.model_name.clone())
                    .unwrap_or_else(|| format!("ident 0x{:04X}", gsd.ident_number))
            }
        };
        Ok(Emulated {
            entry,
            profile,
            name,
        })
    }

    /// [`Configured::device`] with errors in words.
    pub fn device(
        &self,
        e: &Emulated,
        control: Option<profibus_devices::ControlInbox>,
    ) -> Result<profibus_devices::BoxedDevice, EmulationError> {
        e.profile.device(control).map_err(|e| self.in_words(e))
    }
}

/// How a slave chooses its baud rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BaudChoice {
    /// This rate.
    Fixed(Baud),
    /// Search on a serial line; on a pty or a serial server
    /// ([`BaudChoice::NOMINAL`]) the rate is nominal.
    Auto,
    /// Search even on a pty (every rate passes the bytes there, so it
    /// locks at the first rate that sees a valid telegram).
    Search,
}

impl std::str::FromStr for BaudChoice {
    type Err = profibus_fdl::timing::UnknownBaud;
    /// `auto`, `search`, or a rate ([`Baud`]'s forms).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.eq_ignore_ascii_case("auto") {
            Ok(BaudChoice::Auto)
        } else if s.eq_ignore_ascii_case("search") {
            Ok(BaudChoice::Search)
        } else {
            s.parse().map(BaudChoice::Fixed)
        }
    }
}

impl BaudChoice {
    /// The nominal rate with [`BaudChoice::Auto`] on a pty or a serial
    /// server.
    pub const NOMINAL: Baud = Baud::B19200;

    /// On `port`: whether to search, and the first rate. Through a pty or
    /// a serial server (`tcp://`) every byte arrives intact whatever the
    /// rate, so `Auto` takes the nominal rate there.
    pub fn plan(self, port: &Port) -> (bool, Baud) {
        self.plan_within(port, BaudSet::ALL)
    }

    /// [`BaudChoice::plan`] for a device that supports only `rates` (its
    /// GSD's `*_supp` keywords): a search starts at the fastest of them.
    pub fn plan_within(self, port: &Port, rates: BaudSet) -> (bool, Baud) {
        let nominal = port.is_pty() || port.is_tcp();
        match self {
            BaudChoice::Fixed(b) => (false, b),
            BaudChoice::Auto if nominal => (false, Self::NOMINAL),
            BaudChoice::Auto | BaudChoice::Search => (true, rates.fastest()),
        }
    }
}

/// What the shell reports besides the slave's and the runner's events.
#[derive(Debug)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize),
    serde(tag = "event", rename_all = "snake_case")
)]
pub enum ShellEvent<'a> {
    /// A warning from configuring the profile.
    GsdWarning {
        /// In words.
        text: &'a str,
    },
    /// The slave starts.
    Start {
        /// The device's name.
        device: &'a str,
        /// Its ident number (`0x…`).
        ident: String,
        /// Its station address, if it has one yet.
        address: Option<u8>,
        /// The port.
        port: &'a str,
        /// The rate in bit/s, or `auto`.
        baud: String,
        /// Whether the port is a pty.
        pty: bool,
        /// In words.
        #[cfg_attr(feature = "serde", serde(skip))]
        text: String,
    },
    /// An accepted Set_Slave_Add could not be kept.
    AddressStoreError {
        /// Why.
        text: String,
    },
    /// The device's state was kept.
    StateSaved {
        /// Where.
        text: String,
    },
    /// The device's state could not be kept.
    StateStoreError {
        /// Why.
        text: String,
    },
    /// The outputs changed.
    Data {
        /// The output image.
        #[cfg_attr(
            feature = "serde",
            serde(serialize_with = "profibus_fdl::ser::hex_compact")
        )]
        outputs: &'a [u8],
        /// The input image.
        #[cfg_attr(
            feature = "serde",
            serde(serialize_with = "profibus_fdl::ser::hex_compact")
        )]
        inputs: &'a [u8],
        /// Data_Exchange cycles so far.
        cycle: u64,
    },
    /// The slave stopped.
    Stopped {
        /// Its state.
        state: SlaveState,
        /// Its counters.
        #[cfg_attr(feature = "serde", serde(flatten))]
        stats: SlaveStats,
    },
}

impl<'a> ShellEvent<'a> {
    /// The start of `slave` (station `addr` unless its device sets its
    /// own), called `device`, on `port` (`pty` or not) at `baud`, or
    /// searching.
    pub fn start<D: Device>(
        device: &'a str,
        slave: &DpSlave<D>,
        addr: u8,
        port: &'a str,
        pty: bool,
        search: bool,
        baud: Baud,
    ) -> ShellEvent<'a> {
        let ident = slave.device().ident_number();
        let baud_text = match (search, pty) {
            (true, _) => "auto-baud".to_string(),
            (false, true) => format!("{baud}, pty"),
            (false, false) => baud.to_string(),
        };
        let (address, at) = match slave.device().own_address() {
            OwnAddress::NoneYet => (None, "with no address yet".to_string()),
            OwnAddress::Set(a) => (Some(a), format!("at address {a}")),
            OwnAddress::Slave => (Some(addr), format!("at address {addr}")),
        };
        ShellEvent::Start {
            device,
            ident: format!("0x{ident:04X}"),
            address,
            port,
            baud: if search {
                "auto".into()
            } else {
                baud.bps().to_string()
            },
            pty,
            text: format!("{device} (ident 0x{ident:04X}) {at} on {port} ({baud_text})"),
        }
    }
}

impl fmt::Display for ShellEvent<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ShellEvent::GsdWarning { text } => f.write_str(text),
            ShellEvent::Start { text, .. }
            | ShellEvent::AddressStoreError { text }
            | ShellEvent::StateSaved { text }
            | ShellEvent::StateStoreError { text } => f.write_str(text),
            ShellEvent::Data {
                outputs,
                inputs,
                cycle,
            } => write!(
                f,
                "data: outputs {:#} inputs {:#} (cycle {cycle})",
                Hex(outputs),
                Hex(inputs)
            ),
            ShellEvent::Stopped { state, stats: s } => write!(
                f,
                "stopped in {state}: {} Data_Exchange cycles, {} Slave_Diag, {} refused, {} watchdog expiries",
                s.data_exchanges, s.diag_requests, s.refused, s.watchdog_expiries
            ),
        }
    }
}

/// Anything a running slave reports: one JSON object (`"event": …`) or
/// one line of text each.
#[derive(Debug)]
pub enum Emitted<'a> {
    /// From the baud-rate search.
    Runner(RunnerEvent),
    /// From the DP slave core (JSON: its fields and `"text"`).
    Slave(&'a SlaveEvent),
    /// From the shell.
    Shell(ShellEvent<'a>),
}

impl fmt::Display for Emitted<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Emitted::Runner(e) => e.fmt(f),
            Emitted::Slave(e) => e.fmt(f),
            Emitted::Shell(e) => e.fmt(f),
        }
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for Emitted<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        /// A slave event with its text.
        #[derive(serde::Serialize)]
        struct WithText<'a> {
            #[serde(flatten)]
            event: &'a SlaveEvent,
            text: String,
        }
        match self {
            Emitted::Runner(e) => e.serialize(s),
            Emitted::Slave(e) => WithText {
                event: e,
                text: e.to_string(),
            }
            .serialize(s),
            Emitted::Shell(e) => e.serialize(s),
        }
    }
}

/// Runs a slave on a port and keeps what its device reports; see the
/// module docs.
#[derive(Debug, Clone)]
pub struct SlaveShell {
    /// How the station runs (rate search, latency, driver options).
    pub runner: PassiveRunner,
    /// Where an accepted Set_Slave_Add is kept ([`Configured::address_file`]).
    pub address_file: Option<PathBuf>,
    /// Where [`STATE_EVENT`] state is kept ([`Configured::state_file`]).
    pub state_file: Option<PathBuf>,
    /// Report the process data whenever the outputs change.
    pub show_data: bool,
    /// Stop after this many Data_Exchange cycles (0: never).
    pub cycles: u64,
}

impl SlaveShell {
    /// The shell of `profile` running with `runner`.
    pub fn new(runner: PassiveRunner, profile: &dyn Configured) -> SlaveShell {
        SlaveShell {
            runner,
            address_file: profile.address_file(),
            state_file: profile.state_file(),
            show_data: false,
            cycles: 0,
        }
    }

    /// Keep what `e` reports; returns what to report about it, and
    /// whether `e` itself is reported too.
    pub fn keep(&self, e: &SlaveEvent) -> (Option<ShellEvent<'static>>, bool) {
        match (e, &self.address_file, &self.state_file) {
            (
                SlaveEvent::AddressChanged {
                    new, no_add_chg, ..
                },
                Some(f),
                _,
            ) => {
                // The device only accepted it: the shell keeps it.
                let stored = StoredAddress {
                    address: *new,
                    no_add_chg: *no_add_chg,
                };
                let err = stored
                    .save(f)
                    .err()
                    .map(|err| ShellEvent::AddressStoreError {
                        text: err.to_string(),
                    });
                (err, true)
            }
            (SlaveEvent::Device(d), _, Some(f)) if d.kind == STATE_EVENT => {
                // The state directory is made on the first save.
                let dir = f.parent().filter(|p| !p.as_os_str().is_empty());
                let saved = dir.map_or(Ok(()), std::fs::create_dir_all);
                let e = match saved.and_then(|()| std::fs::write(f, &d.text)) {
                    Ok(()) => ShellEvent::StateSaved {
                        text: format!("state saved to {}", f.display()),
                    },
                    Err(err) => ShellEvent::StateStoreError {
                        text: format!("cannot save the state to {}: {err}", f.display()),
                    },
                };
                (Some(e), false)
            }
            _ => (None, true),
        }
    }

    /// Run `slave` on `port` until `shutdown`, the port fails or
    /// [`SlaveShell::cycles`] are done; `emit` hears every event with its
    /// time. Returns the slave.
    pub async fn run<D: Device>(
        &self,
        slave: DpSlave<D>,
        port: &mut Port,
        clock: Clock,
        shutdown: impl Future<Output = ()>,
        mut emit: impl FnMut(Instant, Emitted<'_>),
    ) -> Result<DpSlave<D>, RunnerError> {
        let mut last_outputs: Vec<u8> = vec![];
        let emit = std::cell::RefCell::new(&mut emit);
        let (slave, _) = (self.runner)
            .run(
                slave,
                port,
                clock,
                shutdown,
                |now, e| (*emit.borrow_mut())(now, Emitted::Runner(e)),
                |st, now| {
                    let mut emit = emit.borrow_mut();
                    let emit = &mut *emit;
                    let mut step = Step::Continue;
                    while let Some(e) = st.app_mut().poll_event() {
                        if matches!(e, SlaveEvent::WatchdogExpired { .. }) {
                            step = Step::SearchAgain;
                        }
                        let (kept, report) = self.keep(&e);
                        if let Some(k) = kept {
                            emit(now, Emitted::Shell(k));
                        }
                        if report {
                            emit(now, Emitted::Slave(&e));
                        }
                    }
                    let app = st.app();
                    if self.show_data && app.outputs() != last_outputs.as_slice() {
                        last_outputs.clear();
                        last_outputs.extend_from_slice(app.outputs());
                        let data = ShellEvent::Data {
                            outputs: app.outputs(),
                            inputs: app.inputs(),
                            cycle: app.stats().data_exchanges,
                        };
                        emit(now, Emitted::Shell(data));
                    }
                    if self.cycles > 0 && app.stats().data_exchanges >= self.cycles {
                        return Step::Stop;
                    }
                    step
                },
            )
            .await?;
        Ok(slave)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_dp::slave::DeviceEvent;

    fn generic_args() -> DeviceChoice {
        let mut options = DeviceOptions::new();
        options.set(
            "gsd",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../devices/gsd/DPCTL_GEN.GSD"),
        );
        options.set("modules", vec!["2 words in/out"]);
        DeviceChoice {
            device: None,
            options,
        }
    }

    fn profile(name: &str, opts: &[(&str, &str)]) -> DeviceChoice {
        let mut options = DeviceOptions::new();
        for (k, v) in opts {
            options.set_text(k, v);
        }
        DeviceChoice {
            device: Some(name.into()),
            options,
        }
    }

    #[test]
    fn profile_args_configure_the_generic_device_and_profiles() {
        let e = generic_args().configure(Some(5)).unwrap();
        assert_eq!(e.entry.name, "generic");
        assert!(!e.name.is_empty());
        assert!(matches!(
            DeviceChoice::default().configure(None),
            Err(EmulationError::NoDevice)
        ));
        let unknown = profile("nope", &[]);
        let err = unknown.configure(None).unwrap_err().to_string();
        assert!(err.ends_with("; or use --gsd FILE"), "{err}");
        let omega = profile("omega", &[("switch", "0x19")]);
        let e = omega.configure(None).unwrap();
        assert_eq!((e.name.as_str(), e.profile.address()), ("omega", Some(25)));
        let bad = profile("omega", &[("no-such-option", "1")]);
        let err = bad.configure(None).unwrap_err().to_string();
        assert!(err.starts_with("device `omega`: "), "{err}");
    }

    #[test]
    fn baud_choice_parses_and_plans() {
        assert_eq!("auto".parse::<BaudChoice>().unwrap(), BaudChoice::Auto);
        assert_eq!("SEARCH".parse::<BaudChoice>().unwrap(), BaudChoice::Search);
        assert_eq!(
            "1.5M".parse::<BaudChoice>().unwrap(),
            BaudChoice::Fixed(Baud::B1500000)
        );
        assert!("fast".parse::<BaudChoice>().is_err());
    }

    #[test]
    fn the_shell_keeps_addresses_and_state_in_files() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().to_path_buf();
        let shell = SlaveShell {
            runner: PassiveRunner::new(false, Default::default(), Default::default()),
            address_file: Some(dir.join("address")),
            state_file: Some(dir.join("state.toml")),
            show_data: false,
            cycles: 0,
        };
        let changed = SlaveEvent::AddressChanged {
            old: 126,
            new: 7,
            no_add_chg: true,
        };
        let (kept, report) = shell.keep(&changed);
        assert!(kept.is_none() && report);
        let stored = StoredAddress::load(&dir.join("address")).unwrap().unwrap();
        assert_eq!((stored.address, stored.no_add_chg), (7, true));
        let state = SlaveEvent::Device(DeviceEvent {
            kind: STATE_EVENT,
            text: "x = 1\n".into(),
        });
        let (kept, report) = shell.keep(&state);
        assert!(matches!(kept, Some(ShellEvent::StateSaved { .. })) && !report);
        assert_eq!(
            std::fs::read_to_string(dir.join("state.toml")).unwrap(),
            "x = 1\n"
        );
    }
}
