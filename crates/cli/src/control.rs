//! `--control PATH` of `dpctl master` and `dpctl gateway`: the control
//! socket (`profibus_io::control_io::ControlServer`) through which other
//! `dpctl` commands (`--via PATH`) and scripts use the running master
//! instead of opening the port.
//!
//! Each request is one JSON line and gets exactly one JSON answer line:
//! - the command lines of `dpctl master --input` (`{"slave": 8,
//!   "outputs": "01 02"}`, `{"read_diag": 8}`, `{"dpv1_read": 8, …}`, …):
//!   a command applied at once answers `{"ok": true}`; a job (Slave_Diag,
//!   Get_Cfg, Rd_Inp, Rd_Outp, DP-V1 read or write, Set_Slave_Add)
//!   answers when it ended: `{"job": 3, "ok": true, "result": "ok",
//!   "data": "…"}` (`dpv1_error` with a DP-V1 error response);
//! - `{"pkw": 25, "read": "P218"}` (`crate::pkw::PkwRequest`) and
//!   `{"rfid": 12, "commands": ["VER"]}` (`crate::rfid::RfidRequest`):
//!   run in the master, answered with what `dpctl pkw` / `rfid` print
//!   (`crate::via::Printed`: `ok`, `text`, `json`, `error`);
//! - `{"status": true}`: the status line of `dpctl master --json`.
//!
//! A refused request answers `{"error": "…"}`. Permissions: with
//! `--control-readonly` only reading requests pass; writes (outputs,
//! operating state, Global_Control, DP-V1 writes but the I&M call header
//! that selects a record to read, Set_Slave_Add, PKW writes, RFID
//! commands other than VER, GT and RD) go only to slaves the bus file's
//! `[mqtt] writable` lists with full access (the gateway's key; channel
//! writes by name also to a slave listed with those channels).

use crate::via::{JobAnswer, Printed};
use anyhow::{Context, Result};
use profibus_devices::bus::{ProfiledBus, SetChannels};
use profibus_devices::pkw_task::PkwTask;
use profibus_devices::rfid::jobs::CommandRun;
use profibus_dp::master::{
    CommandOutcome, DpMaster, Job, JobId, JobResult, MasterCommand, MasterEvent, TaskRun,
};
use profibus_dp::pdu::im::{CALL_HEADER_LEN, CALL_INDEX};
use profibus_fdl::{Baud, Instant};
use profibus_gateway::settings::WriteAccess;
use profibus_io::control_io::{ControlRequest, ControlServer};
use profibus_tui::lines::{SlaveInfo, StatusLine};
use serde_json::{json, Value};
use std::ops::ControlFlow;
use std::path::Path;

/// `--control PATH` and `--control-readonly`, shared by `dpctl master`
/// and `dpctl gateway`.
#[derive(clap::Args, Debug, Clone)]
pub struct ControlArgs {
    /// Open a control socket (a Unix socket, mode 0600, removed on exit)
    /// at PATH: other dpctl commands run their jobs through this master
    /// with `--via PATH` (pkw, rfid, dpv1, im, diag, get-cfg), scripts
    /// send the JSON lines of `--input` and get one JSON answer per line.
    /// Writes go only to slaves the bus file's `[mqtt] writable` lists.
    #[arg(long, value_name = "PATH")]
    pub control: Option<std::path::PathBuf>,
    /// The control socket takes reading requests only (diagnosis,
    /// configuration, record and PKW reads, RFID reads, I&M, status).
    #[arg(long, requires = "control")]
    pub control_readonly: bool,
}

impl ControlArgs {
    /// Name the socket in the port locks (before the port opens).
    pub fn announce(&self) {
        if let Some(p) = &self.control {
            crate::common::set_control_path(p);
        }
    }

    /// Open the socket, if asked (inside the runtime).
    pub fn open(&self, bus: &ProfiledBus) -> Result<Option<Control>> {
        let Some(path) = &self.control else {
            return Ok(None);
        };
        Ok(Some(Control::open(path, self.control_readonly, bus)?))
    }
}

