//! `dpctl gsd show FILE` and `dpctl gsd check FILE`: what a GSD file
//! describes, and what is wrong with it.

use crate::out::{out, outln};
use anyhow::bail;
use profibus_dp::config::gsd::{FileDiagnostic, Gsd, GsdCheck, GsdSummary, ParseOptions};
use std::path::PathBuf;

/// Show or check a GSD file.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(clap::Subcommand)]
enum Cmd {
    /// Show identity, baud rates with MaxTsdr, limits, modules with their
    /// decoded I/O sizes, and user parameters with defaults and ranges.
    Show(ShowArgs),
    /// Check a GSD file: print its errors and warnings with
    /// file:line:col; exit status 1 when it has errors.
    Check(CheckArgs),
}

#[derive(clap::Args)]
struct ShowArgs {
    /// The GSD file (Latin-1 text; `.gsd` or a localised `.gse`, `.gsg`, …).
    file: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Accept known vendor quirks with a warning on stderr (the default).
    #[arg(long, conflicts_with = "strict")]
    lenient: bool,
    /// Treat vendor quirks as errors.
    #[arg(long)]
    strict: bool,
}

#[derive(clap::Args)]
struct CheckArgs {
    /// The GSD file (Latin-1 text; `.gsd` or a localised `.gse`, `.gsg`, …).
    file: PathBuf,
    /// Treat vendor quirks (e.g. `MaxTsd_`, `Modules=`, a commented-out
    /// `#Profibus_DP`) as errors instead of warnings.
    #[arg(long)]
    strict: bool,
    /// Print one JSON object per error or warning.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.cmd {
        Cmd::Show(a) => show(a),
        Cmd::Check(a) => check(a),
    }
}

fn opts(strict: bool) -> ParseOptions {
    ParseOptions { lenient: !strict }
}

fn show(a: ShowArgs) -> anyhow::Result<()> {
    let parsed = match Gsd::from_file(&a.file, opts(a.strict)) {
        Ok(p) => p,
        Err(e) => {
            for d in &e.errors {
                crate::out::errln!("{}", FileDiagnostic::new(&a.file, "error", d));
            }
            let n = e.errors.len();
            let s = if n == 1 { "" } else { "s" };
            bail!("{}: {n} error{s}; first: {}", a.file.display(), e.first());
        }
    };
    for w in &parsed.warnings {
        crate::out::errln!("{}", FileDiagnostic::new(&a.file, "warning", w));
    }
    let summary = GsdSummary {
        file: &a.file,
        parsed: &parsed,
    };
    if a.json {
        outln!("{}", crate::common::json_line(&summary))?;
    } else {
        out!("{summary}")?;
    }
    Ok(())
}

fn check(a: CheckArgs) -> anyhow::Result<()> {
    let check = GsdCheck::of_file(&a.file, opts(a.strict));
    for fd in check.lines() {
        match a.json {
            true => outln!("{}", crate::common::json_line(&fd))?,
            false => outln!("{fd}")?,
        }
    }
    if !check.ok() {
        bail!("{check}");
    }
    if !a.json {
        outln!("{check}")?;
    }
    Ok(())
}
