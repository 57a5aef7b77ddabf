//! `dpctl master`: run a DP master from a bus file.

use crate::common;
use crate::view::{bus_view, drain_events, drain_events_except, SlaveInfo, View};
use anyhow::{bail, Context, Result};
use profibus_devices::bus::{execute_input, ProfiledBus};
use profibus_dp::master::{DpMaster, OperatingState, StopReason, StopWhen};
use profibus_fdl::Instant;
use profibus_io::control_io::lines_on_a_thread;
use profibus_io::driver::{self, Clock};
use profibus_tui::lines::CommandLine;
use std::io::IsTerminal;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::Duration;

/// Poll the slaves of a bus file: parameterise, configure and exchange
/// data with them, print their state, data and diagnosis.
///
/// Commands for scripting come as JSON lines from `--input` (a file, or
/// `-` for stdin), one per line:
///   {"slave": 8, "outputs": "01 02"}          write outputs (hex or [1, 2])
///   {"slave": 25, "set": {"setpoint1": 100}}  write outputs by channel name
///                                             (slaves given as `device = …`)
///   {"operating": "clear"}                    operate | clear | stop
///   {"global_control": ["sync"], "group": 1}  sync, unsync, freeze, unfreeze
///   {"read_diag": 8} / {"get_cfg": 8} / {"rd_inp": 8} / {"rd_outp": 8}
///   {"dpv1_read": 8, "slot": 0, "index": 1, "length": 4}
///   {"dpv1_write": 8, "slot": 0, "index": 1, "data": "0A 0B"}
///   {"set_slave_add": 126, "new_address": 7, "ident": "0x0008", "no_add_chg": false}
///   {"rfid": 12, "command": "RD 0 3"}        RFID reader command (answer: `rfid` event)
#[derive(clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// Serial device or pty path, or tcp://HOST:PORT (serial device server).
    #[arg(long, value_name = "PATH")]
    port: String,
    /// Bus file (TOML; see the profibus-dp busfile docs).
    #[arg(long, value_name = "BUS.toml")]
    config: PathBuf,
    /// Stop after this many poll cycles.
    #[arg(long, value_name = "N")]
    cycles: Option<u64>,
    /// Stop once every slave has completed N Data_Exchange cycles (however
    /// long its start-up took): what scripts and tests wait for. Gives up
    /// after 60 s unless `--timeout` says otherwise.
    #[arg(long, value_name = "N")]
    exchanges: Option<u64>,
    /// Give up after this many seconds: exit status 1, naming the slaves
    /// not in Data_Exchange when `--exchanges` was not reached. Default
    /// with `--exchanges`: 60; otherwise none.
    #[arg(long, value_name = "SECS")]
    timeout: Option<f64>,
    /// Print JSON lines instead of text.
    #[arg(long)]
    json: bool,
    /// Print status lines even on a terminal. Without it (and without
    /// `--input -`) a terminal shows a refreshing table: `q` quit, `p`
    /// pause, up/down select a slave, Enter its details, `w` write its
    /// outputs (hex bytes or NAME=VALUE).
    #[arg(long, conflicts_with = "json")]
    plain: bool,
    /// Read commands (JSON lines) from this file, or `-` for stdin.
    #[arg(long, value_name = "FILE")]
    input: Option<String>,
    #[command(flatten)]
    control: crate::control::ControlArgs,
    /// Milliseconds between status prints (JSON/non-terminal output).
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    interval: u64,
    /// Extra milliseconds on the slot time and token timeouts for the
    /// transport's latency (default: 5 on a pty, 20 on a serial adapter).
    #[arg(long, value_name = "MS")]
    latency: Option<f64>,
    #[command(flatten)]
    rts: common::RtsArg,
    /// Start in the clear state (outputs zero) instead of operate.
    #[arg(long)]
    clear: bool,
    /// After each telegram keep polling the port for this many µs instead
    /// of sleeping: faster answers on ptys and USB adapters, a busy CPU.
    #[arg(long, default_value_t = 0, value_name = "US")]
    busy_poll: u64,
    /// After each request wake up shortly before its answer is expected
    /// and poll the port for it, at most US µs past that (100 suits a pty
    /// on a machine with a CPU to spare). 0: off.
    #[arg(long, default_value_t = 0, value_name = "US")]
    anticipate: u64,
    /// Benchmark option for ptys: gather the token to itself and the next
    /// request into one write. Faster on a pty, but the idle time (TSYN)
    /// before the request disappears: slaves that frame by idle time
    /// (ASICs, and slaves behind `dpctl bus`) reject it.
    #[arg(long)]
    gather: bool,
}

pub fn run(args: Args) -> Result<()> {
    let bus = ProfiledBus::load(&args.config)?;
    common::runtime()?.block_on(master(args, bus))
}

