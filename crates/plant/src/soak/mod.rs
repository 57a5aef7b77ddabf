//! The fault soak: a DP master and one slave of every device profile on
//! the simulated bus ([`profibus_fdl::sim::SimBus`], virtual time) at
//! 1.5 Mbit/s, for many poll cycles, with dropped characters, bit errors
//! and noise bursts on the line ([`MediumConfig`]), and invariants checked
//! after every cycle. `dpctl soak` runs it.
//!
//! # What is checked
//!
//! - **No panic**: the simulation runs on a worker thread; a panic in any
//!   station (or the simulator's own stall assertions) is reported as
//!   [`Violation::Panic`].
//! - **No hang**: every poll cycle of the master must complete within
//!   [`SoakConfig::cycle_limit`] of bus time ([`Violation::BusStalled`]:
//!   bus time advances but the master makes no progress), and the worker
//!   must finish a cycle within [`SoakConfig::wall_watchdog`] of wall time
//!   ([`Violation::Hang`]: the computation itself hangs).
//! - **Bounded memory**: the resident set of the process may grow by at
//!   most [`SoakConfig::max_rss_growth`] after the warm-up (Linux,
//!   `/proc/self/status`), and the event queues are drained and must not
//!   overflow ([`Violation::Memory`]).
//! - **Corrupted telegrams are rejected or counted**: a reference receiver
//!   frames what every sender's transmissions became on the line and
//!   compares each telegram it accepts with what that station sent
//!   ([`Integrity`]): intact, or valid framing and FCS although nobody
//!   sent it (the FCS is an 8-bit sum and cannot see every corruption;
//!   such telegrams are counted, never silently taken as sent). Token
//!   telegrams (SD4, `DC DA SA`) have no FCS at all: a bit error forges
//!   one now and then ([`Integrity::forged_tokens`]); when the master
//!   receives one while it holds the token it drops its own (duplicate
//!   token) and claims it again after the token-lost timeout, counted in
//!   [`SoakReport::token_ring`]; the recovery invariant covers the slaves
//!   meanwhile. The stations' own receivers report what they rejected
//!   ([`SoakReport::receiver_errors`]).
//! - **Recovery**: a slave whose Data_Exchange fails in a cycle (no
//!   answer after the retries, or not in Data_Exchange) is *disturbed*;
//!   it must be back in Data_Exchange with a completed exchange within
//!   [`SoakConfig::max_recovery`] of bus time ([`Violation::NotRecovered`]),
//!   also at the end of the run. The time from the first failed cycle to
//!   the first good one is collected per disturbance ([`Distribution`] in
//!   cycles and in milliseconds), and separately for the episodes in
//!   which the master took the slave out of Data_Exchange.
//!
//! The run stops at the first violation; [`SoakReport::violations`] then
//! says which invariant broke. Every run with the same configuration and
//! seed is identical (virtual time; the faults draw from seeded
//! generators).

mod ledger;
mod plant;
mod stats;

pub use ledger::Integrity;
pub use stats::Distribution;

use ledger::{Ledger, Recorded};
use plant::{MasterStation, SlaveStation};
use profibus_dp::master::{MasterEvent, SlaveState};
use profibus_fdl::line::medium::{MediumConfig, MediumStats};
use profibus_fdl::sim::{SimBus, StationId};
use profibus_fdl::{Baud, Instant};
use serde::Serialize;
use std::cell::RefCell;
use std::rc::Rc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::Duration;

/// Station address of the soak's master.
pub const MASTER_ADDRESS: u8 = 1;

/// How a soak runs.
#[derive(Debug, Clone, PartialEq)]
pub struct SoakConfig {
    /// Poll cycles of the master to run.
    pub cycles: u64,
    /// Seed of the fault generators.
    pub seed: u64,
    /// Baud rate of the line.
    pub baud: Baud,
    /// Probability of losing each character.
    pub drop: f64,
    /// Probability of flipping each data bit (bit error rate).
    pub flip_ber: f64,
    /// Noise bursts per second of idle line.
    pub noise_rate: f64,
    /// Watchdog time the master gives every slave.
    pub watchdog: Duration,
    /// Longest time a disturbed slave may take to be back in
    /// Data_Exchange (bus time).
    pub max_recovery: Duration,
    /// Longest bus time one poll cycle may take.
    pub cycle_limit: Duration,
    /// Longest wall time one poll cycle may take.
    pub wall_watchdog: Duration,
    /// Largest growth of the resident set after the warm-up (bytes);
    /// `None`: not checked (e.g. inside a test process that runs other
    /// tests at the same time).
    pub max_rss_growth: Option<u64>,
    /// Pull the plug of this slave (station address) at this cycle and
    /// never put it back: a deliberately broken recovery invariant, to
    /// check that the soak notices.
    pub unplug: Option<(u8, u64)>,
    /// Report progress every this many cycles (0: never).
    pub progress_every: u64,
}

