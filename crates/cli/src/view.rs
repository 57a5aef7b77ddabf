//! The live view shared by `dpctl master` and `dpctl demo`: events as
//! lines or JSON, or on a terminal the table view of `profibus_tui`
//! (`View::open_terminal`). What is
//! printed comes from the library's types (`Display` for text, `Serialize`
//! for JSON): `MasterReport`, `MasterStatus`, `SlaveStatus`,
//! `ImageValues`.

use profibus_devices::channels::{ChannelMap, ImageValues};
use profibus_dp::gsd::Gsd;
use profibus_dp::master::{DpMaster, MasterReport, MasterStatus, SlaveStatus};
use profibus_fdl::{Baud, Instant};
use profibus_tui::bus::{BusView, Decoding, SlaveSpec};
use profibus_tui::term::LiveBus;
use serde::Serialize;
use std::fmt::Display;
use std::ops::ControlFlow;
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
    /// The GSD modules the master configures, in slot order.
    pub modules: Vec<String>,
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
    /// Lines (JSON lines with `json`), a status every `interval`.
    pub fn new(json: bool, interval: Duration) -> View {
        View {
            json,
            live: None,
            last_print: None,
            interval,
        }
    }

    /// Show the slaves `info` as a table on the terminal instead of
    /// lines, titled `title`, until [`View::close`].
    pub fn open_terminal(
        &mut self,
        title: &str,
        baud: Baud,
        info: &[SlaveInfo],
    ) -> std::io::Result<()> {
        let specs = info
            .iter()
            .map(|s| SlaveSpec {
                address: s.address,
                name: s.name.clone(),
                gsd: s.gsd.clone(),
                decoding: match (&s.channels, &s.gsd) {
                    (Some(c), _) => Decoding::Channels(c.clone()),
                    (None, Some(g)) => Decoding::modules(g, &s.modules),
                    (None, None) => Decoding::None,
                },
            })
            .collect();
        self.live = Some(LiveBus::open(BusView::new(title, Some(baud), specs))?);
        Ok(())
    }

    /// Whether the person wrote the slave's outputs on the terminal.
    pub fn by_hand(&self, address: u8) -> bool {
        self.live
            .as_ref()
            .is_some_and(|l| l.view().written_by_hand(address))
    }

    /// Give the terminal back (the table disappears).
    pub fn close(&mut self) {
        self.live = None;
    }

    /// On the terminal: keys (writes go to `m`) and a frame when due.
    /// `Break`: the person quit, or the terminal failed.
    pub fn tick(&mut self, m: &mut DpMaster, now: Instant) -> ControlFlow<()> {
        let Some(live) = &mut self.live else {
            return ControlFlow::Continue(());
        };
        match live.tick(m, now) {
            Ok(true) => ControlFlow::Continue(()),
            Ok(false) => ControlFlow::Break(()),
            Err(e) => {
                tracing::warn!("terminal: {e}");
                ControlFlow::Break(())
            }
        }
    }
}

pub struct View {
    pub json: bool,
    live: Option<LiveBus>,
    last_print: Option<Instant>,
    interval: Duration,
}

impl View {
    /// Show an event: its JSON with `--json`, else its `Display` text.
    pub fn event<E: Serialize + Display + ?Sized>(&mut self, e: &E) {
        if self.json {
            println!("{}", crate::common::json_line(e));
        } else if let Some(live) = &mut self.live {
            live.view_mut().log(e.to_string());
        } else {
            println!("{e}");
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
        if self.live.is_some() || !force && self.last_print.is_some_and(|t| now < t + self.interval)
        {
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
        out.push_str(&format!("{master}\n"));
        for s in &slaves {
            out.push_str(&format!("  {}\n", s.status));
            if let Some(c) = &s.channels {
                out.push_str(&format!("      {c}\n"));
            }
        }
        print!("{out}");
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
