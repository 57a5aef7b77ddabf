//! `dpctl dpv1 read|write`: one DP-V1 class-1 data-record read or write.
//!
//! Runs the DP master of the bus file like `dpctl master`; once the slave
//! is in Data_Exchange, the master's MSAC_C1 job runs (request, then
//! polls until the slave answers or the slave's C1 response timeout of
//! the bus file passes). Exit 0 with the data (or one JSON line), 1 with
//! the slave's negative answer decoded in words, a timeout, or a slave
//! that does not reach Data_Exchange.

use crate::common;
use crate::describe::hex;
use anyhow::{bail, Context, Result};
use profibus_dp::busfile::BusFile;
use profibus_dp::master::{Job, JobId, JobResult};
use std::ops::ControlFlow;

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
    /// Print one JSON object.
    #[arg(long, global = true)]
    json: bool,
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
    let bus = BusFile::load(&args.link.config)?;
    common::runtime()?.block_on(dpv1(args, bus))
}

async fn dpv1(args: Args, bus: BusFile) -> Result<()> {
    let addr = args.link.slave;
    let slave = args.link.slave_of(&bus)?;
    if !slave.params.dpv1 {
        bail!("slave {addr} is not a DP-V1 slave in the bus file (its GSD has no DPV1_Slave=1)");
    }
    let (op, job) = match &args.op {
        Op::Read { length } => (
            "read",
            Job::Dpv1Read {
                address: addr,
                slot: args.slot,
                index: args.index,
                length: *length,
            },
        ),
        Op::Write { data } => {
            let data = crate::decode::parse_hex(data)?;
            if data.is_empty() || data.len() > 240 {
                bail!("a record write carries 1..=240 bytes, not {}", data.len());
            }
            (
                "write",
                Job::Dpv1Write {
                    address: addr,
                    slot: args.slot,
                    index: args.index,
                    data,
                },
            )
        }
    };
    let mut wait = args.link.wait();
    let mut job = Some(job);
    let mut id: Option<JobId> = None;
    let mut result: Option<JobResult> = None;
    let mut failure: Option<anyhow::Error> = None;
    args.link
        .run_master(&bus, |m, now| {
            if let Some(i) = id {
                if let Some(r) = m.take_result(i) {
                    result = Some(r);
                    return ControlFlow::Break(());
                }
                return ControlFlow::Continue(());
            }
            match wait.check(m, now, false) {
                Ok(true) => {}
                Ok(false) => return ControlFlow::Continue(()),
                Err(e) => {
                    failure = Some(e.into());
                    return ControlFlow::Break(());
                }
            }
            if let Some(j) = job.take() {
                match m.submit(j) {
                    Some(i) => id = Some(i),
                    None => {
                        failure = Some(anyhow::anyhow!("job queue full"));
                        return ControlFlow::Break(());
                    }
                }
            }
            ControlFlow::Continue(())
        })
        .await?;
    if let Some(f) = failure {
        return Err(f);
    }
    let (slot, index) = (args.slot, args.index);
    let result = result.context("no result")?;
    let mut rec = Outcome {
        slave: addr,
        op,
        slot,
        index,
        ok: matches!(result, JobResult::Data(_) | JobResult::Done),
        length: None,
        data: None,
        error: None,
        error_decode: None,
        error_code_1: None,
        error_code_2: None,
    };
    let text = match &result {
        JobResult::Data(d) => {
            rec.length = Some(d.len());
            rec.data = Some(d);
            format!("{} bytes {}", d.len(), hex(d))
        }
        JobResult::Done => "written".to_string(),
        JobResult::Dpv1Error(e) => {
            rec.error_decode = Some(e.error_decode);
            rec.error_code_1 = Some(format!("0x{:02X}", e.error_code_1));
            rec.error_code_2 = Some(e.error_code_2);
            e.describe()
        }
        other => other.describe(),
    };
    if !rec.ok {
        rec.error = Some(text.clone());
    }
    if args.json {
        println!("{}", common::json_line(&rec));
    } else if rec.ok {
        println!("slave {addr} slot {slot} index {index}: {text}");
    }
    if !rec.ok {
        bail!("slave {addr} slot {slot} index {index}: {text}");
    }
    Ok(())
}

/// The `--json` line.
#[derive(serde::Serialize)]
struct Outcome<'a> {
    slave: u8,
    op: &'static str,
    slot: u8,
    index: u8,
    ok: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    length: Option<usize>,
    #[serde(
        skip_serializing_if = "Option::is_none",
        serialize_with = "profibus_fdl::ser::opt_hex"
    )]
    data: Option<&'a Vec<u8>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error_decode: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error_code_1: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error_code_2: Option<u8>,
}