impl Default for SoakConfig {
    /// 1,000,000 cycles at 1.5 Mbit/s, seed 1, drop 1e-4 per character,
    /// BER 1e-4, 20 noise bursts per second, watchdog 100 ms, recovery
    /// within 1 s, cycles within 1 s of bus time and 30 s of wall time,
    /// resident set growth at most 16 MiB.
    fn default() -> Self {
        SoakConfig {
            cycles: 1_000_000,
            seed: 1,
            baud: Baud::B1500000,
            drop: 1e-4,
            flip_ber: 1e-4,
            noise_rate: 20.0,
            watchdog: Duration::from_millis(100),
            max_recovery: Duration::from_secs(1),
            cycle_limit: Duration::from_secs(1),
            wall_watchdog: Duration::from_secs(30),
            max_rss_growth: Some(16 << 20),
            unplug: None,
            progress_every: 0,
        }
    }
}

impl SoakConfig {
    /// The line's configuration.
    pub fn medium(&self) -> MediumConfig {
        MediumConfig {
            drop: self.drop,
            flip_ber: self.flip_ber,
            noise_rate: self.noise_rate,
            seed: self.seed,
            ..MediumConfig::paced(self.baud)
        }
    }
}

/// An invariant that broke.
#[derive(Debug, Clone, PartialEq, Serialize, thiserror::Error)]
#[serde(tag = "invariant", rename_all = "snake_case")]
pub enum Violation {
    /// Something panicked.
    #[error("no panic: the simulation panicked at cycle {cycle}: {message}")]
    Panic {
        /// Last completed cycle.
        cycle: u64,
        /// The panic message.
        message: String,
    },
    /// The worker made no progress for the wall-time watchdog.
    #[error("no hang: no poll cycle completed for {wall_s:.1} s of wall time after cycle {cycle}")]
    Hang {
        /// Last completed cycle.
        cycle: u64,
        /// Wall time without progress (s).
        wall_s: f64,
    },
    /// Bus time advanced but the master completed no cycle.
    #[error("no hang: poll cycle {cycle} did not complete within {limit_ms} ms of bus time (bus time {bus_time_s:.3} s)")]
    BusStalled {
        /// The cycle that did not complete.
        cycle: u64,
        /// The limit (ms).
        limit_ms: u64,
        /// Bus time when giving up (s).
        bus_time_s: f64,
    },
    /// Memory grew.
    #[error("bounded memory: {what}")]
    Memory {
        /// What grew.
        what: String,
    },
    /// A slave was not back in Data_Exchange in time.
    #[error("recovery: slave {address} ({profile}) not back in Data_Exchange {waited_ms} ms (limit {limit_ms} ms) after its disturbance at cycle {since_cycle} (state {state})")]
    NotRecovered {
        /// Station address.
        address: u8,
        /// Its profile.
        profile: String,
        /// Cycle of the disturbance.
        since_cycle: u64,
        /// Bus time waited (ms).
        waited_ms: u64,
        /// The limit (ms).
        limit_ms: u64,
        /// The master's state of the slave.
        state: String,
    },
}

/// Counters of one slave over the run.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SlaveSummary {
    /// Station address.
    pub address: u8,
    /// Profile name.
    pub profile: String,
    /// Data_Exchange cycles completed (master's count).
    pub data_exchanges: u64,
    /// Layer-2 repetitions.
    pub retries: u64,
    /// Requests without answer after the retries.
    pub errors: u64,
    /// Start-up sequences begun again.
    pub restarts: u64,
    /// Disturbances (see the module docs).
    pub disturbances: u64,
    /// Times the master took it out of Data_Exchange.
    pub dx_exits: u64,
    /// Watchdog expiries in the slave.
    pub watchdog_expiries: u64,
}

