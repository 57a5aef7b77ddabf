//! The library loop of README.md: a DP master core and a slave core on the
//! simulated bus, in virtual time, no I/O. README.md shows the code below
//! the marker line as it is (`tests/readme_example.rs` compares them).
//!
//! Run: `cargo run --example library_loop`
// README begin
use profibus::devices::generic::GenericDevice;
use profibus::dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams};
use profibus::dp::slave::{DpSlave, Features};
use profibus::fdl::station::{active::*, passive::PassiveStation};
use profibus::fdl::{line::medium::MediumConfig, sim::SimBus, Baud, BusParams};
use std::time::Duration;

fn main() {
    let params = BusParams::defaults(Baud::B1500000);
    let cfg = vec![0x11, 0x21]; // Chk_Cfg: 2 bytes in, 2 bytes out
    let slaves = vec![SlaveParams::new(10, 0x0DCE, cfg.clone())];
    let config = MasterConfig {
        address: 2,
        params,
        slaves,
        options: MasterOptions::default(),
    };
    let device = GenericDevice::new("io", 0x0DCE, cfg, Features::default()); // echoes
    let mut bus = SimBus::new(MediumConfig::paced(Baud::B1500000));
    let master = DpMaster::new(&config).expect("a valid configuration");
    let m = bus.add(ActiveStation::new(ActiveConfig::new(2, params), master));
    bus.add(PassiveStation::new(DpSlave::new(device, 10), params));
    bus.run_for(Duration::from_millis(100)); // virtual time: start-up
    let master = bus.station_mut::<ActiveStation<DpMaster>>(m).app_mut();
    master.set_outputs(10, &[0x12, 0x34]);
    bus.run_for(Duration::from_millis(10)); // Data_Exchange cycles
    let master = bus.station::<ActiveStation<DpMaster>>(m).app();
    println!(
        "slave 10: {:?}, inputs {:?}",
        master.slave_state(10),
        master.inputs(10)
    );
}
