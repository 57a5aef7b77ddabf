//! What a [`BusView`](crate::bus::BusView) shows: a [`BusSnapshot`] of
//! the bus at one moment, taken from a [`BusSource`]. Two sources exist:
//! a [`DpMaster`] (the view of `dpctl master` and `dpctl demo`, which may
//! write the slaves' outputs) and a passive [`Monitor`] (`dpctl monitor`,
//! which never sends: its view refuses writes).

use profibus_dp::master::{DpMaster, OperatingState, SlaveState};
use profibus_dp::monitor::stats::{LiveStation, Stats};
use profibus_dp::monitor::{BusCounters, MasterStatus, Monitor, MonitorStatus};
use profibus_fdl::Instant;
use std::time::Duration;

/// A slave's counters as the view shows them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Data_Exchange cycles completed.
    pub data_exchanges: u64,
    /// Requests repeated at layer 2.
    pub retries: u64,
    /// Requests without a valid reply.
    pub errors: u64,
    /// Times the start-up sequence began again.
    pub restarts: u64,
    /// Slave_Diag reads (`None`: the source does not count them).
    pub diag_reads: Option<u64>,
    /// Answers that came after their request's wait and were dropped
    /// (`None`: the source sends no requests).
    pub late_replies: Option<u64>,
}

/// A slave's last diagnosis.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Diagnosis {
    /// The Slave_Diag data unit (empty: none read yet); the view puts it
    /// in words with the slave's GSD.
    Raw {
        /// The bytes.
        bytes: Vec<u8>,
        /// The slave runs DP-V1 (its extended diagnosis holds alarms).
        dpv1: bool,
    },
    /// Already in words (empty: none seen).
    Words(Vec<String>),
}

/// One slave at one moment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlaveSnapshot {
    /// Station address.
    pub address: u8,
    /// Where it is in the start-up sequence (`None`: not seen on the line
    /// yet).
    pub state: Option<SlaveState>,
    /// The master that polls it, when the source is not that master.
    pub master: Option<u8>,
    /// Inputs of the last Data_Exchange.
    pub inputs: Vec<u8>,
    /// Outputs of the last Data_Exchange.
    pub outputs: Vec<u8>,
    /// Counters.
    pub counters: Counters,
    /// The last diagnosis.
    pub diag: Diagnosis,
    /// Its FMS connections in words, one line each (a monitor's
    /// [`profibus_dp::monitor::fms::FmsConnectionStatus`]; empty: none).
    pub fms: Vec<String>,
}

/// The bus at one moment.
#[derive(Debug, Clone, PartialEq)]
pub struct BusSnapshot {
    /// The master that runs the view (`None`: a passive monitor).
    pub station: Option<u8>,
    /// Operating state of the (first) master.
    pub operating: Option<OperatingState>,
    /// Poll cycles.
    pub cycles: u64,
    /// Shortest, mean and longest cycle time in µs.
    pub cycle_us: [u64; 3],
    /// Bus time of the snapshot.
    pub bus_time: Duration,
    /// The masters heard in the token ring (a monitor's live list; `None`
    /// for a master, which knows only itself).
    pub ring: Option<Vec<MasterStatus>>,
    /// Counters of the whole line (monitor only).
    pub line: Option<BusCounters>,
    /// The slaves.
    pub slaves: Vec<SlaveSnapshot>,
    /// The analyser's live list: role, DP state and health of every
    /// station heard (`None`: no statistics run beside the source;
    /// [`WithLiveList`]).
    pub live: Option<Vec<LiveStation>>,
}

impl BusSnapshot {
    /// The master `m` and its slaves at `now`.
    pub fn of_master(m: &DpMaster, now: Instant) -> BusSnapshot {
        let c = m.cycle_stats();
        let slaves = m
            .slave_addresses()
            .filter_map(|a| {
                let s = m.slave(m.handle(a)?);
                Some(SlaveSnapshot {
                    address: a,
                    state: Some(s.state),
                    master: None,
                    inputs: s.inputs.to_vec(),
                    outputs: s.outputs.to_vec(),
                    counters: Counters {
                        data_exchanges: s.stats.data_exchanges,
                        retries: s.stats.retries,
                        errors: s.stats.errors,
                        restarts: s.stats.restarts,
                        diag_reads: Some(s.stats.diag_reads),
                        late_replies: Some(s.stats.late_replies),
                    },
                    diag: Diagnosis::Raw {
                        bytes: s.diag.to_vec(),
                        dpv1: m.slave_params(a).is_some_and(|p| p.dpv1),
                    },
                    fms: vec![],
                })
            })
            .collect();
        BusSnapshot {
            station: Some(m.address()),
            operating: Some(m.operating_state()),
            cycles: c.cycles,
            cycle_us: [c.min_ns / 1000, c.avg().as_micros() as u64, c.max_ns / 1000],
            bus_time: now - Instant::ZERO,
            ring: None,
            line: None,
            slaves,
            live: None,
        }
    }

