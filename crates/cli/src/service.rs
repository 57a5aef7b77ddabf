//! The service commands of commissioning: `dpctl diag`, `get-cfg`,
//! `set-address`, `read-io` and `global-control`. Each joins the token
//! ring as a master of its own (`--addr`), sends its DP requests
//! (`profibus_dp::scan::ServiceRequests`) and prints the answers in
//! words or JSON. Slave_Diag, Get_Cfg, Rd_Inp and Rd_Outp are answered
//! whichever master owns the slave (IEC 61158-6-3), so they work beside
//! a running master; Set_Slave_Add is taken only by a slave in Wait_Prm;
//! a slave obeys Global_Control only from the master that parameterised
//! it.

use crate::common::{self, LineArgs};
use anyhow::{bail, Context, Result};
use profibus_dp::config::discover::{modules_for_cfg, CfgMatch};
use profibus_dp::config::gsd::{Gsd, ParseOptions};
use profibus_dp::pdu::cfg;
use profibus_dp::pdu::control::{ControlCommand, GlobalControl};
use profibus_dp::pdu::diag::{self, SlaveDiag, NO_MASTER};
use profibus_dp::scan::{ServiceAnswer, ServiceRequest, ServiceRequests};
use profibus_fdl::station::active::{ActiveConfig, ActiveStation, RingState};
use profibus_fdl::wire::{Hex, ResponseStatus};
use profibus_fdl::BusParams;
use serde_json::json;
use std::path::PathBuf;
use std::time::Duration;

/// The station a service command runs as.
#[derive(clap::Args)]
pub struct StationArgs {
    #[command(flatten)]
    line: LineArgs,
    /// This station's address in the token ring (not the address of a
    /// running master).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(0..=125))]
    addr: u8,
    /// Give up after this many seconds.
    #[arg(long, default_value_t = 10.0, value_name = "SECS")]
    timeout: f64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// The slave a command is about, and where its GSD is.
#[derive(clap::Args)]
pub struct SlaveArgs {
    /// The slave's station address.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=125))]
    slave: u8,
    /// The slave's GSD file (default: found by ident number in the
    /// --gsd-dir folders, the built-in files and the user library).
    #[arg(long, value_name = "FILE")]
    gsd: Option<PathBuf>,
    /// A folder of GSD files to find the slave's in. Repeatable.
    #[arg(long, value_name = "DIR", conflicts_with = "gsd")]
    gsd_dir: Vec<PathBuf>,
}

/// The station of `dpctl diag` and `get-cfg`: a station of their own on
/// the line, or (`--via`) the running master behind a control socket.
#[derive(clap::Args)]
pub struct ViaStationArgs {
    /// Serial device or pty path (e.g. /dev/ttyUSB0, a `dpctl bus` link:
    /// waited for up to 10 s if not made yet), or tcp://HOST:PORT (RS-485
    /// serial device server in raw TCP mode).
    #[arg(long, value_name = "PATH", required_unless_present = "via")]
    port: Option<String>,
    /// Baud rate: 9600 … 12000000, or 1.5M, 187.5k, … (on a pty the rate
    /// only sets the bus timing).
    #[arg(long, default_value = "19200", value_name = "B")]
    baud: common::BaudArg,
    /// Extra milliseconds added to the slot time and token timeouts for the
    /// transport's latency (default: 5 on a pty, 20 on a serial adapter).
    #[arg(long, value_name = "MS")]
    latency: Option<f64>,
    #[command(flatten)]
    rts: common::RtsArg,
    /// This station's address in the token ring (not the address of a
    /// running master).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(0..=125))]
    addr: u8,
    /// Give up after this many seconds.
    #[arg(long, default_value_t = 10.0, value_name = "SECS")]
    timeout: f64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
    /// Ask through the running `dpctl master` or `dpctl gateway` whose
    /// control socket (`--control PATH`) this is, instead of joining the
    /// ring as a station of its own.
    #[arg(long, value_name = "PATH", conflicts_with_all = ["port", "latency"])]
    via: Option<PathBuf>,
}

impl ViaStationArgs {
    /// The station of its own (without `--via`).
    fn station(&self) -> Result<StationArgs> {
        Ok(StationArgs {
            line: LineArgs {
                port: self
                    .port
                    .clone()
                    .context("--port PATH is needed (or --via PATH)")?,
                baud: self.baud,
                latency: self.latency,
                rts: self.rts,
            },
            addr: self.addr,
            timeout: self.timeout,
            json: self.json,
        })
    }

