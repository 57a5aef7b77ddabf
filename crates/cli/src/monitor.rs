//! `dpctl monitor`: follow another master's slaves, listening only.
//!
//! `profibus_io::listen` reads the line (it cannot write) and
//! `profibus_dp::monitor::Monitor` tracks the traffic; its events and
//! status go to the view (`crate::view`): a table on a terminal, else
//! lines or JSON lines every `--interval`.

use crate::common;
use crate::view::{bus_view, Line, SlaveInfo, View};
use anyhow::{Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::monitor::{Monitor, MonitorOptions};
use profibus_io::listen::{listen, Heard, ListenOptions};
use profibus_io::transport::Port;
use profibus_tui::lines::monitor_slaves;
use profibus_tui::source::WithLiveList;
use profibus_tui::term::LiveBus;
use std::io::{IsTerminal, Write as _};
use std::path::PathBuf;
use std::time::Duration;

/// Listen to a bus (never send) and follow the master(s) on it: every
/// slave's state, data, diagnosis, cycle times, retries and errors, the
/// masters in the token ring, and FMS services (one event per confirmed
/// service, connections per station). On a terminal a refreshing table with
/// each station's role and health bar: `q` quit, `p` pause, up/down
/// select a slave, Enter its details.
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
    /// Print status lines even on a terminal (no table).
    #[arg(long, conflicts_with = "json")]
    plain: bool,
    /// Milliseconds between status prints (lines and JSON lines).
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    interval: u64,
    /// A master that has not passed the token for this many milliseconds
    /// has left the ring.
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    master_timeout: u64,
    /// The line's rate instead of the bus file's (9600 … 12M), or `auto`:
    /// listen at each rate until a valid telegram decodes (printed first:
    /// a line, or a JSON object with `"event":"baud_found"`).
    #[arg(long, value_name = "B")]
    baud: Option<common::BaudArg>,
    #[command(flatten)]
    stats: crate::stats_args::StatsArgs,
}

pub fn run(args: Args) -> Result<()> {
    let bus = ProfiledBus::load(&args.config)?;
    let info = SlaveInfo::of_bus(&bus)?;
    let options = MonitorOptions {
        master_timeout: Duration::from_millis(args.master_timeout),
        ..MonitorOptions::default()
    };
    let mut monitor = Monitor::new(monitor_slaves(&info), options);
    let rt = common::runtime()?;
    let mut baud = match args.baud {
        Some(common::BaudArg::Fixed(b)) => b,
        _ => bus.file.master.params.baud,
    };
    common::lock_port(&args.port)?;
    let mut port = {
        let _guard = rt.enter();
        Port::open(&args.port, baud)?
    };
    if args.baud == Some(common::BaudArg::Auto) {
        let found = rt.block_on(common::find_baud(&mut port, None))?;
        if args.json {
            crate::out::outln!("{}", common::json_line(&found.json()))?;
        } else {
            crate::out::outln!("{found}")?;
        }
        baud = found.baud();
    }
    let mut listen_opts = ListenOptions::for_port(&port);
    // The target rotation time is not on the wire: the bus file's.
    let params = &bus.file.master.params;
    let ttr = params.baud.bits_to_duration(params.ttr as u64);
    let stats_options = profibus_dp::monitor::stats::StatsOptions {
        baud: Some(baud),
        ttr: Some(ttr),
    };
    let live = !args.json && !args.plain && std::io::stdout().is_terminal();
    // The table shows each station's role and health: statistics run
    // beside the monitor on a terminal even without `--stats`.
    let mut analysis = crate::stats_args::StatsRun::new(&args.stats, stats_options)
        .or_else(|| live.then(|| crate::stats_args::StatsRun::quiet(stats_options)));
    let mut view = View::new(args.json, Duration::from_millis(args.interval.max(10)));
    if live {
        view.open_terminal(bus_view("dpctl monitor", baud, &info).listen_only())?;
        listen_opts.tick = LiveBus::KEYS;
    }
    let on_heard = |heard| {
        let now = match heard {
            Heard::Event(e) => {
                if let Some(s) = analysis.as_mut() {
                    s.hear(&e);
                }
                monitor.hear(&e)
            }
            Heard::Tick(at) => {
                monitor.tick(at);
                at
            }
            Heard::Drained(_) => return std::ops::ControlFlow::Continue(()),
        };
        show(&mut monitor, &mut view, now, false);
        if let Some(due) = analysis.as_mut().and_then(|s| s.due(now)) {
            print_stats(&due, args.json, live);
        }
        match &analysis {
            Some(a) => view.tick(
                &mut WithLiveList {
                    source: &mut monitor,
                    stats: &a.stats,
                },
                now,
            ),
            None => view.tick(&mut monitor, now),
        }
    };
    let stats = rt.block_on(listen(&mut port, listen_opts, common::shutdown(), on_heard));
    view.close();
    let stats = stats.with_context(|| format!("reading {}", args.port))?;
    show(&mut monitor, &mut view, profibus_fdl::Instant::ZERO, true);
    if let Some(due) = analysis
        .as_mut()
        .and_then(|s| s.last(profibus_fdl::Instant::ZERO))
    {
        print_stats(&due, args.json, false);
    }
    tracing::info!(?stats, "line counters");
    Ok(())
}

/// `--stats` and `--alert` lines (not over the live table).
fn print_stats(due: &crate::stats_args::Due, json: bool, live: bool) {
    if live {
        return;
    }
    let mut out = crate::out::stdout();
    if let Err(e) = due.print(json, &mut out).and_then(|()| out.flush()) {
        tracing::debug!(%e, "printing statistics");
    }
}

/// The monitor's events, and its status when due.
fn show(m: &mut Monitor, view: &mut View, now: profibus_fdl::Instant, force: bool) {
    while let Some(e) = m.poll_event() {
        view.event(&e);
    }
    if view.due(now, force) {
        let s = m.status();
        view.event(&Line::new("status", &s, s.to_string()));
    }
}