/// A job that runs in the master for a client.
enum Task {
    Pkw(TaskRun<PkwTask>),
    Rfid(TaskRun<CommandRun>),
}

struct Running {
    slave: u8,
    task: Task,
    request: ControlRequest,
}

/// The control socket of a running master; see the module docs.
pub struct Control {
    server: ControlServer,
    readonly: bool,
    writable: Vec<WriteAccess>,
    jobs: Vec<(JobId, ControlRequest)>,
    tasks: Vec<Running>,
    /// Jobs answered here: their `JobDone` events are not shown.
    answered: Vec<JobId>,
}

/// What a request would change.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Access {
    Read,
    /// Writes to these slaves.
    Write(Vec<u8>),
    /// Writes channels by name to a slave.
    Channels(u8, Vec<String>),
}

fn error(e: impl std::fmt::Display) -> String {
    json!({ "error": e.to_string() }).to_string()
}

impl Control {
    /// Listen at `path` for the master of `bus`.
    pub fn open(path: &Path, readonly: bool, bus: &ProfiledBus) -> Result<Control> {
        let settings =
            profibus_gateway::MqttSettings::for_bus_file(bus.file.mqtt.as_ref(), &bus.file.path)
                .map_err(|e| e.in_bus_file(&bus.file))?;
        let server = ControlServer::bind(path)?;
        tracing::info!(path = %path.display(), readonly, "control socket open");
        Ok(Control {
            server,
            readonly,
            writable: settings.writable,
            jobs: vec![],
            tasks: vec![],
            answered: vec![],
        })
    }

    /// Take the requests that came, and answer the jobs and tasks that
    /// ended. Call on each tick of the driver, before the master's events
    /// are shown.
    pub fn tick(
        &mut self,
        m: &mut DpMaster,
        now: Instant,
        bus: &ProfiledBus,
        info: &[SlaveInfo],
        baud: Baud,
    ) {
        while let Some(req) = self.server.try_next() {
            self.take(req, m, now, bus, info, baud);
        }
        let mut i = 0;
        while i < self.jobs.len() {
            let id = self.jobs[i].0;
            match m.take_result(id) {
                Some(r) => {
                    let (_, req) = self.jobs.swap_remove(i);
                    req.answer(job_answer(id, r));
                    self.answered.push(id);
                }
                None => i += 1,
            }
        }
        // One task per slave at a time (they share its cyclic data), in
        // the order they came.
        let mut busy = vec![];
        let mut i = 0;
        while i < self.tasks.len() {
            let slave = self.tasks[i].slave;
            if busy.contains(&slave) {
                i += 1;
                continue;
            }
            busy.push(slave);
            let t = &mut self.tasks[i];
            let flow = match &mut t.task {
                Task::Pkw(run) => run.tick(m, now),
                Task::Rfid(run) => run.tick(m, now),
            };
            if flow == ControlFlow::Break(()) {
                let done = self.tasks.remove(i);
                let printed = match done.task {
                    Task::Pkw(run) => crate::pkw::printed(run),
                    Task::Rfid(run) => crate::rfid::printed(run),
                };
                done.request
                    .answer(crate::via::json_value(&printed).to_string());
            } else {
                i += 1;
            }
        }
    }

    /// Whether `e` is the end of a job answered here (not to be shown).
    pub fn owns(&mut self, e: &MasterEvent) -> bool {
        match e {
            MasterEvent::JobDone(id) => match self.answered.iter().position(|a| a == id) {
                Some(i) => {
                    self.answered.swap_remove(i);
                    true
                }
                None => false,
            },
            _ => false,
        }
    }

