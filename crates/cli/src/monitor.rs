//! `dpctl monitor`: follow another master's slaves, listening only.
//!
//! `profibus_fdl::listen` reads the line (it cannot write) and
//! `profibus_dp::monitor::Monitor` tracks the traffic; this prints its
//! events and a status every `--interval`.

use crate::common;
use anyhow::{Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::monitor::{Monitor, MonitorOptions, MonitorStatus, SlaveInfo};
use profibus_fdl::listen::{listen, Heard, ListenOptions};
use profibus_fdl::tap::TapEvent;
use profibus_fdl::transport::Port;
use profibus_fdl::{Instant, Telegram};
use serde_json::json;
use std::io::Write;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::Duration;

/// Listen to a bus (never send) and follow the master(s) on it: every
/// slave's state, data, diagnosis, cycle times, retries and errors, and
/// the masters in the token ring.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial device or pty path, or tcp://HOST:PORT (serial device server).
    #[arg(long, value_name = "PATH")]
    port: String,
    /// Bus file naming the slaves (GSD modules or device profiles decode
    /// their data) and the baud rate.
    #[arg(long, value_name = "BUS.toml")]
    config: PathBuf,
    /// Print JSON lines (events and status, shaped like `dpctl master --json`).
    #[arg(long)]
    json: bool,
    /// Milliseconds between status prints.
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    interval: u64,
    /// A master that has not passed the token for this many milliseconds
    /// has left the ring.
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    master_timeout: u64,
}

pub fn run(args: Args) -> Result<()> {
    let bus = ProfiledBus::load(&args.config)?;
    let mut slaves = SlaveInfo::from_bus(&bus.file);
    for s in &mut slaves {
        if let Some(map) = bus.channels(s.address).transpose()? {
            s.decoder = Some(Box::new(map));
        }
    }
    let options = MonitorOptions {
        master_timeout: Duration::from_millis(args.master_timeout),
        ..MonitorOptions::default()
    };
    let mut monitor = Monitor::new(slaves, options);
    let rt = common::runtime()?;
    let mut port = {
        let _guard = rt.enter();
        Port::open(&args.port, bus.file.master.params.baud)?
    };
    let listen_opts = ListenOptions::for_port(&port);
    let interval = Duration::from_millis(args.interval.max(10));
    let mut out = std::io::stdout().lock();
    let mut next_status = Instant::ZERO + interval;
    let mut failure = None;
    let stats = rt.block_on(listen(
        &mut port,
        listen_opts,
        common::shutdown(),
        |heard| {
            let now = match heard {
                Heard::Event(TapEvent::Telegram { at, bytes }) => {
                    if let Ok((t, _)) = Telegram::parse(&bytes) {
                        monitor.observe(at, &t);
                    }
                    at
                }
                Heard::Event(TapEvent::Skipped { at, errors, .. }) => {
                    monitor.observe_skipped(at, &errors);
                    at
                }
                Heard::Tick(at) => {
                    monitor.tick(at);
                    at
                }
            };
            let mut r = print_events(&mut monitor, args.json, &mut out);
            if r.is_ok() && now >= next_status {
                next_status = now + interval;
                r = print_status(&monitor.status(), args.json, &mut out);
            }
            match r.and_then(|()| Ok(out.flush()?)) {
                Ok(()) => ControlFlow::Continue(()),
                Err(e) => {
                    failure = Some(e);
                    ControlFlow::Break(())
                }
            }
        },
    ));
    if let Some(e) = failure {
        return Err(e);
    }
    let stats = stats.with_context(|| format!("reading {}", args.port))?;
    print_events(&mut monitor, args.json, &mut out)?;
    print_status(&monitor.status(), args.json, &mut out)?;
    tracing::info!(?stats, "line counters");
    Ok(())
}

fn print_events(m: &mut Monitor, as_json: bool, out: &mut impl Write) -> Result<()> {
    while let Some(e) = m.poll_event() {
        if as_json {
            writeln!(out, "{}", serde_json::to_string(&e)?)?;
        } else {
            writeln!(out, "{e}")?;
        }
    }
    Ok(())
}

fn print_status(s: &MonitorStatus, as_json: bool, out: &mut impl Write) -> Result<()> {
    if as_json {
        let mut v = serde_json::to_value(s)?;
        v["event"] = json!("status");
        writeln!(out, "{v}")?;
    } else {
        writeln!(out, "{s}")?;
    }
    Ok(())
}
