//! A DP master on a serial line: the slaves of a bus file parameterised,
//! configured and polled by the sans-IO master core (`DpMaster` in an FDL
//! `ActiveStation`), driven by `profibus-io`'s tokio driver on a port: an
//! RS-485 adapter (`/dev/ttyUSB0`), a pty or `tcp://HOST:PORT`. It prints
//! the master's events and stops after 1000 poll cycles or at Ctrl-C.
//!
//! Run, with a virtual bus and an emulated slave instead of an adapter:
//!
//! ```sh
//! dpctl bus --stations 2 --link /tmp/pbx &
//! dpctl slave --port /tmp/pbx1 --addr 8 --gsd crates/devices/gsd/DPCTL_GEN.GSD --module "2 words in/out" &
//! printf '[master]\naddress = 2\nbaud = "1.5M"\n[[slave]]\naddress = 8\ngsd = "%s"\nmodules = ["2 words in/out"]\n' \
//!     "$PWD/crates/devices/gsd/DPCTL_GEN.GSD" > /tmp/pbx.toml
//! cargo run --example master_serial -- /tmp/pbx0 /tmp/pbx.toml
//! kill %2 %1
//! ```

use profibus::dp::config::busfile::BusFile;
use profibus::dp::master::DpMaster;
use profibus::fdl::station::active::{ActiveConfig, ActiveStation};
use profibus::io::driver::{self, Clock};
use profibus::io::transport::Port;
use std::ops::ControlFlow;

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let (Some(path), Some(config)) = (args.next(), args.next()) else {
        return Err("usage: master_serial PORT BUS.toml".into());
    };
    let bus = BusFile::load(&config)?;
    let mut port = Port::open(&path, bus.master.params.baud)?;
    let mut cfg = ActiveConfig::new(bus.master.address, bus.master.params);
    // What the port adds to every answer's wait (USB adapter, pty, TCP).
    cfg.latency_allowance = port.default_latency();
    cfg.whole_telegrams = port.whole_telegrams();
    let mut station = ActiveStation::new(cfg, DpMaster::new(&bus.master)?);
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    driver::run(
        &mut station,
        &mut port,
        Clock::start(),
        ctrl_c,
        |st, _now| {
            let master = st.app_mut();
            while let Some(event) = master.poll_event() {
                println!("{event:?}");
            }
            match master.cycle_stats().cycles >= 1000 {
                true => ControlFlow::Break(()),
                false => ControlFlow::Continue(()),
            }
        },
    )
    .await?;
    for address in station.app().slave_addresses() {
        let m = station.app();
        println!(
            "slave {address}: {:?}, inputs {:?}",
            m.slave_state(address),
            m.inputs(address)
        );
    }
    Ok(())
}
