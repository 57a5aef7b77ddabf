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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::master::tests::{bring_up, data_resp, diag_resp, master, next, FRESH, READY};
    use crate::pdu::sap;
    use profibus_fdl::station::active::{CycleResult, MasterApp, Outcome, Service};
    use profibus_fdl::wire::ResponseStatus;

    /// The master's request at `now` µs answered with `outcome` after
    /// `retries` layer-2 repetitions.
    fn cycle(m: &mut DpMaster, now: u64, outcome: Outcome<'_>, retries: u8) {
        next(m, now).expect("a request");
        m.on_result(
            Instant::from_nanos(now),
            &CycleResult {
                da: 8,
                service: Service::SrdHigh,
                outcome,
                retries,
            },
        );
    }

    fn at(ns: u64) -> Instant {
        Instant::from_nanos(ns)
    }

    #[test]
    fn requests_no_answer_and_retries_are_derived_from_the_masters_counters() {
        let mut m = master();
        let mut c = MasterCounters::new();
        bring_up(&mut m);
        // Two diagnosis reads of the start-up, then four Data_Exchange
        // cycles: one after 2 repetitions, one unanswered.
        cycle(&mut m, 5, data_resp(ResponseStatus::Dl, &[1, 2]), 0);
        cycle(&mut m, 6, data_resp(ResponseStatus::Dl, &[1, 2]), 2);
        cycle(&mut m, 7, Outcome::NoResponse, 0);
        cycle(&mut m, 8, data_resp(ResponseStatus::Dl, &[1, 2]), 0);
        let st = m.slave_stats(8).unwrap();
        assert_eq!((st.data_exchanges, st.diag_reads), (3, 2), "{st:?}");
        assert_eq!((st.retries, st.errors, st.restarts), (2, 1, 0), "{st:?}");

        let r = c.report(&m, at(1_000_000_000));
        let s = &r.interval.stations[&8];
        assert_eq!(s.role, Some(Role::Slave));
        assert_eq!(s.dp_state, Some(SlaveState::DataExchange));
        // requests = exchanges 3 + diagnosis reads 2 + retries 2 + no answer 1.
        assert_eq!((s.requests, s.answers), (8, 5));
        assert_eq!((s.retries, s.no_answer, s.restarts), (2, 1, 0));
        assert_eq!((s.diag_requests, s.diag_answers), (2, 2));
        // 1/8 lost costs 125 points, 2/8 retries 125: nothing left.
        assert_eq!(s.health, 0);
        let own = &r.interval.stations[&2];
        assert_eq!((own.role, own.requests_sent), (Some(Role::Master), 8));
        assert_eq!(r.interval_s, 1.0);

        // The next interval holds only what happened since.
        for k in 0..4 {
            cycle(&mut m, 10 + k, data_resp(ResponseStatus::Dl, &[1, 2]), 0);
        }
        let r = c.report(&m, at(3_000_000_000));
        let s = &r.interval.stations[&8];
        assert_eq!(
            (s.requests, s.answers, s.retries, s.no_answer),
            (4, 4, 0, 0)
        );
        assert_eq!(s.health, 100);
        assert_eq!(r.interval.stations[&2].requests_sent, 4);
        assert_eq!(r.interval_s, 2.0);
        // The totals since the start.
        let t = &r.totals.stations[&8];
        assert_eq!(
            (t.requests, t.answers, t.retries, t.no_answer),
            (12, 9, 2, 1)
        );
        assert_eq!(r.totals.stations[&2].requests_sent, 12);
    }

    #[test]
    fn a_slave_that_goes_offline_and_comes_back_counts_one_restart() {
        let mut m = master();
        let mut c = MasterCounters::new();
        bring_up(&mut m);
        c.observe(&m);
        cycle(&mut m, 5, data_resp(ResponseStatus::Dl, &[1, 2]), 0);
        c.observe(&m);
        // Silent three times: offline.
        for k in 0..3 {
            cycle(&mut m, 10 + k, Outcome::NoResponse, 0);
            c.observe(&m);
        }
        assert_eq!(m.slave_state(8), Some(SlaveState::Offline));
        let r = c.report(&m, at(1_000_000));
        let s = &r.interval.stations[&8];
        assert_eq!((s.no_answer, s.restarts, s.health), (3, 0, 0));

        // Probed again after the reprobe interval: back through the
        // start-up into Data_Exchange.
        let t = 20
            + crate::master::MasterOptions::default()
                .reprobe_interval
                .as_nanos() as u64;
        for (k, (dsap, outcome)) in [
            (Some(sap::SLAVE_DIAG), diag_resp(&FRESH)),
            (Some(sap::SET_PRM), Outcome::ShortAck),
            (Some(sap::CHK_CFG), Outcome::ShortAck),
            (Some(sap::SLAVE_DIAG), diag_resp(&READY)),
        ]
        .into_iter()
        .enumerate()
        {
            let now = t + k as u64;
            assert_eq!(next(&mut m, now).unwrap().0, dsap);
            m.on_result(
                Instant::from_nanos(now),
                &CycleResult {
                    da: 8,
                    service: Service::SrdHigh,
                    outcome,
                    retries: 0,
                },
            );
            c.observe(&m);
        }
        assert_eq!(m.slave_state(8), Some(SlaveState::DataExchange));
        // The master's own counter leaves a return from offline out …
        assert_eq!(m.slave_stats(8).unwrap().restarts, 0);
        cycle(&mut m, t + 10, data_resp(ResponseStatus::Dl, &[1, 2]), 0);
        let r = c.report(&m, at(2_000_000));
        // … the statistics count it once, in the interval and the totals.
        assert_eq!(r.interval.stations[&8].restarts, 1);
        assert_eq!(r.totals.stations[&8].restarts, 1);
        // Observed again and again, it stays one.
        for k in 0..3 {
            cycle(
                &mut m,
                t + 20 + k,
                data_resp(ResponseStatus::Dl, &[1, 2]),
                0,
            );
            c.observe(&m);
        }
        let r = c.report(&m, at(3_000_000));
        assert_eq!(r.interval.stations[&8].restarts, 0);
        assert_eq!(r.totals.stations[&8].restarts, 1);
    }
}
