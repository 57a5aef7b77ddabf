//! `dpctl scan`: live list of the stations on a bus, and with
//! `--write-config` a bus file from what the slaves report
//! (docs/commissioning.md).

use crate::common::{self, BaudArg, LineArgs};
use anyhow::{bail, Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::config::commission::{self, ScannedSlave, SlavePlan, WriteOptions};
use profibus_dp::config::library::GsdLibrary;
use profibus_dp::scan::{LiveListScan, LiveRow};
use profibus_fdl::station::active::{ActiveConfig, ActiveStation, RingState};
use profibus_fdl::wire::StationType;
use profibus_fdl::BusParams;
use profibus_io::driver::{self, Clock, Stop};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Join the bus as a master and list every station that answers FDL
/// Status, with the ident number of DP slaves. With --write-config, also
/// read each DP slave's configuration (Get_Cfg, which a slave answers
/// whichever master owns it), find its GSD by ident number, decode the
/// configuration into the GSD's modules and write a bus file for
/// `dpctl master --config`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    line: LineArgs,
    /// This station's address while scanning (and the master address of
    /// the written bus file).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(0..=125))]
    addr: u8,
    /// Give up after this many seconds.
    #[arg(long, default_value_t = 30.0, value_name = "SECS")]
    timeout: f64,
    /// Print one JSON object per station (with --write-config: per DP
    /// slave, with its configuration or why it has none).
    #[arg(long)]
    json: bool,
    /// A folder of GSD files (`.gsd` and the localised `.gs?`) to find
    /// the slaves' files in, before the built-in files and the user
    /// library ($XDG_DATA_HOME/dpctl/gsd, see `dpctl gsd install`).
    /// Repeatable.
    #[arg(long, value_name = "DIR")]
    gsd_dir: Vec<PathBuf>,
    /// Write a bus file of every slave whose configuration was found:
    /// master address and rate, per slave its GSD, modules, default
    /// parameters and watchdog (or a device profile with its options).
    /// Built-in GSD files used are written to a `gsd/` folder beside it.
    #[arg(long, value_name = "BUS.toml")]
    write_config: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    common::runtime()?.block_on(scan(args))
}