    fn take(
        &mut self,
        req: ControlRequest,
        m: &mut DpMaster,
        now: Instant,
        bus: &ProfiledBus,
        info: &[SlaveInfo],
        baud: Baud,
    ) {
        let line = req.line.trim().to_string();
        let v: Value = match serde_json::from_str(&line) {
            Ok(v @ Value::Object(_)) => v,
            Ok(_) => return req.answer(error("a request is one JSON object")),
            Err(e) => return req.answer(error(format!("not JSON: {e}"))),
        };
        if v.get("status").is_some() {
            let status = StatusLine::of(m, info, baud, now);
            return req.answer(crate::via::json_value(&status).to_string());
        }
        if v.get("pkw").is_some() {
            let r: crate::pkw::PkwRequest = match serde_json::from_value(v) {
                Ok(r) => r,
                Err(e) => return req.answer(error(e)),
            };
            return self.start_job(req, bus, r.pkw, r.writes(), |s| {
                Ok(Task::Pkw(TaskRun::new(r.task(s)?, r.wait())))
            });
        }
        if v.get("rfid").is_some() {
            let r: crate::rfid::RfidRequest = match serde_json::from_value(v) {
                Ok(r) => r,
                Err(e) => return req.answer(error(e)),
            };
            return self.start_job(req, bus, r.rfid, r.writes(), |s| {
                Ok(Task::Rfid(TaskRun::new(r.task(s)?, r.wait())))
            });
        }
        if let Some(c) = SetChannels::from_json(&line) {
            let c = match c {
                Ok(c) => c,
                Err(e) => return req.answer(error(e)),
            };
            let access = Access::Channels(c.slave, c.set.keys().cloned().collect());
            if let Err(e) = self.allowed(&access, bus) {
                return req.answer(error(e));
            }
            let channels = bus.channels(c.slave).and_then(|r| r.ok());
            return match c.apply(m, channels.as_ref()) {
                Ok(()) => req.answer(json!({"ok": true}).to_string()),
                Err(e) => req.answer(error(e)),
            };
        }
        let command = match MasterCommand::from_json(&line) {
            Ok(c) => c,
            Err(e) => return req.answer(error(e)),
        };
        if let Err(e) = self
            .allowed(&access(&command, bus), bus)
            .and_then(|()| dpv1_slave(&command, bus))
        {
            return req.answer(error(e));
        }
        let reply = match &command {
            MasterCommand::Operating(s) => Some(format!("operating state {}", s.as_str())),
            _ => None,
        };
        match m.apply(command) {
            Ok(CommandOutcome::JobQueued(id)) => self.jobs.push((id, req)),
            Ok(CommandOutcome::Applied) => {
                let mut a = json!({"ok": true});
                if let Some(r) = reply {
                    a["reply"] = r.into();
                }
                req.answer(a.to_string())
            }
            Err(e) => req.answer(error(e)),
        }
    }

    /// Whether `access` is allowed on this socket.
    /// Start a PKW or RFID job on `slave` (its bus-file entry made into
    /// a task by `task`) once the socket's permissions allow it; a
    /// refusal, or a job that cannot start, is the request's answer.
    fn start_job(
        &mut self,
        req: ControlRequest,
        bus: &ProfiledBus,
        slave: u8,
        writes: bool,
        task: impl FnOnce(&profibus_dp::config::busfile::BusSlave) -> Result<Task>,
    ) {
        let access = match writes {
            true => Access::Write(vec![slave]),
            false => Access::Read,
        };
        if let Err(e) = self.allowed(&access, bus) {
            return req.answer(error(e));
        }
        let task = bus
            .file
            .slaves
            .iter()
            .find(|s| s.params.address == slave)
            .with_context(|| format!("slave {slave} is not in {}", bus.file.path.display()))
            .and_then(task);
        match task {
            Ok(task) => self.tasks.push(Running {
                slave,
                task,
                request: req,
            }),
            Err(e) => req.answer(crate::via::json_value(&Printed::failed(&e)).to_string()),
        }
    }

