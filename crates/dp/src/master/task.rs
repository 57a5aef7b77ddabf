//! One-shot tasks on one slave (a PKW job, a DP-V1 record read or write,
//! RFID commands): [`SlaveTask`] is the task, [`TaskRun`] runs it from a
//! driver's tick (waiting for Data_Exchange with [`SlaveWait`] first), and
//! [`RecordTask`] is the DP-V1 class-1 record read or write of `dpctl
//! dpv1`. Sans-IO: fed the master and the time on each tick.

use super::{DpMaster, Job, JobId, JobResult, SlaveWait, StartupTimeout};
use profibus_fdl::Instant;
use std::fmt;
use std::ops::ControlFlow;

/// A task on one slave that ends.
pub trait SlaveTask {
    /// Why it failed (a slave that never reached Data_Exchange among
    /// others).
    type Error: From<StartupTimeout>;
    /// A job of the task runs on the slave now (so the start-up timeout
    /// does not apply: the job ends on its own timeout).
    fn busy(&self) -> bool;
    /// Drive the task; `in_dx`: the slave is in Data_Exchange. `Ok(true)`
    /// once the task has ended.
    fn step(&mut self, m: &mut DpMaster, now: Instant, in_dx: bool) -> Result<bool, Self::Error>;
}

/// Runs a [`SlaveTask`] from a driver's tick; see the module docs.
#[derive(Debug)]
pub struct TaskRun<T: SlaveTask> {
    task: T,
    wait: SlaveWait,
    error: Option<T::Error>,
}

impl<T: SlaveTask> TaskRun<T> {
    /// Run `task` once `wait`'s slave is in Data_Exchange.
    pub fn new(task: T, wait: SlaveWait) -> TaskRun<T> {
        TaskRun {
            task,
            wait,
            error: None,
        }
    }

    /// One tick: `Break` once the task ended or failed.
    pub fn tick(&mut self, m: &mut DpMaster, now: Instant) -> ControlFlow<()> {
        let step = match self.wait.check(m, now, self.task.busy()) {
            Ok(in_dx) => self.task.step(m, now, in_dx),
            Err(e) => Err(e.into()),
        };
        match step {
            Ok(false) => ControlFlow::Continue(()),
            Ok(true) => ControlFlow::Break(()),
            Err(e) => {
                self.error = Some(e);
                ControlFlow::Break(())
            }
        }
    }

    /// The task, also after it failed.
    pub fn task(&self) -> &T {
        &self.task
    }

    /// The task, or why it failed.
    pub fn finish(self) -> Result<T, T::Error> {
        match self.error {
            Some(e) => Err(e),
            None => Ok(self.task),
        }
    }
}

/// Why a [`RecordTask`] failed to run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RecordError {
    /// The slave did not reach Data_Exchange.
    #[error(transparent)]
    Startup(#[from] StartupTimeout),
    /// The master's job queue is full.
    #[error("job queue full")]
    QueueFull,
    /// A write of no bytes or more than 240.
    #[error("a record write carries 1..=240 bytes, not {0}")]
    Length(usize),
}

/// A DP-V1 class-1 read or write of the data record (slot, index) of a
/// slave in Data_Exchange (the master's MSAC_C1 job: request, then polls
/// until the slave answers or its C1 response timeout passes).
#[derive(Debug, Clone)]
pub struct RecordTask {
    job: Option<Job>,
    id: Option<JobId>,
    result: Option<JobResult>,
    op: &'static str,
    slave: u8,
    slot: u8,
    index: u8,
}

impl RecordTask {
    /// Read up to `length` bytes of the record.
    pub fn read(slave: u8, slot: u8, index: u8, length: u8) -> RecordTask {
        let job = Job::Dpv1Read {
            address: slave,
            slot,
            index,
            length,
        };
        RecordTask::new(Some(job), "read", slave, slot, index)
    }

    /// Write `data` (1..=240 bytes) to the record.
    pub fn write(slave: u8, slot: u8, index: u8, data: Vec<u8>) -> Result<RecordTask, RecordError> {
        if data.is_empty() || data.len() > 240 {
            return Err(RecordError::Length(data.len()));
        }
        let job = Job::Dpv1Write {
            address: slave,
            slot,
            index,
            data,
        };
        Ok(RecordTask::new(Some(job), "write", slave, slot, index))
    }

    fn new(job: Option<Job>, op: &'static str, slave: u8, slot: u8, index: u8) -> RecordTask {
        RecordTask {
            job,
            id: None,
            result: None,
            op,
            slave,
            slot,
            index,
        }
    }

    /// How it ended, once it has.
    pub fn outcome(&self) -> Option<RecordOutcome<'_>> {
        let result = self.result.as_ref()?;
        let mut o = RecordOutcome {
            slave: self.slave,
            op: self.op,
            slot: self.slot,
            index: self.index,
            ok: matches!(result, JobResult::Data(_) | JobResult::Done),
            length: None,
            data: None,
            error: None,
            error_decode: None,
            error_code_1: None,
            error_code_2: None,
        };
        match result {
            JobResult::Data(d) => (o.length, o.data) = (Some(d.len()), Some(d)),
            JobResult::Done => {}
            JobResult::Dpv1Error(e) => {
                o.error_decode = Some(e.error_decode);
                o.error_code_1 = Some(format!("0x{:02X}", e.error_code_1));
                o.error_code_2 = Some(e.error_code_2);
                o.error = Some(e.describe());
            }
            other => o.error = Some(other.describe()),
        }
        Some(o)
    }
}

