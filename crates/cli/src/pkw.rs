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

pub fn run(args: Args) -> Result<()> {
    let bus = profibus_devices::bus::ProfiledBus::load(&args.link.config)?.file;
    let slave = args.link.slave_of(&bus)?;
    let timeout = Duration::from_millis(args.timeout);
    let task = match &args.op {
        Op::List => {
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
            return Ok(());
        }
        Op::Read { param } => PkwTask::read(slave, param, timeout),
        Op::Describe { param, attr } => PkwTask::describe(slave, param, attr, timeout),
        Op::Write {
            assignment,
            word,
            dword,
        } => {
            let width = (*word || *dword).then_some(*dword);
            PkwTask::write(slave, assignment, width, timeout)
        }
    }?;
    let mut run = TaskRun::new(task, args.link.wait());
    common::runtime()?.block_on(args.link.run_master(&bus, |m, now| run.tick(m, now)))?;
    args.link
        .print(run.finish()?.outcome().context("no result")?)
}