    fn allowed(&self, access: &Access, bus: &ProfiledBus) -> Result<()> {
        let slaves = match access {
            Access::Read => return Ok(()),
            Access::Write(s) => s.clone(),
            Access::Channels(s, _) => vec![*s],
        };
        if self.readonly {
            anyhow::bail!(
                "refused: a read-only control socket (--control-readonly) takes no writes"
            );
        }
        let file = bus.file.path.display();
        for slave in slaves {
            let entry = self.writable.iter().find(|w| w.address == slave);
            match (entry.map(|w| &w.channels), access) {
                (Some(None), _) => {}
                (Some(Some(allowed)), Access::Channels(_, names)) => {
                    if let Some(n) = names.iter().find(|n| !allowed.contains(n)) {
                        anyhow::bail!(
                            "refused: channel `{n}` of slave {slave} is not writable \
                             ([mqtt] writable in {file} allows {})",
                            allowed.join(", ")
                        );
                    }
                }
                (Some(Some(_)), _) => anyhow::bail!(
                    "refused: only named channels of slave {slave} are writable \
                     ([mqtt] writable in {file})"
                ),
                (None, _) => anyhow::bail!(
                    "refused: slave {slave} is not writable (list it in [mqtt] writable of {file})"
                ),
            }
        }
        Ok(())
    }
}

/// What a master command changes: outputs, the operating state and
/// Global_Control change the slaves they reach; of the jobs DP-V1 writes
/// (but an I&M call header alone, which selects a record to read) and
/// Set_Slave_Add.
fn access(c: &MasterCommand, bus: &ProfiledBus) -> Access {
    let all = || bus.file.slaves.iter().map(|s| s.params.address).collect();
    match c {
        MasterCommand::SetOutputs { slave, .. } => Access::Write(vec![*slave]),
        MasterCommand::Operating(_) => Access::Write(all()),
        MasterCommand::GlobalControl { group: 0, .. } => Access::Write(all()),
        MasterCommand::GlobalControl { group, .. } => Access::Write(
            (bus.file.slaves.iter())
                .filter(|s| s.params.group & group != 0)
                .map(|s| s.params.address)
                .collect(),
        ),
        MasterCommand::Job(Job::Dpv1Write {
            address,
            index,
            data,
            ..
        }) => {
            if *index == CALL_INDEX && data.len() == CALL_HEADER_LEN {
                Access::Read
            } else {
                Access::Write(vec![*address])
            }
        }
        MasterCommand::Job(Job::SetSlaveAdd { address, .. }) => Access::Write(vec![*address]),
        MasterCommand::Job(_) => Access::Read,
    }
}

/// DP-V1 jobs go to DP-V1 slaves only (as `dpctl dpv1` checks).
fn dpv1_slave(c: &MasterCommand, bus: &ProfiledBus) -> Result<()> {
    let address = match c {
        MasterCommand::Job(Job::Dpv1Read { address, .. } | Job::Dpv1Write { address, .. }) => {
            *address
        }
        _ => return Ok(()),
    };
    match bus.file.slaves.iter().find(|s| s.params.address == address) {
        None => anyhow::bail!("slave {address} is not in {}", bus.file.path.display()),
        Some(s) if !s.params.dpv1 => anyhow::bail!(
            "slave {address} is not a DP-V1 slave in the bus file (its GSD has no DPV1_Slave=1)"
        ),
        Some(_) => Ok(()),
    }
}

/// The answer to a job that ended.
fn job_answer(id: JobId, r: JobResult) -> String {
    let mut a = JobAnswer {
        job: id.0,
        ok: matches!(r, JobResult::Data(_) | JobResult::Done),
        result: "ok".into(),
        data: None,
        dpv1_error: None,
    };
    match &r {
        JobResult::Data(d) => a.data = Some(profibus_fdl::wire::Hex(d).to_string()),
        JobResult::Done => {}
        JobResult::Dpv1Error(e) => {
            a.result = r.describe();
            a.dpv1_error = Some((*e).into());
        }
        other => a.result = other.describe(),
    }
    crate::via::json_value(&a).to_string()
}
