//! `dpctl master`: run a DP master from a bus file.

use crate::common;
use crate::view::{drain_events, Line, SlaveInfo, View};
use anyhow::{bail, Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_devices::channels::Value as ChannelValue;
use profibus_dp::master::{CommandOutcome, DpMaster, MasterCommand, OperatingState, SlaveState};
use profibus_fdl::driver::{self, Clock};
use profibus_fdl::Instant;
use serde_json::Value;
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
    /// long its start-up took): what scripts and tests wait for.
    #[arg(long, value_name = "N")]
    exchanges: Option<u64>,
    /// Give up after this many seconds: exit status 1, naming the slaves
    /// not in Data_Exchange when `--exchanges` was not reached.
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

/// `{"slave": N, "set": {"NAME": VALUE, …}}`: outputs by channel name.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct SetChannels {
    slave: u8,
    set: std::collections::BTreeMap<String, ChannelValue>,
}

/// Apply a channel command; `None` when `line` is none.
fn set_channels(m: &mut DpMaster, info: &[SlaveInfo], line: &str) -> Option<Result<()>> {
    let v: Value = serde_json::from_str(line).ok()?;
    v.get("set")?;
    Some((|| {
        let c: SetChannels = serde_json::from_value(v)?;
        let map = info
            .iter()
            .find(|s| s.address == c.slave)
            .and_then(|s| s.channels.as_ref())
            .with_context(|| {
                format!(
                    "slave {} has no named channels (give it as `device = …` in the bus file)",
                    c.slave
                )
            })?;
        let h = m.handle(c.slave).context("slave not in the bus file")?;
        map.write_outputs(
            c.set.iter().map(|(k, v)| (k.as_str(), *v)),
            m.outputs_mut(h),
        )?;
        Ok(())
    })())
}

/// The reply to a command.
#[derive(serde::Serialize)]
struct CommandReply<'a> {
    result: &'a str,
}

/// A refused command line.
#[derive(serde::Serialize)]
struct BadCommand<'a> {
    line: &'a str,
    error: String,
}

/// Apply one command line to the master; returns a reply for the log.
/// A refused command changes nothing.
pub fn apply_command(m: &mut DpMaster, line: &str) -> Result<Option<String>> {
    let command = MasterCommand::from_json(line)?;
    let reply = match &command {
        MasterCommand::Operating(s) => Some(format!("operating state {}", s.as_str())),
        _ => None,
    };
    Ok(match m.apply(command)? {
        CommandOutcome::JobQueued(id) => Some(format!("job {} queued", id.0)),
        CommandOutcome::Applied => reply,
    })
}