async fn master(args: Args, profiled: ProfiledBus) -> Result<()> {
    let bus = &profiled.file;
    for w in &bus.warnings {
        crate::out::errln!("dpctl master: warning: {w}");
    }
    let mut dp = DpMaster::new(&bus.master)?;
    if args.clear {
        dp.set_operating_state(OperatingState::Clear);
    }
    args.control.announce();
    let (mut station, mut port) =
        common::master_station(&args.port, bus, dp, args.latency, args.rts)?;
    let options = driver::Options {
        anticipate: Duration::from_micros(args.anticipate),
        ..common::driver_options(&port, args.busy_poll, args.gather)?
    };

    // Commands come from a plain thread: a blocking read of stdin must not
    // keep the runtime from shutting down on Ctrl-C / SIGTERM.
    let mut rx = match &args.input {
        Some(input) => Some(lines_on_a_thread(input)?),
        None => None,
    };

    let mut control = args.control.open(&profiled)?;
    let mut view = View::new(args.json, Duration::from_millis(args.interval.max(10)));
    let info = SlaveInfo::of_bus(&profiled)?;
    let baud = bus.master.params.baud;
    // Commands typed on stdin (`--input -`) keep the terminal for lines.
    let stdin_commands = args.input.as_deref() == Some("-");
    if !args.json && !args.plain && !stdin_commands && std::io::stdout().is_terminal() {
        view.open_terminal(bus_view("dpctl master", baud, &info))?;
    }
    let stop_when = stop_when(&args)?;
    if let (Some(n), Some(d)) = (args.exchanges, stop_when.deadline) {
        tracing::info!(
            exchanges = n,
            timeout_s = d.as_secs_f64(),
            "waiting for Data_Exchange at most this long"
        );
    }
    let mut timed_out = false;
    let mut last_now = Instant::ZERO;
    let mut rfid = profibus_devices::rfid::jobs::MasterJobs::default();
    // SIGTERM / Ctrl-C: Clear to the slaves and the token passed on first.
    let mut clean = common::CleanStop::default();
    let result = driver::run_with(
        &mut station,
        &mut port,
        Clock::start(),
        options,
        clean.shutdown(common::shutdown()),
        |st, now| {
            last_now = now;
            if clean.step(st, now).is_break() {
                return ControlFlow::Break(());
            }
            let m = st.app_mut();
            while let Some(line) = rx.as_mut().and_then(|rx| rx.try_recv().ok()) {
                let channels = |a| {
                    info.iter()
                        .find(|s| s.layout.address == a)?
                        .channels
                        .as_ref()
                };
                let result = execute_input(m, channels, &mut rfid, &line);
                if let Some(shown) = CommandLine::of(&line, result) {
                    view.event(&shown);
                }
            }
            for e in rfid.step(m, now) {
                view.event(&e);
            }
            match &mut control {
                Some(c) => {
                    c.tick(m, now, &profiled, &info, baud);
                    drain_events_except(m, &info, &mut view, |e| c.owns(e));
                }
                None => drain_events(m, &info, &mut view),
            }
            view.status(m, &info, baud, now, false);
            view.tick(m, now)?;
            match stop_when.check(m, now) {
                Some(why) => {
                    timed_out = why == StopReason::Deadline;
                    ControlFlow::Break(())
                }
                None => ControlFlow::Continue(()),
            }
        },
    )
    .await;
    view.close();
    let m = station.app_mut();
    drain_events(m, &info, &mut view);
    view.status(m, &info, baud, last_now, true);
    result.with_context(|| format!("on {}", args.port))?;
    let stuck = m.not_exchanging();
    if args.cycles.is_some() && !stuck.is_empty() {
        tracing::info!(?stuck, "slaves not in data exchange at the end");
    }
    if let (true, Some(n)) = (timed_out, args.exchanges) {
        let short: Vec<String> = m
            .slave_addresses()
            .filter_map(|a| {
                let done = m.slave_stats(a)?.data_exchanges;
                let state = m.slave_state(a)?.name();
                (done < n).then(|| format!("slave {a} ({state}, {done} exchanges)"))
            })
            .collect();
        bail!(
            "timeout after {:.1} s: not every slave reached {n} Data_Exchange cycles: {}",
            stop_when.deadline.unwrap_or_default().as_secs_f64(),
            short.join(", ")
        );
    }
    Ok(())
}

/// The stop conditions of the arguments: `--exchanges` without
/// `--timeout` gives up after `profibus_dp::master::EXCHANGES_TIMEOUT`.
fn stop_when(args: &Args) -> Result<StopWhen> {
    let deadline = match args.timeout {
        Some(t) if t.is_finite() && t > 0.0 => Some(Duration::from_secs_f64(t)),
        Some(t) => bail!("--timeout takes a positive number of seconds, not {t}"),
        None => None,
    };
    Ok(StopWhen::new(args.cycles, args.exchanges, deadline))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use profibus_dp::master::EXCHANGES_TIMEOUT;

    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn parse(extra: &[&str]) -> Args {
        let mut argv = vec!["dpctl", "--port", "/dev/null", "--config", "bus.toml"];
        argv.extend_from_slice(extra);
        Cli::parse_from(argv).args
    }

    #[test]
    fn exchanges_without_timeout_give_up_after_the_default() {
        let w = stop_when(&parse(&["--exchanges", "5"])).unwrap();
        assert_eq!(w.deadline, Some(EXCHANGES_TIMEOUT));
        assert_eq!(EXCHANGES_TIMEOUT, Duration::from_secs(60));
        let w = stop_when(&parse(&["--exchanges", "5", "--timeout", "3"])).unwrap();
        assert_eq!(w.deadline, Some(Duration::from_secs(3)));
        let w = stop_when(&parse(&[])).unwrap();
        assert_eq!(w.deadline, None, "no deadline without --exchanges");
        assert!(stop_when(&parse(&["--timeout", "0"])).is_err());
    }
}
