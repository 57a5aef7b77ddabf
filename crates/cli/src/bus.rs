//! `dpctl bus`: a virtual RS-485 multidrop bus made of ptys.
//!
//! The bus itself is [`profibus_fdl::transport::hub::Hub`]; this command
//! maps its arguments, handles signals (SIGINT/SIGTERM stop, SIGUSR1
//! prints the counters) and prints.

use anyhow::{Context, Result};
use nix::sys::signal::{SigSet, Signal};
use nix::sys::signalfd::{SfdFlags, SignalFd};
use profibus_fdl::medium::{Collisions, MediumConfig};
use profibus_fdl::transport::hub::{Hub, HubError};
use profibus_fdl::Baud;
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
    /// Pace the line at this rate (9600 … 12M; 11 bit per character, one
    /// transmitter at a time). Without it bytes pass as fast as they come.
    #[arg(long, value_name = "B")]
    pub baud: Option<Baud>,
    /// Probability of losing each character (0 … 1).
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = probability)]
    pub drop: f64,
    /// Bit error rate: probability of flipping each data bit (0 … 1).
    #[arg(long, value_name = "BER", default_value_t = 0.0, value_parser = probability)]
    pub flip: f64,
    /// Bursts of random characters per second of idle line.
    #[arg(long, value_name = "RATE", default_value_t = 0.0, value_parser = rate)]
    pub noise: f64,
    /// Seed of the fault injection, for reproducible runs (default: from
    /// the clock; printed at start).
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// What two stations sending at once do on a paced line: garble each
    /// other (as on a real line) or serialize (the later one waits).
    #[arg(long, value_enum, default_value_t = CollisionMode::Garble)]
    pub collisions: CollisionMode,
    /// Also print the counters every SECS seconds (they are printed on
    /// SIGUSR1 and at exit anyway).
    #[arg(long, value_name = "SECS", value_parser = rate)]
    pub stats: Option<f64>,
    /// Record every telegram on the line to FILE (pcapng, link type 257
    /// PROFIBUS DL; tshark and Wireshark read it).
    #[arg(long, value_name = "FILE")]
    pub pcap: Option<PathBuf>,
}

/// `--collisions`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CollisionMode {
    /// Overlapping characters of both transmissions are corrupted.
    Garble,
    /// A station that starts while the line is busy waits its turn.
    Serialize,
}

fn probability(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(p) if (0.0..=1.0).contains(&p) => Ok(p),
        _ => Err(format!("`{s}` is not a probability between 0 and 1")),
    }
}

fn rate(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(r) if r >= 0.0 && r.is_finite() => Ok(r),
        _ => Err(format!("`{s}` is not a number ≥ 0")),
    }
}

/// A usage error found after parsing: one line, exit status 2.
fn usage(msg: impl std::fmt::Display) -> ! {
    eprintln!("dpctl bus: {msg}");
    std::process::exit(2)
}

/// Run the bus until SIGINT or SIGTERM.
pub fn run(args: Args) -> Result<()> {
    let n = args.stations as usize;
    let links: Vec<PathBuf> = (0..n)
        .map(|i| PathBuf::from(format!("{}{i}", args.link)))
        .collect();
    let seed = args.seed.unwrap_or_else(|| {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or(0)
    });
    let cfg = MediumConfig {
        baud: args.baud,
        drop: args.drop,
        flip_ber: args.flip,
        noise_rate: args.noise,
        seed,
        collisions: match args.collisions {
            CollisionMode::Garble => Collisions::Garble,
            CollisionMode::Serialize => Collisions::Serialize,
        },
    };
    if let Err(e) = cfg.validate() {
        usage(e);
    }

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
    if let Some(path) = &args.pcap {
        let f = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        let epoch = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        hub.record(Box::new(BufWriter::new(f)), epoch)?;
    }
    {
        let mut out = std::io::stdout().lock();
        for (link, tty) in hub.links() {
            writeln!(out, "{} -> {}", link.display(), tty.display())?;
        }
        let pace = args
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
                    Ok(Signal::SIGUSR1) => eprintln!("dpctl bus: {}", hub.status()),
                    _ => stop = true,
                }
            }
            if stop {
                break;
            }
        }
        if let (Some(t), Some(d)) = (next_stats, stats_every) {
            if Instant::now() >= t {
                eprintln!("dpctl bus: {}", hub.status());
                next_stats = Some(t.max(Instant::now()) + d);
            }
        }
    }
    let status = hub.finish()?;
    eprintln!("dpctl bus: {status}");
    Ok(())
}