/// What the master's FDL station did in the token ring. The soak has one
/// master, so every token it did not pass itself is forged by the line:
/// an SD4 token telegram (`DC DA SA`) has no FCS, and a bit error can
/// turn one token into another, or another byte into SD4.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct TokenRing {
    /// Tokens the master received (as the only master, its passes to
    /// itself).
    pub tokens: u64,
    /// Frames of another station while the master held the token: it
    /// dropped its token as the standard requires (duplicate token) and
    /// claimed it again after the token-lost timeout. With one master,
    /// every one was forged by the line.
    pub duplicate_tokens: u64,
    /// Tokens claimed after the token-lost timeout (the first, at the
    /// start, included).
    pub claims: u64,
    /// Replies that came after the slot time (ignored).
    pub late_replies: u64,
    /// Frames with the master's own address as the source (forged too).
    pub address_collisions: u64,
}

/// The outcome of a soak.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SoakReport {
    /// Seed used.
    pub seed: u64,
    /// Cycles asked for.
    pub cycles_requested: u64,
    /// Cycles completed.
    pub cycles: u64,
    /// Bus time (s).
    pub bus_time_s: f64,
    /// Wall time (s).
    pub wall_time_s: f64,
    /// What the line carried and injected.
    #[serde(serialize_with = "stats::medium_stats")]
    pub medium: MediumStats,
    /// The reference receiver's classification of what was on the line.
    pub integrity: Integrity,
    /// Telegram candidates the stations' own receivers rejected (bad FCS,
    /// length, end delimiter, format, truncated).
    pub receiver_errors: u64,
    /// The master's token ring counters: duplicate tokens (forged) and
    /// claims.
    pub token_ring: TokenRing,
    /// Per slave.
    pub slaves: Vec<SlaveSummary>,
    /// Disturbances in total.
    pub disturbances: u64,
    /// Time from the first failed cycle to the first good one, per
    /// disturbance.
    pub recovery: Distribution,
    /// Time back to Data_Exchange, per exit from it.
    pub dx_recovery: Distribution,
    /// Resident set after the warm-up and at its largest later (bytes;
    /// 0 when not measured).
    pub rss_baseline: u64,
    /// See `rss_baseline`.
    pub rss_max: u64,
    /// Invariants that broke (the run stops at the first).
    pub violations: Vec<Violation>,
}

impl SoakReport {
    /// Whether every invariant held.
    pub fn passed(&self) -> bool {
        self.violations.is_empty()
    }
}

impl std::fmt::Display for Distribution {
    /// `n=…, cycles p50/p99/max …/…/…, ms p50/p99/max …/…/…`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.count() == 0 {
            return write!(f, "n=0");
        }
        let ms = |d: Option<Duration>| d.map_or(0.0, |d| d.as_secs_f64() * 1e3);
        write!(
            f,
            "n={}, cycles p50/p99/max {}/{}/{}, ms p50/p99/max {:.2}/{:.2}/{:.2}",
            self.count(),
            self.cycles_quantile(0.5).unwrap_or(0),
            self.cycles_quantile(0.99).unwrap_or(0),
            self.max_cycles(),
            ms(self.time_quantile(0.5)),
            ms(self.time_quantile(0.99)),
            ms(Some(self.max_time())),
        )
    }
}

