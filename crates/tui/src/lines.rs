//! The views as lines, for output that is no terminal: events and
//! statuses that are text (`Display`) and JSON (`Serialize`) at once, in
//! the shape `dpctl master --json` prints.

use crate::bus::{BusView, Decoding, SlaveSpec};
use profibus_devices::bus::ProfiledBus;
use profibus_devices::channels::{ChannelMap, ImageValues};
use profibus_devices::profile::ProfileError;
use profibus_dp::config::layout::SlaveLayout;
use profibus_dp::master::{DpMaster, MasterStatus, SlaveStatus};
use profibus_dp::monitor;
use profibus_fdl::{Baud, Instant};
use serde::Serialize;
use std::fmt;

/// What a view shows of a slave of a bus file besides the master's
/// state: its layout, and the named channels of its images.
#[derive(Debug, Clone)]
pub struct SlaveInfo {
    /// Address, name, GSD (for diagnosis texts) and GSD modules with
    /// their spans.
    pub layout: SlaveLayout,
    /// Named channels of its process images (a slave given as a device
    /// profile).
    pub channels: Option<ChannelMap>,
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
    /// The slaves of a bus file ([`ProfiledBus::layouts`]), with the named
    /// channels of those given as device profiles; the error names the
    /// slave whose profile failed.
    pub fn of_bus(bus: &ProfiledBus) -> Result<Vec<SlaveInfo>, SlaveProfileError> {
        (bus.layouts().into_iter())
            .map(|layout| {
                let address = layout.address;
                let channels = bus.channels(address).transpose();
                Ok(SlaveInfo {
                    layout,
                    channels: channels.map_err(|error| SlaveProfileError { address, error })?,
                })
            })
            .collect()
    }

    /// The slave for a [`BusView`]: decoded by its
    /// channels, else by its GSD modules.
    pub fn spec(&self) -> SlaveSpec {
        let l = &self.layout;
        SlaveSpec {
            address: l.address,
            name: l.name.clone(),
            gsd: l.gsd.clone(),
            decoding: match (&self.channels, &l.gsd) {
                (Some(c), _) => Decoding::Channels(c.clone()),
                (None, Some(_)) => Decoding::Modules(l.modules.clone()),
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

/// The slaves `info` for a passive monitor ([`profibus_dp::monitor`]):
/// their layouts, and their named channels as decoders.
pub fn monitor_slaves(info: &[SlaveInfo]) -> Vec<monitor::SlaveInfo> {
    (info.iter())
        .map(|i| monitor::SlaveInfo {
            layout: i.layout.clone(),
            decoder: (i.channels.clone()).map(|c| Box::new(c) as Box<dyn monitor::ImageDecoder>),
        })
        .collect()
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
                let status = SlaveStatus::of(m, s.layout.address);
                let channels = s
                    .channels
                    .as_ref()
                    .map(|map| map.values(&status.inputs, &status.outputs));
                SlaveLine {
                    status: SlaveStatus {
                        name: s.layout.name.clone(),
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
