//! `dpctl dpv1 read|write`: one DP-V1 class-1 data-record read or write.
//!
//! Runs the DP master of the bus file like `dpctl master`; once the slave
//! is in Data_Exchange, `profibus_dp::master::RecordTask` runs (request, then
//! polls until the slave answers or the slave's C1 response timeout of
//! the bus file passes). Exit 0 with the data (or one JSON line), 1 with
//! the slave's negative answer decoded in words, a timeout, or a slave
//! that does not reach Data_Exchange.

use crate::common;
use anyhow::{bail, Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::master::{RecordTask, TaskRun};

/// Read or write a DP-V1 data record (slot, index) of a slave.
#[derive(clap::Args)]
pub struct Args {
    /// The line, the bus file, the slave.
    #[command(flatten)]
    link: common::SlaveArgs,
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
}

pub fn run(args: Args) -> Result<()> {
    // Like every command taking --config: `device = …` slaves resolved
    // by the profile registry.
    let bus = ProfiledBus::load(&args.link.config)?.file;
    let addr = args.link.slave;
    if !args.link.slave_of(&bus)?.params.dpv1 {
        bail!("slave {addr} is not a DP-V1 slave in the bus file (its GSD has no DPV1_Slave=1)");
    }
    let (slot, index) = (args.slot, args.index);
    let task = match &args.op {
        Op::Read { length } => RecordTask::read(addr, slot, index, *length),
        Op::Write { data } => {
            let data = profibus_fdl::wire::parse_hex(&data.join(" "))?;
            RecordTask::write(addr, slot, index, data)?
        }
    };
    let mut run = TaskRun::new(task, args.link.wait());
    common::runtime()?.block_on(args.link.run_master(&bus, |m, now| run.tick(m, now)))?;
    let task = run.finish()?;
    let out = task.outcome().context("no result")?;
    args.link.print(if out.ok { Ok(out) } else { Err(out) })
}