    /// Run `requests` (Slave_Diag, Get_Cfg) and return their data, on
    /// the line or through the master (`read_diag`, `get_cfg` jobs).
    fn data(&self, slave: u8, requests: &[ServiceRequest]) -> Result<Vec<Vec<u8>>> {
        let name = |r: &ServiceRequest| match r {
            ServiceRequest::GetCfg(_) => "Get_Cfg",
            _ => "Slave_Diag",
        };
        if let Some(path) = &self.via {
            let mut via = crate::via::Via::connect(path)?;
            return requests
                .iter()
                .map(|r| {
                    let key = match r {
                        ServiceRequest::GetCfg(_) => "get_cfg",
                        _ => "read_diag",
                    };
                    match via.job(&json!({ key: slave }))? {
                        Ok(a) => a.bytes(),
                        Err(crate::via::JobFailure::Other(why)) => {
                            bail!("slave {slave}: {}: {why}", name(r))
                        }
                        Err(crate::via::JobFailure::Dpv1(e)) => {
                            bail!("slave {slave}: {}: {}", name(r), e.describe())
                        }
                    }
                })
                .collect();
        }
        let station = self.station()?;
        let answers = run_async_value(exchange(&station, requests.to_vec()))?;
        requests
            .iter()
            .zip(&answers)
            .map(|(r, a)| data(a, slave, name(r)))
            .collect()
    }
}

/// `dpctl diag`: a slave's diagnosis in words.
#[derive(clap::Args)]
pub struct DiagArgs {
    #[command(flatten)]
    station: ViaStationArgs,
    #[command(flatten)]
    slave: SlaveArgs,
}

/// `dpctl get-cfg`: a slave's configuration, decoded into modules.
#[derive(clap::Args)]
pub struct GetCfgArgs {
    #[command(flatten)]
    station: ViaStationArgs,
    #[command(flatten)]
    slave: SlaveArgs,
}

/// `dpctl set-address`: give a slave a new station address.
#[derive(clap::Args)]
pub struct SetAddressArgs {
    #[command(flatten)]
    station: StationArgs,
    /// The slave's present address.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=126))]
    slave: u8,
    /// The address it is to take (0..=125).
    #[arg(long, value_name = "M", value_parser = clap::value_parser!(u8).range(0..=125))]
    new: u8,
    /// Forbid further address changes over the bus (No_Add_Chg; the
    /// slave's own reset may clear it).
    #[arg(long)]
    no_further_change: bool,
}

/// `dpctl read-io`: a slave's inputs and outputs.
#[derive(clap::Args)]
pub struct ReadIoArgs {
    #[command(flatten)]
    station: StationArgs,
    /// The slave's station address.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=125))]
    slave: u8,
}

/// `dpctl global-control`: one Global_Control broadcast.
#[derive(clap::Args)]
pub struct GlobalControlArgs {
    #[command(flatten)]
    station: StationArgs,
    /// The groups addressed (Group_Select bits 1..=8, as in a bus file's
    /// `group`); 0: every slave.
    #[arg(long, default_value_t = 0, value_name = "G")]
    group: u8,
    /// The command.
    #[arg(value_enum)]
    command: Control,
}

/// The commands of Global_Control.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum Control {
    /// Clear_Data: outputs to their safe state.
    Clear,
    /// Operate: Clear_Data off.
    Operate,
    /// Sync: apply the outputs received last and hold them.
    Sync,
    /// Unsync: apply outputs as they come again.
    Unsync,
    /// Freeze: latch the inputs.
    Freeze,
    /// Unfreeze: inputs follow the process again.
    Unfreeze,
}

