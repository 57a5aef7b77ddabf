//! `dpctl rfid`: run commands on an AEG ID RFID reader (ARE I2 / K1 PFB)
//! over its 16-byte handshake.
//!
//! Runs the DP master of the bus file like `dpctl master`; once the reader
//! is in Data_Exchange, the client (`profibus_devices::rfid::client`)
//! sends each command and fetches the whole answer. Prints each answer
//! (its lines; or one JSON object per command with `--json`). Exit 0 when
//! every command was answered, 1 on a timeout or a reader that does not
//! reach Data_Exchange.

use crate::common;
use crate::view::Line;
use anyhow::{bail, Context, Result};
use profibus_devices::rfid::client::RfidClient;
use profibus_devices::rfid::{CFG, IDENT};
use profibus_dp::busfile::BusFile;
use profibus_dp::master::{DpMaster, SlaveState};
use profibus_fdl::Instant;
use std::ops::ControlFlow;
use std::time::Duration;

/// Run reader commands (VER, GT, RD b [e], WD b DATA, TOR [n]) on an RFID
/// reader and print the answers.
#[derive(clap::Args)]
pub struct Args {
    /// The line, the bus file, the slave.
    #[command(flatten)]
    link: common::SlaveArgs,
    /// Milliseconds to wait for the whole answer of each command.
    #[arg(long, value_name = "MS", default_value_t = 5000)]
    timeout: u64,
    /// Print one JSON object per command.
    #[arg(long)]
    json: bool,
    /// The commands, in order (CR is appended), e.g. "VER" "RD 0 3".
    #[arg(value_name = "COMMAND", required = true)]
    commands: Vec<String>,
}

/// One command's outcome.
struct Done {
    command: String,
    answer: Result<Vec<u8>, String>,
    took: Duration,
    drained: usize,
    /// Start-ups of the reader while the command ran (it was sent again).
    restarts: u64,
}

pub fn run(args: Args) -> Result<()> {
    let bus = profibus_devices::bus::ProfiledBus::load(&args.link.config)?.file;
    common::runtime()?.block_on(rfid(args, bus))
}

async fn rfid(args: Args, bus: BusFile) -> Result<()> {
    let addr = args.link.slave;
    let slave = args.link.slave_of(&bus)?;
    if slave.params.cfg != CFG {
        bail!(
            "slave {addr} is configured {:02X?}; the reader has 16 bytes in and out (0x3F, gsd/AEGI0DC4.GSD)",
            slave.params.cfg
        );
    }
    if slave.params.ident_number != IDENT {
        tracing::warn!(
            ident = slave.params.ident_number,
            "slave {addr} is not ident 0x{IDENT:04X}; trying the reader's handshake anyway"
        );
    }
    let mut client = RfidClient::new(Duration::from_millis(args.timeout.max(1)));
    let mut wait = args.link.wait();
    let mut todo = args.commands.iter().rev().cloned().collect::<Vec<_>>();
    let mut done: Vec<Done> = vec![];
    let mut running: Option<(String, Instant, u64)> = None;
    let mut failure: Option<String> = None;
    args.link
        .run_master(&bus, |m, now| {
            let in_dx = match wait.check(m, now, !client.is_idle()) {
                Ok(dx) => dx,
                Err(e) => {
                    failure = Some(e.to_string());
                    return ControlFlow::Break(());
                }
            };
            let Some(handle) = m.handle(addr) else {
                return ControlFlow::Break(());
            };
            if let Some(r) = client.poll_master(now, m, handle) {
                let (command, t, r0) = running.take().expect("a command runs");
                let restarts = m.slave_stats(addr).map_or(0, |s| s.restarts) - r0;
                done.push(Done {
                    command,
                    answer: r.map(<[u8]>::to_vec).map_err(|e| e.to_string()),
                    took: now.saturating_duration_since(t),
                    drained: client.drained(),
                    restarts,
                });
                if done.last().is_some_and(|d| d.answer.is_err()) {
                    return ControlFlow::Break(());
                }
            }
            if client.is_idle() && in_dx {
                let Some(cmd) = todo.pop() else {
                    return ControlFlow::Break(());
                };
                if let Err(e) = client.start(now, cmd.as_bytes()) {
                    failure = Some(format!("`{cmd}`: {e}"));
                    return ControlFlow::Break(());
                }
                running = Some((cmd, now, m.slave_stats(addr).map_or(0, |s| s.restarts)));
            }
            ControlFlow::Continue(())
        })
        .await?;
    for d in &done {
        print(&args, d);
    }
    if let Some(f) = failure {
        bail!("{f}");
    }
    if let Some(Done {
        command,
        answer: Err(e),
        ..
    }) = done.last()
    {
        bail!("slave {addr} `{command}`: {e}");
    }
    Ok(())
}