impl SlaveTask for RecordTask {
    type Error = RecordError;

    fn busy(&self) -> bool {
        self.id.is_some()
    }

    fn step(&mut self, m: &mut DpMaster, _: Instant, in_dx: bool) -> Result<bool, RecordError> {
        if let Some(id) = self.id {
            self.result = m.take_result(id);
            return Ok(self.result.is_some());
        }
        if let Some(job) = self.job.take_if(|_| in_dx) {
            self.id = Some(m.submit(job).ok_or(RecordError::QueueFull)?);
        }
        Ok(false)
    }
}

/// How a [`RecordTask`] ended: `Display` is the line `dpctl dpv1`
/// prints (`slave 8 slot 1 index 2: 3 bytes 01 02 03`); with the feature
/// `serde` it serialises as its `--json` object.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct RecordOutcome<'a> {
    /// Station address.
    pub slave: u8,
    /// `read` or `write`.
    pub op: &'static str,
    /// Slot.
    pub slot: u8,
    /// Index.
    pub index: u8,
    /// Data read or written.
    pub ok: bool,
    /// Bytes read.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub length: Option<usize>,
    /// The data read.
    #[cfg_attr(
        feature = "serde",
        serde(
            skip_serializing_if = "Option::is_none",
            serialize_with = "profibus_fdl::ser::opt_hex"
        )
    )]
    pub data: Option<&'a Vec<u8>>,
    /// What went wrong, in words.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error: Option<String>,
    /// A DP-V1 error response's Error_Decode.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error_decode: Option<u8>,
    /// Its Error_Code_1 (`0xB0`).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error_code_1: Option<String>,
    /// Its Error_Code_2.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error_code_2: Option<u8>,
}

impl fmt::Display for RecordOutcome<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "slave {} slot {} index {}: ",
            self.slave, self.slot, self.index
        )?;
        match (&self.data, &self.error) {
            (Some(d), _) => write!(f, "{} bytes {}", d.len(), profibus_fdl::wire::Hex(d)),
            (None, Some(e)) => f.write_str(e),
            (None, None) => f.write_str("written"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::master::{MasterConfig, MasterOptions, SlaveParams};
    use profibus_fdl::{Baud, BusParams};
    use std::time::Duration;

    #[test]
    fn a_record_job_waits_for_data_exchange_and_a_start_up_timeout_ends_the_run() {
        let cfg = MasterConfig {
            address: 1,
            params: BusParams::defaults(Baud::B1500000),
            slaves: vec![SlaveParams::new(8, 0x0DCE, vec![0x11, 0x21])],
            options: MasterOptions::default(),
        };
        let mut m = DpMaster::new(&cfg).unwrap();
        let mut task = RecordTask::read(8, 1, 2, 5);
        assert_eq!(task.step(&mut m, Instant::ZERO, false), Ok(false));
        assert!(
            !task.busy() && task.job.is_some(),
            "kept until the slave is in DX"
        );
        assert_eq!(task.step(&mut m, Instant::ZERO, true), Ok(false));
        assert!(task.busy(), "submitted");
        assert_eq!(task.outcome(), None);
        assert_eq!(
            RecordTask::write(8, 0, 0, vec![]).unwrap_err(),
            RecordError::Length(0)
        );
        let wait = SlaveWait::new(8, Duration::from_millis(10));
        let mut run = TaskRun::new(RecordTask::read(8, 1, 2, 5), wait);
        let t = |ms| Instant::ZERO + Duration::from_millis(ms);
        assert_eq!(run.tick(&mut m, t(0)), ControlFlow::Continue(()));
        assert_eq!(run.tick(&mut m, t(20)), ControlFlow::Break(()));
        let e = run.finish().unwrap_err();
        assert!(e.to_string().contains("did not reach Data_Exchange"), "{e}");
    }

    #[test]
    fn record_outcome_lines() {
        let mut task = RecordTask::read(8, 1, 2, 5);
        task.result = Some(JobResult::Data(vec![1, 2, 3]));
        let o = task.outcome().unwrap();
        assert!(o.ok);
        assert_eq!(o.to_string(), "slave 8 slot 1 index 2: 3 bytes 01 02 03");
        let mut task = RecordTask::write(8, 0, 5, vec![1]).unwrap();
        task.result = Some(JobResult::Done);
        assert_eq!(
            task.outcome().unwrap().to_string(),
            "slave 8 slot 0 index 5: written"
        );
        task.result = Some(JobResult::Timeout);
        let o = task.outcome().unwrap();
        assert!(!o.ok && o.error.is_some());
    }
}
