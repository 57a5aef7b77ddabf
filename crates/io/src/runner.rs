//! A passive station (a slave) on a port, with the baud-rate search of a
//! slave with `Auto_Baud_supp`: the thin tokio part around the sans-IO
//! [`AutoBaud`](profibus_fdl::station::autobaud::AutoBaud) search and [`Relisten`] policy, next to [`crate::driver`].
//!
//! [`PassiveRunner::run`] listens for the rate (when searching), builds a
//! [`PassiveStation`] at the rate found, runs it with the driver, and when
//! the line goes quiet for [`PassiveRunner::silence`] or the application
//! asks ([`Step::SearchAgain`], e.g. a DP slave whose watchdog expired)
//! takes the application back, searches again and builds a new station.
//! Any embedder of a slave uses it the way `dpctl slave` does.

use crate::driver::{self, Clock, Stop};
use crate::transport::{Port, TransportError};
use profibus_fdl::station::autobaud::{BaudSet, Relisten, RELISTEN_AFTER};
use profibus_fdl::station::passive::{PassiveStation, Responder};
use profibus_fdl::timing::{Baud, BusParams};
use profibus_fdl::Instant;
use std::cell::{Cell, RefCell};
use std::future::Future;
use std::ops::ControlFlow;
use std::time::Duration;

/// What the application's `tick` wants next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Keep running.
    Continue,
    /// Stop: [`PassiveRunner::run`] returns [`Stop::Done`].
    Stop,
    /// The master was lost: search the rate again (only when searching;
    /// otherwise the same as `Continue`).
    SearchAgain,
}

/// What the runner reports besides the station's own events.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize),
    serde(tag = "event", rename_all = "snake_case")
)]
pub enum RunnerEvent {
    /// The search found the rate.
    BaudLocked {
        /// The rate.
        baud: Baud,
    },
    /// The search starts again (silence, or the application asked).
    BaudSearch {
        /// Why, in words.
        text: &'static str,
    },
}

impl std::fmt::Display for RunnerEvent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunnerEvent::BaudLocked { baud } => write!(f, "baud rate {baud} found"),
            RunnerEvent::BaudSearch { text } => f.write_str(text),
        }
    }
}

/// Why the runner failed.
#[derive(Debug, thiserror::Error)]
pub enum RunnerError {
    /// Reading or writing the port failed (or its other side went away).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The port refused a rate.
    #[error(transparent)]
    Transport(#[from] TransportError),
}

/// How a passive station runs on a port; see the module docs.
#[derive(Debug, Clone, Copy)]
pub struct PassiveRunner {
    /// Search the rate ([`AutoBaud`](profibus_fdl::station::autobaud::AutoBaud)) instead of using the port's.
    pub search: bool,
    /// With `search`: search again after this long without a valid
    /// telegram.
    pub silence: Duration,
    /// Extra time an incomplete telegram may take to arrive (see
    /// [`PassiveStation::with_latency_allowance`]).
    pub latency: Duration,
    /// How the driver writes.
    pub options: driver::Options,
    /// With `search`: the rates searched (the device's GSD `*_supp`
    /// rates; default all).
    pub rates: BaudSet,
}

impl PassiveRunner {
    /// At the port's rate (`search` false) or searching, with the default
    /// silence ([`RELISTEN_AFTER`]).
    pub fn new(search: bool, latency: Duration, options: driver::Options) -> PassiveRunner {
        PassiveRunner {
            search,
            silence: RELISTEN_AFTER,
            latency,
            options,
            rates: BaudSet::ALL,
        }
    }

