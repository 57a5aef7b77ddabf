//! `dpctl soak`: the fault soak of `profibus_plant::soak` (a master and
//! one slave of every device profile on the simulated bus, with faults
//! on the line), printed.

use anyhow::{bail, Result};
use profibus_plant::soak::{self, SoakConfig};
use std::time::Duration;

/// Run the fault soak: a master and one slave of every device profile on
/// the simulated bus at 1.5 Mbit/s with dropped characters, bit errors
/// and noise; exit status 1 when an invariant breaks.
#[derive(clap::Args)]
pub struct Args {
    /// Poll cycles of the master.
    #[arg(long, default_value_t = 1_000_000, value_name = "N")]
    cycles: u64,
    /// Seed of the fault generators (same seed, same run).
    #[arg(long, default_value_t = 1, value_name = "S")]
    seed: u64,
    /// Probability of losing each character.
    #[arg(long, default_value_t = 1e-4, value_name = "P")]
    drop: f64,
    /// Bit error rate (probability of flipping each data bit).
    #[arg(long, default_value_t = 1e-4, value_name = "BER")]
    flip: f64,
    /// Noise bursts per second of idle line.
    #[arg(long, default_value_t = 20.0, value_name = "RATE")]
    noise: f64,
    /// Watchdog time the master gives the slaves (ms).
    #[arg(long, default_value_t = 100, value_name = "MS")]
    watchdog_ms: u64,
    /// Longest time a disturbed slave may take back to Data_Exchange (ms of bus time).
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    max_recovery_ms: u64,
    /// Largest growth of the resident set after the warm-up (MiB).
    #[arg(long, default_value_t = 16, value_name = "MIB")]
    max_rss_growth_mib: u64,
    /// Pull the plug of slave ADDR at cycle CYCLE for good (a deliberately
    /// broken invariant: the soak must fail).
    #[arg(long, value_name = "ADDR:CYCLE", value_parser = parse_unplug)]
    unplug: Option<(u8, u64)>,
    /// Print progress every N cycles (stderr).
    #[arg(long, value_name = "N")]
    progress: Option<u64>,
    /// Print the report as one JSON object.
    #[arg(long)]
    json: bool,
}

fn parse_unplug(s: &str) -> Result<(u8, u64), String> {
    let (a, c) = s.split_once(':').ok_or("expected ADDR:CYCLE")?;
    Ok((
        a.parse().map_err(|e| format!("address: {e}"))?,
        c.parse().map_err(|e| format!("cycle: {e}"))?,
    ))
}

pub fn run(args: Args) -> Result<()> {
    let cfg = SoakConfig {
        cycles: args.cycles,
        seed: args.seed,
        drop: args.drop,
        flip_ber: args.flip,
        noise_rate: args.noise,
        watchdog: Duration::from_millis(args.watchdog_ms),
        max_recovery: Duration::from_millis(args.max_recovery_ms),
        max_rss_growth: Some(args.max_rss_growth_mib << 20),
        unplug: args.unplug,
        progress_every: args.progress.unwrap_or(0),
        ..SoakConfig::default()
    };
    let report = soak::run(&cfg, |p| {
        crate::out::errln!(
            "soak: {} cycles, {:.1} s bus time, {} disturbances",
            p.cycles,
            p.bus_time_s,
            p.disturbances
        )
    })?;
    if args.json {
        crate::out::outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        crate::out::out!("{report}")?;
    }
    if let Some(v) = report.violations.first() {
        bail!("soak failed: invariant broken: {v}");
    }
    Ok(())
}
