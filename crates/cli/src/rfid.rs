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
use crate::via::{Printed, Via};
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

/// Reader commands as the control socket of `dpctl master --control`
/// takes them (`dpctl rfid --via`): `{"rfid": 12, "commands": ["VER",
/// "RD 0 3"]}` (or one `"command"`), with `timeout_ms` and
/// `startup_timeout_ms`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RfidRequest {
    /// The reader.
    pub rfid: u8,
    /// The commands, in order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub commands: Vec<String>,
    /// One command.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command: Option<String>,
    /// Milliseconds to wait for the whole answer of each command
    /// (default 5000).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeout_ms: Option<u64>,
    /// Milliseconds the reader may take to reach Data_Exchange (default
    /// 10000).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub startup_timeout_ms: Option<u64>,
}

/// Reader commands that only read: VER, GT, RD (the rest, WD and
/// anything unknown, count as writes).
const READING: [&str; 3] = ["VER", "GT", "RD"];

impl RfidRequest {
    /// All commands, in order.
    pub fn all(&self) -> Vec<String> {
        self.command.iter().chain(&self.commands).cloned().collect()
    }

    /// Whether a command may change the tag or the reader.
    pub fn writes(&self) -> bool {
        self.all().iter().any(|c| {
            let word = c.split_whitespace().next().unwrap_or("");
            !READING.iter().any(|r| r.eq_ignore_ascii_case(word))
        })
    }

    /// The run on `slave` of a bus file.
    pub fn task(&self, slave: &profibus_dp::config::busfile::BusSlave) -> Result<CommandRun> {
        let all = self.all();
        if all.is_empty() {
            anyhow::bail!("`rfid` needs `commands` (e.g. [\"VER\"])");
        }
        let timeout = Duration::from_millis(self.timeout_ms.unwrap_or(5000));
        Ok(CommandRun::new(slave, &all, timeout)?)
    }

    /// How long the reader may take to reach Data_Exchange.
    pub fn wait(&self) -> profibus_dp::master::SlaveWait {
        profibus_dp::master::SlaveWait::new(
            self.rfid,
            Duration::from_millis(self.startup_timeout_ms.unwrap_or(10_000)),
        )
    }
}

/// What `dpctl rfid` prints for a run that ended.
pub fn printed(run: TaskRun<CommandRun>) -> Printed {
    let mut p = Printed {
        ok: true,
        ..Printed::default()
    };
    for r in run.task().results() {
        p.text.push_str(&r.to_string());
        p.json.push(crate::via::json_value(r));
    }
    let error = match run.finish() {
        Err(e) => Some(anyhow::Error::from(e)),
        Ok(t) => t.failure().map(anyhow::Error::from),
    };
    if let Some(e) = error {
        p.ok = false;
        p.error = Some(format!("{e:#}"));
    }
    p
}

pub fn run(args: Args) -> Result<()> {
    let request = RfidRequest {
        rfid: args.link.slave,
        commands: args.commands.clone(),
        command: None,
        timeout_ms: Some(args.timeout),
        startup_timeout_ms: Some(args.link.startup_timeout),
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
