//! `dpctl scan`: live list of the stations on a bus, and with
//! `--write-config` a bus file from what the slaves report
//! (docs/commissioning.md).

use crate::common::{self, BaudArg, LineArgs};
use anyhow::{bail, Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::class2::{Class2Config, Class2Master, Class2Run};
use profibus_dp::config::commission::{self, Im0Scan, ScannedSlave, SlavePlan, WriteOptions};
use profibus_dp::config::library::GsdLibrary;
use profibus_dp::master::records::{ImRead, ImReader, RecordAnswer, RecordOp, RecordOps};
use profibus_dp::scan::{LiveListScan, LiveRow};
use profibus_fdl::station::active::{ActiveConfig, ActiveStation, MasterApp, RingState};
use profibus_fdl::wire::StationType;
use profibus_fdl::BusParams;
use profibus_io::driver::{self, Clock};
use profibus_io::transport::Port;
use std::collections::VecDeque;
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
    /// With --write-config: do not read the slaves' I&M0 (by default
    /// read through a class-2 connection from each slave whose GSD has
    /// `DPV1_Slave=1` and `C2_Read_Write_supp=1`, or that has no GSD in
    /// the library; written as a comment and in the JSON).
    #[arg(long)]
    no_im: bool,
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
    let station_cfg = cfg;
    let app = match library {
        Some(_) => LiveListScan::with_config(args.addr),
        None => LiveListScan::new(args.addr),
    };
    let mut station = ActiveStation::new(cfg, app);
    let limit = Duration::from_secs_f64(args.timeout.max(0.0));
    if let Some(ring) = run_until(&mut station, &mut port, limit, |a| a.is_done()).await? {
        if ring == RingState::ListenToken {
            bail!(
                "no token within {:.0} s: not invited into the ring",
                limit.as_secs_f64()
            );
        }
        bail!("scan did not finish within {:.0} s", limit.as_secs_f64());
    }
    let app = station.app();
    if let (Some(lib), Some(path)) = (library, &args.write_config) {
        let mut scanned = scanned(app);
        if !args.no_im {
            read_im0(&mut port, station_cfg, &mut scanned, &lib, limit).await?;
        }
        return write_config(&args, baud, scanned, &lib, path);
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

/// Run `station` on `port` until `done` says its application has
/// finished, `limit` has passed or the process is asked to stop (the
/// one station loop of `dpctl scan` and the service commands). `None`
/// when done; else where the station was in the ring, for the caller's
/// words ([`RingState::ListenToken`]: never invited into the ring).
pub async fn run_until<A: MasterApp>(
    station: &mut ActiveStation<A>,
    port: &mut Port,
    limit: Duration,
    done: impl Fn(&A) -> bool,
) -> Result<Option<RingState>> {
    let deadline = tokio::time::sleep(limit);
    driver::run_with(
        station,
        port,
        Clock::start(),
        driver::Options::default(),
        async {
            tokio::select! {
                _ = common::shutdown() => {}
                _ = deadline => {}
            }
        },
        |st, _| {
            if done(st.app()) {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
    )
    .await?;
    Ok((!done(station.app())).then(|| station.ring_state()))
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

/// What the scan read of each DP slave, by address.
fn scanned(app: &LiveListScan) -> Vec<ScannedSlave> {
    let mut stations: Vec<_> = app
        .stations()
        .iter()
        .filter(|s| s.station == StationType::Passive)
        .collect();
    stations.sort_by_key(|s| s.address);
    stations
        .iter()
        .map(|s| {
            let data = app.slave_data(s.address).cloned().unwrap_or_default();
            ScannedSlave {
                address: s.address,
                diag: data.diag,
                cfg: data.cfg,
                im0: None,
            }
        })
        .collect()
}

/// [`ImReader`] stopped after I&M0.
struct Im0Only(ImReader);

impl RecordOps for Im0Only {
    fn next_op(&mut self) -> Option<RecordOp> {
        if self.0.records[0].is_some() {
            return None;
        }
        self.0.next_op()
    }

    fn answered(&mut self, op: &RecordOp, answer: &RecordAnswer) {
        self.0.answered(op, answer);
    }
}

/// Whether to ask `slave` for I&M0: `Err(why not)` when every GSD file
/// of its ident in the library says it has no class-2 services; a slave
/// without a file is asked (it answers or refuses). `Ok` with the
/// longest `C2_Response_Timeout` its files give.
fn offers_im(slave: &ScannedSlave, lib: &GsdLibrary) -> Result<Option<Duration>, String> {
    let Some(ident) = slave.ident() else {
        return Err("no Slave_Diag".into());
    };
    let entries = lib.find(ident);
    if entries.is_empty() {
        return Ok(None);
    }
    let c2: Vec<_> = entries
        .iter()
        .filter(|e| e.gsd.dpv1_slave && e.gsd.c2_read_write_supp)
        .collect();
    if c2.is_empty() {
        return Err(format!(
            "{} has no class-2 services (DPV1_Slave, C2_Read_Write_supp)",
            entries[0].source
        ));
    }
    Ok(c2
        .iter()
        .filter_map(|e| e.gsd.c2_response_timeout)
        .max()
        .map(|t| Duration::from_millis(10 * u64::from(t.max(1)))))
}

/// Read the I&M0 of every slave that offers it, one class-2 connection
/// after the other, as a station of the ring at the scan's address;
/// each slave's [`Im0Scan`] into `slaves`. A slave that refuses or does
/// not answer is noted, never an error.
async fn read_im0(
    port: &mut Port,
    station: ActiveConfig,
    slaves: &mut [ScannedSlave],
    lib: &GsdLibrary,
    limit: Duration,
) -> Result<()> {
    let mut queue = VecDeque::new();
    // At least 3 s for the set-up and each answer (the GSD's
    // C2_Response_Timeout is the slave's own figure, without the token's
    // rotation through other masters; the class-2 default of 10 s would
    // hold up the scan at a silent slave).
    let mut response = Duration::from_secs(3);
    for s in slaves.iter_mut() {
        match offers_im(s, lib) {
            Ok(t) => {
                response = response.max(t.unwrap_or_default());
                queue.push_back((
                    s.address,
                    Class2Run::new(s.address, Im0Only(ImReader::new(0, None))),
                ));
            }
            Err(why) => s.im0 = Some(Im0Scan::Skipped(why)),
        }
    }
    if queue.is_empty() {
        return Ok(());
    }
    let mut cfg = Class2Config::for_baud(station.params.baud);
    cfg.response_timeout = response;
    let mut st = ActiveStation::new(station, Class2Master::new(cfg));
    let mut done: Vec<(u8, Class2Run<Im0Only>)> = vec![];
    let deadline = tokio::time::sleep(limit);
    driver::run_with(
        &mut st,
        port,
        Clock::start(),
        driver::Options::default(),
        async {
            tokio::select! {
                _ = common::shutdown() => {}
                _ = deadline => {}
            }
        },
        |st, now| loop {
            // The response timeout runs from the connect: not before
            // this station is in the ring (it has held the token).
            if st.stats().tokens == 0 {
                return ControlFlow::Continue(());
            }
            let Some((_, run)) = queue.front_mut() else {
                return ControlFlow::Break(());
            };
            if run.tick(st.app_mut(), now).is_continue() {
                return ControlFlow::Continue(());
            }
            done.extend(queue.pop_front());
        },
    )
    .await?;
    let unfinished = format!("no end within {:.0} s", limit.as_secs_f64());
    for ((address, run), finished) in done
        .into_iter()
        .map(|r| (r, true))
        .chain(queue.into_iter().map(|r| (r, false)))
    {
        let result = match run.finish() {
            _ if !finished => Im0Scan::Failed(unfinished.clone()),
            Err((e, _)) => Im0Scan::Failed(e.to_string()),
            Ok(Im0Only(r)) => match (&r.records[0], r.im0()) {
                (_, Some(im)) => Im0Scan::Read(im),
                (Some(ImRead::Refused(e)), _) => {
                    Im0Scan::Failed(format!("refused: {}", e.describe()))
                }
                (Some(ImRead::Invalid(why)), _) => Im0Scan::Failed(format!("not valid: {why}")),
                (Some(ImRead::Record(_)), None) => Im0Scan::Failed("not valid".into()),
                (None, _) => Im0Scan::Failed("not read".into()),
            },
        };
        if let Some(s) = slaves.iter_mut().find(|s| s.address == address) {
            s.im0 = Some(result);
        }
    }
    Ok(())
}

fn write_config(
    args: &Args,
    baud: profibus_fdl::Baud,
    scanned: Vec<ScannedSlave>,
    lib: &GsdLibrary,
    path: &Path,
) -> Result<()> {
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
            // I&M0 with the keys of `dpctl im --json`.
            let mut v = serde_json::to_value(p)?;
            if let (Some(o), Some(im)) = (v.as_object_mut(), &p.scanned.im0) {
                let im = match im {
                    Im0Scan::Read(im) => crate::im::im0_json(im),
                    Im0Scan::Failed(why) => serde_json::json!({ "error": why }),
                    Im0Scan::Skipped(why) => serde_json::json!({ "skipped": why }),
                };
                o.insert("im0".into(), im);
            }
            crate::out::outln!("{}", common::json_line(&v))?;
        } else {
            crate::out::outln!("{}", commission::describe(p, dir))?;
        }
    }
    Ok(())
}