fn print(args: &Args, d: &Done) {
    let ms = d.took.as_secs_f64() * 1000.0;
    match &d.answer {
        Ok(a) if args.json => {
            let line = Answered {
                done: RfidDone::new(args.link.slave, d.command.clone(), Ok::<_, String>(a)),
                bytes: a.len(),
                ms: (ms * 1000.0).round() / 1000.0,
                drained: d.drained,
                restarts: d.restarts,
            };
            println!("{}", common::json_line(&line));
        }
        Ok(a) => {
            let text = String::from_utf8_lossy(a);
            for line in text.split_terminator('\r') {
                println!("{line}");
            }
        }
        Err(e) if args.json => {
            let done = RfidDone::new(args.link.slave, d.command.clone(), Err::<&[u8], _>(e));
            println!("{}", common::json_line(&done));
        }
        Err(_) => {}
    }
}

/// `dpctl rfid --json`: an answered command.
#[derive(serde::Serialize)]
struct Answered {
    #[serde(flatten)]
    done: RfidDone,
    bytes: usize,
    ms: f64,
    drained: usize,
    restarts: u64,
}

/// The demo plant's RFID reader: a tag that comes and goes, and the
/// PLC's commands over the handshake in turn.
pub mod demo {
    use super::{Event, Line, RfidDone, TagMoved};
    use profibus_devices::channels::ChannelMap;
    use profibus_devices::rfid::client::RfidClient;
    use profibus_devices::rfid::tags::TagField;
    use profibus_devices::rfid::Rfid;
    use profibus_devices::{ControlInbox, DeviceOptions};
    use profibus_dp::gsd::Gsd;
    use profibus_dp::master::{DpMaster, SlaveState};
    use profibus_dp::slave::Device;
    use profibus_fdl::Instant;
    use std::time::Duration;

    /// The tag of the demo.
    const TAGS: &str = "[reader]\ntor = 3\nuid_ms = 10\nblock_ms = 20\n\n\
        [[tag]]\nuid = \"E004015012345678\"\ndata = [\"00C0FFEE\"]\n";

    /// How long the tag stays in the antenna field, and away.
    const IN_FIELD: Duration = Duration::from_millis(1500);
    const AWAY: Duration = Duration::from_millis(1000);

    /// Pause between two commands.
    const PAUSE: Duration = Duration::from_millis(150);

    /// The slave side of the demo reader: its GSD, modules, device and
    /// channels.
    pub struct Parts {
        /// The GSD.
        pub gsd: Gsd,
        /// Its module.
        pub modules: Vec<String>,
        /// The emulated reader.
        pub device: Box<dyn Device + Send>,
        /// Named channels.
        pub channels: ChannelMap,
    }

    /// The PLC side: runs the commands and moves the tag.
    pub struct DemoReader {
        address: u8,
        client: RfidClient,
        inbox: ControlInbox,
        tag_in: bool,
        tag_due: Instant,
        next: usize,
        due: Instant,
        running: Option<String>,
    }