impl std::fmt::Display for SoakReport {
    /// A summary of several lines, each ending in a newline.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "soak: seed {}, {} of {} cycles, {:.1} s bus time, {:.1} s wall time",
            self.seed, self.cycles, self.cycles_requested, self.bus_time_s, self.wall_time_s
        )?;
        writeln!(f, "line: {}", self.medium)?;
        let i = &self.integrity;
        writeln!(
            f,
            "telegrams: {} sent, {} intact, {} corrupted ({} rejected, {} undetected by the FCS, counted); {} valid-looking in noise; receivers rejected {} candidates",
            i.sent, i.intact, i.corrupted, i.rejected, i.undetected, i.noise_telegrams, self.receiver_errors
        )?;
        let r = &self.token_ring;
        writeln!(
            f,
            "token ring: the only master dropped its token {} times for a duplicate token and claimed it {} times \
             (forged tokens: an SD4 token has no FCS; the line carried {} forged and {} made of noise); {} address collisions, {} late replies",
            r.duplicate_tokens, r.claims, i.forged_tokens, i.noise_tokens, r.address_collisions, r.late_replies
        )?;
        for s in &self.slaves {
            writeln!(
                f,
                "slave {:3} {:8} {} exchanges, {} retries, {} errors, {} restarts, {} disturbances, {} Data_Exchange exits, {} watchdog expiries",
                s.address,
                s.profile,
                s.data_exchanges,
                s.retries,
                s.errors,
                s.restarts,
                s.disturbances,
                s.dx_exits,
                s.watchdog_expiries
            )?;
        }
        writeln!(f, "recovery after a disturbance: {}", self.recovery)?;
        writeln!(
            f,
            "back in Data_Exchange after an exit: {}",
            self.dx_recovery
        )?;
        if self.rss_max > 0 {
            writeln!(
                f,
                "resident set: {} KiB after the warm-up, at most {} KiB",
                self.rss_baseline >> 10,
                self.rss_max >> 10
            )?;
        }
        match self.violations.first() {
            None => writeln!(f, "invariants: all held"),
            Some(v) => writeln!(f, "invariant broken: {v}"),
        }
    }
}

/// Progress of a running soak.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Progress {
    /// Cycles completed.
    pub cycles: u64,
    /// Bus time (s).
    pub bus_time_s: f64,
    /// Disturbances so far.
    pub disturbances: u64,
}

/// Why a soak could not start.
#[derive(Debug, thiserror::Error)]
pub enum SoakError {
    /// A device profile cannot be configured.
    #[error("device profile {name}: {error}")]
    Profile {
        /// The profile.
        name: &'static str,
        /// The cause (in the message; not also `source()`, so that a
        /// printed error chain names it once).
        error: profibus_devices::ProfileError,
    },
    /// The plant's builder refused a slave or the master.
    #[error(transparent)]
    Plant(#[from] crate::PlantError),
    /// A fault setting is out of range.
    #[error(transparent)]
    Medium(#[from] profibus_fdl::line::medium::MediumConfigError),
    /// A JX2 PLC setup error.
    #[error("jx2: {0}")]
    Jx2(String),
    /// The worker thread cannot be started.
    #[error("cannot start the soak thread: {0}")]
    Thread(std::io::Error),
}

enum Msg {
    Progress(Progress),
    Done(Box<SoakReport>),
}

/// Run a soak; `progress` is called every [`SoakConfig::progress_every`]
/// cycles. Violations are in the report; an error means it could not
/// start.
pub fn run(cfg: &SoakConfig, mut progress: impl FnMut(&Progress)) -> Result<SoakReport, SoakError> {
    cfg.medium().validate()?;
    // Configure once here so that setup errors come back as errors.
    plant::stations(cfg)?;
    let heartbeat = Arc::new(AtomicU64::new(0));
    let (tx, rx) = mpsc::channel();
    let worker = {
        let cfg = cfg.clone();
        let heartbeat = heartbeat.clone();
        let tx = tx.clone();
        std::thread::Builder::new()
            .name("soak".into())
            .spawn(move || {
                let report = Soak::new(&cfg, heartbeat, tx.clone()).map(|s| s.run());
                if let Ok(report) = report {
                    let _ = tx.send(Msg::Done(Box::new(report)));
                }
            })
            .map_err(SoakError::Thread)?
    };
    drop(tx);
    let start = std::time::Instant::now();
    let mut last = (0u64, std::time::Instant::now());
    let mut report = None;
    while report.is_none() {
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(Msg::Progress(p)) => progress(&p),
            Ok(Msg::Done(r)) => report = Some(*r),
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
            Err(mpsc::RecvTimeoutError::Timeout) => {}
        }
        let beat = heartbeat.load(Ordering::Relaxed);
        if beat != last.0 {
            last = (beat, std::time::Instant::now());
        } else if report.is_none() && last.1.elapsed() > cfg.wall_watchdog {
            // The worker is stuck inside a computation: report and leave
            // it (a thread cannot be stopped from outside).
            return Ok(SoakReport {
                seed: cfg.seed,
                cycles_requested: cfg.cycles,
                cycles: beat,
                wall_time_s: start.elapsed().as_secs_f64(),
                violations: vec![Violation::Hang {
                    cycle: beat,
                    wall_s: last.1.elapsed().as_secs_f64(),
                }],
                ..SoakReport::default()
            });
        }
    }
    match report {
        Some(mut r) => {
            let _ = worker.join();
            r.wall_time_s = start.elapsed().as_secs_f64();
            Ok(r)
        }
        None => {
            let message = match worker.join() {
                Err(p) => p
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "(no message)".into()),
                Ok(()) => "the soak thread ended without a report".into(),
            };
            Ok(SoakReport {
                seed: cfg.seed,
                cycles_requested: cfg.cycles,
                cycles: heartbeat.load(Ordering::Relaxed),
                wall_time_s: start.elapsed().as_secs_f64(),
                violations: vec![Violation::Panic {
                    cycle: heartbeat.load(Ordering::Relaxed),
                    message,
                }],
                ..SoakReport::default()
            })
        }
    }
}