    /// What a passive monitor saw.
    pub fn of_monitor(s: &MonitorStatus) -> BusSnapshot {
        BusSnapshot {
            station: None,
            operating: s.operating,
            cycles: s.cycles,
            cycle_us: [s.cycle_us.min, s.cycle_us.avg, s.cycle_us.max],
            bus_time: Duration::from_secs_f64(s.t.max(0.0)),
            ring: Some(s.masters.iter().filter(|m| m.in_ring).copied().collect()),
            line: Some(s.bus),
            slaves: s
                .slaves
                .iter()
                .map(|x| SlaveSnapshot {
                    address: x.address,
                    state: x.state,
                    master: x.master,
                    inputs: x.inputs.clone(),
                    outputs: x.outputs.clone(),
                    counters: Counters {
                        data_exchanges: x.counters.data_exchanges,
                        retries: x.counters.retries,
                        errors: x.counters.errors,
                        restarts: x.counters.restarts,
                        diag_reads: None,
                        late_replies: None,
                    },
                    diag: Diagnosis::Words(x.diag.clone()),
                    fms: x.fms.iter().map(|c| c.to_string()).collect(),
                })
                .collect(),
            live: None,
        }
    }
}

/// Something a [`BusView`](crate::bus::BusView) can show.
pub trait BusSource {
    /// The bus at `now` (bus time).
    fn snapshot(&self, now: Instant) -> BusSnapshot;

    /// The output image of the slave at `address`, to write into (`None`:
    /// not a slave of this source, or a source that never sends).
    fn outputs_mut(&mut self, address: u8) -> Option<&mut [u8]>;
}

impl BusSource for DpMaster {
    fn snapshot(&self, now: Instant) -> BusSnapshot {
        BusSnapshot::of_master(self, now)
    }

    fn outputs_mut(&mut self, address: u8) -> Option<&mut [u8]> {
        let h = self.handle(address)?;
        Some(DpMaster::outputs_mut(self, h))
    }
}

/// A monitor only listens: it has no outputs to write.
impl BusSource for Monitor {
    fn snapshot(&self, _now: Instant) -> BusSnapshot {
        BusSnapshot::of_monitor(&self.status())
    }

    fn outputs_mut(&mut self, _address: u8) -> Option<&mut [u8]> {
        None
    }
}

/// A source with the analyser's statistics core beside it (`dpctl
/// monitor`): its snapshots carry the live list, so the view shows each
/// station's role and health ([`crate::health`]).
pub struct WithLiveList<'a, S: ?Sized> {
    /// The source.
    pub source: &'a mut S,
    /// The statistics core fed with the same telegrams.
    pub stats: &'a Stats,
}

impl<S: BusSource + ?Sized> BusSource for WithLiveList<'_, S> {
    fn snapshot(&self, now: Instant) -> BusSnapshot {
        let mut s = self.source.snapshot(now);
        s.live = Some(self.stats.live());
        s
    }

    fn outputs_mut(&mut self, address: u8) -> Option<&mut [u8]> {
        self.source.outputs_mut(address)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_dp::config::layout::SlaveLayout;
    use profibus_dp::monitor::{MonitorOptions, SlaveInfo};
    use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus};
    use profibus_fdl::Telegram;

    #[test]
    fn a_monitor_snapshot_has_the_ring_the_line_and_the_slaves_it_heard() {
        let slaves = vec![SlaveInfo::from(SlaveLayout {
            address: 8,
            name: "valve".into(),
            ..SlaveLayout::default()
        })];
        let mut mon = Monitor::new(slaves, MonitorOptions::default());
        let data = |da, sa, fc, du| {
            Telegram::Data(DataTelegram {
                da,
                sa,
                fc,
                dsap: None,
                ssap: None,
                data: du,
                format: None,
            })
        };
        let req = FunctionCode::Request {
            kind: RequestKind::SrdHigh,
            fcb: true,
            fcv: true,
        };
        let ms = |n: u64| Instant::from_nanos(n * 1_000_000);
        mon.observe(ms(1), &data(8, 2, req, &[0x55]));
        let resp = FunctionCode::slave_response(ResponseStatus::Dl);
        mon.observe(ms(2), &data(2, 8, resp, &[0x2A]));
        mon.observe(ms(3), &Telegram::Token { da: 2, sa: 2 });
        let s = mon.snapshot(ms(3));
        assert_eq!(s.station, None);
        let ring: Vec<u8> = s.ring.unwrap().iter().map(|m| m.address).collect();
        assert_eq!(ring, [2]);
        assert_eq!(s.line.unwrap().telegrams, 3);
        let v = &s.slaves[0];
        assert_eq!(v.state, Some(SlaveState::DataExchange));
        assert_eq!(
            (v.master, &v.inputs[..], &v.outputs[..]),
            (Some(2), &[0x2A][..], &[0x55][..])
        );
        assert_eq!(mon.outputs_mut(8), None, "a monitor never writes");
    }
}
