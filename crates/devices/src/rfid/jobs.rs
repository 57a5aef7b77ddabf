//! Reader commands run by a DP master: [`CommandRun`] runs a list of
//! commands on one reader (`dpctl rfid`, a [`SlaveTask`]), [`MasterJobs`]
//! queues commands that arrive while a master runs (`dpctl master`'s
//! stdin); each ended command is an [`RfidDone`] (`Display` for people,
//! `Serialize` for JSON lines).

use super::client::{RfidClient, RfidError, StartError};
use super::commands::{nak_code, NakText};
use super::{CFG, IDENT};
use profibus_dp::config::busfile::BusSlave;
use profibus_dp::master::{DpMaster, SlaveState, SlaveTask, StartupTimeout};
use profibus_fdl::wire::Hex;
use profibus_fdl::Instant;
use serde::Serialize;
use std::collections::VecDeque;
use std::fmt;
use std::time::Duration;

/// An RFID command that ended: the `rfid` event of `dpctl master` and
/// `dpctl demo`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "event", rename = "rfid")]
pub struct RfidDone {
    /// The reader's station address.
    pub slave: u8,
    /// The command as given.
    pub command: String,
    /// It was answered.
    pub ok: bool,
    /// The answer as text (CRs kept).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub answer: Option<String>,
    /// The answer's bytes, hex.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub answer_hex: Option<String>,
    /// Why there is no answer, or why the answer is an error (a NAK).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The error number of an answer `NAK #nn` (then `ok` is false and
    /// `error` says what the number means).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nak: Option<u8>,
}

impl RfidDone {
    /// `command` on the reader at `slave` ended with `r`. An answer
    /// `NAK #nn` is a failure, explained in words ([`NakText`]).
    pub fn new<E: fmt::Display>(slave: u8, command: String, r: Result<&[u8], E>) -> RfidDone {
        let (answer, answer_hex, error, nak) = match r {
            Ok(a) => {
                let nak = nak_code(a);
                (
                    Some(String::from_utf8_lossy(a).into_owned()),
                    Some(Hex(a).to_string()),
                    nak.map(|n| format!("the reader refused it: {}", NakText(n))),
                    nak,
                )
            }
            Err(e) => (None, None, Some(e.to_string()), None),
        };
        RfidDone {
            slave,
            command,
            ok: error.is_none(),
            answer,
            answer_hex,
            error,
            nak,
        }
    }
}

impl fmt::Display for RfidDone {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (slave, cmd) = (self.slave, &self.command);
        match (&self.answer, &self.error) {
            (_, Some(e)) => write!(f, "rfid slave {slave}: {cmd} failed: {e}"),
            (Some(a), None) => write!(
                f,
                "rfid slave {slave}: {cmd} → {}",
                a.trim_end_matches('\r').replace('\r', " | ")
            ),
            (None, None) => write!(f, "rfid slave {slave}: {cmd} failed"),
        }
    }
}

/// One command of a [`CommandRun`] that ended: `Display` is the command
/// (`> VER`) and then the answer's lines, a `NAK #nn` in words (nothing
/// more for a command without an answer); `Serialize` the `dpctl rfid
/// --json` object.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CommandResult {
    /// The command and its answer.
    #[serde(flatten)]
    pub done: RfidDone,
    /// Bytes of the answer.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bytes: Option<usize>,
    /// Milliseconds from start to the whole answer.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ms: Option<f64>,
    /// Bytes of an earlier answer fetched and dropped first.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drained: Option<usize>,
    /// Start-ups of the reader while the command ran (it was sent again).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub restarts: Option<u64>,
}

impl fmt::Display for CommandResult {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "> {}", self.done.command)?;
        if let Some(n) = self.done.nak {
            return writeln!(f, "{}", NakText(n));
        }
        for line in self
            .done
            .answer
            .iter()
            .flat_map(|a| a.split_terminator('\r'))
        {
            writeln!(f, "{line}")?;
        }
        Ok(())
    }
}

/// Why a [`CommandRun`] stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RunError {
    /// The slave is not configured as the reader.
    #[error(
        "slave {0} is configured {h}; the reader has 16 bytes in and out (3F, crates/devices/gsd/AEGI0DC4.GSD)", h = Hex(.1)
    )]
    NotAReader(u8, Vec<u8>),
    /// The reader did not reach Data_Exchange.
    #[error(transparent)]
    Startup(#[from] StartupTimeout),
    /// A command cannot be sent.
    #[error("`{0}`: {1}")]
    Start(String, StartError),
    /// A command got no (complete) answer.
    #[error("slave {0} `{1}`: {2}")]
    Failed(u8, String, RfidError),
    /// The reader answered a command with an error (`NAK #nn`).
    #[error("slave {0} `{1}`: the reader refused it: {2}")]
    Refused(u8, String, NakText),
}

