//! Bus timing on the simulated line (virtual time, so the numbers are
//! exact and repeatable, not machine-dependent):
//!
//! 1. Token rotation time with 3 masters (2, 5, 9) and no traffic at
//!    1.5 Mbit/s and 12 Mbit/s, next to the theoretical minimum
//!    3 × (token telegram + TID1).
//! 2. DP poll cycle with 32 slaves × 2 bytes in/out at 1.5 Mbit/s, next
//!    to the wire minimum from `BusParams::exchange_bits`.
//!
//! Run: `cargo bench --bench bus_timing`

use profibus::devices::generic::{GenericDevice, InputPattern};
use profibus::dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams, SlaveState};
use profibus::dp::slave::{DpSlave, Features};
use profibus::fdl::line::medium::MediumConfig;
use profibus::fdl::sim::SimBus;
use profibus::fdl::station::active::{
    ActiveConfig, ActiveStation, CycleResult, MasterApp, Request, TokenContext,
};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::{Baud, BusParams, Instant, Telegram};
use profibus::io::FdlCodec;
use std::cell::RefCell;
use std::rc::Rc;
use std::time::Duration;
use tokio_util::codec::Decoder;

struct Idle;
impl MasterApp for Idle {
    fn poll_request(&mut self, _: &TokenContext) -> Option<Request<'_>> {
        None
    }
    fn on_result(&mut self, _: Instant, _: &CycleResult<'_>) {}
}

fn us(bits: u64, baud: Baud) -> f64 {
    baud.bits_to_duration(bits).as_nanos() as f64 / 1000.0
}

fn token_rotation(baud: Baud, hsa: u8) {
    let mut params = BusParams::defaults(baud);
    params.hsa = hsa;
    let mut bus = SimBus::new(MediumConfig::paced(baud));
    for a in [2u8, 5, 9] {
        bus.add(ActiveStation::new(ActiveConfig::new(a, params), Idle));
    }
    // Arrival times of the token at master 2, and whether any FDL Status
    // went over the line in that rotation.
    let log: Rc<RefCell<Vec<(Instant, bool)>>> = Rc::default();
    let l2 = log.clone();
    let mut codec = FdlCodec::new();
    let mut buf = bytes::BytesMut::new();
    let mut gap_seen = false;
    bus.set_tap(Box::new(move |at, _, bytes| {
        buf.extend_from_slice(bytes);
        while let Ok(Some(t)) = codec.decode(&mut buf) {
            match t.telegram() {
                Telegram::Token { da: 2, sa } if sa != 2 => {
                    l2.borrow_mut().push((at, gap_seen));
                    gap_seen = false;
                }
                Telegram::Data(_) => gap_seen = true,
                _ => {}
            }
        }
    }));
    bus.run_for(Duration::from_secs(2));
    let log = log.borrow();
    let mut all = vec![];
    let mut quiet = vec![];
    for w in log.windows(2).skip(log.len() / 2) {
        let d = (w[1].0 - w[0].0).as_nanos() as f64 / 1000.0;
        all.push(d);
        if !w[1].1 {
            quiet.push(d);
        }
    }
    all.sort_by(f64::total_cmp);
    quiet.sort_by(f64::total_cmp);
    let min_bits = 3 * (33 + params.tid1() as u64);
    let theory = us(min_bits, baud);
    let avg = all.iter().sum::<f64>() / all.len() as f64;
    let q50 = quiet.get(quiet.len() / 2).copied().unwrap_or(f64::NAN);
    println!(
        "| {baud} | {hsa} | {theory:.2} µs ({min_bits} bit) | {:.2} µs | {q50:.2} µs ({:.3}×) | {avg:.2} µs ({:.2}×) | {}/{} |",
        quiet.first().copied().unwrap_or(f64::NAN),
        q50 / theory,
        avg / theory,
        quiet.len(),
        all.len(),
    );
}

fn poll_cycle(baud: Baud, n: u8) {
    let params = BusParams::defaults(baud);
    let mut bus = SimBus::new(MediumConfig::paced(baud));
    let slaves: Vec<u8> = (3..3 + n).collect();
    let cfg = MasterConfig {
        address: 1,
        params,
        slaves: slaves
            .iter()
            .map(|&a| SlaveParams::new(a, 0x0DCE, vec![0x11, 0x21]))
            .collect(),
        options: MasterOptions::default(),
    };
    let m = bus.add(ActiveStation::new(
        ActiveConfig::new(1, params),
        DpMaster::new(&cfg).unwrap(),
    ));
    for &a in &slaves {
        let dev = GenericDevice::new("b", 0x0DCE, vec![0x11, 0x21], Features::default())
            .with_inputs(InputPattern::Echo);
        bus.add(PassiveStation::new(DpSlave::new(dev, a), params));
    }
    let ok = bus.run_while(Duration::from_secs(5), |b| {
        let d = b.station::<ActiveStation<DpMaster>>(m).app();
        d.slave_addresses()
            .all(|a| d.slave_state(a) == Some(SlaveState::DataExchange))
    });
    assert!(ok, "all slaves in data exchange");
    bus.station_mut::<ActiveStation<DpMaster>>(m)
        .app_mut()
        .reset_cycle_stats();
    bus.run_for(Duration::from_secs(10));
    let c1 = bus
        .station::<ActiveStation<DpMaster>>(m)
        .app()
        .cycle_stats();
    let cycles = c1.cycles;
    let avg = c1.sum_ns as f64 / cycles as f64 / 1000.0;
    // Data_Exchange: SD2 request and response of 11 characters each.
    let per_slave = params.exchange_bits(11, 11);
    let token = 33 + params.tid1() as u64;
    let min_bits = per_slave * n as u64 + token;
    let theory = us(min_bits, baud);
    println!(
        "| {baud} | {n} × 2 B in/out | {theory:.1} µs ({min_bits} bit) | {:.1} µs | {avg:.1} µs ({:.3}×) | {:.1} µs | {cycles} |",
        c1.min_ns as f64 / 1000.0,
        avg / theory,
        c1.max_ns as f64 / 1000.0,
    );
}

fn main() {
    // `cargo bench` passes `--bench`; nothing to configure.
    println!("Token rotation, 3 masters (2, 5, 9), no traffic; second half of 2 s of bus time");
    println!("| baud | HSA | minimum 3 × (token + TID1) | fastest | median without GAP poll | average with GAP polls | rotations without GAP / all |");
    println!("|---|---|---|---|---|---|---|");
    for baud in [Baud::B1500000, Baud::B12000000] {
        for hsa in [126, 9] {
            token_rotation(baud, hsa);
        }
    }
    println!();
    println!("DP poll cycle, master 1 alone, 10 s of bus time after start-up");
    println!("| baud | slaves | wire minimum | min | average | max | cycles |");
    println!("|---|---|---|---|---|---|---|");
    poll_cycle(Baud::B1500000, 32);
    poll_cycle(Baud::B12000000, 32);
}