async fn master(args: Args, profiled: ProfiledBus) -> Result<()> {
    let bus = &profiled.file;
    for w in &bus.warnings {
        eprintln!("dpctl master: warning: {w}");
    }
    let mut dp = DpMaster::new(&bus.master)?;
    if args.clear {
        dp.set_operating_state(OperatingState::Clear);
    }
    let (mut station, mut port) =
        common::master_station(&args.port, bus, dp, args.latency, args.rts)?;
    let options = common::driver_options(&port, args.busy_poll, args.gather)?;

    // Commands come from a plain thread: a blocking read of stdin must not
    // keep the runtime from shutting down on Ctrl-C / SIGTERM.
    let (tx, mut rx) = tokio::sync::mpsc::channel::<String>(256);
    if let Some(input) = args.input.clone() {
        let reader: Box<dyn std::io::Read + Send> = if input == "-" {
            Box::new(std::io::stdin())
        } else {
            Box::new(std::fs::File::open(&input).with_context(|| format!("cannot open {input}"))?)
        };
        std::thread::spawn(move || {
            use std::io::BufRead;
            for l in std::io::BufReader::new(reader)
                .lines()
                .map_while(Result::ok)
            {
                if !l.trim().is_empty() && tx.blocking_send(l).is_err() {
                    break;
                }
            }
        });
    }

    let mut view = View::new(args.json, Duration::from_millis(args.interval.max(10)));
    let mut info: Vec<SlaveInfo> = vec![];
    for s in &bus.slaves {
        let a = s.params.address;
        info.push(SlaveInfo {
            address: a,
            name: s.params.name.clone(),
            gsd: Some(s.gsd.clone()),
            channels: profiled
                .channels(a)
                .transpose()
                .with_context(|| format!("slave {a}"))?,
            modules: s.modules.clone(),
        });
    }
    let baud = bus.master.params.baud;
    // Commands typed on stdin (`--input -`) keep the terminal for lines.
    let stdin_commands = args.input.as_deref() == Some("-");
    if !args.json && !args.plain && !stdin_commands && std::io::stdout().is_terminal() {
        view.open_terminal("dpctl master", baud, &info)?;
    }
    let cycles = args.cycles;
    let exchanges = args.exchanges;
    let deadline = match args.timeout {
        Some(t) if t.is_finite() && t > 0.0 => Some(Duration::from_secs_f64(t)),
        Some(t) => bail!("--timeout takes a positive number of seconds, not {t}"),
        None => None,
    };
    let mut timed_out = false;
    let mut last_now = Instant::ZERO;
    let mut rfid = crate::rfid::MasterJobs::default();
    let result = driver::run_with(
        &mut station,
        &mut port,
        Clock::start(),
        options,
        common::shutdown(),
        |st, now| {
            last_now = now;
            let m = st.app_mut();
            while let Ok(line) = rx.try_recv() {
                let result = match (set_channels(m, &info, &line), rfid.command(m, &line)) {
                    (Some(r), _) => r.map(|_| None),
                    (None, Some(r)) => r.map(Some),
                    (None, None) => apply_command(m, &line),
                };
                match result {
                    Ok(Some(reply)) => view.event(&Line::new(
                        "command",
                        CommandReply { result: &reply },
                        reply.as_str(),
                    )),
                    Ok(None) => {}
                    Err(e) => {
                        let error = format!("{e:#}");
                        let text = format!("bad command `{line}`: {error}");
                        view.event(&Line::new("error", BadCommand { line: &line, error }, text))
                    }
                }
            }
            for e in rfid.step(m, now) {
                view.event(&e);
            }
            drain_events(m, &info, &mut view);
            view.status(m, &info, baud, now, false);
            view.tick(m, now)?;
            let exchanged = exchanges.is_some_and(|n| {
                m.slave_addresses()
                    .all(|a| m.slave_stats(a).is_some_and(|s| s.data_exchanges >= n))
            });
            if deadline.is_some_and(|d| now - Instant::ZERO >= d) {
                timed_out = true;
                return ControlFlow::Break(());
            }
            match cycles {
                Some(n) if m.cycle_stats().cycles >= n => ControlFlow::Break(()),
                _ if exchanged => ControlFlow::Break(()),
                _ => ControlFlow::Continue(()),
            }
        },
    )
    .await;
    view.close();
    let m = station.app_mut();
    drain_events(m, &info, &mut view);
    view.status(m, &info, baud, last_now, true);
    result.with_context(|| format!("on {}", args.port))?;
    let stuck: Vec<u8> = bus
        .slaves
        .iter()
        .map(|s| s.params.address)
        .filter(|&a| m.slave_state(a) != Some(SlaveState::DataExchange))
        .collect();
    if cycles.is_some() && !stuck.is_empty() {
        tracing::info!(?stuck, "slaves not in data exchange at the end");
    }
    if timed_out && exchanges.is_some() {
        bail!(
            "timeout after {:.1} s: {} Data_Exchange cycles not reached (not in Data_Exchange: {stuck:?})",
            args.timeout.unwrap_or(0.0),
            exchanges.unwrap_or(0)
        );
    }
    Ok(())
}
