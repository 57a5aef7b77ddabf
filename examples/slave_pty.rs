//! A DP slave on a pty: a generic device with one module of 2 words in
//! and 2 words out (inputs echo the outputs) behind the sans-IO slave
//! core (`DpSlave` in an FDL `PassiveStation`), driven by `profibus-io`'s
//! tokio driver. It prints what the slave's master does with it and runs
//! until Ctrl-C.
//!
//! Run, polled by `dpctl master` on a virtual bus:
//!
//! ```sh
//! dpctl bus --stations 2 --link /tmp/pby &
//! cargo run --example slave_pty -- /tmp/pby1 8 &
//! printf '[master]\naddress = 2\nbaud = "1.5M"\n[[slave]]\naddress = 8\ngsd = "%s"\nmodules = ["2 words in/out"]\n' \
//!     "$PWD/crates/devices/gsd/DPCTL_GEN.GSD" > /tmp/pby.toml
//! dpctl master --plain --port /tmp/pby0 --config /tmp/pby.toml --exchanges 100
//! kill %2 %1
//! ```

use profibus::devices::generic::GenericDevice;
use profibus::dp::slave::{DpSlave, Features};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::{Baud, BusParams};
use profibus::io::driver::{self, Clock};
use profibus::io::transport::Port;
use std::ops::ControlFlow;

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let (Some(path), Some(address)) = (args.next(), args.next()) else {
        return Err("usage: slave_pty PTY ADDRESS".into());
    };
    // On a pty the rate only sets the bit times of the slave's timings.
    let baud = Baud::B1500000;
    let mut port = Port::open(&path, baud)?;
    // The identifier 0x71: 2 words in, 2 words out (as `DPCTL_GEN.GSD`'s
    // module "2 words in/out"); the ident number of that GSD file.
    let device = GenericDevice::new("example", 0x0DCE, vec![0x71], Features::default());
    let slave = DpSlave::new(device, address.parse()?);
    let mut station = PassiveStation::new(slave, BusParams::defaults(baud));
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    driver::run(
        &mut station,
        &mut port,
        Clock::start(),
        ctrl_c,
        |st, _now| {
            while let Some(event) = st.app_mut().poll_event() {
                println!("{event:?}");
            }
            ControlFlow::Continue(())
        },
    )
    .await?;
    Ok(())
}