/// A disturbance being watched: cycle and bus time of the first failed
/// cycle.
#[derive(Debug, Clone, Copy)]
struct Episode {
    cycle: u64,
    at: Instant,
}

struct Tracked {
    station: StationId,
    address: u8,
    profile: &'static str,
    last: profibus_dp::master::SlaveStats,
    disturbed: Option<Episode>,
    dx_left: Option<Episode>,
    summary: SlaveSummary,
}

struct Soak {
    cfg: SoakConfig,
    bus: SimBus,
    master: StationId,
    slaves: Vec<Tracked>,
    ledger: Rc<RefCell<Ledger>>,
    heartbeat: Arc<AtomicU64>,
    tx: mpsc::Sender<Msg>,
    report: SoakReport,
    cycle: u64,
}

impl Soak {
    fn new(
        cfg: &SoakConfig,
        heartbeat: Arc<AtomicU64>,
        tx: mpsc::Sender<Msg>,
    ) -> Result<Soak, SoakError> {
        let stations = plant::stations(cfg)?;
        let ledger = Rc::new(RefCell::new(Ledger::new(stations.slaves.len() + 1)));
        let mut bus = SimBus::new(stations.medium);
        let master = bus.add(Recorded::new(stations.master, 0, ledger.clone()));
        let mut tracked = Vec::new();
        for (i, (s, station)) in stations.slaves.into_iter().enumerate() {
            let station = bus.add(Recorded::new(station, i + 1, ledger.clone()));
            let profile = plant::profile(&s);
            tracked.push(Tracked {
                station,
                address: s.address,
                profile,
                last: Default::default(),
                disturbed: None,
                dx_left: None,
                summary: SlaveSummary {
                    address: s.address,
                    profile: profile.into(),
                    ..SlaveSummary::default()
                },
            });
        }
        {
            let ledger = ledger.clone();
            bus.set_tap(Box::new(move |_at, from, bytes| {
                ledger.borrow_mut().delivered(from, bytes);
            }));
        }
        Ok(Soak {
            cfg: cfg.clone(),
            bus,
            master,
            slaves: tracked,
            ledger,
            heartbeat,
            tx,
            report: SoakReport {
                seed: cfg.seed,
                cycles_requested: cfg.cycles,
                recovery: Distribution::new(),
                dx_recovery: Distribution::new(),
                ..SoakReport::default()
            },
            cycle: 0,
        })
    }

    fn master(bus: &SimBus, id: StationId) -> &profibus_dp::master::DpMaster {
        bus.station::<Recorded<MasterStation>>(id).inner().app()
    }

    /// Run one more poll cycle; false when it did not complete in time.
    fn step_cycle(&mut self) -> bool {
        let target = Self::master(&self.bus, self.master).cycle_stats().cycles + 1;
        let id = self.master;
        self.bus.run_while(self.cfg.cycle_limit, |b| {
            Self::master(b, id).cycle_stats().cycles >= target
        })
    }