    /// Run `app` on `port` until `tick` returns [`Step::Stop`] or
    /// `shutdown` completes; returns the application and why it stopped.
    /// `on_event` hears of the search.
    pub async fn run<R, F>(
        &self,
        mut app: R,
        port: &mut Port,
        clock: Clock,
        shutdown: F,
        mut on_event: impl FnMut(Instant, RunnerEvent),
        mut tick: impl FnMut(&mut PassiveStation<R>, Instant) -> Step,
    ) -> Result<(R, Stop), RunnerError>
    where
        R: Responder,
        F: Future<Output = ()>,
    {
        tokio::pin!(shutdown);
        loop {
            let baud = if self.search {
                match crate::baud::listen_for_baud(port, &clock, self.rates, shutdown.as_mut())
                    .await?
                {
                    Some(b) => {
                        on_event(clock.now(), RunnerEvent::BaudLocked { baud: b });
                        b
                    }
                    None => return Ok((app, Stop::Shutdown)),
                }
            } else {
                port.baud()
            };
            let mut station = PassiveStation::with_latency_allowance(
                app,
                BusParams::defaults(baud),
                self.latency,
            );
            let again = Cell::new(false);
            let quiet = RefCell::new(Relisten::new(clock.now(), self.silence));
            let search = self.search;
            // Silence is noticed even when nothing at all arrives (no
            // read, no station deadline wakes the driver).
            let silent = async {
                loop {
                    let due = quiet.borrow().deadline();
                    tokio::time::sleep_until(clock.to_tokio(due)).await;
                    if clock.now() >= quiet.borrow().deadline() {
                        return;
                    }
                }
            };
            let stop_or_silence = async {
                tokio::select! {
                    _ = shutdown.as_mut() => {}
                    _ = silent, if search => again.set(true),
                }
            };
            let stop = driver::run_with(
                &mut station,
                port,
                clock.clone(),
                self.options,
                stop_or_silence,
                |st, now| match tick(st, now) {
                    Step::Stop => ControlFlow::Break(()),
                    Step::SearchAgain if search => {
                        again.set(true);
                        ControlFlow::Break(())
                    }
                    _ if search
                        && quiet
                            .borrow_mut()
                            .is_silent(now, st.codec_stats().telegrams) =>
                    {
                        again.set(true);
                        ControlFlow::Break(())
                    }
                    _ => ControlFlow::Continue(()),
                },
            )
            .await?;
            app = station.into_app();
            match stop {
                _ if again.get() => on_event(
                    clock.now(),
                    RunnerEvent::BaudSearch {
                        text: "searching the baud rate again",
                    },
                ),
                stop => return Ok((app, stop)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::fdl_status;
    use profibus_fdl::station::passive::Reply;
    use profibus_fdl::wire::{DataTelegram, ResponseStatus};
    use tokio::io::AsyncReadExt;

    /// The error and its sources as `{:#}` of anyhow prints them.
    fn chain(e: &dyn std::error::Error) -> String {
        let mut s = e.to_string();
        let mut next = e.source();
        while let Some(c) = next {
            s += &format!(": {c}");
            next = c.source();
        }
        s
    }

    #[test]
    fn a_closed_port_is_named_once_in_the_error_chain() {
        let e = RunnerError::from(std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            "/tmp/pty-a: port closed",
        ));
        assert_eq!(chain(&e), "/tmp/pty-a: port closed");
        let e = RunnerError::from(TransportError::Open {
            path: "/dev/ttyX".into(),
            error: std::io::Error::from(std::io::ErrorKind::NotFound),
        });
        assert_eq!(chain(&e), "cannot open /dev/ttyX: entity not found");
    }
    use tokio::io::AsyncWriteExt;

    struct Quiet;
    impl Responder for Quiet {
        fn address(&self) -> u8 {
            5
        }
        fn on_request(&mut self, _: Instant, _: &DataTelegram<'_>, _: &mut [u8]) -> Reply {
            Reply::Data {
                status: ResponseStatus::Ok,
                dsap: None,
                ssap: None,
                len: 0,
            }
        }
    }

    /// Locks, searches again when the application asks, locks, searches
    /// again after silence, locks: the master side sends only while the
    /// runner searches.
    #[tokio::test]
    async fn searches_again_when_asked_and_after_silence() {
        let (mut master, mut slave) = Port::pty_pair(Baud::B19200).unwrap();
        let runner = PassiveRunner {
            silence: Duration::from_millis(300),
            ..PassiveRunner::new(true, Duration::from_millis(5), driver::Options::default())
        };
        let events = RefCell::new(Vec::new());
        let (tx, mut rx) = tokio::sync::watch::channel(0usize);
        let locks = |ev: &[RunnerEvent]| {
            ev.iter()
                .filter(|e| matches!(e, RunnerEvent::BaudLocked { .. }))
                .count()
        };
        let slave_side = runner.run(
            Quiet,
            &mut slave,
            Clock::start(),
            std::future::pending(),
            |_, e| {
                events.borrow_mut().push(e);
                tx.send_modify(|n| *n += 1);
            },
            |_, _| match locks(&events.borrow()) {
                1 => Step::SearchAgain,
                3 => Step::Stop,
                _ => Step::Continue,
            },
        );
        let master_side = async {
            let mut buf = [0u8; 256];
            loop {
                let searching =
                    !matches!(events.borrow().last(), Some(RunnerEvent::BaudLocked { .. }));
                if locks(&events.borrow()) >= 3 {
                    return;
                }
                if searching {
                    master.write_all(&fdl_status(5, 1)).await.unwrap();
                }
                tokio::select! {
                    _ = rx.changed() => {}
                    _ = tokio::time::sleep(Duration::from_millis(20)), if searching => {}
                    _ = master.read(&mut buf) => {}
                }
            }
        };
        let (r, ()) = tokio::time::timeout(Duration::from_secs(60), async {
            tokio::join!(slave_side, master_side)
        })
        .await
        .expect("runner finished");
        let (_, stop) = r.unwrap();
        assert_eq!(stop, Stop::Done);
        let kinds: Vec<&str> = events
            .borrow()
            .iter()
            .map(|e| match e {
                RunnerEvent::BaudLocked { .. } => "locked",
                RunnerEvent::BaudSearch { .. } => "search",
            })
            .collect();
        assert_eq!(
            kinds,
            ["locked", "search", "locked", "search", "locked"],
            "{:?}",
            events.borrow()
        );
    }
}
