//! `dpctl dpv1 read|write|transport`: one DP-V1 data-record request.
//!
//! Class 1 (default): runs the DP master of the bus file like `dpctl
//! master`; once the slave is in Data_Exchange,
//! `profibus_dp::master::RecordTask` runs (request, then polls until the
//! slave answers or the slave's C1 response timeout of the bus file
//! passes).
//!
//! Class 2 (`--class2`): a master of its own at `--addr` joins the token
//! ring next to the running class-1 master and opens an MSAC_C2
//! connection (`profibus_dp::class2`): Initiate, the request, Abort. The
//! slave needs no parameterisation and stays with its class-1 master.
//!
//! Exit 0 with the data (or one JSON line), 1 with the slave's negative
//! answer decoded in words, a timeout, an abort in words, or a slave that
//! does not reach Data_Exchange (class 1).

use crate::common::{self, RtsArg};
use anyhow::{bail, Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::class2::{
    Class2Config, Class2Error, Opened, RecordAnswer, RecordOp, RecordOps, SingleOp,
};
use profibus_dp::config::busfile::BusFile;
use profibus_dp::master::records::C1Records;
use profibus_dp::master::{RecordOutcome, RecordTask, TaskRun};
use profibus_fdl::station::active::{ActiveConfig, RingState};
use profibus_fdl::{Baud, BusParams};
use std::path::PathBuf;
use std::time::Duration;

/// Read or write a DP-V1 data record (slot, index) of a slave.
#[derive(clap::Args)]
pub struct Args {
    /// The line, the slave, and which class of master asks.
    #[command(flatten)]
    link: Link,
    /// Slot of the record (0..=254).
    #[arg(long, global = true, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=254))]
    slot: u8,
    /// Index of the record (0..=254).
    #[arg(long, global = true, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=254))]
    index: u8,
    #[command(subcommand)]
    op: Op,
}

/// What to do.
#[derive(clap::Subcommand)]
enum Op {
    /// Read up to LENGTH bytes (1..=240) of the record.
    Read {
        /// Bytes wanted.
        #[arg(long, default_value_t = 240, value_parser = clap::value_parser!(u8).range(1..=240))]
        length: u8,
    },
    /// Write the bytes (hex, e.g. `0A 0B` or `0a0b`) to the record.
    Write {
        /// Data, hex.
        #[arg(value_name = "HEX", required = true)]
        data: Vec<String>,
    },
    /// Data_Transport (class 2 only): send the bytes (hex), print the
    /// bytes the slave returns.
    Transport {
        /// Data, hex.
        #[arg(value_name = "HEX", required = true)]
        data: Vec<String>,
    },
}

/// The line, the slave, and the master that asks: the bus file's
/// class-1 master (MSAC_C1), or with `--class2` a class-2 master of its
/// own (MSAC_C2). Shared by `dpctl dpv1` and `dpctl im`.
#[derive(clap::Args, Debug, Clone)]
pub struct Link {
    /// Serial device or pty path, or tcp://HOST:PORT (serial device server).
    #[arg(long, value_name = "PATH", required_unless_present = "via")]
    pub port: Option<String>,
    /// Run the requests as MSAC_C1 jobs of the running `dpctl master` or
    /// `dpctl gateway` whose control socket (`--control PATH`) this is,
    /// instead of opening the port: its slaves stay in Data_Exchange.
    #[arg(long, value_name = "PATH", conflicts_with_all = ["port", "config", "latency"])]
    pub via: Option<PathBuf>,
    /// Bus file (TOML) with the slave. Class 1: needed (its master runs).
    /// Class 2: optional; gives the baud rate, the bus parameters and the
    /// slave's C2_Response_Timeout.
    #[arg(long, value_name = "BUS.toml")]
    pub config: Option<PathBuf>,
    /// Station address of the slave.
    #[arg(long, value_name = "ADDR")]
    pub slave: u8,
    /// Ask as a class-2 master (MSAC_C2 connection) of its own, next to
    /// the master that holds the slave, instead of running the bus
    /// file's class-1 master (MSAC_C1).
    #[arg(long)]
    pub class2: bool,
    /// Class 2: this master's station address [default: 1].
    #[arg(long, value_name = "ADDR", requires = "class2", value_parser = clap::value_parser!(u8).range(0..=125))]
    pub addr: Option<u8>,
    /// Class 2: the bus's baud rate (9600 … 12000000, 1.5M, 187.5k, …)
    /// [default: the bus file's, else 19200].
    #[arg(long, value_name = "B", requires = "class2")]
    pub baud: Option<Baud>,
    /// Class 2: Send_Timeout of the connection in ms: the slave aborts it
    /// when nothing comes for this long; Idle keeps it open at half of it
    /// [default: 2000 at 1.5 Mbit/s and above, 4000 at 500k, 8000 below].
    #[arg(long, value_name = "MS", requires = "class2", value_parser = clap::value_parser!(u64).range(10..=655_350))]
    pub send_timeout: Option<u64>,
    /// Class 2: ms the connection set-up and each answer may take
    /// [default: the GSD's C2_Response_Timeout, else 10000].
    #[arg(long, value_name = "MS", requires = "class2")]
    pub response_timeout: Option<u64>,
    /// Class 1: milliseconds to wait for the slave to reach Data_Exchange.
    #[arg(long, value_name = "MS", default_value_t = 10000)]
    pub startup_timeout: u64,
    /// Extra milliseconds on the slot time for the transport's latency
    /// (default: 5 on a pty, 20 on a serial adapter).
    #[arg(long, value_name = "MS")]
    pub latency: Option<f64>,
    #[command(flatten)]
    pub rts: RtsArg,
    /// Print JSON: one object.
    #[arg(long, global = true)]
    pub json: bool,
}

/// How a class-2 run ended: the requests with their answers and the
/// slave's Initiate.res, or why the connection failed (with the answers
/// before it).
pub type Class2Outcome<O> = std::result::Result<(O, Option<Opened>), (Class2Error, O)>;

/// The class-1 path's arguments and its bus file.
fn class1(link: &Link) -> Result<(common::SlaveArgs, BusFile)> {
    let Some(config) = link.config.clone() else {
        bail!("--config BUS.toml is needed without --class2: the bus file's class-1 master runs");
    };
    let args = common::SlaveArgs {
        port: link.port.clone(),
        via: None,
        config: Some(config),
        slave: link.slave,
        startup_timeout: link.startup_timeout,
        latency: link.latency,
        rts: link.rts,
        json: link.json,
    };
    // Like every command taking --config: `device = …` slaves resolved
    // by the profile registry.
    let bus = ProfiledBus::load(args.config()?)?.file;
    if !args.slave_of(&bus)?.params.dpv1 {
        bail!(
            "slave {} is not a DP-V1 slave in the bus file (its GSD has no DPV1_Slave=1)",
            args.slave
        );
    }
    Ok((args, bus))
}

impl Link {
    /// Print a success (text or JSON); a failure is printed as JSON
    /// with `--json` and is the error.
    pub fn print<T, E>(&self, outcome: std::result::Result<T, E>) -> Result<()>
    where
        T: serde::Serialize + std::fmt::Display,
        E: serde::Serialize + std::fmt::Display,
    {
        common::SlaveArgs {
            port: None,
            via: None,
            config: None,
            slave: self.slave,
            startup_timeout: 0,
            latency: None,
            rts: self.rts,
            json: self.json,
        }
        .print(outcome)
    }

    /// Run `ops` as MSAC_C1 jobs of the bus file's master (with `--via`,
    /// of the master behind the control socket).
    pub fn run_class1<O: RecordOps>(&self, ops: O) -> Result<O> {
        if let Some(via) = &self.via {
            return match crate::via::Via::connect(via)?.records(self.slave, ops)? {
                Ok(ops) => Ok(ops),
                Err((f, _)) => Err(crate::via::record_failure(self.slave, &f)),
            };
        }
        let (args, bus) = class1(self)?;
        let mut run = TaskRun::new(C1Records::new(self.slave, ops), args.wait());
        common::runtime()?.block_on(args.run_master(&bus, |m, now| run.tick(m, now)))?;
        Ok(run.finish()?.into_ops())
    }

    /// Run `ops` on a class-2 connection of a master of its own. The
    /// outer error: the set-up; the inner one: the connection failed
    /// (with the answers before it).
    pub fn run_class2<O: RecordOps>(&self, ops: O) -> Result<Class2Outcome<O>> {
        let bus = match &self.config {
            Some(path) => Some(ProfiledBus::load(path)?.file),
            None => None,
        };
        let addr = self.addr.unwrap_or(1);
        if addr == self.slave {
            bail!("--addr {addr} is the slave's address: the class-2 master needs its own");
        }
        if let Some(b) = bus.as_ref().filter(|b| b.master.address == addr) {
            bail!(
                "--addr {addr} is the address of the bus file's master in {}: \
                 the class-2 master needs its own (e.g. --addr {})",
                b.path.display(),
                (0..=125u8)
                    .find(|a| *a != addr && *a != self.slave)
                    .unwrap_or(0)
            );
        }
        let params = match (self.baud, &bus) {
            (Some(b), _) => BusParams::defaults(b),
            (None, Some(bus)) => bus.master.params,
            (None, None) => BusParams::defaults(Baud::B19200),
        };
        let mut cfg = Class2Config::for_baud(params.baud);
        if let Some(ms) = self.send_timeout {
            cfg.send_timeout = Duration::from_millis(ms);
        }
        let gsd_timeout = bus
            .as_ref()
            .and_then(|b| b.slaves.iter().find(|s| s.params.address == self.slave))
            .and_then(|s| s.gsd.c2_response_timeout)
            .map(|t| Duration::from_millis(10 * t.max(1) as u64));
        cfg.response_timeout = self
            .response_timeout
            .map(Duration::from_millis)
            .or(gsd_timeout)
            .unwrap_or(cfg.response_timeout);
        let path = self.port.as_deref().context("--port PATH is needed")?;
        let rt = common::runtime()?;
        let done = rt.block_on(async {
            let mut port = self.rts.open(path, params.baud)?;
            let mut acfg = ActiveConfig::new(addr, params);
            common::allow_for_port(&mut acfg, self.latency, &port)?;
            let done =
                profibus_io::class2::run(&mut port, acfg, cfg, self.slave, ops, common::shutdown())
                    .await
                    .with_context(|| format!("on {path}"))?;
            anyhow::Ok(done)
        })?;
        if done.stop == profibus_io::driver::Stop::Shutdown {
            bail!("interrupted");
        }
        let run = done.run;
        let opened = run.opened().copied();
        Ok(match run.finish() {
            Ok(ops) => Ok((ops, opened)),
            Err((e, ops)) => {
                let e = match e {
                    Class2Error::Timeout { op: "initiate", .. }
                        if done.ring == RingState::ListenToken =>
                    {
                        tracing::warn!(%e, "no token");
                        return Err(anyhow::anyhow!(
                            "{e}: master {addr} was not taken into the token ring \
                             (check --baud and that the ring has room for address {addr})"
                        ));
                    }
                    e => e,
                };
                Err((e, ops))
            }
        })
    }
}

pub fn run(args: Args) -> Result<()> {
    let (slot, index) = (args.slot, args.index);
    let hex = |data: &[String]| profibus_fdl::wire::parse_hex(&data.join(" "));
    let op = match &args.op {
        Op::Read { length } => RecordOp::Read {
            slot,
            index,
            length: *length,
        },
        Op::Write { data } => RecordOp::Write {
            slot,
            index,
            data: hex(data)?,
        },
        Op::Transport { data } => RecordOp::Transport {
            slot,
            index,
            data: hex(data)?,
        },
    };
    op.check()?;
    let link = &args.link;
    if let Some(via) = &link.via {
        if link.class2 {
            return Err(crate::via::no_class2(via));
        }
        return run_via(link, via, op);
    }
    if !link.class2 {
        return run_class1(link, op);
    }
    match link.run_class2(SingleOp::new(op.clone()))? {
        Ok((single, _)) => {
            let o = outcome(link.slave, &op, single.answer.as_ref(), None);
            link.print(if o.ok { Ok(o.clone()) } else { Err(o) })
        }
        Err((e, _)) => link.print(Err::<RecordOutcome, _>(outcome(
            link.slave,
            &op,
            None,
            Some(without_slave(link.slave, &e.to_string())),
        ))),
    }
}

/// `e` with its leading "slave N" as "the slave" (the outcome line names
/// the slave already), "slave N: " dropped.
fn without_slave(slave: u8, e: &str) -> String {
    let prefix = format!("slave {slave}");
    match e.strip_prefix(&prefix) {
        Some(rest) if rest.starts_with(':') => rest[1..].trim_start().to_string(),
        Some(rest) => format!("the slave{rest}"),
        None => e.to_string(),
    }
}

/// A class-2 request's outcome as the class-1 path prints it.
fn outcome<'a>(
    slave: u8,
    op: &RecordOp,
    answer: Option<&'a RecordAnswer>,
    error: Option<String>,
) -> RecordOutcome<'a> {
    let (slot, index) = op.record();
    let mut o = RecordOutcome {
        slave,
        op: op.name(),
        slot,
        index,
        ok: false,
        length: None,
        data: None,
        error,
        error_decode: None,
        error_code_1: None,
        error_code_2: None,
    };
    match answer {
        Some(RecordAnswer::Read(d) | RecordAnswer::Transport(d)) => {
            (o.ok, o.length, o.data) = (true, Some(d.len()), Some(d));
        }
        Some(RecordAnswer::Written(_)) => o.ok = true,
        Some(RecordAnswer::Negative(e)) => {
            o.error_decode = Some(e.error_decode);
            o.error_code_1 = Some(format!("0x{:02X}", e.error_code_1));
            o.error_code_2 = Some(e.error_code_2);
            o.error = Some(e.describe());
        }
        None => {}
    }
    o
}