/// Commands run in turn on one reader, each answer fetched whole; stops
/// at the first failure (no answer, or an answer `NAK #nn`). See the
/// module docs.
#[derive(Debug)]
pub struct CommandRun {
    address: u8,
    client: RfidClient,
    todo: VecDeque<String>,
    /// The command running, when it started, the reader's start-ups then.
    running: Option<(String, Instant, u64)>,
    results: Vec<CommandResult>,
    /// Why the last command failed.
    failed: Option<RunError>,
}

impl CommandRun {
    /// `commands` (CR appended) for the reader `slave` of a bus file,
    /// each given `timeout` for its whole answer.
    pub fn new(slave: &BusSlave, commands: &[String], timeout: Duration) -> Result<Self, RunError> {
        let (address, p) = (slave.params.address, &slave.params);
        if p.cfg != CFG {
            return Err(RunError::NotAReader(address, p.cfg.clone()));
        }
        if p.ident_number != IDENT {
            tracing::warn!(
                ident = p.ident_number,
                "slave {address} is not ident 0x{IDENT:04X}; trying the reader's handshake anyway"
            );
        }
        Ok(CommandRun {
            address,
            client: RfidClient::new(timeout.max(Duration::from_millis(1))),
            todo: commands.iter().cloned().collect(),
            running: None,
            results: vec![],
            failed: None,
        })
    }

    /// The commands that ended, in order.
    pub fn results(&self) -> &[CommandResult] {
        &self.results
    }

    /// Why the last command failed, if it did.
    pub fn failure(&self) -> Option<RunError> {
        self.failed.clone()
    }
}

impl SlaveTask for CommandRun {
    type Error = RunError;

    fn busy(&self) -> bool {
        !self.client.is_idle()
    }

    fn step(&mut self, m: &mut DpMaster, now: Instant, in_dx: bool) -> Result<bool, RunError> {
        let addr = self.address;
        let Some(h) = m.handle(addr) else {
            return Ok(true);
        };
        let restarts = |m: &DpMaster| m.slave_stats(addr).map_or(0, |s| s.restarts);
        if let Some(r) = self.client.poll_master(now, m, h) {
            let (command, t, r0) = self.running.take().unwrap_or((String::new(), now, 0));
            let ok = r.as_ref().ok().map(|a| a.len());
            let ms = now.saturating_duration_since(t).as_secs_f64() * 1000.0;
            let done = RfidDone::new(addr, command.clone(), r.as_ref().map(|a| &a[..]));
            self.failed = match (r.as_ref().err(), done.nak) {
                (Some(e), _) => Some(RunError::Failed(addr, command, *e)),
                (None, Some(n)) => Some(RunError::Refused(addr, command, NakText(n))),
                (None, None) => None,
            };
            self.results.push(CommandResult {
                done,
                bytes: ok,
                ms: ok.map(|_| (ms * 1000.0).round() / 1000.0),
                drained: ok.map(|_| self.client.drained()),
                restarts: ok.map(|_| restarts(m) - r0),
            });
            if self.failed.is_some() {
                return Ok(true);
            }
        }
        if self.client.is_idle() && in_dx {
            let Some(cmd) = self.todo.pop_front() else {
                return Ok(true);
            };
            if let Err(e) = self.client.start(now, cmd.as_bytes()) {
                return Err(RunError::Start(cmd, e));
            }
            self.running = Some((cmd, now, restarts(m)));
        }
        Ok(false)
    }
}

/// Why a reader command given to a running master was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum QueueError {
    /// `rfid` is not a station address.
    #[error("`rfid` takes a station address")]
    Address,
    /// No `command`.
    #[error("`command` missing (e.g. \"VER\")")]
    Command,
    /// The master has no such slave.
    #[error("slave {0} is not in the bus file")]
    NoSlave(u8),
    /// Too many commands wait for this reader.
    #[error("slave {0}: {MAX_QUEUED} RFID commands are waiting already")]
    Full(u8),
}

/// RFID commands given to a running `dpctl master` as JSON lines
/// (`{"rfid": 12, "command": "VER"}`): one client per reader, commands
/// queued and run in turn, each answer reported as an [`RfidDone`].
#[derive(Debug, Default)]
pub struct MasterJobs {
    readers: Vec<MasterReader>,
}

#[derive(Debug)]
struct MasterReader {
    address: u8,
    client: RfidClient,
    queue: VecDeque<String>,
    running: Option<String>,
}

/// Most commands waiting per reader.
pub const MAX_QUEUED: usize = 64;

