//! `dpctl bus`: a virtual RS-485 multidrop bus made of ptys.
//!
//! The bus itself is [`profibus_io::transport::hub::Hub`]; this command
//! maps its arguments, handles signals (SIGINT/SIGTERM stop, SIGUSR1
//! prints the counters) and prints.

use crate::medium_args::{parse_rate, MediumArgs};
use anyhow::{Context, Result};
use nix::sys::signal::{SigSet, Signal};
use nix::sys::signalfd::{SfdFlags, SignalFd};
use profibus_io::transport::hub::{Hub, HubError};
use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::os::fd::AsFd;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Create a virtual RS-485 bus of N ptys linked as PREFIX0 … PREFIX{N-1}.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Number of stations (ptys) on the bus, 2 to 1024.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(2..=1024))]
    pub stations: u16,
    /// Link prefix: PREFIX0 … PREFIX{N-1} become symlinks to the pty ends
    /// the stations open (an existing symlink is replaced; any other file
    /// is an error).
    #[arg(long, value_name = "PREFIX")]
    pub link: String,
    #[command(flatten)]
    pub line: MediumArgs,
    /// Also print the counters every SECS seconds (they are printed on
    /// SIGUSR1 and at exit anyway).
    #[arg(long, value_name = "SECS", value_parser = parse_rate)]
    pub stats: Option<f64>,
    /// Record every telegram on the line to FILE (pcapng, link type 257
    /// PROFIBUS DL; tshark and Wireshark read it). Corrupted telegrams are
    /// kept, flagged (CRC-error flag; the dissector's `pbdl.fcs.good == 0`).
    #[arg(long, value_name = "FILE")]
    pub pcap: Option<PathBuf>,
    /// With --baud: a station whose port is set to another rate receives
    /// garbage and sends garbage, as on a real line (without it the rate
    /// a station sets on its pty only sets its timing). For testing
    /// `--baud auto` and slaves with auto-baud.
    #[arg(long, requires = "baud")]
    pub check_rates: bool,
}

/// A usage error found after parsing: one line, exit status 2.
fn usage(msg: impl std::fmt::Display) -> ! {
    crate::out::errln!("dpctl bus: {msg}");
    std::process::exit(2)
}

/// Run the bus until SIGINT or SIGTERM.
pub fn run(args: Args) -> Result<()> {
    let n = args.stations as usize;
    let links: Vec<PathBuf> = (0..n)
        .map(|i| PathBuf::from(format!("{}{i}", args.link)))
        .collect();
    let cfg = args.line.config().unwrap_or_else(|e| usage(e));
    let seed = cfg.seed;

    // Signals arrive through a signalfd the hub also waits on.
    let mut mask = SigSet::empty();
    for s in [Signal::SIGINT, Signal::SIGTERM, Signal::SIGUSR1] {
        mask.add(s);
    }
    mask.thread_block().context("blocking signals")?;
    let signals = SignalFd::with_flags(&mask, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC)
        .context("signalfd")?;

    let mut hub = match Hub::open(&links, cfg) {
        Ok(h) => h,
        Err(e @ HubError::NotASymlink(_)) => usage(e),
        Err(e) => return Err(e.into()),
    };
    hub.check_rates(args.check_rates);
    if let Some(path) = &args.pcap {
        let f = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        let epoch = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        hub.record(Box::new(BufWriter::new(f)), epoch)?;
    }
    {
        // A closed output ends the bus quietly (`crate::out`).
        let mut out = crate::out::stdout();
        for (link, tty) in hub.links() {
            writeln!(out, "{} -> {}", link.display(), tty.display())?;
        }
        let pace = args
            .line
            .baud
            .map_or("unpaced".to_string(), |b| format!("paced at {b}"));
        writeln!(out, "bus of {n} stations, {pace}, seed {seed}")?;
        out.flush()?;
    }

    let stats_every = args.stats.map(Duration::from_secs_f64);
    let mut next_stats = stats_every.map(|d| Instant::now() + d);
    loop {
        let wait = next_stats.map(|t| t.saturating_duration_since(Instant::now()));
        if hub.poll(Some(signals.as_fd()), wait)? {
            let mut stop = false;
            while let Ok(Some(info)) = signals.read_signal() {
                match Signal::try_from(info.ssi_signo as i32) {
                    Ok(Signal::SIGUSR1) => crate::out::errln!("dpctl bus: {}", hub.status()),
                    _ => stop = true,
                }
            }
            if stop {
                break;
            }
        }
        if let (Some(t), Some(d)) = (next_stats, stats_every) {
            if Instant::now() >= t {
                crate::out::errln!("dpctl bus: {}", hub.status());
                next_stats = Some(t.max(Instant::now()) + d);
            }
        }
    }
    let status = hub.finish()?;
    crate::out::errln!("dpctl bus: {status}");
    Ok(())
}