/// The class-1 path through a running master's control socket: its
/// MSAC_C1 job, printed as [`run_class1`] prints it.
fn run_via(link: &Link, via: &std::path::Path, op: RecordOp) -> Result<()> {
    if let RecordOp::Transport { .. } = op {
        bail!("Data_Transport is a class-2 service (MSAC_C2): add --class2 (without --via)")
    }
    if let RecordOp::Write { data, .. } = &op {
        if data.is_empty() || data.len() > 240 {
            return Err(profibus_dp::master::RecordError::Length(data.len()).into());
        }
    }
    let single = SingleOp::new(op.clone());
    match crate::via::Via::connect(via)?.records(link.slave, single)? {
        Ok(single) => {
            let o = outcome(link.slave, &op, single.answer.as_ref(), None);
            link.print(if o.ok { Ok(o.clone()) } else { Err(o) })
        }
        Err((f, _)) => link.print(Err::<RecordOutcome, _>(outcome(
            link.slave,
            &op,
            None,
            Some(f.why),
        ))),
    }
}

/// The class-1 path as `dpctl dpv1` always ran it.
fn run_class1(link: &Link, op: RecordOp) -> Result<()> {
    let (args, bus) = class1(link)?;
    let task = match op {
        RecordOp::Read {
            slot,
            index,
            length,
        } => RecordTask::read(link.slave, slot, index, length),
        RecordOp::Write { slot, index, data } => RecordTask::write(link.slave, slot, index, data)?,
        RecordOp::Transport { .. } => {
            bail!("Data_Transport is a class-2 service (MSAC_C2): add --class2")
        }
    };
    let mut run = TaskRun::new(task, args.wait());
    common::runtime()?.block_on(args.run_master(&bus, |m, now| run.tick(m, now)))?;
    let task = run.finish()?;
    let out = task.outcome().context("no result")?;
    args.print(if out.ok { Ok(out) } else { Err(out) })
}
