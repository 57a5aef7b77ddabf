//! The master's steady state does not allocate: an FDL active station
//! running the DP master core, exchanging data with two DP slave stations
//! through a tiny allocation-free router, is counted by a global
//! allocator over 1000 poll cycles.

use profibus::devices::generic::{GenericDevice, InputPattern};
use profibus::dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams, SlaveState};
use profibus::dp::slave::{DpSlave, Features};
use profibus::fdl::station::active::{ActiveConfig, ActiveStation};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::station::Station;
use profibus::fdl::{Baud, BusParams, Instant};
use std::time::Duration;

use profibus_io::alloc_count;

#[global_allocator]
static GLOBAL: alloc_count::Counting = alloc_count::Counting;

/// Delivers every transmission to all other stations at once (an unpaced
/// line), advancing time to the earliest deadline when nothing is sent.
struct Router<'a> {
    stations: [&'a mut dyn Station; 3],
    now: Instant,
    buf: [u8; 256],
}

impl Router<'_> {
    fn step(&mut self) {
        let mut sent = false;
        for i in 0..3 {
            while let Some(b) = self.stations[i].poll_transmit(self.now) {
                let n = b.len();
                self.buf[..n].copy_from_slice(b);
                sent = true;
                let at = self.now + Baud::B1500000.chars_to_duration(n as u64);
                for j in 0..3 {
                    if j != i {
                        self.stations[j].handle_rx(at, &self.buf[..n]);
                    }
                }
                self.now = at;
            }
        }
        if !sent {
            let next = self
                .stations
                .iter()
                .filter_map(|s| s.poll_timeout())
                .min()
                .expect("something is scheduled");
            self.now = self.now.max(next);
            for s in self.stations.iter_mut() {
                if s.poll_timeout().is_some_and(|t| t <= self.now) {
                    s.handle_timeout(self.now);
                }
            }
        }
    }
}

#[test]
fn steady_state_master_cycle_does_not_allocate() {
    let params = BusParams::defaults(Baud::B1500000);
    let cfg = MasterConfig {
        address: 1,
        params,
        slaves: [3u8, 4]
            .iter()
            .map(|&a| {
                let mut p = SlaveParams::new(a, 0x0DCE, vec![0x13, 0x23]);
                p.watchdog = Some(Duration::from_millis(100));
                p
            })
            .collect(),
        options: MasterOptions::default(),
    };
    let mut master = ActiveStation::new(ActiveConfig::new(1, params), DpMaster::new(&cfg).unwrap());
    let slave = |a| {
        PassiveStation::new(
            DpSlave::new(
                GenericDevice::new("t", 0x0DCE, vec![0x13, 0x23], Features::default())
                    .with_inputs(InputPattern::Echo),
                a,
            ),
            params,
        )
    };
    let (mut s3, mut s4) = (slave(3), slave(4));
    let h3 = master.app().handle(3).unwrap();
    let mut r = Router {
        stations: [&mut master, &mut s3, &mut s4],
        now: Instant::ZERO,
        buf: [0; 256],
    };
    // Start-up (allocations allowed: events, diagnosis buffers).
    for _ in 0..200_000 {
        r.step();
    }
    let now = r.now;
    assert_eq!(
        master.app().slave(h3).state,
        SlaveState::DataExchange,
        "slaves reached data exchange"
    );
    while master.app_mut().poll_event().is_some() {}
    let c0 = master.app().cycle_stats().cycles;
    let before = alloc_count::allocations();
    assert!(before > 0, "the counter counts");
    let mut r = Router {
        stations: [&mut master, &mut s3, &mut s4],
        now,
        buf: [0; 256],
    };
    for _ in 0..60_000 {
        r.step();
    }
    let allocated = alloc_count::allocations() - before;
    let cycles = master.app().cycle_stats().cycles - c0;
    assert!(cycles >= 1000, "only {cycles} cycles");
    assert_eq!(allocated, 0, "{allocated} allocations in {cycles} cycles");
    assert_eq!(master.app().slave(h3).stats.errors, 0);
}
