//! `dpctl slave`: emulate a DP slave on a serial line or pty.
//!
//! The device is a profile (`--device NAME`) or the generic device a GSD
//! file describes (`--gsd FILE --module NAME …`). The slave runs as
//! `PassiveStation<DpSlave<…>>` on the port through the tokio driver and
//! prints its state changes, faults and Global_Control commands (one JSON
//! object per line with `--json`).
//!
//! Baud rate: `--baud auto` (the default) searches on a serial line like
//! a real slave with `Auto_Baud_supp` (only the rates of the device's GSD
//! `*_supp` keywords, fastest first, lock on the first valid telegram, search again after a watchdog expiry or 10 s
//! without a valid telegram; `profibus_io::runner::PassiveRunner`).
//! A pty carries bytes, not bits, so there the
//! rate is nominal: the slave locks at once, at 19.2 kbit/s unless
//! `--baud` names a rate (the rate sets the bit times of min TSDR and of
//! the receive timeouts). `--latency` (default 5 ms on a pty, 20 ms on a
//! serial adapter) lengthens the time an incomplete telegram may take to
//! arrive, for transports that deliver bytes late.

use crate::common;
use crate::profile_args::ProfileArgs;
use anyhow::bail;
use profibus_devices::{ControlInbox, PROFILES};
use profibus_dp::slave::{Device, DpSlave, OwnAddress};
use profibus_fdl::station::autobaud::BaudSet;
use profibus_fdl::Instant;
use profibus_io::control_io::ControlSource;
use profibus_io::driver::Clock;
use profibus_io::emulation::{BaudChoice, Emitted, ShellEvent, SlaveShell};
use profibus_io::jx2::{self as clients, Console};
use profibus_io::runner::{PassiveRunner, RunnerEvent};
use std::io::Write;
use std::path::Path;

/// Emulate a PROFIBUS-DP slave.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial port or pty path (e.g. /dev/ttyUSB0, or one end of a socat
    /// pty pair), or tcp://HOST:PORT (serial device server, raw TCP).
    #[arg(long, value_name = "PATH", required_unless_present = "list_devices")]
    port: Option<String>,
    /// Station address of the slave (0..=126). The bm4 profile takes its
    /// address from --us-device / --switch instead when given, the omega
    /// profile from --switch.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=126),
          required_unless_present_any = ["list_devices", "us_device", "switch", "device"])]
    addr: Option<u8>,
    /// Baud rate (9600 … 12M), or `auto` to search for the rate of the
    /// traffic on a serial line (on a pty: nominal 19.2 kbit/s), or
    /// `search` to search even on a pty (where every rate passes the
    /// bytes, so it locks at the first rate that sees a valid telegram).
    #[arg(long, value_name = "B", default_value = "auto")]
    baud: String,
    #[command(flatten)]
    profile: ProfileArgs,
    /// Print the process data whenever the outputs change.
    #[arg(long)]
    show_data: bool,
    /// Stop after this many Data_Exchange cycles (0: run until Ctrl-C).
    #[arg(long, value_name = "N", default_value_t = 0)]
    cycles: u64,
    /// Extra milliseconds an incomplete telegram may take to arrive, for
    /// the transport's latency (default: 5 on a pty, 20 on a serial
    /// adapter).
    #[arg(long, value_name = "MS")]
    latency: Option<f64>,
    #[command(flatten)]
    rts: common::RtsArg,
    /// After each telegram keep polling the port for this many µs instead
    /// of sleeping: faster answers on ptys and USB adapters, a busy CPU.
    #[arg(long, default_value_t = 0, value_name = "US")]
    busy_poll: u64,
    /// Benchmark option for ptys: gather telegrams due within 100 µs into
    /// one write (see `dpctl master --gather`).
    #[arg(long)]
    gather: bool,
    /// Print one JSON object per line.
    #[arg(long)]
    json: bool,
}

