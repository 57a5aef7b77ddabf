//! The live view shared by `dpctl master`, `dpctl demo` and `dpctl
//! monitor`: events as lines or JSON, or on a terminal the table view of
//! `profibus_tui` (`View::open_terminal`). What is printed comes from the
//! libraries' types (`Display` for text, `Serialize` for JSON):
//! `MasterReport`, `profibus_tui::lines::StatusLine`, `MonitorStatus`.

use crate::out::outln;
use profibus_dp::master::{DpMaster, MasterReport};
use profibus_fdl::{Baud, Instant};
use profibus_tui::bus::BusView;
use profibus_tui::lines::StatusLine;
pub use profibus_tui::lines::{bus_view, EventLine as Line, SlaveInfo};
use profibus_tui::source::BusSource;
use profibus_tui::term::LiveBus;
use serde::Serialize;
use std::fmt::Display;
use std::ops::ControlFlow;
use std::time::Duration;

/// Lines or JSON lines, or a table on the terminal.
pub struct View {
    /// JSON lines.
    pub json: bool,
    live: Option<LiveBus>,
    last_print: Option<Instant>,
    interval: Duration,
    /// Standard output's reader went away.
    closed: bool,
}

impl View {
    /// Lines (JSON lines with `json`), a status every `interval`.
    pub fn new(json: bool, interval: Duration) -> View {
        View {
            json,
            live: None,
            last_print: None,
            interval,
            closed: false,
        }
    }

    /// Show `view` (a table of the slaves, [`bus_view`]) on the terminal
    /// instead of lines, until [`View::close`].
    pub fn open_terminal(&mut self, view: BusView) -> std::io::Result<()> {
        self.live = Some(LiveBus::open(view)?);
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

    /// On the terminal: keys (writes go to `source`) and a frame when
    /// due. `Break`: the person quit, or the terminal failed.
    pub fn tick<S: BusSource + ?Sized>(&mut self, source: &mut S, now: Instant) -> ControlFlow<()> {
        let Some(live) = &mut self.live else {
            return ControlFlow::Continue(());
        };
        match live.tick(source, now) {
            Ok(true) => ControlFlow::Continue(()),
            Ok(false) => ControlFlow::Break(()),
            Err(e) => {
                tracing::warn!("terminal: {e}");
                ControlFlow::Break(())
            }
        }
    }

    /// Show an event: its JSON with `--json`, else its `Display` text
    /// (in the table's log on the terminal).
    /// A closed standard output stops the command as SIGTERM would
    /// ([`crate::common::request_stop`]); nothing more is printed.
    pub fn event<E: Serialize + Display + ?Sized>(&mut self, e: &E) {
        if self.closed {
            return;
        }
        let printed = if self.json {
            outln!("{}", crate::common::json_line(e))
        } else if let Some(live) = &mut self.live {
            live.view_mut().log(e.to_string());
            Ok(())
        } else {
            outln!("{e}")
        };
        match printed {
            Ok(()) => {}
            Err(e) if crate::out::closed(&e) => {
                self.closed = true;
                crate::common::request_stop();
            }
            Err(e) => tracing::warn!("standard output: {e}"),
        }
    }

    /// Whether a status line is due at `now` (always with `force`; never
    /// while the table is on the terminal).
    pub fn due(&mut self, now: Instant, force: bool) -> bool {
        if self.live.is_some() || !force && self.last_print.is_some_and(|t| now < t + self.interval)
        {
            return false;
        }
        self.last_print = Some(now);
        true
    }

    /// The master's status line, when due.
    pub fn status(
        &mut self,
        m: &DpMaster,
        info: &[SlaveInfo],
        baud: Baud,
        now: Instant,
        force: bool,
    ) {
        if self.due(now, force) {
            self.event(&StatusLine::of(m, info, baud, now));
        }
    }
}

/// Show the master's events.
pub fn drain_events(m: &mut DpMaster, slaves_info: &[SlaveInfo], view: &mut View) {
    drain_events_except(m, slaves_info, view, |_| false);
}

/// Show the master's events but those `skip` takes (the ends of jobs a
/// control socket answered).
pub fn drain_events_except(
    m: &mut DpMaster,
    slaves_info: &[SlaveInfo],
    view: &mut View,
    mut skip: impl FnMut(&profibus_dp::master::MasterEvent) -> bool,
) {
    while let Some(e) = m.poll_event() {
        if skip(&e) {
            continue;
        }
        let gsd = match &e {
            profibus_dp::master::MasterEvent::Diag { address }
            | profibus_dp::master::MasterEvent::Alarm { address, .. }
            | profibus_dp::master::MasterEvent::CfgMismatch { address } => slaves_info
                .iter()
                .find(|s| s.layout.address == *address)
                .and_then(|s| s.layout.gsd.as_ref()),
            _ => None,
        };
        let report = MasterReport::new(m, e, gsd);
        view.event(&report);
    }
}
