//! `dpctl pkw`: read or write one parameter of a slave through its PKW
//! channel (BM4-O-PRO-01, Omega Drive-Line II).
//!
//! Runs the DP master of the bus file like `dpctl master`; once the slave
//! is in Data_Exchange, `profibus_devices::pkw_task::PkwTask`
//! runs the handshake over its cyclic data. Exit 0 with the result in
//! words (or one JSON line), 1 with the decoded error on a PKW error, a
//! timeout, or a slave that does not reach Data_Exchange.

use crate::common;
use crate::out::outln;
use crate::via::{Printed, Via};
use anyhow::{Context, Result};
use profibus_devices::pkw_task::PkwTask;
use profibus_dp::master::TaskRun;
use std::time::Duration;

/// Read or write a parameter over the PKW channel of a slave.
///
/// P is a parameter number (218, P218, 0x7E) or a name: for a
/// BM4-O-PRO-01 a variable module of its GSD (di_MyReadVar3), for an
/// Omega Drive-Line II a parameter of the V-controller table
/// (L_rev_actual_value; `_` or `-` for spaces). `P[i]` is array element
/// i (BM4); on the Omega, which has no array commands, P1000[i] is
/// parameter 1000+i of its DINT array. `list` shows the names (no bus
/// traffic).
#[derive(clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The line, the bus file, the slave.
    #[command(flatten)]
    link: common::SlaveArgs,
    /// Milliseconds to wait for the PKW response.
    #[arg(long, global = true, value_name = "MS", default_value_t = 2000)]
    timeout: u64,
    #[command(subcommand)]
    op: Op,
}

/// What to do.
#[derive(clap::Subcommand)]
enum Op {
    /// Read parameter P (or array element P[i]).
    Read {
        /// Parameter.
        #[arg(value_name = "P")]
        param: String,
    },
    /// Write V to parameter P: `P=V` (V decimal, 0x hex or negative).
    /// Word or double word as the parameter is (read first), unless
    /// --word or --dword says.
    Write {
        /// `P=V`.
        #[arg(value_name = "P=V")]
        assignment: String,
        /// Use the word write command.
        #[arg(long, conflicts_with = "dword")]
        word: bool,
        /// Use the double word write command.
        #[arg(long)]
        dword: bool,
    },
    /// List the parameters the slave's device names (no bus traffic).
    List,
    /// Read an element of the parameter description (Omega: PBE).
    Describe {
        /// Parameter.
        #[arg(value_name = "P")]
        param: String,
        /// attribute, info, min or max.
        #[arg(value_name = "ATTR")]
        attr: String,
    },
}

/// A PKW job as the control socket of `dpctl master --control` takes it
/// (`dpctl pkw --via`): `{"pkw": 25, "read": "P218"}`, `{"pkw": 25,
/// "write": "P218=5", "width": "word"}`, `{"pkw": 25, "describe": "P218",
/// "attr": "min"}`, with `timeout_ms` and `startup_timeout_ms`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PkwRequest {
    /// The slave.
    pub pkw: u8,
    /// Read this parameter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub read: Option<String>,
    /// Write `P=V`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub write: Option<String>,
    /// `word` or `dword` (write; default: as the parameter is).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<String>,
    /// Read an element of this parameter's description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub describe: Option<String>,
    /// The element (`attribute`, `info`, `min`, `max`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attr: Option<String>,
    /// Milliseconds to wait for the PKW response (default 2000).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeout_ms: Option<u64>,
    /// Milliseconds the slave may take to reach Data_Exchange (default
    /// 10000).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub startup_timeout_ms: Option<u64>,
}

impl PkwRequest {
    /// Whether it changes the slave (a write).
    pub fn writes(&self) -> bool {
        self.write.is_some()
    }

    /// The task on `slave` of a bus file.
    pub fn task(&self, slave: &profibus_dp::config::busfile::BusSlave) -> Result<PkwTask> {
        let timeout = Duration::from_millis(self.timeout_ms.unwrap_or(2000));
        Ok(match (&self.read, &self.write, &self.describe) {
            (Some(p), None, None) => PkwTask::read(slave, p, timeout)?,
            (None, Some(a), None) => {
                let width = match self.width.as_deref() {
                    None => None,
                    Some("word") => Some(false),
                    Some("dword") => Some(true),
                    Some(w) => anyhow::bail!("`width` is word or dword, not {w:?}"),
                };
                PkwTask::write(slave, a, width, timeout)?
            }
            (None, None, Some(p)) => {
                let attr = self.attr.as_deref().context("`describe` needs `attr`")?;
                PkwTask::describe(slave, p, attr, timeout)?
            }
            _ => anyhow::bail!("`pkw` takes one of read, write, describe"),
        })
    }

    /// How long the slave may take to reach Data_Exchange.
    pub fn wait(&self) -> profibus_dp::master::SlaveWait {
        profibus_dp::master::SlaveWait::new(
            self.pkw,
            Duration::from_millis(self.startup_timeout_ms.unwrap_or(10_000)),
        )
    }
}

/// What `dpctl pkw` prints for a run that ended.
pub fn printed(run: TaskRun<PkwTask>) -> Printed {
    match run.finish() {
        Err(e) => Printed::failed(&e.into()),
        Ok(task) => match task.outcome() {
            Some(o) => Printed::outcome(o),
            None => Printed::failed(&anyhow::anyhow!("no result")),
        },
    }
}

pub fn run(args: Args) -> Result<()> {
    let request = |read, write, describe, attr, width| PkwRequest {
        pkw: args.link.slave,
        read,
        write,
        width,
        describe,
        attr,
        timeout_ms: Some(args.timeout),
        startup_timeout_ms: Some(args.link.startup_timeout),
    };
    let request = match &args.op {
        Op::List => return list(&args),
        Op::Read { param } => request(Some(param.clone()), None, None, None, None),
        Op::Describe { param, attr } => {
            request(None, None, Some(param.clone()), Some(attr.clone()), None)
        }
        Op::Write {
            assignment,
            word,
            dword,
        } => {
            let width = (*word || *dword).then(|| if *dword { "dword" } else { "word" }.into());
            request(None, Some(assignment.clone()), None, None, width)
        }
    };
    if let Some(via) = &args.link.via {
        let printed = Via::connect(via)?.printed(&crate::via::json_value(&request))?;
        return printed.emit(args.link.json);
    }
    let bus = profibus_devices::bus::ProfiledBus::load(args.link.config()?)?.file;
    let slave = args.link.slave_of(&bus)?;
    let task = request.task(slave)?;
    let mut run = TaskRun::new(task, args.link.wait());
    common::runtime()?.block_on(args.link.run_master(&bus, |m, now| run.tick(m, now)))?;
    printed(run).emit(args.link.json)
}

/// `dpctl pkw list`: the parameters the slave's device names.
fn list(args: &Args) -> Result<()> {
    let Some(config) = &args.link.config else {
        anyhow::bail!("pkw list reads the bus file: give --config BUS.toml (no bus traffic)");
    };
    let bus = profibus_devices::bus::ProfiledBus::load(config)?.file;
    let slave = args.link.slave_of(&bus)?;
    let list = profibus_devices::pkw_parameters(slave.params.ident_number, &slave.gsd);
    if list.is_empty() {
        anyhow::bail!(
            "slave {}: its device names no PKW parameters (give numbers)",
            slave.params.address
        );
    }
    for p in list {
        if args.link.json {
            outln!("{}", common::json_line(&p))?;
        } else {
            outln!("P{:<4} {:<40} {}", p.pnu, p.name, p.details)?;
        }
    }
    Ok(())
}