/// Run `requests` as a station of the ring; their answers in order.
async fn exchange(s: &StationArgs, requests: Vec<ServiceRequest>) -> Result<Vec<ServiceAnswer>> {
    let mut cfg = ActiveConfig::new(s.addr, BusParams::defaults(s.line.baud.fixed()?));
    let mut port = s.line.open()?;
    common::allow_for_port(&mut cfg, s.line.latency, &port)?;
    let mut station = ActiveStation::new(cfg, ServiceRequests::new(requests));
    let limit = Duration::from_secs_f64(s.timeout.max(0.0));
    if let Some(ring) =
        crate::scan::run_until(&mut station, &mut port, limit, ServiceRequests::is_done).await?
    {
        if ring == RingState::ListenToken {
            bail!(
                "no token within {:.0} s: not invited into the ring (is --addr {} free and below the masters' HSA?)",
                limit.as_secs_f64(),
                s.addr
            );
        }
        bail!("no end within {:.0} s", limit.as_secs_f64());
    }
    Ok(station.app().answers().to_vec())
}

fn run_async(f: impl std::future::Future<Output = Result<()>>) -> Result<()> {
    common::runtime()?.block_on(f)
}

fn run_async_value<T>(f: impl std::future::Future<Output = Result<T>>) -> Result<T> {
    common::runtime()?.block_on(f)
}

/// The data of a positive answer, or the error in words.
fn data(answer: &ServiceAnswer, slave: u8, service: &str) -> Result<Vec<u8>> {
    match answer {
        ServiceAnswer::Data(d) => Ok(d.clone()),
        ServiceAnswer::NoAnswer => bail!("slave {slave}: no answer to {service}"),
        ServiceAnswer::Refused(ResponseStatus::Rs) => bail!(
            "slave {slave}: {service} refused (RS: the service is not active in the slave's state)"
        ),
        other => bail!("slave {slave}: {service}: {other}"),
    }
}

/// The slave's GSD: `--gsd`, else the library's first file of `ident`.
fn find_gsd(a: &SlaveArgs, ident: u16) -> Result<Option<(String, Gsd)>> {
    if let Some(f) = &a.gsd {
        let p = Gsd::from_file(f, ParseOptions::LENIENT)
            .map_err(|e| anyhow::anyhow!("{}", profibus_dp::config::library::first_error(f, &e)))?;
        if p.gsd.ident_number != ident {
            tracing::warn!(
                "{} has ident 0x{:04X}, the slave 0x{ident:04X}",
                f.display(),
                p.gsd.ident_number
            );
        }
        return Ok(Some((f.display().to_string(), p.gsd)));
    }
    let lib = crate::scan::library(&a.gsd_dir)?;
    Ok(lib
        .find(ident)
        .first()
        .map(|e| (e.source.to_string(), e.gsd.clone())))
}

fn owner(d: &SlaveDiag<'_>) -> Option<u8> {
    (d.master_address != NO_MASTER).then_some(d.master_address)
}

pub fn diag(a: DiagArgs) -> Result<()> {
    let n = a.slave.slave;
    let du = a
        .station
        .data(n, &[ServiceRequest::SlaveDiag(n)])?
        .remove(0);
    let d = SlaveDiag::parse(&du).with_context(|| format!("slave {n}"))?;
    let gsd = find_gsd(&a.slave, d.ident_number)?;
    let dpv1 = gsd.as_ref().is_some_and(|(_, g)| g.dpv1_slave);
    let lines = diag::describe(&du, gsd.as_ref().map(|(_, g)| g), dpv1);
    if a.station.json {
        let v = json!({
            "address": n,
            "ident": format!("0x{:04X}", d.ident_number),
            "owner": owner(&d),
            "status": d.status_words(),
            "diag": Hex(&du).to_string(),
            "gsd": gsd.as_ref().map(|(f, _)| f),
            "lines": lines,
        });
        crate::out::outln!("{}", common::json_line(&v))?;
    } else {
        crate::out::outln!("slave {n}: Slave_Diag {}", Hex(&du))?;
        for l in lines {
            crate::out::outln!("  {l}")?;
        }
    }
    Ok(())
}