    impl DemoReader {
        /// The reader at `address`.
        pub fn new(address: u8) -> anyhow::Result<(DemoReader, Parts)> {
            let p = profibus_devices::profile("rfid")?
                .configure(&DeviceOptions::new(), Some(address))?;
            let inbox = ControlInbox::new();
            let field = TagField::parse(TAGS)?;
            let device = Box::new(Rfid::new(field).with_inbox(inbox.clone()));
            let parts = Parts {
                gsd: p.gsd().clone(),
                modules: p.modules(),
                device,
                channels: p.channels(&p.chk_cfg()?)?,
            };
            Ok((
                DemoReader {
                    address,
                    client: RfidClient::new(Duration::from_millis(2000)),
                    inbox,
                    tag_in: false,
                    tag_due: Instant::ZERO + Duration::from_millis(300),
                    next: 0,
                    due: Instant::ZERO,
                    running: None,
                },
                parts,
            ))
        }

        fn command(&self, ramp: u16) -> String {
            match self.next {
                0 => "VER".into(),
                1 => "GT".into(),
                2 => format!("WD 1 {:08X}", ramp as u32),
                _ => "RD 0 1".into(),
            }
        }

        /// One step of the PLC program; returns what happened, for the
        /// view.
        pub fn step(&mut self, m: &mut DpMaster, now: Instant, ramp: u16) -> Vec<Event> {
            let mut out = vec![];
            if now >= self.tag_due {
                self.tag_in = !self.tag_in;
                self.tag_due = now + if self.tag_in { IN_FIELD } else { AWAY };
                self.inbox.push(if self.tag_in {
                    "enter E004015012345678"
                } else {
                    "leave"
                });
                let what = if self.tag_in { "enters" } else { "leaves" };
                out.push(Event::Tag(Line::new(
                    "rfid_tag",
                    TagMoved {
                        slave: self.address,
                        tag: "E004015012345678",
                        in_field: self.tag_in,
                    },
                    format!(
                        "rfid slave {}: tag E004015012345678 {what} the field",
                        self.address
                    ),
                )));
            }
            let Some(h) = m.handle(self.address) else {
                return out;
            };
            if m.slave(h).state != SlaveState::DataExchange && self.client.is_idle() {
                return out;
            }
            if let Some(r) = self.client.poll_master(now, m, h) {
                let cmd = self.running.take().unwrap_or_default();
                out.push(Event::Done(RfidDone::new(self.address, cmd, r)));
                self.due = now + PAUSE;
            }
            if self.client.is_idle() && now >= self.due {
                let cmd = self.command(ramp);
                self.next = if self.next == 3 { 1 } else { self.next + 1 };
                if self.client.start(now, cmd.as_bytes()).is_ok() {
                    self.running = Some(cmd);
                }
            }
            out
        }
    }
}

/// An RFID command that ended: the `rfid` event of `dpctl master` and
/// `dpctl demo`.
#[derive(serde::Serialize)]
#[serde(tag = "event", rename = "rfid")]
pub struct RfidDone {
    slave: u8,
    command: String,
    ok: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    answer: Option<String>,
    #[serde(
        skip_serializing_if = "Option::is_none",
        serialize_with = "profibus_fdl::ser::opt_hex"
    )]
    answer_hex: Option<Vec<u8>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

impl RfidDone {
    fn new<E: std::fmt::Display>(slave: u8, command: String, r: Result<&[u8], E>) -> RfidDone {
        let (answer, answer_hex, error) = match r {
            Ok(a) => (
                Some(String::from_utf8_lossy(a).into_owned()),
                Some(a.to_vec()),
                None,
            ),
            Err(e) => (None, None, Some(e.to_string())),
        };
        RfidDone {
            slave,
            command,
            ok: error.is_none(),
            answer,
            answer_hex,
            error,
        }
    }
}

