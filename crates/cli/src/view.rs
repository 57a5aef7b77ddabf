//! The live view shared by `dpctl master` and `dpctl demo`: events as
//! lines or JSON, a refreshing table of the slaves on a terminal. What is
//! printed comes from the library's types (`Display` for text, `Serialize`
//! for JSON): `MasterReport`, `MasterStatus`, `SlaveStatus`,
//! `ImageValues`.

pub use crate::describe::hex;
use profibus_devices::channels::{ChannelMap, ImageValues};
use profibus_dp::gsd::Gsd;
use profibus_dp::master::{DpMaster, MasterReport, MasterStatus, SlaveStatus};
use profibus_fdl::{Baud, Instant};
use serde::Serialize;
use std::fmt::Display;
use std::io::Write;
use std::time::Duration;

/// What the view shows of a slave besides the master's state.
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
}

/// An event the command line makes itself: `{"event": KIND, …body}` in
/// JSON, `text` as text.
#[derive(Serialize)]
pub struct Line<T: Serialize> {
    /// The event's kind.
    pub event: &'static str,
    /// Its fields.
    #[serde(flatten)]
    pub body: T,
    /// The event in words.
    #[serde(skip)]
    pub text: String,
}

impl<T: Serialize> Line<T> {
    /// An event `kind` with fields `body`, shown as `text`.
    pub fn new(event: &'static str, body: T, text: impl Into<String>) -> Line<T> {
        Line {
            event,
            body,
            text: text.into(),
        }
    }
}

impl<T: Serialize> Display for Line<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
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

/// A status line: the master and its slaves.
#[derive(Serialize)]
struct StatusLine<'a> {
    event: &'static str,
    #[serde(flatten)]
    master: MasterStatus,
    slaves: &'a [SlaveLine],
}

impl View {
    pub fn new(json: bool, tty: bool, interval: Duration) -> View {
        View {
            json,
            tty,
            log: Vec::new(),
            last_print: None,
            interval,
        }
    }
}

pub struct View {
    pub json: bool,
    pub tty: bool,
    log: Vec<String>,
    last_print: Option<Instant>,
    interval: Duration,
}

impl View {
    /// Show an event: its JSON with `--json`, else its `Display` text.
    pub fn event<E: Serialize + Display + ?Sized>(&mut self, e: &E) {
        if self.json {
            println!("{}", crate::common::json_line(e));
        } else {
            self.text(e.to_string());
        }
    }

    fn text(&mut self, text: String) {
        if self.tty {
            self.log.push(text);
            let n = self.log.len();
            if n > 12 {
                self.log.drain(..n - 12);
            }
        } else {
            println!("{text}");
        }
    }

    pub fn status(
        &mut self,
        m: &DpMaster,
        slaves_info: &[SlaveInfo],
        baud: Baud,
        now: Instant,
        force: bool,
    ) {
        if !force && self.last_print.is_some_and(|t| now < t + self.interval) {
            return;
        }
        self.last_print = Some(now);
        let master = MasterStatus::of(m, baud, now);
        let slaves: Vec<SlaveLine> = slaves_info
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
        if self.json {
            let line = StatusLine {
                event: "status",
                master,
                slaves: &slaves,
            };
            println!("{}", crate::common::json_line(&line));
            return;
        }
        let mut out = String::new();
        if self.tty {
            out.push_str("\x1b[H\x1b[2J");
        }
        out.push_str(&format!("{master}\n"));
        for s in &slaves {
            out.push_str(&format!("  {}\n", s.status));
            if let Some(c) = &s.channels {
                out.push_str(&format!("      {c}\n"));
            }
        }
        if self.tty {
            for l in &self.log {
                out.push_str(l);
                out.push('\n');
            }
        }
        print!("{out}");
        let _ = std::io::stdout().flush();
    }
}

pub fn drain_events(m: &mut DpMaster, slaves_info: &[SlaveInfo], view: &mut View) {
    while let Some(e) = m.poll_event() {
        let gsd = match &e {
            profibus_dp::master::MasterEvent::Diag { address } => slaves_info
                .iter()
                .find(|s| s.address == *address)
                .and_then(|s| s.gsd.as_ref()),
            _ => None,
        };
        let report = MasterReport::new(m, e, gsd);
        view.event(&report);
    }
}