pub fn get_cfg(a: GetCfgArgs) -> Result<()> {
    let n = a.slave.slave;
    let mut got = a.station.data(
        n,
        &[ServiceRequest::SlaveDiag(n), ServiceRequest::GetCfg(n)],
    )?;
    let bytes = got.remove(1);
    let du = got.remove(0);
    let d = SlaveDiag::parse(&du).with_context(|| format!("slave {n}"))?;
    let ids: Vec<String> = cfg::identifiers(&bytes)
        .map(|id| match id {
            Ok(id) => format!("{}: {id}", Hex(id.raw)),
            Err(e) => e.to_string(),
        })
        .collect();
    let gsd = find_gsd(&a.slave, d.ident_number)?;
    let (mut modules, mut others, mut nearest) = (None, vec![], None);
    if let Some((_, g)) = &gsd {
        match modules_for_cfg(g, &bytes) {
            CfgMatch::Found { best, others: o } => {
                let names = |f: &profibus_dp::config::discover::Fit| {
                    f.names(g)
                        .into_iter()
                        .map(|s| s.trim().to_string())
                        .collect::<Vec<_>>()
                };
                modules = Some(names(&best));
                others = o.iter().map(names).collect();
            }
            CfgMatch::NoFit(near) => nearest = Some(near.describe(g)),
        }
    }
    if a.station.json {
        let v = json!({
            "address": n,
            "ident": format!("0x{:04X}", d.ident_number),
            "owner": owner(&d),
            "cfg": Hex(&bytes).to_string(),
            "identifiers": ids,
            "gsd": gsd.as_ref().map(|(f, _)| f),
            "modules": modules,
            "others": others,
            "nearest": nearest,
        });
        crate::out::outln!("{}", common::json_line(&v))?;
        return Ok(());
    }
    crate::out::outln!(
        "slave {n} (ident 0x{:04X}): Get_Cfg {}",
        d.ident_number,
        Hex(&bytes)
    )?;
    for id in &ids {
        crate::out::outln!("  {id}")?;
    }
    match (&gsd, modules) {
        (None, _) => crate::out::outln!(
            "no GSD for ident 0x{:04X}: give --gsd or --gsd-dir",
            d.ident_number
        )?,
        (Some((f, _)), Some(m)) => {
            let list: Vec<String> = m.iter().map(|x| format!("\"{x}\"")).collect();
            crate::out::outln!("modules of {f}: {}", list.join(", "))?;
            for o in others {
                let list: Vec<String> = o.iter().map(|x| format!("\"{x}\"")).collect();
                crate::out::outln!("  also fits: {}", list.join(", "))?;
            }
        }
        (Some((f, _)), None) => crate::out::outln!(
            "no module combination of {f} gives these bytes: {}",
            nearest.unwrap_or_default()
        )?,
    }
    Ok(())
}