    fn run(mut self) -> SoakReport {
        let warmup = (self.cfg.cycles / 20).clamp(1000, 50_000);
        let mem_every = 10_000;
        let mut started = false;
        while self.report.violations.is_empty() {
            let done = self.cycle >= self.cfg.cycles;
            if done && self.slaves.iter().all(|s| s.disturbed.is_none()) {
                break;
            }
            if !self.step_cycle() {
                self.report.violations.push(Violation::BusStalled {
                    cycle: self.cycle + 1,
                    limit_ms: self.cfg.cycle_limit.as_millis() as u64,
                    bus_time_s: secs(self.bus.now()),
                });
                break;
            }
            if !done {
                self.cycle += 1;
            }
            self.heartbeat.store(self.cycle, Ordering::Relaxed);
            if let Some((address, at)) = self.cfg.unplug {
                if self.cycle == at {
                    if let Some(s) = self.slaves.iter().find(|s| s.address == address) {
                        self.bus.set_online(s.station, false);
                    }
                }
            }
            // Slaves must reach Data_Exchange once before disturbances
            // count.
            if !started {
                started = self.all_in_data_exchange();
                let m = self.bus.station_mut::<Recorded<MasterStation>>(self.master);
                while m.inner_mut().app_mut().poll_event().is_some() {}
                self.snapshot();
                if !started && self.bus.now() > Instant::ZERO + self.cfg.max_recovery * 5 {
                    let s = self
                        .slaves
                        .iter()
                        .find(|s| {
                            Self::master(&self.bus, self.master).slave_state(s.address)
                                != Some(SlaveState::DataExchange)
                        })
                        .expect("a slave outside Data_Exchange");
                    self.report.violations.push(Violation::NotRecovered {
                        address: s.address,
                        profile: s.profile.into(),
                        since_cycle: 0,
                        waited_ms: self.bus.now().as_nanos() / 1_000_000,
                        limit_ms: (self.cfg.max_recovery * 5).as_millis() as u64,
                        state: Self::master(&self.bus, self.master)
                            .slave_state(s.address)
                            .map_or("unknown", |st| st.name())
                            .into(),
                    });
                }
                continue;
            }
            self.check_cycle();
            self.drain_slaves();
            if self.cycle.is_multiple_of(mem_every) || self.cycle == warmup {
                self.check_memory(self.cycle == warmup, self.cycle > warmup);
            }
            if self.cfg.progress_every > 0 && self.cycle.is_multiple_of(self.cfg.progress_every) {
                let _ = self.tx.send(Msg::Progress(Progress {
                    cycles: self.cycle,
                    bus_time_s: secs(self.bus.now()),
                    disturbances: self.report.disturbances,
                }));
            }
        }
        self.finish()
    }

    fn all_in_data_exchange(&self) -> bool {
        let m = Self::master(&self.bus, self.master);
        self.slaves
            .iter()
            .all(|s| m.slave_state(s.address) == Some(SlaveState::DataExchange))
    }

    fn snapshot(&mut self) {
        let m = Self::master(&self.bus, self.master);
        for s in &mut self.slaves {
            s.last = m.slave_stats(s.address).unwrap_or_default();
        }
    }

    /// After a completed cycle: disturbances, recoveries, DX exits.
    fn check_cycle(&mut self) {
        let now = self.bus.now();
        let cycle = self.cycle;
        let id = self.master;
        let m = self
            .bus
            .station_mut::<Recorded<MasterStation>>(id)
            .inner_mut()
            .app_mut();
        while let Some(e) = m.poll_event() {
            if let MasterEvent::StateChanged { address, from, to } = e {
                let Some(s) = self.slaves.iter_mut().find(|s| s.address == address) else {
                    continue;
                };
                if from == SlaveState::DataExchange && s.dx_left.is_none() {
                    s.dx_left = Some(Episode { cycle, at: now });
                    s.summary.dx_exits += 1;
                } else if to == SlaveState::DataExchange {
                    if let Some(e) = s.dx_left.take() {
                        self.report
                            .dx_recovery
                            .record(cycle - e.cycle, now.saturating_duration_since(e.at));
                    }
                }
            }
        }
        if m.events_dropped() > 0 {
            self.report.violations.push(Violation::Memory {
                what: format!(
                    "the master's event queue overflowed ({} events dropped)",
                    m.events_dropped()
                ),
            });
        }
        let m = Self::master(&self.bus, self.master);
        for s in &mut self.slaves {
            let st = m.slave_stats(s.address).unwrap_or_default();
            let state = m.slave_state(s.address);
            let failed = st.errors > s.last.errors || state != Some(SlaveState::DataExchange);
            let good = !failed && st.data_exchanges > s.last.data_exchanges;
            s.last = st;
            match s.disturbed {
                None if failed => {
                    s.disturbed = Some(Episode { cycle, at: now });
                    s.summary.disturbances += 1;
                    self.report.disturbances += 1;
                }
                Some(e) if good => {
                    self.report
                        .recovery
                        .record(cycle - e.cycle, now.saturating_duration_since(e.at));
                    s.disturbed = None;
                }
                Some(e) if now.saturating_duration_since(e.at) > self.cfg.max_recovery => {
                    self.report.violations.push(Violation::NotRecovered {
                        address: s.address,
                        profile: s.profile.into(),
                        since_cycle: e.cycle,
                        waited_ms: now.saturating_duration_since(e.at).as_millis() as u64,
                        limit_ms: self.cfg.max_recovery.as_millis() as u64,
                        state: state.map_or("unknown", |st| st.name()).into(),
                    });
                    return;
                }
                _ => {}
            }
        }
    }