impl MasterJobs {
    /// Take `line` if it is an RFID command (`{"rfid": ADDR, "command":
    /// "…", "timeout_ms": MS}`): `None` when it is not one, else the reply
    /// for the log or why it was refused.
    pub fn command(&mut self, m: &DpMaster, line: &str) -> Option<Result<String, QueueError>> {
        let v: serde_json::Value = serde_json::from_str(line).ok()?;
        let addr = v.get("rfid")?;
        Some((|| {
            let addr = (addr.as_u64().filter(|&a| a <= 126)).ok_or(QueueError::Address)? as u8;
            let cmd = (v.get("command").and_then(|c| c.as_str())).ok_or(QueueError::Command)?;
            if m.handle(addr).is_none() {
                return Err(QueueError::NoSlave(addr));
            }
            let timeout = v.get("timeout_ms").and_then(|t| t.as_u64()).unwrap_or(5000);
            let i = match self.readers.iter().position(|r| r.address == addr) {
                Some(i) => i,
                None => {
                    self.readers.push(MasterReader {
                        address: addr,
                        client: RfidClient::new(Duration::from_millis(timeout.max(1))),
                        queue: VecDeque::new(),
                        running: None,
                    });
                    self.readers.len() - 1
                }
            };
            let r = &mut self.readers[i];
            if r.queue.len() >= MAX_QUEUED {
                return Err(QueueError::Full(addr));
            }
            r.queue.push_back(cmd.to_string());
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

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_dp::master::{MasterConfig, MasterOptions, SlaveParams};
    use profibus_fdl::{Baud, BusParams};

    #[test]
    fn results_in_words_and_json() {
        let ok = RfidDone::new::<RfidError>(12, "VER".into(), Ok(b"V1.0\rOK\r"));
        assert_eq!(ok.to_string(), "rfid slave 12: VER → V1.0 | OK");
        assert_eq!(ok.answer_hex.as_deref(), Some("56 31 2E 30 0D 4F 4B 0D"));
        let r = CommandResult {
            done: ok,
            bytes: Some(8),
            ms: Some(1.5),
            drained: Some(0),
            restarts: Some(0),
        };
        assert_eq!(r.to_string(), "> VER\nV1.0\nOK\n");
        // A NAK is a failure, in words.
        let nak = RfidDone::new::<RfidError>(12, "RD 0 99".into(), Ok(b"NAK #02\r"));
        assert!(!nak.ok);
        assert_eq!(nak.nak, Some(2));
        assert_eq!(
            nak.to_string(),
            "rfid slave 12: RD 0 99 failed: the reader refused it: NAK #02: wrong or missing \
             parameter (or a block beyond the tag's memory)"
        );
        let r = CommandResult {
            done: nak,
            bytes: Some(8),
            ms: Some(1.0),
            drained: Some(0),
            restarts: Some(0),
        };
        assert!(r
            .to_string()
            .starts_with("> RD 0 99\nNAK #02: wrong or missing"));
        let failed = RfidDone::new(12, "GT".into(), Err::<&[u8], _>("gone"));
        assert_eq!(failed.to_string(), "rfid slave 12: GT failed: gone");
        let v = serde_json::to_value(&failed).unwrap();
        assert_eq!(v["event"], "rfid");
        assert_eq!(v["ok"], false);
        assert!(v.get("answer").is_none());
    }

    #[test]
    fn commands_for_a_running_master_are_checked() {
        let cfg = MasterConfig {
            address: 1,
            params: BusParams::defaults(Baud::B1500000),
            slaves: vec![SlaveParams::new(12, IDENT, CFG.to_vec())],
            options: MasterOptions::default(),
        };
        let m = DpMaster::new(&cfg).unwrap();
        let mut jobs = MasterJobs::default();
        assert_eq!(
            jobs.command(&m, r#"{"slot": 1}"#),
            None,
            "not an RFID command"
        );
        let mut c = |l: &str| jobs.command(&m, l).unwrap();
        assert_eq!(
            c(r#"{"rfid": 300, "command": "VER"}"#),
            Err(QueueError::Address)
        );
        assert_eq!(c(r#"{"rfid": 12}"#), Err(QueueError::Command));
        assert_eq!(
            c(r#"{"rfid": 7, "command": "VER"}"#),
            Err(QueueError::NoSlave(7))
        );
        assert_eq!(
            c(r#"{"rfid": 12, "command": "VER"}"#).unwrap(),
            "rfid slave 12: `VER` queued"
        );
        let wrong = BusSlave {
            params: SlaveParams::new(12, IDENT, vec![0x11]),
            gsd_path: "x".into(),
            device: None,
            gsd: Default::default(),
            modules: vec![],
        };
        let e = CommandRun::new(&wrong, &[], Duration::from_secs(1)).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("slave 12 is configured 11; the reader has 16 bytes"),
            "{e}"
        );
    }
}
