//! `dpctl rfid`: run commands on an AEG ID RFID reader (ARE I2 / K1 PFB)
//! over its 16-byte handshake.
//!
//! Runs the DP master of the bus file like `dpctl master`; once the reader
//! is in Data_Exchange, `profibus_devices::rfid::jobs::CommandRun`
//! sends each command and fetches the whole answer. Prints each command
//! (`> VER`) and then its answer's lines, an error answer `NAK #nn` in
//! words (or one JSON object per command with `--json`, `"nak"` the
//! error's number). Exit 0 when every command was answered; 1 on an
//! error answer (the commands after it are not sent), a timeout or a
//! reader that does not reach Data_Exchange.

use crate::common;
use anyhow::Result;
use profibus_devices::rfid::jobs::CommandRun;
use profibus_dp::master::TaskRun;
use std::time::Duration;

/// Run reader commands on an RFID reader and print the answers (see the
/// subcommand's help: only VER is from the manual).
#[derive(clap::Args)]
pub struct Args {
    /// The line, the bus file, the slave.
    #[command(flatten)]
    link: common::SlaveArgs,
    /// Milliseconds to wait for the whole answer of each command.
    #[arg(long, value_name = "MS", default_value_t = 5000)]
    timeout: u64,
    /// The commands, in order (CR is appended), e.g. "VER" "RD 0 3": sent
    /// as given; VER from the manual, GT, RD b [e], WD b DATA, TOR [n]
    /// modelled.
    #[arg(value_name = "COMMAND", required = true)]
    commands: Vec<String>,
}

pub fn run(args: Args) -> Result<()> {
    let bus = profibus_devices::bus::ProfiledBus::load(&args.link.config)?.file;
    let slave = args.link.slave_of(&bus)?;
    let timeout = Duration::from_millis(args.timeout);
    let task = CommandRun::new(slave, &args.commands, timeout)?;
    let mut run = TaskRun::new(task, args.link.wait());
    common::runtime()?.block_on(args.link.run_master(&bus, |m, now| run.tick(m, now)))?;
    for r in run.task().results() {
        match args.link.json {
            true => crate::out::outln!("{}", common::json_line(r))?,
            false => crate::out::out!("{r}")?,
        }
    }
    match run.finish()?.failure() {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}