    fn drain_slaves(&mut self) {
        for s in &self.slaves {
            let slave = self
                .bus
                .station_mut::<Recorded<SlaveStation>>(s.station)
                .inner_mut()
                .app_mut();
            while slave.poll_event().is_some() {}
        }
    }

    fn check_memory(&mut self, baseline: bool, check: bool) {
        let Some(rss) = stats::resident_set() else {
            return;
        };
        if baseline {
            self.report.rss_baseline = rss;
        }
        self.report.rss_max = self.report.rss_max.max(rss);
        if let (true, Some(limit)) = (check, self.cfg.max_rss_growth) {
            let growth = rss.saturating_sub(self.report.rss_baseline);
            if growth > limit {
                self.report.violations.push(Violation::Memory {
                    what: format!(
                        "the resident set grew by {} KiB after the warm-up (limit {} KiB) by cycle {}",
                        growth >> 10,
                        limit >> 10,
                        self.cycle
                    ),
                });
            }
        }
        let pending = self.ledger.borrow().pending();
        if pending > ledger::PENDING_LIMIT {
            self.report.violations.push(Violation::Memory {
                what: format!("the reference receiver holds {pending} unframed bytes"),
            });
        }
    }

    fn finish(mut self) -> SoakReport {
        let now = self.bus.now();
        // Let the line deliver what is still on it (stations off, so
        // nothing new is sent), for the reference receiver's count.
        if self.report.violations.is_empty() {
            for id in std::iter::once(self.master).chain(self.slaves.iter().map(|s| s.station)) {
                self.bus.set_online(id, false);
            }
            self.bus.run_for(Duration::from_millis(5));
        }
        let m = Self::master(&self.bus, self.master);
        let station = self
            .bus
            .station::<Recorded<MasterStation>>(self.master)
            .inner();
        let mut receiver_errors = station.codec_stats().errors();
        let fdl = station.stats();
        self.report.token_ring = TokenRing {
            tokens: fdl.tokens,
            duplicate_tokens: fdl.duplicate_tokens,
            claims: fdl.claims,
            late_replies: fdl.late_replies,
            address_collisions: fdl.collisions,
        };
        for s in &mut self.slaves {
            let st = m.slave_stats(s.address).unwrap_or_default();
            s.summary.data_exchanges = st.data_exchanges;
            s.summary.retries = st.retries;
            s.summary.errors = st.errors;
            s.summary.restarts = st.restarts;
            let station = self
                .bus
                .station::<Recorded<SlaveStation>>(s.station)
                .inner();
            s.summary.watchdog_expiries = station.app().stats().watchdog_expiries;
            receiver_errors += station.codec_stats().errors();
        }
        self.report.cycles = self.cycle;
        self.report.bus_time_s = secs(now);
        self.report.medium = self.bus.medium_stats();
        self.report.integrity = self.ledger.borrow().integrity();
        self.report.receiver_errors = receiver_errors;
        self.report.slaves = self.slaves.into_iter().map(|s| s.summary).collect();
        self.report
    }
}

fn secs(t: Instant) -> f64 {
    t.as_nanos() as f64 / 1e9
}

#[cfg(test)]
mod tests;
