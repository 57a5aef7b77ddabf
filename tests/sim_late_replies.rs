//! Late, duplicated and reordered replies on the simulated bus: slaves
//! whose answers (seeded at random) arrive after the master's slot time,
//! twice, or after the next answer, as on a loaded machine behind a pty.
//! The master must take none of them for the answer to another request:
//! every slave stays in Data_Exchange, and the counters say what was
//! dropped.

use profibus::devices::generic::{GenericDevice, InputPattern};
use profibus::dp::master::{
    DpMaster, MasterConfig, MasterEvent, MasterOptions, SlaveParams, SlaveState,
};
use profibus::dp::slave::{DpSlave, Features};
use profibus::fdl::line::medium::{Collisions, MediumConfig};
use profibus::fdl::sim::SimBus;
use profibus::fdl::station::active::{ActiveConfig, ActiveStation};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::station::Station;
use profibus::fdl::time::Instant;
use profibus::fdl::{Baud, BusParams};
use std::collections::VecDeque;
use std::time::Duration;

type Master = ActiveStation<DpMaster>;
type Slave = PassiveStation<DpSlave<GenericDevice>>;

/// What a [`Laggard`] does with one answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fate {
    OnTime,
    /// Sent only after the slot time ran out.
    Late,
    /// Sent on time, and once more later.
    Duplicated,
    /// Held back and sent after the station's next answer.
    Reordered,
}

/// A slave station whose answers are delayed, repeated or reordered at
/// random (seeded): the transport of a busy machine, not the slave core.
struct Laggard<S> {
    inner: S,
    rng: u64,
    /// Probability (in 1/1000) of each fate other than on time.
    permille: u64,
    delay: Duration,
    held: VecDeque<(Instant, Vec<u8>)>,
    reorder: Option<Vec<u8>>,
    out: Vec<u8>,
    fates: [u64; 4],
}

impl<S> Laggard<S> {
    fn new(inner: S, seed: u64, permille: u64, delay: Duration) -> Self {
        Laggard {
            inner,
            rng: seed,
            permille,
            delay,
            held: VecDeque::new(),
            reorder: None,
            out: Vec::new(),
            fates: [0; 4],
        }
    }

    fn roll(&mut self) -> Fate {
        // splitmix64
        self.rng = self.rng.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.rng;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        let r = (z ^ (z >> 31)) % 1000;
        match r {
            r if r < self.permille => Fate::Late,
            r if r < 2 * self.permille => Fate::Duplicated,
            r if r < 3 * self.permille => Fate::Reordered,
            _ => Fate::OnTime,
        }
    }
}