/// Print `e` at `now` (s since the start): text, or a JSON line with `"t"`.
fn emit(json: bool, now: Instant, e: &Emitted<'_>) {
    /// A line with its time.
    #[derive(serde::Serialize)]
    struct Timed<'a, 'b> {
        #[serde(flatten)]
        event: &'a Emitted<'b>,
        t: f64,
    }
    let t = now.as_nanos() as f64 / 1e9;
    let mut out = crate::out::stdout();
    let printed = if json {
        let line = Timed {
            event: e,
            t: (t * 1e6).round() / 1e6,
        };
        writeln!(out, "{}", common::json_line(&line))
    } else {
        writeln!(out, "[{t:>11.6}] {e}")
    };
    // Nobody reads the output any more: stop as on SIGTERM.
    if printed
        .and_then(|()| out.flush())
        .is_err_and(|e| crate::out::closed(&e))
    {
        crate::common::request_stop();
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.profile.list_devices {
        for p in PROFILES {
            crate::out::outln!("{p}")?;
        }
        return Ok(());
    }
    let rt = common::runtime()?;
    let source = args.profile.control.as_deref().map(ControlSource::of);
    let result = rt.block_on(run_async(args));
    // The control socket we created.
    if let Some(s) = &source {
        s.remove_socket();
    }
    // A --control reader may be blocked on stdin: do not wait for it.
    rt.shutdown_background();
    result
}

async fn run_async(args: Args) -> anyhow::Result<()> {
    let clock = Clock::start();
    let path = args.port.clone().expect("clap requires --port");
    let choice: BaudChoice = args.baud.parse()?;
    let device = args.profile.choice()?;
    let emulated = device.configure(args.addr)?;
    for w in emulated.profile.warnings() {
        emit(
            args.json,
            clock.now(),
            &Emitted::Shell(ShellEvent::GsdWarning { text: &w }),
        );
    }
    let mut jx2 = None;
    let device = if emulated.entry.name == profibus_devices::jx2::profile::NAME {
        // The register interface runs beside the slave (stdin, a socket).
        let opts = args.profile.options()?.decode()?;
        let control = args.profile.control.as_deref().map(Path::new);
        let console = Console {
            input: tokio::io::stdin,
            output: tokio::io::stdout,
        };
        let plc = clients::start(&opts, control, console, clock.clone())?;
        jx2 = Some(plc.clone());
        Box::new(plc)
    } else {
        let control = args.profile.control.as_deref().map(|src| {
            let inbox = ControlInbox::new();
            if let Err(e) = ControlSource::of(src).spawn(inbox.clone()) {
                crate::out::errln!("dpctl slave: {e}");
            }
            inbox
        });
        device.device(&emulated, control)?
    };
    let addr = match emulated.profile.address().or(args.addr) {
        Some(a) => a,
        // A device that sets its address itself (jx2: its PLC writes it).
        None if device.own_address() != OwnAddress::Slave => 0,
        None => bail!("give --addr N"),
    };
    let mut port = args.rts.open(&path, BaudChoice::NOMINAL)?;
    let latency = common::latency(args.latency, &port)?;
    let options = common::driver_options(&port, args.busy_poll, args.gather)?;
    // The search keeps to the rates the device's GSD supports (`*_supp`).
    let rates: BaudSet = emulated
        .profile
        .gsd()
        .supported_bauds()
        .into_iter()
        .collect();
    let (search, first) = choice.plan_within(&port, rates);
    port.set_baud(first)?;
    let slave = DpSlave::new(device, addr);
    let start = ShellEvent::start(
        &emulated.name,
        &slave,
        addr,
        &path,
        port.is_pty(),
        search,
        first,
    );
    emit(args.json, clock.now(), &Emitted::Shell(start));
    if let (Some(plc), false) = (&jx2, search) {
        plc.lock().module.set_baud(first.bps());
    }
    let mut shell = SlaveShell::new(
        PassiveRunner {
            rates,
            ..PassiveRunner::new(search, latency, options)
        },
        &*emulated.profile,
    );
    shell.show_data = args.show_data;
    shell.cycles = args.cycles;
    let slave = shell
        .run(
            slave,
            &mut port,
            clock.clone(),
            common::shutdown(),
            |now, e| {
                if let (Some(plc), Emitted::Runner(RunnerEvent::BaudLocked { baud })) = (&jx2, &e) {
                    plc.lock().module.set_baud(baud.bps());
                }
                emit(args.json, now, &e);
            },
        )
        .await
        .map_err(|e| anyhow::Error::new(e).context(path.clone()))?;
    let stopped = ShellEvent::Stopped {
        state: slave.state(),
        stats: slave.stats(),
    };
    emit(args.json, clock.now(), &Emitted::Shell(stopped));
    Ok(())
}