impl std::fmt::Display for RfidDone {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (slave, cmd) = (self.slave, &self.command);
        match (&self.answer, &self.error) {
            (Some(a), _) => write!(
                f,
                "rfid slave {slave}: {cmd} → {}",
                a.trim_end_matches('\r').replace('\r', " | ")
            ),
            (None, e) => write!(
                f,
                "rfid slave {slave}: {cmd} failed: {}",
                e.as_deref().unwrap_or("")
            ),
        }
    }
}

/// The demo reader's events.
#[derive(serde::Serialize)]
#[serde(untagged)]
pub enum Event {
    /// A tag entered or left the field.
    Tag(Line<TagMoved>),
    /// A command ended.
    Done(RfidDone),
}

impl std::fmt::Display for Event {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Event::Tag(l) => l.fmt(f),
            Event::Done(d) => d.fmt(f),
        }
    }
}

/// A tag entered or left the reader's field.
#[derive(serde::Serialize)]
pub struct TagMoved {
    slave: u8,
    tag: &'static str,
    in_field: bool,
}

/// RFID commands given to a running `dpctl master` as JSON lines
/// (`{"rfid": 12, "command": "VER"}`): one client per reader, commands
/// queued and run in turn, each answer reported as an `rfid` event.
#[derive(Default)]
pub struct MasterJobs {
    readers: Vec<MasterReader>,
}

struct MasterReader {
    address: u8,
    client: RfidClient,
    queue: std::collections::VecDeque<String>,
    running: Option<String>,
}

/// Most commands waiting per reader.
const MAX_QUEUED: usize = 64;

impl MasterJobs {
    /// Take `line` if it is an RFID command (`{"rfid": ADDR, "command":
    /// "…", "timeout_ms": MS}`): `None` when it is not one, else the reply
    /// for the log or why it was refused.
    pub fn command(&mut self, m: &DpMaster, line: &str) -> Option<Result<String>> {
        let v: serde_json::Value = serde_json::from_str(line).ok()?;
        let addr = v.get("rfid")?;
        Some((|| {
            let addr = addr
                .as_u64()
                .filter(|&a| a <= 126)
                .context("`rfid` takes a station address")? as u8;
            let cmd = v
                .get("command")
                .and_then(|c| c.as_str())
                .context("`command` missing (e.g. \"VER\")")?
                .to_string();
            if m.handle(addr).is_none() {
                bail!("slave {addr} is not in the bus file");
            }
            let timeout = v.get("timeout_ms").and_then(|t| t.as_u64()).unwrap_or(5000);
            let i = match self.readers.iter().position(|r| r.address == addr) {
                Some(i) => i,
                None => {
                    self.readers.push(MasterReader {
                        address: addr,
                        client: RfidClient::new(Duration::from_millis(timeout.max(1))),
                        queue: Default::default(),
                        running: None,
                    });
                    self.readers.len() - 1
                }
            };
            let r = &mut self.readers[i];
            if r.queue.len() >= MAX_QUEUED {
                bail!("slave {addr}: {MAX_QUEUED} RFID commands are waiting already");
            }
            r.queue.push_back(cmd.clone());
            Ok(format!("rfid slave {addr}: `{cmd}` queued"))
        })())
    }

    /// Drive the clients; returns the finished commands.
    pub fn step(&mut self, m: &mut DpMaster, now: Instant) -> Vec<RfidDone> {
        let mut out = vec![];
        for r in &mut self.readers {
            let Some(h) = m.handle(r.address) else {
                continue;
            };
            if let Some(res) = r.client.poll_master(now, m, h) {
                let cmd = r.running.take().unwrap_or_default();
                out.push(RfidDone::new(r.address, cmd, res));
            }
            if r.client.is_idle() && m.slave(h).state == SlaveState::DataExchange {
                if let Some(cmd) = r.queue.pop_front() {
                    match r.client.start(now, cmd.as_bytes()) {
                        Ok(()) => r.running = Some(cmd),
                        Err(e) => out.push(RfidDone::new(r.address, cmd, Err(e))),
                    }
                }
            }
        }
        out
    }
}