pub fn set_address(a: SetAddressArgs) -> Result<()> {
    run_async(async move {
        let (n, m) = (a.slave, a.new);
        let answers = exchange(&a.station, vec![ServiceRequest::SlaveDiag(n)]).await?;
        let du = data(&answers[0], n, "Slave_Diag")?;
        let d = SlaveDiag::parse(&du).with_context(|| format!("slave {n}"))?;
        let req = ServiceRequest::SetSlaveAdd {
            slave: n,
            new_address: m,
            ident_number: d.ident_number,
            no_add_chg: a.no_further_change,
        };
        let answers = exchange(&a.station, vec![req, ServiceRequest::SlaveDiag(m)]).await?;
        match &answers[0] {
            ServiceAnswer::Ack => {}
            ServiceAnswer::Refused(st) => bail!(
                "slave {n} refused Set_Slave_Add ({}): a slave takes a new address only in \
                 Wait_Prm (no master has parameterised it), with its own ident number \
                 0x{:04X}, where its GSD has Set_Slave_Add_supp and no earlier \
                 --no-further-change forbids it",
                st.mnemonic(),
                d.ident_number
            ),
            other => bail!("slave {n}: Set_Slave_Add: {other}"),
        }
        let confirmed = matches!(&answers[1], ServiceAnswer::Data(x)
            if SlaveDiag::parse(x).is_ok_and(|x| x.ident_number == d.ident_number));
        if a.station.json {
            let v = json!({
                "address": n,
                "new": m,
                "ident": format!("0x{:04X}", d.ident_number),
                "no_further_change": a.no_further_change,
                "confirmed": confirmed,
            });
            crate::out::outln!("{}", common::json_line(&v))?;
        } else if confirmed {
            crate::out::outln!(
                "slave {n} (ident 0x{:04X}) now answers at address {m}",
                d.ident_number
            )?;
        } else {
            crate::out::outln!(
                "slave {n} (ident 0x{:04X}) took address {m}, but gave no diagnosis there yet",
                d.ident_number
            )?;
        }
        Ok(())
    })
}

pub fn read_io(a: ReadIoArgs) -> Result<()> {
    run_async(async move {
        let n = a.slave;
        let answers = exchange(
            &a.station,
            vec![ServiceRequest::RdInp(n), ServiceRequest::RdOutp(n)],
        )
        .await?;
        let why = |x: &ServiceAnswer, service: &str| match x {
            ServiceAnswer::Refused(ResponseStatus::Rs) => anyhow::anyhow!(
                "slave {n}: {service} refused (RS): a slave answers it in Data_Exchange only"
            ),
            other => data(other, n, service)
                .err()
                .unwrap_or_else(|| anyhow::anyhow!("?")),
        };
        let (ServiceAnswer::Data(i), ServiceAnswer::Data(o)) = (&answers[0], &answers[1]) else {
            let bad = if matches!(answers[0], ServiceAnswer::Data(_)) {
                why(&answers[1], "Rd_Outp")
            } else {
                why(&answers[0], "Rd_Inp")
            };
            return Err(bad);
        };
        if a.station.json {
            let v = json!({
                "address": n,
                "inputs": Hex(i).to_string(),
                "outputs": Hex(o).to_string(),
            });
            crate::out::outln!("{}", common::json_line(&v))?;
        } else {
            crate::out::outln!("slave {n}: inputs {}", Hex(i))?;
            crate::out::outln!("slave {n}: outputs {}", Hex(o))?;
        }
        Ok(())
    })
}

pub fn global_control(a: GlobalControlArgs) -> Result<()> {
    run_async(async move {
        let command = match a.command {
            Control::Clear => ControlCommand::CLEAR_DATA,
            Control::Operate => ControlCommand::empty(),
            Control::Sync => ControlCommand::SYNC,
            Control::Unsync => ControlCommand::UNSYNC,
            Control::Freeze => ControlCommand::FREEZE,
            Control::Unfreeze => ControlCommand::UNFREEZE,
        };
        let gc = GlobalControl {
            command,
            group_select: a.group,
        };
        let answers = exchange(&a.station, vec![ServiceRequest::GlobalControl(gc)]).await?;
        if answers[0] != ServiceAnswer::Sent {
            bail!("Global_Control: {}", answers[0]);
        }
        let groups = match a.group {
            0 => "every slave".to_string(),
            g => format!("group select 0x{g:02X}"),
        };
        let name = format!("{:?}", a.command).to_lowercase();
        if a.station.json {
            let v = json!({
                "command": name,
                "group": a.group,
                "bytes": Hex(&gc.to_bytes()).to_string(),
            });
            crate::out::outln!("{}", common::json_line(&v))?;
        } else {
            crate::out::outln!(
                "Global_Control {name} ({}) sent to {groups}; slaves obey it only from the master that parameterised them",
                Hex(&gc.to_bytes())
            )?;
        }
        Ok(())
    })
}