async fn scan(args: Args) -> Result<()> {
    // The library first: a wrong folder is said before the bus is used.
    let library = if args.write_config.is_some() {
        Some(library(&args.gsd_dir)?)
    } else {
        if !args.gsd_dir.is_empty() {
            bail!("--gsd-dir is for --write-config");
        }
        None
    };
    let mut port = args.line.open()?;
    let baud = match args.line.baud {
        BaudArg::Fixed(b) => b,
        BaudArg::Auto => {
            let latency = common::latency(args.line.latency, &port)?;
            let found = common::find_baud(&mut port, Some((args.addr, latency))).await?;
            if args.json {
                crate::out::outln!("{}", common::json_line(&found.json()))?;
            } else {
                crate::out::outln!("{found}")?;
            }
            found.baud()
        }
    };
    let mut cfg = ActiveConfig::new(args.addr, BusParams::defaults(baud));
    common::allow_for_port(&mut cfg, args.line.latency, &port)?;
    let app = match library {
        Some(_) => LiveListScan::with_config(args.addr),
        None => LiveListScan::new(args.addr),
    };
    let mut station = ActiveStation::new(cfg, app);
    let limit = Duration::from_secs_f64(args.timeout.max(0.0));
    let deadline = tokio::time::sleep(limit);
    let stop = driver::run_with(
        &mut station,
        &mut port,
        Clock::start(),
        driver::Options::default(),
        async {
            tokio::select! {
                _ = common::shutdown() => {}
                _ = deadline => {}
            }
        },
        |st, _| {
            if st.app().is_done() {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
    )
    .await?;
    if stop == Stop::Shutdown && !station.app().is_done() {
        if station.ring_state() == RingState::ListenToken {
            bail!(
                "no token within {:.0} s: not invited into the ring",
                limit.as_secs_f64()
            );
        }
        bail!("scan did not finish within {:.0} s", limit.as_secs_f64());
    }
    let app = station.app();
    if let (Some(lib), Some(path)) = (library, &args.write_config) {
        return write_config(&args, baud, app, &lib, path);
    }
    let mut rows: Vec<LiveRow> = vec![LiveRow::scanner(args.addr)];
    rows.extend(app.stations().iter().map(|&s| LiveRow::from(s)));
    rows[1..].sort_by_key(|r| r.station.address);
    for row in rows {
        if args.json {
            crate::out::outln!("{}", common::json_line(&row))?;
        } else {
            crate::out::outln!("{row}")?;
        }
    }
    Ok(())
}

/// The GSD library of `--gsd-dir` folders, the built-in files and the
/// user library; files that do not parse are warned about.
pub fn library(dirs: &[PathBuf]) -> Result<GsdLibrary> {
    let mut lib = GsdLibrary::new();
    for d in dirs {
        lib.add_dir(d)?;
    }
    lib.add_built_in(profibus_devices::gsd_files::BUILT_IN);
    lib.add_user_dir()?;
    for s in lib.skipped() {
        tracing::warn!("GSD file left out: {}", s.error);
    }
    Ok(lib)
}

fn write_config(
    args: &Args,
    baud: profibus_fdl::Baud,
    app: &LiveListScan,
    lib: &GsdLibrary,
    path: &Path,
) -> Result<()> {
    let mut stations: Vec<_> = app
        .stations()
        .iter()
        .filter(|s| s.station == StationType::Passive)
        .collect();
    stations.sort_by_key(|s| s.address);
    let scanned: Vec<ScannedSlave> = stations
        .iter()
        .map(|s| {
            let data = app.slave_data(s.address).cloned().unwrap_or_default();
            ScannedSlave {
                address: s.address,
                diag: data.diag,
                cfg: data.cfg,
            }
        })
        .collect();
    let plans = commission::plan(&scanned, lib, &profibus_devices::commission::Registry);
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let dir = dir
        .canonicalize()
        .with_context(|| format!("folder of {}", path.display()))?;
    let o = WriteOptions {
        master: args.addr,
        baud,
        dir: dir.clone(),
        built_in_dir: PathBuf::from("gsd"),
    };
    for (name, bytes) in commission::built_in_files(&plans, lib) {
        let to = dir.join(&o.built_in_dir).join(&name);
        if std::fs::read(&to).is_ok_and(|b| b == bytes) {
            continue;
        }
        std::fs::create_dir_all(to.parent().unwrap_or(&dir))
            .with_context(|| format!("{}", to.display()))?;
        std::fs::write(&to, bytes).with_context(|| format!("{}", to.display()))?;
    }
    let text = commission::bus_file_text(&plans, &o);
    let target = dir.join(path.file_name().context("--write-config names no file")?);
    // The file must load as `dpctl master --config` loads it, with each
    // slave's Chk_Cfg the configuration it reported.
    let bus = ProfiledBus::parse(&target, &text)
        .map_err(|e| anyhow::anyhow!("the bus file written would not load: {e}"))?;
    for s in &bus.file.slaves {
        let read = plans
            .iter()
            .find(|p| p.scanned.address == s.params.address)
            .and_then(|p| p.scanned.cfg.as_deref());
        if read != Some(&s.params.cfg[..]) {
            bail!(
                "slave {}: the bus file's Chk_Cfg differs from its Get_Cfg (a bug: please report)",
                s.params.address
            );
        }
    }
    let tmp = target.with_extension("toml.tmp");
    std::fs::write(&tmp, &text).with_context(|| format!("{}", tmp.display()))?;
    std::fs::rename(&tmp, &target).with_context(|| format!("{}", target.display()))?;
    print_plans(&plans, &dir, args.json)?;
    let done = plans.iter().filter(|p| p.result.is_ok()).count();
    crate::out::errln!(
        "dpctl scan: wrote {}: {done} slave(s) configured, {} not",
        path.display(),
        plans.len() - done
    );
    Ok(())
}

fn print_plans(plans: &[SlavePlan], dir: &Path, json: bool) -> Result<()> {
    for p in plans {
        if json {
            crate::out::outln!("{}", common::json_line(p))?;
        } else {
            crate::out::outln!("{}", commission::describe(p, dir))?;
        }
    }
    Ok(())
}
