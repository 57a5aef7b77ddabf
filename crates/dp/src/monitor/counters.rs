//! The statistics of a master's own slaves, from its counters: what a
//! gateway (which runs the master itself and has no tap on the line)
//! hands to the same [`StatsReport`]s and [`alert`](super::alert) rules
//! as `dpctl sniff` and `dpctl monitor`.
//!
//! [`MasterCounters::report`] takes the difference of each slave's
//! [`SlaveStats`] since the last report and fills a [`StationStats`] per
//! slave (and one for the master's own address):
//!
//! - **retries**: the master's layer-2 request repetitions;
//!   **no_answer**: its requests without an answer
//!   ([`SlaveStats::errors`]);
//! - **requests**: Data_Exchange cycles + Slave_Diag reads + retries +
//!   requests without an answer — the master does not count its
//!   start-up requests (Set_Prm, Chk_Cfg, Get_Cfg) one by one, so `%`
//!   rules are a share of the cyclic traffic; **answers**: Data_Exchange
//!   cycles + Slave_Diag reads;
//! - **diag_requests** / **diag_answers**: Slave_Diag reads;
//! - **restarts**: times the start-up sequence began again after the
//!   slave had reached Data_Exchange, as the tap counts them: the
//!   master's own counter ([`SlaveStats::restarts`]), plus a slave that
//!   fell silent (`offline`, counted in `no_answer` meanwhile) and comes
//!   back into the start-up — which the master's counter leaves out.
//!   The states are sampled by [`MasterCounters::observe`];
//! - **dp_state**: the master's state of the slave; **health**: the same
//!   formula as the tap's ([`health`]);
//! - the master's own entry: **requests_sent** (all of the above),
//!   **bus_cycle** (its poll cycles of the interval, taken by
//!   [`MasterCounters::observe`] at each cycle boundary).
//!
//! Times between requests and answers, tokens and illegal telegrams are
//! not known to the master's application layer and stay empty.

use super::stats::{health, Durations, Role, StationStats, StatsReport, StatsSet};
use crate::master::{CycleStats, DpMaster, SlaveState, SlaveStats};
use profibus_fdl::Instant;
use std::collections::BTreeMap;
use std::time::Duration;

/// Interval statistics of a [`DpMaster`]'s slaves from its counters; see
/// the module docs.
#[derive(Debug, Default, Clone)]
pub struct MasterCounters {
    last: BTreeMap<u8, SlaveStats>,
    cycles: CycleStats,
    bus_cycle: Durations,
    tracks: BTreeMap<u8, Track>,
    totals: StatsSet,
    start: Option<Instant>,
}

/// A slave's state as last observed.
#[derive(Debug, Default, Clone, Copy)]
struct Track {
    /// Reached Data_Exchange since its last start-up.
    in_dx: bool,
    offline: bool,
    /// The master's restart counter when last observed.
    restarts_seen: u64,
    /// Restarts from `offline` (not in the master's counter).
    from_offline: u64,
}

fn station(d: &SlaveStats) -> StationStats {
    let answered = d.data_exchanges + d.diag_reads;
    let mut s = StationStats {
        role: Some(Role::Slave),
        requests: answered + d.retries + d.errors,
        answers: answered,
        retries: d.retries,
        no_answer: d.errors,
        diag_requests: d.diag_reads,
        diag_answers: d.diag_reads,
        restarts: d.restarts,
        ..StationStats::default()
    };
    s.health = health(&s);
    s
}

fn diff(now: &SlaveStats, before: &SlaveStats) -> SlaveStats {
    SlaveStats {
        data_exchanges: now.data_exchanges.saturating_sub(before.data_exchanges),
        retries: now.retries.saturating_sub(before.retries),
        errors: now.errors.saturating_sub(before.errors),
        restarts: now.restarts.saturating_sub(before.restarts),
        diag_reads: now.diag_reads.saturating_sub(before.diag_reads),
        ..SlaveStats::default()
    }
}

impl MasterCounters {
    /// Nothing counted yet: the first report covers everything since the
    /// master started.
    pub fn new() -> MasterCounters {
        MasterCounters::default()
    }

    /// Takes the poll cycles completed since the last call. Called at
    /// every cycle boundary, the interval's minimum and maximum cycle
    /// times are exact; cycles completed between two calls count at
    /// their mean.
    pub fn observe(&mut self, m: &DpMaster) {
        let c = m.cycle_stats();
        if c.cycles < self.cycles.cycles {
            // The master's cycle statistics started afresh.
            self.cycles = CycleStats::default();
        }
        let n = c.cycles - self.cycles.cycles;
        let sum = c.sum_ns.saturating_sub(self.cycles.sum_ns);
        if let Some(mean) = sum.checked_div(n) {
            self.bus_cycle.add_many(Duration::from_nanos(mean), n);
        }
        self.cycles = c;
        for a in m.slave_addresses() {
            let (Some(st), Some(c)) = (m.slave_state(a), m.slave_stats(a)) else {
                continue;
            };
            let t = self.tracks.entry(a).or_default();
            if c.restarts > t.restarts_seen {
                t.in_dx = false;
            } else if t.in_dx && t.offline && st != SlaveState::Offline {
                t.from_offline += 1;
                t.in_dx = false;
            }
            t.restarts_seen = c.restarts;
            t.offline = st == SlaveState::Offline;
            t.in_dx |= st == SlaveState::DataExchange;
        }
    }

    /// The statistics since the last report (or the start), ending at
    /// `now`, with the totals since the start.
    pub fn report(&mut self, m: &DpMaster, now: Instant) -> StatsReport {
        self.observe(m);
        let start = *self.start.get_or_insert(Instant::ZERO);
        let mut interval = StatsSet::default();
        let mut sent = SlaveStats::default();
        for a in m.slave_addresses() {
            let Some(mut c) = m.slave_stats(a) else {
                continue;
            };
            c.restarts += self.tracks.get(&a).map_or(0, |t| t.from_offline);
            let d = diff(&c, self.last.get(&a).unwrap_or(&SlaveStats::default()));
            self.last.insert(a, c);
            let mut s = station(&d);
            s.dp_state = m.slave_state(a);
            s.health = health(&s);
            sent.data_exchanges += d.data_exchanges;
            sent.diag_reads += d.diag_reads;
            sent.retries += d.retries;
            sent.errors += d.errors;
            interval.stations.insert(a, s);
            let mut t = station(&c);
            t.dp_state = m.slave_state(a);
            t.health = health(&t);
            self.totals.stations.insert(a, t);
        }
        let mut own = StationStats {
            role: Some(Role::Master),
            requests_sent: sent.data_exchanges + sent.diag_reads + sent.retries + sent.errors,
            ..StationStats::default()
        };
        own.bus_cycle = std::mem::take(&mut self.bus_cycle);
        own.health = health(&own);
        let addr = m.address();
        let t = self.totals.stations.entry(addr).or_default();
        t.role = Some(Role::Master);
        t.requests_sent += own.requests_sent;
        t.bus_cycle.merge(&own.bus_cycle);
        t.health = health(t);
        interval.stations.insert(addr, own);
        self.start = Some(now);
        StatsReport {
            event: "stats",
            interval_s: now.saturating_duration_since(start).as_secs_f64(),
            t_s: now.as_nanos() as f64 / 1e9,
            interval,
            totals: self.totals.clone(),
        }
    }
}
