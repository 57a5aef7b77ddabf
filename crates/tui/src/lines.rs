//! The views as lines, for output that is no terminal: events and
//! statuses that are text (`Display`) and JSON (`Serialize`) at once, in
//! the shape `dpctl master --json` prints.

use crate::bus::{BusView, Decoding, SlaveSpec};
use profibus_devices::bus::ProfiledBus;
use profibus_devices::channels::{ChannelMap, ImageValues};
use profibus_devices::profile::ProfileError;
use profibus_dp::config::busfile::{BusFile, BusSlave};
use profibus_dp::config::gsd::Gsd;
use profibus_dp::master::{DpMaster, MasterStatus, SlaveStatus};
use profibus_dp::monitor;
use profibus_fdl::{Baud, Instant};
use serde::Serialize;
use std::fmt;

/// What a view shows of a slave of a bus file besides the master's
/// state.
#[derive(Debug, Clone)]
pub struct SlaveInfo {
    /// Station address.
    pub address: u8,
    /// Name.
    pub name: String,
    /// The GSD, for diagnosis texts.
    pub gsd: Option<Gsd>,
    /// Named channels of its process images (a slave given as a device
    /// profile).
    pub channels: Option<ChannelMap>,
    /// The GSD modules the master configures, in slot order.
    pub modules: Vec<String>,
}

/// A slave's device profile could not give its channels.
#[derive(Debug, thiserror::Error)]
#[error("slave {address}: {error}")]
pub struct SlaveProfileError {
    /// Station address.
    pub address: u8,
    /// Why.
    pub error: ProfileError,
}

impl SlaveInfo {
    /// The slaves of a bus file, with the named channels of those given
    /// as device profiles; the error names the slave whose profile failed.
    pub fn of_bus(bus: &ProfiledBus) -> Result<Vec<SlaveInfo>, SlaveProfileError> {
        (bus.file.slaves.iter())
            .map(|s| SlaveInfo::of_slave(bus, s))
            .collect()
    }

    /// The slave `s` of `bus`.
    fn of_slave(bus: &ProfiledBus, s: &BusSlave) -> Result<SlaveInfo, SlaveProfileError> {
        let address = s.params.address;
        let channels = bus.channels(address).transpose();
        Ok(SlaveInfo {
            address,
            name: s.params.name.clone(),
            gsd: Some(s.gsd.clone()),
            channels: channels.map_err(|error| SlaveProfileError { address, error })?,
            modules: s.modules.clone(),
        })
    }

    /// The slave for a [`BusView`]: decoded by its
    /// channels, else by its GSD modules.
    pub fn spec(&self) -> SlaveSpec {
        SlaveSpec {
            address: self.address,
            name: self.name.clone(),
            gsd: self.gsd.clone(),
            decoding: match (&self.channels, &self.gsd) {
                (Some(c), _) => Decoding::Channels(c.clone()),
                (None, Some(g)) => Decoding::modules(g, &self.modules),
                (None, None) => Decoding::None,
            },
        }
    }
}

/// The table view of the slaves `info` on a bus at `baud`, titled
/// `title`.
pub fn bus_view(title: &str, baud: Baud, info: &[SlaveInfo]) -> BusView {
    BusView::new(
        title,
        Some(baud),
        info.iter().map(SlaveInfo::spec).collect(),
    )
}

/// The slaves of `bus` for a passive monitor
/// ([`profibus_dp::monitor`]): their GSD modules, and the named channels
/// of `info` (of the same bus, [`SlaveInfo::of_bus`]) as decoders.
pub fn monitor_slaves(bus: &BusFile, info: &[SlaveInfo]) -> Vec<monitor::SlaveInfo> {
    let mut slaves = monitor::SlaveInfo::from_bus(bus);
    for s in &mut slaves {
        let channels = info.iter().find(|i| i.address == s.address);
        if let Some(c) = channels.and_then(|i| i.channels.clone()) {
            s.decoder = Some(Box::new(c));
        }
    }
    slaves
}

/// An event an application makes itself: `{"event": KIND, …body}` in
/// JSON, `text` as text.
#[derive(Serialize)]
pub struct EventLine<T: Serialize> {
    /// The event's kind.
    pub event: &'static str,
    /// Its fields.
    #[serde(flatten)]
    pub body: T,
    /// The event in words.
    #[serde(skip)]
    pub text: String,
}

impl<T: Serialize> EventLine<T> {
    /// An event `kind` with fields `body`, shown as `text`.
    pub fn new(event: &'static str, body: T, text: impl Into<String>) -> EventLine<T> {
        EventLine {
            event,
            body,
            text: text.into(),
        }
    }
}

impl<T: Serialize> fmt::Display for EventLine<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

/// The outcome of a command line of `dpctl master --input`
/// ([`profibus_devices::bus::execute_input`]) when there is one to show:
/// `{"event": "command", "result": …}` with its reply as text, or
/// `{"event": "error", "line": …, "error": …}` with ``bad command `LINE`:
/// ERROR`` as text (the error with its sources).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(tag = "event", rename_all = "lowercase")]
pub enum CommandLine {
    /// The command's reply.
    Command {
        /// The reply.
        result: String,
    },
    /// The command was refused.
    Error {
        /// The command line.
        line: String,
        /// Why.
        error: String,
    },
}

impl CommandLine {
    /// What to show after running `line` with `result`; `None` for a
    /// command that went through without a reply.
    pub fn of<E: std::error::Error>(line: &str, result: Result<Option<String>, E>) -> Option<Self> {
        match result {
            Ok(reply) => reply.map(|result| CommandLine::Command { result }),
            Err(e) => {
                let mut error = e.to_string();
                let mut source = e.source();
                while let Some(s) = source {
                    error = format!("{error}: {s}");
                    source = s.source();
                }
                let line = line.to_string();
                Some(CommandLine::Error { line, error })
            }
        }
    }
}

impl fmt::Display for CommandLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CommandLine::Command { result } => f.write_str(result),
            CommandLine::Error { line, error } => write!(f, "bad command `{line}`: {error}"),
        }
    }
}

/// One slave of a status line.
#[derive(Serialize)]
struct SlaveLine {
    #[serde(flatten)]
    status: SlaveStatus,
    #[serde(skip_serializing_if = "Option::is_none")]
    channels: Option<ImageValues>,
}

/// A master's status: `{"event": "status", …master, "slaves": […]}` in
/// JSON; as text the master's headline, then a line per slave (and one
/// with its named channels).
#[derive(Serialize)]
pub struct StatusLine {
    event: &'static str,
    #[serde(flatten)]
    master: MasterStatus,
    slaves: Vec<SlaveLine>,
}

impl StatusLine {
    /// The master `m` on a bus at `baud` and its slaves `info` at `now`.
    pub fn of(m: &DpMaster, info: &[SlaveInfo], baud: Baud, now: Instant) -> StatusLine {
        let slaves = info
            .iter()
            .map(|s| {
                let status = SlaveStatus::of(m, s.address);
                let channels = s
                    .channels
                    .as_ref()
                    .map(|map| map.values(&status.inputs, &status.outputs));
                SlaveLine {
                    status: SlaveStatus {
                        name: s.name.clone(),
                        ..status
                    },
                    channels,
                }
            })
            .collect();
        StatusLine {
            event: "status",
            master: MasterStatus::of(m, baud, now),
            slaves,
        }
    }
}

impl fmt::Display for StatusLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.master)?;
        for s in &self.slaves {
            write!(f, "\n  {}", s.status)?;
            if let Some(c) = &s.channels {
                write!(f, "\n      {c}")?;
            }
        }
        Ok(())
    }
}