impl<S: Station> Station for Laggard<S> {
    fn handle_rx(&mut self, now: Instant, bytes: &[u8]) {
        self.inner.handle_rx(now, bytes)
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.inner.handle_timeout(now)
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<&[u8]> {
        if self.held.front().is_some_and(|(t, _)| *t <= now) {
            self.out = self.held.pop_front().unwrap().1;
            return Some(&self.out);
        }
        let reply = self.inner.poll_transmit(now)?.to_vec();
        let fate = self.roll();
        self.fates[fate as usize] += 1;
        let release = now + self.delay;
        self.out = match fate {
            Fate::OnTime => reply,
            Fate::Late => {
                self.held.push_back((release, reply));
                return None;
            }
            Fate::Duplicated => {
                self.held.push_back((release, reply.clone()));
                reply
            }
            // Two in a row: the older one goes now.
            Fate::Reordered => self.reorder.replace(reply)?,
        };
        // A reordered answer follows the next one that goes out.
        if fate != Fate::Reordered {
            if let Some(r) = self.reorder.take() {
                self.held.push_front((now, r));
            }
        }
        Some(&self.out)
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let held = self.held.front().map(|(t, _)| *t);
        match (self.inner.poll_timeout(), held) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

#[test]
fn late_duplicated_and_reordered_replies_never_knock_a_slave_out_of_data_exchange() {
    let baud = Baud::B1500000;
    let params = BusParams::defaults(baud);
    // A pty-like line: a late sender waits for the line instead of
    // garbling the master's next request.
    let mut medium = MediumConfig::paced(baud);
    medium.collisions = Collisions::Serialize;
    let mut bus = SimBus::new(medium);
    let addrs = [10u8, 11, 12];
    // Different input lengths, so that a late answer of one slave would
    // not even fit another's image.
    let cfgs: [&[u8]; 3] = [&[0x11, 0x21], &[0x13, 0x23], &[0x17, 0x27]];
    // Read every diagnosis often, so that late Data_Exchange answers meet
    // pending Slave_Diag requests.
    let options = MasterOptions {
        diag_interval: Some(Duration::from_millis(1)),
        ..MasterOptions::default()
    };
    let slaves = addrs
        .iter()
        .zip(cfgs)
        .map(|(&a, cfg)| {
            let mut p = SlaveParams::new(a, 0x0DCE, cfg.to_vec());
            p.watchdog = Some(Duration::from_millis(200));
            p
        })
        .collect();
    let dp = DpMaster::new(&MasterConfig {
        address: 2,
        params,
        slaves,
        options,
    })
    .unwrap();
    let master = bus.add(ActiveStation::new(ActiveConfig::new(2, params), dp));
    let mut ids = vec![];
    for (k, (&a, cfg)) in addrs.iter().zip(cfgs).enumerate() {
        let dev = GenericDevice::new("test", 0x0DCE, cfg.to_vec(), Features::default())
            .with_inputs(InputPattern::Counter);
        let slave: Slave = PassiveStation::new(DpSlave::new(dev, a), params);
        // 3 % late, 3 % duplicated, 3 % reordered; late by 1.5 slot times.
        let delay = params.bits(params.slot_time as u64 * 3 / 2);
        ids.push(bus.add(Laggard::new(slave, 0x5EED + k as u64, 30, delay)));
    }
    let in_dx = |b: &SimBus| {
        let m = b.station::<Master>(master).app();
        addrs
            .iter()
            .all(|&a| m.slave_state(a) == Some(SlaveState::DataExchange))
    };
    // Start-up may take a few rounds when answers go astray.
    assert!(bus.run_while(Duration::from_secs(2), |b| in_dx(b)));
    while bus
        .station_mut::<Master>(master)
        .app_mut()
        .poll_event()
        .is_some()
    {}

    // Steady state: 1 s of cycles with late, duplicated and reordered
    // answers, checked after every step.
    let end = bus.now() + Duration::from_millis(1000);
    while bus.now() < end {
        assert!(bus.step(), "the simulation stopped");
        let m = bus.station_mut::<Master>(master).app_mut();
        while let Some(e) = m.poll_event() {
            assert!(
                !matches!(
                    e,
                    MasterEvent::StateChanged {
                        from: SlaveState::DataExchange,
                        ..
                    } | MasterEvent::Fault { .. }
                ),
                "at {:?}: {e:?}",
                bus.now()
            );
        }
    }
    let m = bus.station::<Master>(master);
    let dropped = m.stats().late_replies;
    let fates: Vec<[u64; 4]> = ids
        .iter()
        .map(|&id| bus.station::<Laggard<Slave>>(id).fates)
        .collect();
    eprintln!("late replies dropped by the master: {dropped}; fates (on time, late, dup, reordered): {fates:?}");
    for f in &fates {
        assert!(
            f[1] > 5 && f[2] > 5 && f[3] > 5,
            "every fate happened: {f:?}"
        );
    }
    assert!(
        dropped > 10,
        "late and duplicated answers were counted: {dropped}"
    );
    for &a in &addrs {
        let s = m.app().slave_stats(a).unwrap();
        assert!(s.data_exchanges > 200, "{a}: {s:?}");
        assert!(s.diag_reads > 50, "{a}: {s:?}");
        // The FDL layer already dropped the stray answers: the DP layer
        // never saw one as a diagnosis.
        assert_eq!(s.invalid_diags, 0, "{a}: {s:?}");
    }
    assert_eq!(m.stats().duplicate_tokens, 0);
}

/// A slave station that holds back one answer, when armed: the next
/// Data_Exchange answer (an SD2 reply without SAPs) goes out `delay` after
/// the slave core gave it.
struct OneLate<S> {
    inner: S,
    armed: Option<Duration>,
    held: Option<(Instant, Vec<u8>)>,
    released: bool,
    out: Vec<u8>,
}

impl<S: Station> Station for OneLate<S> {
    fn handle_rx(&mut self, now: Instant, bytes: &[u8]) {
        self.inner.handle_rx(now, bytes)
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.inner.handle_timeout(now)
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<&[u8]> {
        if self.held.as_ref().is_some_and(|(t, _)| *t <= now) {
            self.out = self.held.take().unwrap().1;
            self.released = true;
            return Some(&self.out);
        }
        let reply = self.inner.poll_transmit(now)?.to_vec();
        let data_exchange = reply[0] == 0x68 && reply[4] & 0x80 == 0;
        match self.armed {
            Some(delay) if data_exchange => {
                self.armed = None;
                self.held = Some((now + delay, reply));
                None
            }
            _ => {
                self.out = reply;
                Some(&self.out)
            }
        }
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let held = self.held.as_ref().map(|(t, _)| *t);
        match (self.inner.poll_timeout(), held) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// Issue 26, item 1: at 19.2 kbit/s on a transport that hands over whole
/// telegrams (a paced `dpctl bus`), the master waits for a Data_Exchange
/// answer with 4 bytes of inputs for the slot time (100 bit, 5.2 ms) plus
/// the transport's latency (5 ms on a pty) plus that answer's wire time
/// (13 characters, 7.4 ms): about 18 ms, not the 151 ms that allowed for
/// the longest telegram. An answer complete 44 ms after the request is
/// late: the master retries, takes the answer to the retry, and counts the
/// late one (in the station's and the slave's counters) and drops it
/// instead of taking it as the answer, with one slave on the bus and
/// with two. The inputs (a counter that steps with each Data_Exchange)
/// step by one with each exchange: no answer is taken for another's.
#[test]
fn a_data_exchange_answer_44_ms_late_at_19200_is_counted_late_and_dropped() {
    late_answer_dropped(&[10]);
    late_answer_dropped(&[10, 11]);
}

fn late_answer_dropped(addrs: &[u8]) {
    let baud = Baud::B19200;
    let params = BusParams::defaults(baud);
    // A paced `dpctl bus` with the late sender waiting for the line (so
    // the late answer arrives whole, not garbled by the next request).
    let mut medium = MediumConfig::paced(baud);
    medium.collisions = Collisions::Serialize;
    let mut bus = SimBus::new(medium).with_whole_transmissions();
    let cfg = [0x13u8, 0x21]; // 4 bytes in, 2 bytes out
    let slaves = addrs
        .iter()
        .map(|&a| {
            let mut p = SlaveParams::new(a, 0x0DCE, cfg.to_vec());
            p.watchdog = Some(Duration::from_secs(2));
            p
        })
        .collect();
    let dp = DpMaster::new(&MasterConfig {
        address: 2,
        params,
        slaves,
        options: MasterOptions::default(),
    })
    .unwrap();
    // As `dpctl master` on a pty: its latency and whole telegrams.
    let mut fdl = ActiveConfig::new(2, params);
    fdl.latency_allowance = Duration::from_millis(5);
    fdl.whole_telegrams = true;
    let master = bus.add(ActiveStation::new(fdl, dp));
    let ids: Vec<_> = addrs
        .iter()
        .map(|&a| {
            let dev = GenericDevice::new("test", 0x0DCE, cfg.to_vec(), Features::default())
                .with_inputs(InputPattern::Counter);
            let slave: Slave = PassiveStation::new(DpSlave::new(dev, a), params);
            bus.add(OneLate {
                inner: slave,
                armed: None,
                held: None,
                released: false,
                out: Vec::new(),
            })
        })
        .collect();
    let in_dx = |b: &SimBus| {
        let m = b.station::<Master>(master).app();
        addrs
            .iter()
            .all(|&a| m.slave_state(a) == Some(SlaveState::DataExchange))
    };
    assert!(bus.run_while(Duration::from_secs(10), |b| in_dx(b)));
    bus.run_for(Duration::from_millis(200));
    while bus
        .station_mut::<Master>(master)
        .app_mut()
        .poll_event()
        .is_some()
    {}
    let m = bus.station::<Master>(master);
    let (late_before, retries_before) = (m.stats().late_replies, m.stats().retries);
    let s10_before = m.app().slave_stats(10).unwrap();
    let counter = |b: &SimBus| {
        let m = b.station::<Master>(master).app();
        let i = m.inputs(10).unwrap();
        (
            m.slave_stats(10).unwrap().data_exchanges,
            u32::from_be_bytes([i[0], i[1], i[2], i[3]]),
        )
    };
    let mut last = counter(&bus);

    // Slave 10's next Data_Exchange answer leaves 44 ms after it was due,
    // less its own wire time: it is complete at the master about 44 ms
    // after the request.
    let delay = Duration::from_millis(44) - baud.chars_to_duration(13);
    bus.station_mut::<OneLate<Slave>>(ids[0]).armed = Some(delay);
    let end = bus.now() + Duration::from_millis(500);
    while bus.now() < end {
        assert!(bus.step(), "the simulation stopped");
        let now = counter(&bus);
        if now.0 != last.0 {
            assert_eq!(
                (now.0, now.1),
                (last.0 + 1, last.1 + 1),
                "slave 10's inputs step with each exchange ({addrs:?}, at {:?})",
                bus.now()
            );
            last = now;
        }
        let m = bus.station_mut::<Master>(master).app_mut();
        while let Some(e) = m.poll_event() {
            assert!(
                !matches!(
                    e,
                    MasterEvent::StateChanged {
                        from: SlaveState::DataExchange,
                        ..
                    } | MasterEvent::Fault { .. }
                ),
                "at {:?}: {e:?}",
                bus.now()
            );
        }
    }
    assert!(bus.station::<OneLate<Slave>>(ids[0]).released);
    let m = bus.station::<Master>(master);
    let s10 = m.app().slave_stats(10).unwrap();
    eprintln!(
        "{addrs:?}: master {:?}\nslave 10 before {s10_before:?}\nslave 10 after {s10:?}",
        m.stats()
    );
    assert_eq!(
        m.stats().late_replies - late_before,
        1,
        "the late answer was counted as late ({addrs:?})"
    );
    assert_eq!(s10.late_replies - s10_before.late_replies, 1, "{s10:?}");
    assert_eq!(
        m.stats().retries - retries_before,
        1,
        "the request was repeated after its wait ({addrs:?})"
    );
    assert_eq!(s10.retries - s10_before.retries, 1, "{s10:?}");
    assert_eq!(s10.errors, s10_before.errors, "the retry was answered");
    assert!(s10.data_exchanges > s10_before.data_exchanges + 5);
    for &a in &addrs[1..] {
        assert_eq!(m.app().slave_stats(a).unwrap().late_replies, 0);
    }
    assert_eq!(m.stats().duplicate_tokens, 0);
}
