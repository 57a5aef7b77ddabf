//! A live list on the simulated bus: a scanning master finds two DP
//! slaves and a second master (FDL Status, then Slave_Diag for the
//! passive stations), in virtual time, with no I/O. `dpctl scan` runs the
//! same `LiveListScan` on a real line.
//!
//! Run: `cargo run --example live_list`

use profibus::devices::generic::GenericDevice;
use profibus::dp::master::{DpMaster, MasterConfig, MasterOptions};
use profibus::dp::scan::{LiveListScan, LiveRow};
use profibus::dp::slave::{DpSlave, Features};
use profibus::fdl::line::medium::MediumConfig;
use profibus::fdl::sim::SimBus;
use profibus::fdl::station::active::{ActiveConfig, ActiveStation};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::{Baud, BusParams};
use std::time::Duration;

fn main() {
    let params = BusParams::defaults(Baud::B1500000);
    let mut bus = SimBus::new(MediumConfig::paced(Baud::B1500000));
    // Two slaves with one module each (2 bytes in and out).
    for (address, ident) in [(8, 0x0DCE), (25, 0x00D0)] {
        let device = GenericDevice::new("io", ident, vec![0x31], Features::default());
        bus.add(PassiveStation::new(DpSlave::new(device, address), params));
    }
    // Another master, with no slaves of its own, holding the token too.
    let other = MasterConfig {
        address: 5,
        params,
        slaves: vec![],
        options: MasterOptions::default(),
    };
    let other = DpMaster::new(&other).expect("a valid configuration");
    bus.add(ActiveStation::new(ActiveConfig::new(5, params), other));
    // The scanner: station 1, a master that joins the ring and asks every
    // address once.
    let scanner = bus.add(ActiveStation::new(
        ActiveConfig::new(1, params),
        LiveListScan::new(1),
    ));
    // Virtual time: until the scan is done, at most 5 s of bus time.
    let done = bus.run_while(Duration::from_secs(5), |b| {
        b.station::<ActiveStation<LiveListScan>>(scanner)
            .app()
            .is_done()
    });
    assert!(done, "the scan did not finish within 5 s of bus time");
    let scan = bus.station::<ActiveStation<LiveListScan>>(scanner).app();
    println!("{}", LiveRow::scanner(1));
    for &station in scan.stations() {
        println!("{}", LiveRow::from(station));
    }
}
