//! A passive monitor: reads a line and never writes, frames telegrams by
//! their contents and the line's idle time (`profibus-fdl`'s tap, through
//! `profibus-io`'s `listen`) and prints each with its time and decoded
//! header; broken bytes are printed with what was wrong. `dpctl sniff`
//! and `dpctl monitor` are built on the same loop. It stops at Ctrl-C
//! or after 50 telegrams.
//!
//! Run, on a virtual bus where `dpctl master` polls an emulated slave:
//!
//! ```sh
//! dpctl bus --stations 3 --link /tmp/pbz &
//! dpctl slave --port /tmp/pbz1 --addr 8 --gsd crates/devices/gsd/DPCTL_GEN.GSD --module "2 words in/out" &
//! printf '[master]\naddress = 2\nbaud = "1.5M"\n[[slave]]\naddress = 8\ngsd = "%s"\nmodules = ["2 words in/out"]\n' \
//!     "$PWD/crates/devices/gsd/DPCTL_GEN.GSD" > /tmp/pbz.toml
//! dpctl master --plain --port /tmp/pbz0 --config /tmp/pbz.toml > /dev/null &
//! cargo run --example monitor -- /tmp/pbz2
//! kill %3 %2 %1
//! ```

use profibus::fdl::line::tap::TapEvent;
use profibus::fdl::wire::Telegram;
use profibus::fdl::Baud;
use profibus::io::listen::{listen, Heard, ListenOptions};
use profibus::io::transport::Port;
use std::ops::ControlFlow;

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Some(path) = std::env::args().nth(1) else {
        return Err("usage: monitor PORT".into());
    };
    let mut port = Port::open(&path, Baud::B1500000)?;
    let options = ListenOptions::for_port(&port);
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    let mut seen = 0;
    let stats = listen(&mut port, options, ctrl_c, |heard| {
        match heard {
            Heard::Event(TapEvent::Telegram { at, bytes }) => {
                seen += 1;
                match Telegram::parse_exact(&bytes) {
                    Ok(t) => println!("{at:?} {t:?}"),
                    Err(e) => println!("{at:?} {e}"),
                }
            }
            Heard::Event(TapEvent::Skipped { at, bytes, errors }) => {
                println!("{at:?} !! {} bytes skipped: {errors:?}", bytes.len());
            }
            Heard::Tick(_) | Heard::Drained(_) => {}
        }
        match seen >= 50 {
            true => ControlFlow::Break(()),
            false => ControlFlow::Continue(()),
        }
    })
    .await?;
    println!("line counters: {stats:?}");
    Ok(())
}
