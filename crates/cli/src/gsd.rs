//! `dpctl gsd show FILE` and `dpctl gsd check FILE`: what a GSD file
//! describes, and what is wrong with it; `dpctl gsd install FILE…`: copy
//! files into the user library that `dpctl scan --write-config` searches.

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
    /// Copy GSD files into the user library ($XDG_DATA_HOME/dpctl/gsd,
    /// default ~/.local/share/dpctl/gsd), where `dpctl scan
    /// --write-config` finds them by ident number. Each file is parsed
    /// first: one that does not parse is refused with file:line:col and
    /// nothing is copied.
    Install(InstallArgs),
}

#[derive(clap::Args)]
struct InstallArgs {
    /// The GSD files (`.gsd` or a localised `.gse`, `.gsg`, …).
    #[arg(required = true)]
    files: Vec<PathBuf>,
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
        Cmd::Install(a) => install(a),
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

fn install(a: InstallArgs) -> anyhow::Result<()> {
    use profibus_dp::config::library::{first_error, is_gsd_name, user_dir};
    let dir = user_dir()
        .ok_or_else(|| anyhow::anyhow!("no user library: neither XDG_DATA_HOME nor HOME is set"))?;
    // Every file parsed before any is copied.
    let mut parsed = Vec::new();
    for f in &a.files {
        if !is_gsd_name(f) {
            bail!(
                "{}: not a GSD file name (.gsd, or a localised .gse, .gsg, …)",
                f.display()
            );
        }
        let name = f
            .file_name()
            .ok_or_else(|| anyhow::anyhow!("{}: names no file", f.display()))?;
        match Gsd::from_file(f, ParseOptions::LENIENT) {
            Ok(p) => parsed.push((f, name, p.gsd)),
            Err(e) => bail!("{} (not installed)", first_error(f, &e)),
        }
    }
    std::fs::create_dir_all(&dir).map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
    for (from, name, gsd) in parsed {
        let to = dir.join(name);
        std::fs::copy(from, &to).map_err(|e| anyhow::anyhow!("{}: {e}", to.display()))?;
        let model = gsd.model_name.as_deref().unwrap_or("no Model_Name").trim();
        outln!(
            "installed {} (ident 0x{:04X}, {model})",
            to.display(),
            gsd.ident_number
        )?;
    }
    Ok(())
}
