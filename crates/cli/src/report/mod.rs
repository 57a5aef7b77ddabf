//! `dpctl report`: a capture file replayed through the passive monitor
//! (`profibus_dp::monitor`) and written as one self-contained HTML page
//! (inline CSS and SVG, nothing fetched from the network), or as one JSON
//! object with `--json`.
//!
//! What the page holds: the segment's parameters (rate, masters, TTR,
//! span, totals), the live list, a per-station table, histograms of the
//! Data_Exchange cycle times and the response times, a timeline of
//! restarts, diagnoses and errors, the token rotation over time, and the
//! diagnoses in words (with the texts of the slave's GSD when one is
//! found by its ident number). The model is [`model::Report`]; [`html`] renders
//! it.

mod html;
mod model;
mod svg;

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Turn a capture into an HTML report (or JSON): live list, per-station
/// statistics, plots, diagnoses in words.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The capture (pcapng or classic pcap, link type 257 PROFIBUS DL),
    /// as `dpctl sniff --pcap` writes it.
    #[arg(value_name = "CAPTURE")]
    pub capture: PathBuf,
    /// A folder of GSD files to find the slaves' by ident number (for the
    /// diagnosis texts; besides the built-in files and the user
    /// library). Repeatable.
    #[arg(long, value_name = "DIR")]
    pub gsd_dir: Vec<PathBuf>,
    /// The bus file of the segment: slave names, modules, GSD files, the
    /// rate and the target rotation time.
    #[arg(long, value_name = "BUS.toml")]
    pub config: Option<PathBuf>,
    /// The line's rate (9600 … 12M) instead of the bus file's or the one
    /// guessed from the telegrams' timing.
    #[arg(long, value_name = "B")]
    pub baud: Option<profibus_fdl::Baud>,
    /// Where to write the HTML page (default: CAPTURE with `.html`).
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Print the report's data as one JSON object instead of writing HTML.
    #[arg(long)]
    pub json: bool,
}

/// CAPTURE with its extension replaced by `.html`.
pub fn default_output(capture: &Path) -> PathBuf {
    capture.with_extension("html")
}

pub fn run(args: Args) -> Result<()> {
    let bus = match &args.config {
        Some(p) => Some(profibus_devices::bus::ProfiledBus::load(p)?),
        None => None,
    };
    let lib = crate::scan::library(&args.gsd_dir)?;
    let file = std::fs::File::open(&args.capture)
        .with_context(|| format!("cannot open {}", args.capture.display()))?;
    let options = model::Options {
        name: args.capture.display().to_string(),
        baud: args.baud,
        bus: bus.as_ref(),
        library: &lib,
    };
    let report = model::Report::from_capture(std::io::BufReader::new(file), &options)
        .with_context(|| format!("reading {}", args.capture.display()))?;
    if args.json {
        crate::out::outln!("{}", crate::common::json_line(&report))?;
        return Ok(());
    }
    let out = args
        .output
        .clone()
        .unwrap_or_else(|| default_output(&args.capture));
    std::fs::write(&out, html::render(&report))
        .with_context(|| format!("cannot write {}", out.display()))?;
    crate::out::outln!(
        "{}: {} telegrams, {} stations, {} s → {}",
        args.capture.display(),
        report.segment.telegrams,
        report.stations.len(),
        report.segment.span_s,
        out.display()
    )?;
    Ok(())
}
