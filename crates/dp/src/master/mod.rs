//! The DP master (DPM1, with class-2 services and DP-V1 class-1
//! read/write), as a sans-IO core.
//!
//! [`DpMaster`] is the application of an FDL active station
//! ([`profibus_fdl::station::active::ActiveStation`]): it runs inside the
//! token hold time, so a master shares its bus with other masters.
//!
//! Per slave it walks the start-up sequence of the standard (IEC
//! 61158-6-3): **Slave_Diag → Set_Prm → Chk_Cfg → Slave_Diag** (until the slave
//! reports no Station_Not_Ready, Cfg_Fault, Prm_Fault, Prm_Req or
//! Stat_Diag and names this master in Master_Add) **→ Data_Exchange**.
//! A step that succeeds is followed by the next one in the same pass
//! (at most four in a row), so a slave that answers again is back in
//! Data_Exchange in the pass in which it answers. Faults send it back to
//! the right step: Prm_Req or an RS answer to
//! Data_Exchange to Set_Prm; Prm_Fault/Cfg_Fault are reported in words and
//! the slave is parameterised again; a slave locked by another master is
//! left alone and watched.
//!
//! A start-up that fails (a Prm/Cfg fault, a negative answer to Set_Prm
//! or Chk_Cfg, a slave that stays Station_Not_Ready) is retried, as the
//! standard's masters do, but with a bounded exponential back-off: the
//! n-th failure in a row waits [`STARTUP_RETRY_FIRST`] × 2^(n−1), at most
//! [`STARTUP_RETRY_MAX`], before the next Slave_Diag. A persistent fault
//! is reported once ([`MasterEvent::Fault`]) and, when it changes or the
//! slave reaches Data_Exchange, with its repeat count
//! ([`MasterEvent::FaultEnded`]); the state changes of the retries are
//! not reported. On a Cfg_Fault the master reads the slave's real
//! configuration (Get_Cfg) and reports it next to its own
//! ([`MasterEvent::CfgMismatch`]). A slave that stops answering for
//! [`MasterOptions::lost_after`] cycles is *lost*: it is probed with
//! Slave_Diag every [`MasterOptions::reprobe_interval`] and parameterised
//! again as soon as it answers. A "data high" (DH) answer to
//! Data_Exchange makes the next poll of that slave a Slave_Diag.
//!
//! One **poll cycle** is one pass over all slaves; a pass that the token
//! hold time cuts short continues at the next token visit. After the pass
//! the master sends at most one acyclic request per token visit: queued
//! Global_Control commands, class-2 services ([`Job`]) and DP-V1
//! MSAC_C1 read/write, which is polled until the slave's answer is ready.
//! A one-shot job on one slave (a DP-V1 record: [`RecordTask`]; a PKW
//! job or RFID commands in `profibus-devices`) is a [`SlaveTask`], run
//! from a driver's tick by [`TaskRun`] once the slave is in Data_Exchange.
//!
//! The master owns the process images: [`DpMaster::inputs`] and
//! [`DpMaster::set_outputs`] read and write them between calls; nothing is
//! allocated per cycle in the steady state. What changes is reported as
//! [`MasterEvent`]s ([`DpMaster::poll_event`]).
//!
//! # A gateway loop
//!
//! A gateway copies the inputs of a slave somewhere else and writes
//! outputs it got from elsewhere, between two events of the driver, with
//! no locks and no allocation: the module docs of `profibus_io::driver`
//! show that loop on a serial line.

mod alarm;
mod command;
mod config;
pub mod records;
mod report;
mod stop;
mod task;
mod wait;

pub use alarm::{AlarmNotice, ALARM_ACK_TRIES};
pub use command::{CommandError, CommandOutcome, MasterCommand, Queue};
pub use config::{
    join_bound, MasterConfig, MasterOptions, SlaveParams, ALONE_HOLD_BITS_FAST, ALONE_VISIT_MAX,
    DEFAULT_ALONE_HOLD_BITS, DEFAULT_GLOBAL_CONTROL_INTERVAL, STARTUP_RETRY_FIRST,
    STARTUP_RETRY_MAX,
};
pub use report::{AlarmReport, CfgGroup, CycleMicros, MasterReport, MasterStatus, SlaveStatus};
pub use stop::{Farewell, StopReason, StopWhen, EXCHANGES_TIMEOUT, FAREWELL_LIMIT};
pub use task::{RecordError, RecordOutcome, RecordTask, SlaveTask, TaskRun};
pub use wait::{SlaveWait, StartupTimeout};

use crate::pdu::control::{ControlCommand, GlobalControl, SetSlaveAdd};
use crate::pdu::diag::SlaveDiag;
use crate::pdu::dpv1::{Dpv1Error, Pdu};
use crate::pdu::sap;
use profibus_fdl::station::active::{
    CycleResult, FdlEvent, MasterApp, Outcome, Request, Service, TokenContext,
};
use profibus_fdl::time::Instant;
use profibus_fdl::wire::{consts, ResponseStatus, StationType};
use std::collections::VecDeque;
use std::time::Duration;

/// A slave of a [`DpMaster`], resolved once from its address
/// ([`DpMaster::handle`]) so that a gateway loop reaches its process image
/// without a lookup.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SlaveHandle(u8);

/// A view of one slave: state, process images, diagnosis, counters.
#[derive(Debug, Clone, Copy)]
pub struct SlaveView<'a> {
    /// Station address.
    pub address: u8,
    /// Where it is in the start-up sequence.
    pub state: SlaveState,
    /// The last inputs received.
    pub inputs: &'a [u8],
    /// The outputs sent.
    pub outputs: &'a [u8],
    /// The last diagnosis read (empty before the first).
    pub diag: &'a [u8],
    /// Counters.
    pub stats: SlaveStats,
}

/// One slave's process images for in-place work: the inputs to read and
/// the outputs to write at the same time ([`DpMaster::io_mut`]).
#[derive(Debug)]
pub struct SlaveIoMut<'a> {
    /// Where it is in the start-up sequence.
    pub state: SlaveState,
    /// Counters (`data_exchanges` tells what was sent).
    pub stats: SlaveStats,
    /// The last inputs received.
    pub inputs: &'a [u8],
    /// The output image, to write in place.
    pub outputs: &'a mut [u8],
}

/// Where a slave is in the master's start-up sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SlaveState {
    /// Not answering; probed with Slave_Diag now and then.
    Offline,
    /// First Slave_Diag of the start-up sequence.
    Diag,
    /// Set_Prm sent next.
    SetPrm,
    /// Chk_Cfg sent next.
    ChkCfg,
    /// Slave_Diag until the slave is ready for data exchange.
    CheckDiag,
    /// Cyclic Data_Exchange.
    DataExchange,
    /// Parameterised by another master; watched with Slave_Diag.
    Locked,
}

impl SlaveState {
    /// Name for people and JSON.
    pub fn name(self) -> &'static str {
        match self {
            SlaveState::Offline => "offline",
            SlaveState::Diag => "diag",
            SlaveState::SetPrm => "set_prm",
            SlaveState::ChkCfg => "chk_cfg",
            SlaveState::CheckDiag => "check_diag",
            SlaveState::DataExchange => "data_exchange",
            SlaveState::Locked => "locked",
        }
    }
}

/// Operating state of the master (DPM1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OperatingState {
    /// No data exchange; slaves are only parameterised and watched.
    Stop,
    /// Data exchange with outputs cleared (zero, or no outputs for
    /// Fail_Safe slaves); Global_Control announces Clear_Data.
    Clear,
    /// Data exchange with the application's outputs.
    Operate,
}

impl OperatingState {
    /// The name in commands and logs: `stop`, `clear`, `operate`.
    pub fn as_str(self) -> &'static str {
        match self {
            OperatingState::Stop => "stop",
            OperatingState::Clear => "clear",
            OperatingState::Operate => "operate",
        }
    }
}

/// A class-2 service or DP-V1 request for one slave.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Job {
    /// Slave_Diag of any slave.
    ReadDiag {
        /// Station address.
        address: u8,
    },
    /// Get_Cfg: the slave's real configuration.
    GetCfg {
        /// Station address.
        address: u8,
    },
    /// Rd_Inp: the slave's inputs.
    RdInp {
        /// Station address.
        address: u8,
    },
    /// Rd_Outp: the slave's outputs.
    RdOutp {
        /// Station address.
        address: u8,
    },
    /// Set_Slave_Add: give the slave at `address` a new address.
    SetSlaveAdd {
        /// Current station address.
        address: u8,
        /// New address.
        new_address: u8,
        /// The slave's ident number.
        ident_number: u16,
        /// Forbid further address changes.
        no_add_chg: bool,
    },
    /// DP-V1 MSAC_C1 Read (slave must be in Data_Exchange with us).
    Dpv1Read {
        /// Station address.
        address: u8,
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// Bytes wanted.
        length: u8,
    },
    /// DP-V1 MSAC_C1 Write.
    Dpv1Write {
        /// Station address.
        address: u8,
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// Data.
        data: Vec<u8>,
    },
}

impl Job {
    /// The slave the job is for.
    pub fn address(&self) -> u8 {
        match *self {
            Job::ReadDiag { address }
            | Job::GetCfg { address }
            | Job::RdInp { address }
            | Job::RdOutp { address }
            | Job::SetSlaveAdd { address, .. }
            | Job::Dpv1Read { address, .. }
            | Job::Dpv1Write { address, .. } => address,
        }
    }
}

/// Identifies a submitted [`Job`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct JobId(pub u32);

/// How a [`Job`] ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum JobResult {
    /// Data returned (diagnosis, configuration, inputs, outputs, DP-V1
    /// read data).
    Data(Vec<u8>),
    /// Done without data (Set_Slave_Add, DP-V1 write).
    Done,
    /// The slave answered with a negative acknowledge.
    Refused(ResponseStatus),
    /// DP-V1 error response.
    Dpv1Error(Dpv1Error),
    /// No answer.
    NoResponse,
    /// The DP-V1 answer did not come within the timeout.
    Timeout,
    /// The job needs the slave in Data_Exchange with this master.
    NotInDataExchange,
    /// The answer could not be decoded.
    BadResponse(BadResponse),
}

/// Why a job's answer could not be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum BadResponse {
    /// A DP-V1 PDU that does not answer the request (its function byte).
    #[error("unexpected DP-V1 PDU, function 0x{function:02X}")]
    UnexpectedPdu {
        /// The PDU's function byte.
        function: u8,
    },
    /// A DP-V1 PDU that does not decode.
    #[error(transparent)]
    Dpv1(#[from] crate::pdu::dpv1::Dpv1ParseError),
}

impl JobResult {
    /// The result in words.
    pub fn describe(&self) -> String {
        match self {
            JobResult::Data(d) => format!("{} bytes", d.len()),
            JobResult::Done => "done".into(),
            JobResult::Refused(s) => format!("refused by the slave ({})", s.mnemonic()),
            JobResult::Dpv1Error(e) => e.describe(),
            JobResult::NoResponse => "no response".into(),
            JobResult::Timeout => "timeout".into(),
            JobResult::NotInDataExchange => "slave not in data exchange with this master".into(),
            JobResult::BadResponse(s) => format!("bad response: {s}"),
        }
    }
}

/// Why the master reports a slave fault ([`MasterEvent::Fault`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FaultReason {
    /// The slave reports another ident number than the configuration.
    #[error(
        "slave reports ident number 0x{reported:04X}, the configuration expects 0x{expected:04X}"
    )]
    IdentMismatch {
        /// In the slave's diagnosis.
        reported: u16,
        /// In the configuration.
        expected: u16,
    },
    /// The station status bytes report a fault (Prm_Fault, Cfg_Fault,
    /// Not_Supported, …); shown as the status bits in words.
    #[error("{}", crate::pdu::diag::SlaveDiag {
        status1: *status1,
        status2: *status2,
        status3: *status3,
        master_address: crate::pdu::diag::NO_MASTER,
        ident_number: 0,
        ext_diag: &[],
    }.status_words())]
    Station {
        /// Station_Status_1.
        status1: crate::pdu::diag::StationStatus1,
        /// Station_Status_2.
        status2: crate::pdu::diag::StationStatus2,
        /// Station_Status_3.
        status3: crate::pdu::diag::StationStatus3,
    },
}

impl FaultReason {
    fn station(d: &SlaveDiag<'_>) -> FaultReason {
        FaultReason::Station {
            status1: d.status1,
            status2: d.status2,
            status3: d.status3,
        }
    }

    /// Whether `other` is the same fault: the same ident numbers, or the
    /// same fault bits of Station_Status_1 (Prm_Fault, Cfg_Fault,
    /// Not_Supported; the other status bits may change between reads).
    pub fn same_as(&self, other: &FaultReason) -> bool {
        use crate::pdu::diag::StationStatus1 as S1;
        let bits = S1::PRM_FAULT | S1::CFG_FAULT | S1::NOT_SUPPORTED;
        match (self, other) {
            (FaultReason::Station { status1: a, .. }, FaultReason::Station { status1: b, .. }) => {
                *a & bits == *b & bits
            }
            _ => self == other,
        }
    }
}

/// What the master reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MasterEvent {
    /// A slave changed state.
    StateChanged {
        /// Station address.
        address: u8,
        /// Previous state.
        from: SlaveState,
        /// New state.
        to: SlaveState,
    },
    /// A slave's diagnosis changed; read it with [`DpMaster::diag`].
    Diag {
        /// Station address.
        address: u8,
    },
    /// A slave reported a parameterisation or configuration fault: once
    /// per fault, not again for each retry of the start-up while the same
    /// fault persists.
    Fault {
        /// Station address.
        address: u8,
        /// What is wrong (`Display`: in words).
        reason: FaultReason,
    },
    /// A reported fault is over: the slave reached Data_Exchange, or
    /// reported another fault (a [`MasterEvent::Fault`] follows).
    FaultEnded {
        /// Station address.
        address: u8,
        /// The fault that ended.
        reason: FaultReason,
        /// How many start-ups ended in it in a row.
        repeats: u64,
    },
    /// A slave reported Cfg_Fault and answered Get_Cfg: its real
    /// configuration ([`DpMaster::actual_cfg`]) next to the configured
    /// one ([`SlaveParams::cfg`]).
    CfgMismatch {
        /// Station address.
        address: u8,
    },
    /// A DP-V1 alarm of a slave was acknowledged (Alarm_Ack confirmed),
    /// or given up after [`ALARM_ACK_TRIES`] attempts or because the
    /// slave left Data_Exchange (`alarm.acknowledged` false, with the
    /// problem in words). Reported once per alarm.
    Alarm {
        /// Station address.
        address: u8,
        /// The alarm.
        alarm: AlarmNotice,
    },
    /// A job ended; take its result with [`DpMaster::take_result`].
    JobDone(JobId),
    /// The token ring changed.
    Ring(FdlEvent),
}

/// Counters of one slave.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SlaveStats {
    /// Data_Exchange cycles completed.
    pub data_exchanges: u64,
    /// Request repetitions at layer 2.
    pub retries: u64,
    /// Requests that got no answer.
    pub errors: u64,
    /// Times the start-up sequence began again.
    pub restarts: u64,
    /// Slave_Diag reads.
    pub diag_reads: u64,
    /// Slave_Diag answers rejected as invalid (shorter than 6 bytes, or
    /// without the SAPs of a Slave_Diag answer); the diagnosis is read
    /// again and nothing is derived from them.
    pub invalid_diags: u64,
    /// Warnings: Slave_Diag answers with the always-1 bit (bit 2 of
    /// Station_Status_2) clear. They are diagnoses all the same (the
    /// SAPs and length of a Slave_Diag answer) and are acted on; older
    /// and home-made slave cores send them.
    pub always_one_clear: u64,
    /// Start-ups that failed (a Prm/Cfg fault, a negative answer to
    /// Set_Prm or Chk_Cfg, Station_Not_Ready for too long) and were
    /// retried after a back-off.
    pub failed_startups: u64,
    /// Answers that came after their request's wait ran out (the retry
    /// had gone out, or the request had failed) and were dropped
    /// ([`profibus_fdl::station::active::ActiveStats::late_replies`]).
    pub late_replies: u64,
}

/// Poll-cycle statistics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct CycleStats {
    /// Completed cycles.
    pub cycles: u64,
    /// Shortest cycle (ns).
    pub min_ns: u64,
    /// Longest cycle (ns).
    pub max_ns: u64,
    /// Sum of cycle times (ns).
    pub sum_ns: u64,
}

impl CycleStats {
    /// Average cycle time.
    pub fn avg(&self) -> Duration {
        Duration::from_nanos(self.sum_ns.checked_div(self.cycles).unwrap_or(0))
    }
}

#[derive(Debug)]
struct Slave {
    p: SlaveParams,
    prm: Vec<u8>,
    input_len: usize,
    output_len: usize,
    state: SlaveState,
    inputs: Vec<u8>,
    outputs: Vec<u8>,
    diag: Vec<u8>,
    need_diag: bool,
    fails: u8,
    not_ready: u16,
    next_probe: Instant,
    last_poll: Option<Instant>,
    last_diag: Instant,
    stats: SlaveStats,
    /// Start-up steps still allowed back to back in this pass.
    chain: u8,
    /// Failed start-ups in a row (0 once in Data_Exchange).
    failed_in_row: u32,
    /// No new start-up before this time (the back-off after a failure).
    retry_at: Instant,
    /// The fault reported last, and how many start-ups ended in it.
    fault: Option<(FaultReason, u64)>,
    /// The ident number reported last in an ident mismatch.
    ident_reported: Option<u16>,
    /// Get_Cfg is due (after a new Cfg_Fault).
    read_cfg: bool,
    /// The slave's answer to the last Get_Cfg.
    actual_cfg: Vec<u8>,
    /// DP-V1 alarms waiting for their Alarm_Ack.
    alarms: alarm::SlaveAlarms,
}

/// The next request of a poll cycle ([`DpMaster::next_cyclic`]).
enum Cyclic {
    GlobalControl(GlobalControl),
    Slave(usize),
}

/// What the request in flight was for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Inflight {
    Slave(usize, Step),
    GlobalControl,
    Job,
    /// Alarm_Ack of slave `.0`'s waiting alarm `.1`.
    AlarmAck(usize, usize),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    Diag,
    SetPrm,
    ChkCfg,
    DataExchange,
    GetCfg,
}

#[derive(Debug)]
struct ActiveJob {
    id: JobId,
    job: Job,
    /// DP-V1: request accepted, polling for the answer since this time.
    polling_since: Option<Instant>,
    buf: Vec<u8>,
}

/// Error building a master from its configuration.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MasterConfigError {
    /// Two slaves share an address.
    #[error("two slaves use address {0}")]
    DuplicateAddress(u8),
    /// A slave address is out of range or the master's own.
    #[error("slave address {0} is invalid (0..=125, not the master's own)")]
    BadAddress(u8),
    /// The configuration bytes of a slave cannot be decoded.
    #[error("slave {address}: {error}")]
    Cfg {
        /// Station address.
        address: u8,
        /// The error.
        error: crate::pdu::cfg::CfgError,
    },
    /// A slave's I/O exceeds 244 bytes in one direction.
    #[error("slave {address}: {input} input / {output} output bytes exceed 244")]
    TooLong {
        /// Station address.
        address: u8,
        /// Input bytes.
        input: usize,
        /// Output bytes.
        output: usize,
    },
    /// The Set_Prm data unit would exceed 244 bytes.
    #[error("slave {0}: Set_Prm exceeds 244 bytes")]
    PrmTooLong(u8),
}

const EVENT_LIMIT: usize = 1024;
const JOB_LIMIT: usize = 64;

/// Start-up steps a slave may take back to back in one pass, right after
/// the previous one succeeded: Set_Prm after the diagnosis that asks for
/// it, Chk_Cfg, the checking Slave_Diag and the first Data_Exchange. A
/// slave that answers again (after a restart, a lost connection) is then
/// back in Data_Exchange in the pass in which it answers, instead of one
/// step per pass; a step that fails or repeats (a fault, Station_Not_Ready)
/// waits for the next pass as before.
const STARTUP_CHAIN: u8 = 4;

/// The DP master core; see the module docs.
#[derive(Debug)]
pub struct DpMaster {
    address: u8,
    options: MasterOptions,
    slaves: Vec<Slave>,
    index: [u8; 128],
    cursor: usize,
    cycle_start: Option<Instant>,
    cycle_stats: CycleStats,
    state: OperatingState,
    inflight: Option<Inflight>,
    gc_queue: VecDeque<GlobalControl>,
    gc_bytes: [u8; 2],
    next_gc: Option<Instant>,
    jobs: VecDeque<(JobId, Job)>,
    active_job: Option<ActiveJob>,
    results: Vec<(JobId, JobResult)>,
    next_job_id: u32,
    events: VecDeque<MasterEvent>,
    events_dropped: u64,
    job_sent_this_visit: bool,
    /// Start of the current token visit.
    visit_start: Instant,
    /// [`MasterOptions::alone_hold_bits`] as a duration
    /// ([`ALONE_VISIT_MAX`] without it).
    alone_hold: Duration,
    live: [Option<StationType>; 128],
    zeros: [u8; 244],
    req: [u8; 248],
    /// The slave whose alarm was acknowledged last.
    alarm_cursor: usize,
}

const NO_SLAVE: u8 = 0xFF;

/// The back-off after the `n`-th failed start-up in a row (n ≥ 1).
fn startup_retry_delay(n: u32) -> Duration {
    let doublings = n.saturating_sub(1).min(16);
    STARTUP_RETRY_FIRST
        .saturating_mul(1 << doublings)
        .min(STARTUP_RETRY_MAX)
}

impl SlaveState {
    /// A step of the start-up sequence (Diag, SetPrm, ChkCfg, CheckDiag).
    fn starting(self) -> bool {
        matches!(
            self,
            SlaveState::Diag | SlaveState::SetPrm | SlaveState::ChkCfg | SlaveState::CheckDiag
        )
    }
}

impl DpMaster {
    /// A master polling the slaves of `cfg`, starting in [`OperatingState::Operate`].
    pub fn new(cfg: &MasterConfig) -> Result<DpMaster, MasterConfigError> {
        let mut index = [NO_SLAVE; 128];
        let mut slaves = Vec::with_capacity(cfg.slaves.len());
        for (i, p) in cfg.slaves.iter().enumerate() {
            if p.address > 125 || p.address == cfg.address {
                return Err(MasterConfigError::BadAddress(p.address));
            }
            if index[p.address as usize] != NO_SLAVE {
                return Err(MasterConfigError::DuplicateAddress(p.address));
            }
            index[p.address as usize] = i as u8;
            let (input_len, output_len) =
                p.io_lengths().map_err(|error| MasterConfigError::Cfg {
                    address: p.address,
                    error,
                })?;
            if input_len > 244 || output_len > 244 {
                return Err(MasterConfigError::TooLong {
                    address: p.address,
                    input: input_len,
                    output: output_len,
                });
            }
            let prm = p.set_prm();
            if prm.len() > 244 {
                return Err(MasterConfigError::PrmTooLong(p.address));
            }
            let mut outputs = vec![0u8; output_len];
            let n = p.initial_outputs.len().min(output_len);
            outputs[..n].copy_from_slice(&p.initial_outputs[..n]);
            slaves.push(Slave {
                p: p.clone(),
                prm,
                input_len,
                output_len,
                state: SlaveState::Diag,
                inputs: vec![0u8; input_len],
                outputs,
                diag: Vec::with_capacity(244),
                need_diag: false,
                fails: 0,
                not_ready: 0,
                next_probe: Instant::ZERO,
                last_poll: None,
                last_diag: Instant::ZERO,
                stats: SlaveStats::default(),
                chain: STARTUP_CHAIN,
                failed_in_row: 0,
                retry_at: Instant::ZERO,
                fault: None,
                ident_reported: None,
                read_cfg: false,
                actual_cfg: Vec::new(),
                alarms: alarm::SlaveAlarms::default(),
            });
        }
        Ok(DpMaster {
            address: cfg.address,
            options: cfg.options.clone(),
            slaves,
            index,
            cursor: 0,
            cycle_start: None,
            cycle_stats: CycleStats::default(),
            state: OperatingState::Operate,
            inflight: None,
            gc_queue: VecDeque::with_capacity(16),
            gc_bytes: [0; 2],
            next_gc: None,
            jobs: VecDeque::with_capacity(JOB_LIMIT),
            active_job: None,
            results: Vec::new(),
            next_job_id: 1,
            events: VecDeque::with_capacity(EVENT_LIMIT),
            events_dropped: 0,
            job_sent_this_visit: false,
            visit_start: Instant::ZERO,
            alone_hold: match cfg.options.alone_hold_bits {
                Some(b) => cfg.params.bits(u64::from(b)),
                None => ALONE_VISIT_MAX,
            },
            live: [None; 128],
            zeros: [0; 244],
            req: [0; 248],
            alarm_cursor: 0,
        })
    }

    /// The master's own address.
    pub fn address(&self) -> u8 {
        self.address
    }

    /// Addresses of the configured slaves, in poll order.
    pub fn slave_addresses(&self) -> impl Iterator<Item = u8> + '_ {
        self.slaves.iter().map(|s| s.p.address)
    }

    fn by_address(&self, address: u8) -> Option<&Slave> {
        let i = *self.index.get(address as usize)?;
        self.slaves.get(i as usize)
    }

    /// The configuration of a slave.
    pub fn slave_params(&self, address: u8) -> Option<&SlaveParams> {
        self.by_address(address).map(|s| &s.p)
    }

    /// The handle of the slave at `address`.
    pub fn handle(&self, address: u8) -> Option<SlaveHandle> {
        let i = *self.index.get(address as usize)?;
        (i != NO_SLAVE).then_some(SlaveHandle(i))
    }

    /// Everything about one slave.
    pub fn slave(&self, h: SlaveHandle) -> SlaveView<'_> {
        let s = &self.slaves[h.0 as usize];
        SlaveView {
            address: s.p.address,
            state: s.state,
            inputs: &s.inputs,
            outputs: &s.outputs,
            diag: &s.diag,
            stats: s.stats,
        }
    }

    /// The output image of a slave, to write in place.
    pub fn outputs_mut(&mut self, h: SlaveHandle) -> &mut [u8] {
        &mut self.slaves[h.0 as usize].outputs
    }

    /// The state, counters and both process images of a slave, the
    /// outputs writable: for helpers that answer the inputs in the
    /// outputs without copying (e.g. a PKW client).
    pub fn io_mut(&mut self, h: SlaveHandle) -> SlaveIoMut<'_> {
        let s = &mut self.slaves[h.0 as usize];
        SlaveIoMut {
            state: s.state,
            stats: s.stats,
            inputs: &s.inputs,
            outputs: &mut s.outputs,
        }
    }

    /// A slave's state.
    pub fn slave_state(&self, address: u8) -> Option<SlaveState> {
        self.by_address(address).map(|s| s.state)
    }

    /// A slave's input image (the last inputs received).
    pub fn inputs(&self, address: u8) -> Option<&[u8]> {
        self.by_address(address).map(|s| &s.inputs[..])
    }

    /// A slave's output image.
    pub fn outputs(&self, address: u8) -> Option<&[u8]> {
        self.by_address(address).map(|s| &s.outputs[..])
    }

    /// Write a slave's outputs (copied into its image; shorter data leave
    /// the rest unchanged, longer data are cut). Returns false for an
    /// unknown slave.
    pub fn set_outputs(&mut self, address: u8, data: &[u8]) -> bool {
        let Some(&i) = self.index.get(address as usize) else {
            return false;
        };
        let Some(s) = self.slaves.get_mut(i as usize) else {
            return false;
        };
        let n = data.len().min(s.output_len);
        s.outputs[..n].copy_from_slice(&data[..n]);
        true
    }

    /// The last diagnosis read from a slave (empty before the first).
    pub fn diag(&self, address: u8) -> Option<&[u8]> {
        self.by_address(address).map(|s| &s.diag[..])
    }

    /// The slave's answer to the Get_Cfg read after its last Cfg_Fault
    /// (empty before; see [`MasterEvent::CfgMismatch`]).
    pub fn actual_cfg(&self, address: u8) -> Option<&[u8]> {
        self.by_address(address).map(|s| &s.actual_cfg[..])
    }

    /// A slave's counters.
    pub fn slave_stats(&self, address: u8) -> Option<SlaveStats> {
        self.by_address(address).map(|s| s.stats)
    }

    /// Poll-cycle statistics.
    pub fn cycle_stats(&self) -> CycleStats {
        self.cycle_stats
    }

    /// Start the poll-cycle statistics afresh (e.g. after start-up).
    pub fn reset_cycle_stats(&mut self) {
        self.cycle_stats = CycleStats::default();
    }

    /// Operating state.
    pub fn operating_state(&self) -> OperatingState {
        self.state
    }

    /// Change the operating state; Clear and Operate are announced with a
    /// Global_Control to all slaves.
    pub fn set_operating_state(&mut self, state: OperatingState) {
        if state == self.state {
            return;
        }
        self.state = state;
        let command = if state == OperatingState::Clear {
            ControlCommand::CLEAR_DATA
        } else {
            ControlCommand::empty()
        };
        if state != OperatingState::Stop {
            self.global_control(command, 0);
        }
    }

    /// Whether a queued Global_Control is still to be sent.
    pub fn global_control_pending(&self) -> bool {
        !self.gc_queue.is_empty()
    }

    /// Queue a Global_Control (sync/unsync, freeze/unfreeze, clear) for
    /// the groups in `group_select` (0 = all). The Clear_Data bit follows
    /// the operating state. Returns false when the queue is full.
    pub fn global_control(&mut self, command: ControlCommand, group_select: u8) -> bool {
        if self.gc_queue.len() >= 16 {
            return false;
        }
        let mut command = command;
        command.set(
            ControlCommand::CLEAR_DATA,
            self.state == OperatingState::Clear,
        );
        self.gc_queue.push_back(GlobalControl {
            command,
            group_select,
        });
        true
    }

    /// Queue a class-2 service or DP-V1 request. `None` when the queue is
    /// full.
    pub fn submit(&mut self, job: Job) -> Option<JobId> {
        if self.jobs.len() >= JOB_LIMIT {
            return None;
        }
        let id = JobId(self.next_job_id);
        self.next_job_id = self.next_job_id.wrapping_add(1);
        self.jobs.push_back((id, job));
        Some(id)
    }

    /// Take the result of a finished job.
    pub fn take_result(&mut self, id: JobId) -> Option<JobResult> {
        let i = self.results.iter().position(|(j, _)| *j == id)?;
        Some(self.results.swap_remove(i).1)
    }

    /// Whether jobs are queued or running.
    pub fn jobs_pending(&self) -> bool {
        !self.jobs.is_empty() || self.active_job.is_some()
    }

    /// Stations found by the GAP polls of this master's station (the part
    /// of the live list between this master and its successor).
    pub fn live_list(&self) -> impl Iterator<Item = (u8, StationType)> + '_ {
        self.live
            .iter()
            .enumerate()
            .filter_map(|(a, t)| t.map(|t| (a as u8, t)))
    }

    /// The next event.
    pub fn poll_event(&mut self) -> Option<MasterEvent> {
        self.events.pop_front()
    }

    /// Events lost because nobody fetched them (the queue holds 1024).
    pub fn events_dropped(&self) -> u64 {
        self.events_dropped
    }

    fn events_push_alarm(&mut self, address: u8, alarm: AlarmNotice) {
        self.emit(MasterEvent::Alarm { address, alarm });
    }

    fn emit(&mut self, e: MasterEvent) {
        if self.events.len() >= EVENT_LIMIT {
            self.events.pop_front();
            self.events_dropped += 1;
        }
        self.events.push_back(e);
    }

    fn set_state(&mut self, i: usize, to: SlaveState) {
        let from = self.slaves[i].state;
        if from == to {
            return;
        }
        let s = &mut self.slaves[i];
        s.state = to;
        if to == SlaveState::Diag && from != SlaveState::Offline {
            s.stats.restarts += 1;
        }
        if to != SlaveState::DataExchange {
            s.need_diag = false;
        }
        let address = s.p.address;
        if from == SlaveState::DataExchange {
            let why = format!("the slave left Data_Exchange ({})", to.name());
            for alarm in s.alarms.abandon(&why) {
                tracing::warn!(
                    address,
                    "DP-V1 alarm {}",
                    alarm.problem.as_deref().unwrap_or("")
                );
                self.events_push_alarm(address, alarm);
            }
        }
        let s = &mut self.slaves[i];
        tracing::debug!(address, from = from.name(), to = to.name(), "slave state");
        // The steps of a start-up retried after a failure are not
        // reported again: the fault (and its end) tells what happens.
        let retry = s.failed_in_row > 0 && from.starting() && to.starting();
        if to == SlaveState::DataExchange {
            s.failed_in_row = 0;
            s.ident_reported = None;
            if let Some((reason, repeats)) = s.fault.take() {
                tracing::info!(address, %reason, repeats, "slave fault ended");
                self.emit(MasterEvent::FaultEnded {
                    address,
                    reason,
                    repeats,
                });
            }
        }
        if !retry {
            self.emit(MasterEvent::StateChanged { address, from, to });
        }
    }

    /// A start-up of slave `i` failed: back to Slave_Diag after the
    /// back-off ([`STARTUP_RETRY_FIRST`] doubled per failure in a row, at
    /// most [`STARTUP_RETRY_MAX`]).
    fn startup_failed(&mut self, i: usize, now: Instant) {
        self.set_state(i, SlaveState::Diag);
        let s = &mut self.slaves[i];
        s.stats.failed_startups += 1;
        s.failed_in_row = s.failed_in_row.saturating_add(1);
        s.retry_at = now + startup_retry_delay(s.failed_in_row);
        if let Some((_, repeats)) = &mut s.fault {
            *repeats += 1;
        }
    }

    /// Report `reason` for slave `i` unless it is the fault reported last
    /// (then it only counts, in [`Self::startup_failed`]). A new Cfg_Fault
    /// asks for the slave's real configuration (Get_Cfg).
    fn fault(&mut self, i: usize, reason: FaultReason) {
        use crate::pdu::diag::StationStatus1 as S1;
        let s = &mut self.slaves[i];
        let address = s.p.address;
        if s.fault.as_ref().is_some_and(|(f, _)| f.same_as(&reason)) {
            return;
        }
        if let Some((old, repeats)) = s.fault.take() {
            self.emit(MasterEvent::FaultEnded {
                address,
                reason: old,
                repeats,
            });
        }
        let s = &mut self.slaves[i];
        s.fault = Some((reason, 0));
        if let FaultReason::Station { status1, .. } = reason {
            if status1.contains(S1::CFG_FAULT) {
                s.read_cfg = true;
            }
        }
        tracing::warn!(address, %reason, "slave fault");
        self.emit(MasterEvent::Fault { address, reason });
    }

    /// Whether slave `i` is to be polled in this pass at `now`.
    fn due(&self, i: usize, now: Instant) -> bool {
        now >= self.due_at(i)
    }

    /// From when slave `i` may be polled: its probe time (offline,
    /// locked), its start-up retry time, and its Min_Slave_Interval after
    /// the last poll (GSD `Min_Slave_Intervall`, in units of 100 µs).
    fn due_at(&self, i: usize) -> Instant {
        let s = &self.slaves[i];
        if s.state == SlaveState::Offline || s.state == SlaveState::Locked {
            return s.next_probe;
        }
        let interval = s
            .last_poll
            .map_or(Instant::ZERO, |t| t + s.p.min_slave_interval);
        if s.state == SlaveState::Diag && !s.read_cfg {
            return interval.max(s.retry_at);
        }
        interval
    }

    fn slave_request(&mut self, i: usize, now: Instant) -> Request<'_> {
        let periodic_diag = self
            .options
            .diag_interval
            .is_some_and(|d| now >= self.slaves[i].last_diag + d);
        let stop = self.state == OperatingState::Stop;
        let s = &mut self.slaves[i];
        s.last_poll = Some(now);
        let da = s.p.address;
        let diag = |da| Request {
            da,
            service: Service::SrdHigh,
            dsap: Some(sap::SLAVE_DIAG),
            ssap: Some(sap::MASTER),
            data: &[],
            max_reply_len: Some(crate::pdu::diag::MAX_DIAG_LEN as u8),
        };
        let (step, req) = match s.state {
            SlaveState::Diag if s.read_cfg => (
                Step::GetCfg,
                Request {
                    da,
                    service: Service::SrdHigh,
                    dsap: Some(sap::GET_CFG),
                    ssap: Some(sap::MASTER),
                    data: &[],
                    // Up to 244 bytes: as long as the longest telegram.
                    max_reply_len: None,
                },
            ),
            SlaveState::Offline | SlaveState::Diag | SlaveState::CheckDiag | SlaveState::Locked => {
                (Step::Diag, diag(da))
            }
            SlaveState::DataExchange if s.need_diag || periodic_diag || stop => {
                (Step::Diag, diag(da))
            }
            SlaveState::SetPrm => (
                Step::SetPrm,
                Request {
                    da,
                    service: Service::SrdHigh,
                    dsap: Some(sap::SET_PRM),
                    ssap: Some(sap::MASTER),
                    data: &s.prm,
                    // A short acknowledge, or a negative one.
                    max_reply_len: Some(0),
                },
            ),
            SlaveState::ChkCfg => (
                Step::ChkCfg,
                Request {
                    da,
                    service: Service::SrdHigh,
                    dsap: Some(sap::CHK_CFG),
                    ssap: Some(sap::MASTER),
                    data: &s.p.cfg,
                    max_reply_len: Some(0),
                },
            ),
            SlaveState::DataExchange => {
                let data: &[u8] = match self.state {
                    OperatingState::Operate => &s.outputs,
                    _ if s.p.fail_safe => &[],
                    _ => &self.zeros[..s.output_len],
                };
                (
                    Step::DataExchange,
                    Request {
                        da,
                        service: Service::SrdHigh,
                        dsap: None,
                        ssap: None,
                        data,
                        // The inputs (at most 244 bytes, checked in `new`).
                        max_reply_len: Some(s.input_len as u8),
                    },
                )
            }
        };
        self.inflight = Some(Inflight::Slave(i, step));
        req
    }

    fn slave_failed(&mut self, i: usize, now: Instant) {
        let lost_after = self.options.lost_after.max(1);
        let reprobe = self.options.reprobe_interval;
        let s = &mut self.slaves[i];
        s.stats.errors += 1;
        s.fails = s.fails.saturating_add(1);
        match s.state {
            SlaveState::Offline | SlaveState::Locked => s.next_probe = now + reprobe,
            _ if s.fails >= lost_after => {
                s.next_probe = now + reprobe;
                self.set_state(i, SlaveState::Offline);
            }
            _ => {}
        }
    }

    fn slave_result(&mut self, i: usize, step: Step, now: Instant, r: &CycleResult<'_>) {
        let before = self.slaves[i].state;
        self.slave_outcome(i, step, now, r);
        // A start-up step succeeded: take the next one at once (see
        // STARTUP_CHAIN), if this slave was just polled in the pass.
        let s = &mut self.slaves[i];
        let next = matches!(
            s.state,
            SlaveState::SetPrm
                | SlaveState::ChkCfg
                | SlaveState::CheckDiag
                | SlaveState::DataExchange
        );
        if next && s.state != before && s.chain > 0 && self.cursor == i + 1 {
            s.chain -= 1;
            self.cursor = i;
        }
    }

    fn slave_outcome(&mut self, i: usize, step: Step, now: Instant, r: &CycleResult<'_>) {
        self.slaves[i].stats.retries += r.retries as u64;
        let acked = matches!(
            r.outcome,
            Outcome::ShortAck
                | Outcome::Response {
                    status: ResponseStatus::Ok,
                    ..
                }
        );
        if step == Step::GetCfg {
            // Asked once per new Cfg_Fault, whatever the answer.
            self.slaves[i].read_cfg = false;
        }
        match (step, r.outcome) {
            (_, Outcome::NoResponse) => self.slave_failed(i, now),
            (
                Step::GetCfg,
                Outcome::Response {
                    status,
                    data,
                    dsap,
                    ssap,
                    ..
                },
            ) if !status.is_negative()
                && (dsap, ssap) == (Some(sap::MASTER), Some(sap::GET_CFG)) =>
            {
                let s = &mut self.slaves[i];
                s.fails = 0;
                s.actual_cfg.clear();
                s.actual_cfg.extend_from_slice(&data[..data.len().min(244)]);
                let address = s.p.address;
                self.emit(MasterEvent::CfgMismatch { address });
            }
            (Step::GetCfg, _) => {
                // No configuration to show (refused, or no answer data).
                self.slaves[i].fails = 0;
                let address = self.slaves[i].p.address;
                tracing::debug!(address, "no answer data to Get_Cfg");
            }
            (
                Step::Diag,
                Outcome::Response {
                    data,
                    status,
                    dsap,
                    ssap,
                    ..
                },
            ) if !status.is_negative() => {
                self.slaves[i].fails = 0;
                let saps = (dsap, ssap) == (Some(sap::MASTER), Some(sap::SLAVE_DIAG));
                self.on_diag(i, data, saps, now);
            }
            (Step::SetPrm, _) if acked => {
                self.slaves[i].fails = 0;
                self.set_state(i, SlaveState::ChkCfg);
            }
            (Step::ChkCfg, _) if acked => {
                self.slaves[i].fails = 0;
                self.slaves[i].not_ready = 0;
                self.set_state(i, SlaveState::CheckDiag);
            }
            (
                Step::DataExchange,
                Outcome::Response {
                    status: status @ (ResponseStatus::Dl | ResponseStatus::Dh),
                    data,
                    ..
                },
            ) => {
                let s = &mut self.slaves[i];
                s.fails = 0;
                s.stats.data_exchanges += 1;
                let n = data.len().min(s.input_len);
                s.inputs[..n].copy_from_slice(&data[..n]);
                if status == ResponseStatus::Dh {
                    s.need_diag = true;
                }
            }
            (Step::DataExchange, Outcome::ShortAck) => {
                let s = &mut self.slaves[i];
                s.fails = 0;
                s.stats.data_exchanges += 1;
            }
            (_, Outcome::Response { status, .. }) => {
                // A negative answer: the slave is not in the state we
                // thought (e.g. RS to Data_Exchange after a restart). To
                // Set_Prm or Chk_Cfg, the start-up failed.
                let s = &mut self.slaves[i];
                let address = s.p.address;
                s.fails = 0;
                if s.failed_in_row == 0 {
                    tracing::info!(
                        address,
                        status = status.mnemonic(),
                        ?step,
                        "negative answer"
                    );
                }
                if matches!(step, Step::SetPrm | Step::ChkCfg) {
                    self.startup_failed(i, now);
                } else {
                    self.set_state(i, SlaveState::Diag);
                }
            }
            (_, Outcome::ShortAck | Outcome::Sent) => {
                // SC to Slave_Diag: no diagnosis data; ask again.
                self.slaves[i].fails = 0;
            }
        }
    }

    /// A Slave_Diag answer of slave `i`; `saps`: it carries the SAPs of
    /// a Slave_Diag answer (DSAP 62, SSAP 60: the request's swapped).
    fn on_diag(&mut self, i: usize, data: &[u8], saps: bool, now: Instant) {
        let me = self.address;
        let s = &mut self.slaves[i];
        s.stats.diag_reads += 1;
        let d = match SlaveDiag::parse(data) {
            Ok(d) if saps => d,
            _ => {
                // Not a diagnosis (shorter than 6 bytes, or without the
                // SAPs of a Slave_Diag answer: a stray reply, e.g. a late
                // Data_Exchange answer). Count it, keep the last
                // diagnosis and state, and read it again.
                s.stats.invalid_diags += 1;
                s.need_diag = true;
                tracing::debug!(
                    address = s.p.address,
                    len = data.len(),
                    saps,
                    "invalid Slave_Diag answer ignored"
                );
                return;
            }
        };
        if !d.is_valid() {
            // The always-1 bit clear: a diagnosis all the same (the SAPs
            // and the length say so), acted on; counted as a warning,
            // logged once per slave.
            s.stats.always_one_clear += 1;
            if s.stats.always_one_clear == 1 {
                tracing::warn!(
                    address = s.p.address,
                    "Slave_Diag with the always-1 bit (Station_Status_2 bit 2) clear: \
                     taken as a diagnosis"
                );
            }
        }
        s.last_diag = now;
        s.need_diag = false;
        if s.p.dpv1 && !s.p.alarms.is_empty() {
            s.alarms.on_diag(&d);
        }
        let changed = s.diag != data;
        if changed {
            s.diag.clear();
            s.diag.extend_from_slice(&data[..data.len().min(244)]);
        }
        let address = s.p.address;
        if changed {
            self.emit(MasterEvent::Diag { address });
        }
        use crate::pdu::diag::{StationStatus1 as S1, StationStatus2 as S2};
        let state = self.slaves[i].state;
        let ident = self.slaves[i].p.ident_number;
        let locked_by_other = d.master_address != crate::pdu::diag::NO_MASTER
            && d.master_address != me
            && !d.status2.contains(S2::PRM_REQ);
        match state {
            SlaveState::Offline | SlaveState::Diag | SlaveState::Locked => {
                if locked_by_other {
                    // Parameterised by another master: hands off.
                    let reprobe = self.options.reprobe_interval;
                    self.slaves[i].next_probe = now + reprobe;
                    self.set_state(i, SlaveState::Locked);
                } else {
                    let s = &mut self.slaves[i];
                    if d.ident_number != ident && s.ident_reported != Some(d.ident_number) {
                        s.ident_reported = Some(d.ident_number);
                        tracing::warn!(
                            address,
                            reported = d.ident_number,
                            expected = ident,
                            "slave reports another ident number"
                        );
                        self.emit(MasterEvent::Fault {
                            address,
                            reason: FaultReason::IdentMismatch {
                                reported: d.ident_number,
                                expected: ident,
                            },
                        });
                    }
                    if state == SlaveState::Offline || state == SlaveState::Locked {
                        self.set_state(i, SlaveState::Diag);
                    }
                    self.set_state(i, SlaveState::SetPrm);
                }
            }
            SlaveState::CheckDiag => {
                if d.ready_for(me) {
                    self.set_state(i, SlaveState::DataExchange);
                } else if d
                    .status1
                    .intersects(S1::PRM_FAULT | S1::CFG_FAULT | S1::NOT_SUPPORTED)
                {
                    self.fault(i, FaultReason::station(&d));
                    self.startup_failed(i, now);
                } else if d.status2.contains(S2::PRM_REQ) || locked_by_other {
                    self.startup_failed(i, now);
                } else {
                    let limit = self.options.not_ready_limit;
                    let s = &mut self.slaves[i];
                    s.not_ready += 1;
                    if s.not_ready > limit {
                        self.startup_failed(i, now);
                    }
                }
            }
            SlaveState::DataExchange => {
                if !d.ready_for(me) && !d.status2.contains(S2::STAT_DIAG) {
                    if d.status1.intersects(S1::PRM_FAULT | S1::CFG_FAULT) {
                        self.fault(i, FaultReason::station(&d));
                        self.startup_failed(i, now);
                    } else {
                        self.set_state(i, SlaveState::Diag);
                    }
                } else if d.status2.contains(S2::STAT_DIAG) {
                    // Static diagnosis: keep reading it, no data exchange.
                    self.slaves[i].need_diag = true;
                }
            }
            SlaveState::SetPrm | SlaveState::ChkCfg => {}
        }
    }

    fn job_request(&mut self) -> Option<Request<'_>> {
        if self.active_job.is_none() {
            let (id, job) = self.jobs.pop_front()?;
            // DP-V1 needs the slave in data exchange with us.
            if matches!(job, Job::Dpv1Read { .. } | Job::Dpv1Write { .. })
                && self.slave_state(job.address()) != Some(SlaveState::DataExchange)
            {
                self.finish_job(id, JobResult::NotInDataExchange);
                return None;
            }
            self.active_job = Some(ActiveJob {
                id,
                job,
                polling_since: None,
                buf: Vec::new(),
            });
        }
        let j = self.active_job.as_mut()?;
        let da = j.job.address();
        let max_reply_len = match j.job {
            Job::SetSlaveAdd { .. } => Some(0),
            Job::ReadDiag { .. } => Some(crate::pdu::diag::MAX_DIAG_LEN as u8),
            // Get_Cfg, Rd_Inp, Rd_Outp of any slave and DP-V1 answers
            // carry up to 244 bytes: as long as the longest telegram.
            _ => None,
        };
        let (dsap, ssap, len) = match (&j.job, j.polling_since) {
            (Job::ReadDiag { .. }, _) => (sap::SLAVE_DIAG, sap::MASTER, 0),
            (Job::GetCfg { .. }, _) => (sap::GET_CFG, sap::MASTER, 0),
            (Job::RdInp { .. }, _) => (sap::RD_INP, sap::MASTER, 0),
            (Job::RdOutp { .. }, _) => (sap::RD_OUTP, sap::MASTER, 0),
            (
                Job::SetSlaveAdd {
                    new_address,
                    ident_number,
                    no_add_chg,
                    ..
                },
                _,
            ) => {
                let n = SetSlaveAdd {
                    new_address: *new_address,
                    ident_number: *ident_number,
                    no_add_chg: *no_add_chg,
                    rem_slave_data: &[],
                }
                .emit(&mut self.req)
                .unwrap_or(0);
                (sap::SET_SLAVE_ADD, sap::MASTER, n)
            }
            (Job::Dpv1Read { .. } | Job::Dpv1Write { .. }, Some(_)) => {
                (sap::MSAC_C1, sap::MSAC_C1, 0)
            }
            (
                Job::Dpv1Read {
                    slot,
                    index,
                    length,
                    ..
                },
                None,
            ) => {
                let n = Pdu::ReadReq {
                    slot: *slot,
                    index: *index,
                    length: *length,
                }
                .emit(&mut self.req)
                .unwrap_or(0);
                (sap::MSAC_C1, sap::MSAC_C1, n)
            }
            (
                Job::Dpv1Write {
                    slot, index, data, ..
                },
                None,
            ) => {
                let n = Pdu::WriteReq {
                    slot: *slot,
                    index: *index,
                    data,
                }
                .emit(&mut self.req)
                .unwrap_or(0);
                (sap::MSAC_C1, sap::MSAC_C1, n)
            }
        };
        self.inflight = Some(Inflight::Job);
        Some(Request {
            da,
            service: Service::SrdHigh,
            dsap: Some(dsap),
            ssap: Some(ssap),
            data: &self.req[..len],
            max_reply_len,
        })
    }

    fn finish_job(&mut self, id: JobId, result: JobResult) {
        if self.results.len() >= JOB_LIMIT {
            self.results.remove(0);
        }
        self.results.push((id, result));
        self.emit(MasterEvent::JobDone(id));
    }

    fn job_result(&mut self, now: Instant, r: &CycleResult<'_>) {
        let Some(mut j) = self.active_job.take() else {
            return;
        };
        let dpv1 = matches!(j.job, Job::Dpv1Read { .. } | Job::Dpv1Write { .. });
        let result = match r.outcome {
            Outcome::NoResponse => Some(JobResult::NoResponse),
            Outcome::Sent => Some(JobResult::NoResponse),
            Outcome::ShortAck if dpv1 => {
                // Accepted; the answer is not ready yet: poll on.
                let since = *j.polling_since.get_or_insert(now);
                let timeout = self
                    .by_address(j.job.address())
                    .map_or(Duration::from_secs(1), |s| s.p.dpv1_timeout);
                (now >= since + timeout).then_some(JobResult::Timeout)
            }
            Outcome::ShortAck => Some(match j.job {
                Job::SetSlaveAdd { .. } => JobResult::Done,
                _ => JobResult::Data(Vec::new()),
            }),
            Outcome::Response { status, data, .. } => Some(if status.is_negative() {
                JobResult::Refused(status)
            } else if dpv1 {
                match Pdu::parse_response(data) {
                    Ok(Pdu::ReadRes { data, .. }) => JobResult::Data(data.to_vec()),
                    Ok(Pdu::WriteRes { .. }) => JobResult::Done,
                    Ok(Pdu::Error(e)) => JobResult::Dpv1Error(e),
                    Ok(_) => JobResult::BadResponse(BadResponse::UnexpectedPdu {
                        function: data.first().copied().unwrap_or(0),
                    }),
                    Err(e) => JobResult::BadResponse(e.into()),
                }
            } else if let Job::SetSlaveAdd { .. } = j.job {
                JobResult::Done
            } else {
                j.buf.clear();
                j.buf.extend_from_slice(data);
                JobResult::Data(std::mem::take(&mut j.buf))
            }),
        };
        match result {
            Some(res) => self.finish_job(j.id, res),
            None => self.active_job = Some(j),
        }
    }

    /// A slave in Data_Exchange with an alarm waiting for its Alarm_Ack,
    /// the one after the slave acknowledged last first (round robin).
    fn alarm_due(&self) -> Option<usize> {
        let n = self.slaves.len();
        (1..=n).map(|k| (self.alarm_cursor + k) % n).find(|&i| {
            let s = &self.slaves[i];
            s.state == SlaveState::DataExchange && s.alarms.waiting()
        })
    }

    /// The Alarm_Ack of slave `i`'s next alarm (in sequence-number
    /// order): MSAC_C1 from SAP 51 to SAP 50, `5C slot type specifier`,
    /// or an empty poll for the answer.
    fn alarm_request(&mut self, i: usize) -> Request<'_> {
        self.alarm_cursor = i;
        let s = &self.slaves[i];
        let k = s.alarms.next().unwrap_or(0);
        let len = s.alarms.request(k, &mut self.req);
        self.inflight = Some(Inflight::AlarmAck(i, k));
        Request {
            da: s.p.address,
            service: Service::SrdHigh,
            dsap: Some(sap::ALARM_ACK),
            ssap: Some(sap::MSAC_C1),
            data: &self.req[..len],
            // The echo, or a 4-byte negative response.
            max_reply_len: Some(4),
        }
    }

    fn alarm_result(&mut self, i: usize, k: usize, now: Instant, r: &CycleResult<'_>) {
        use alarm::AckOutcome;
        let Some(s) = self.slaves.get_mut(i) else {
            return;
        };
        let outcome = match r.outcome {
            Outcome::NoResponse | Outcome::Sent => AckOutcome::Failed("no answer".into()),
            Outcome::ShortAck => AckOutcome::Poll,
            Outcome::Response { status, .. } if status.is_negative() => {
                AckOutcome::Failed(format!("refused by the slave ({})", status.mnemonic()))
            }
            Outcome::Response { data, .. } => match Pdu::parse_response(data) {
                Ok(Pdu::AlarmAck {
                    slot,
                    alarm_type,
                    specifier,
                }) if s.alarms.answers(k, slot, alarm_type, specifier) => AckOutcome::Confirmed,
                Ok(Pdu::Error(e)) => AckOutcome::Failed(e.describe()),
                _ => AckOutcome::Failed(format!(
                    "the answer {} is not the Alarm_Ack's echo",
                    profibus_fdl::wire::Hex(data)
                )),
            },
        };
        let address = s.p.address;
        let timeout = s.p.dpv1_timeout;
        if let Some(alarm) = s.alarms.outcome(k, outcome, now, timeout) {
            if !alarm.acknowledged {
                tracing::warn!(
                    address,
                    "DP-V1 alarm {}",
                    alarm.problem.as_deref().unwrap_or("")
                );
            }
            self.events_push_alarm(address, alarm);
        }
    }

    fn start_visit(&mut self, now: Instant) {
        self.job_sent_this_visit = false;
        self.visit_start = now;
        if self.cursor >= self.slaves.len() {
            self.start_poll_cycle(now);
        }
        self.queue_cyclic_global_control(now);
    }

    /// Begin a new poll cycle (every slave once, from the first) and count
    /// the cycle time of the one that ended.
    fn start_poll_cycle(&mut self, now: Instant) {
        self.cursor = 0;
        for s in &mut self.slaves {
            s.chain = STARTUP_CHAIN;
        }
        if let Some(start) = self.cycle_start {
            let ns = (now - start).as_nanos() as u64;
            let c = &mut self.cycle_stats;
            c.min_ns = if c.cycles == 0 { ns } else { c.min_ns.min(ns) };
            c.max_ns = c.max_ns.max(ns);
            c.sum_ns += ns;
            c.cycles += 1;
        }
        self.cycle_start = Some(now);
    }

    /// Queue the cyclic operate/clear Global_Control when its period has
    /// passed.
    fn queue_cyclic_global_control(&mut self, now: Instant) {
        if let Some(iv) = self.options.global_control_interval {
            if self.state != OperatingState::Stop
                && self.next_gc.is_none_or(|t| now >= t)
                && self.gc_queue.is_empty()
            {
                self.next_gc = Some(now + iv);
                let command = if self.state == OperatingState::Clear {
                    ControlCommand::CLEAR_DATA
                } else {
                    ControlCommand::empty()
                };
                self.gc_queue.push_back(GlobalControl {
                    command,
                    group_select: 0,
                });
            }
        }
    }

    /// Alone in the ring: whether one more poll cycle started at `at`,
    /// as long as the last one, ends within the token hold time and the
    /// visit's share (alone_hold_bits, by default ALONE_VISIT_MAX).
    fn next_cycle_fits(&self, at: Instant, ctx: &TokenContext) -> bool {
        self.cycle_start.is_some_and(|start| {
            let end = at + (at - start);
            end < ctx.hold_until && end <= self.visit_start + self.alone_hold
        })
    }

    /// Any slave due for a poll now (its Min_Slave_Interval passed, or its
    /// probe time come)?
    fn any_due(&self, now: Instant) -> bool {
        (0..self.slaves.len()).any(|i| self.due(i, now))
    }

    /// The broadcast SDN request of a Global_Control.
    /// What the running poll cycle sends next: a queued Global_Control
    /// first (broadcast SDN), then the next due slave.
    fn next_cyclic(&mut self, now: Instant) -> Option<Cyclic> {
        if let Some(gc) = self.gc_queue.pop_front() {
            return Some(Cyclic::GlobalControl(gc));
        }
        while self.cursor < self.slaves.len() {
            let i = self.cursor;
            self.cursor += 1;
            if self.due(i, now) {
                return Some(Cyclic::Slave(i));
            }
        }
        None
    }

    fn cyclic_request(&mut self, next: Cyclic, now: Instant) -> Request<'_> {
        match next {
            Cyclic::GlobalControl(gc) => self.global_control_request(gc),
            Cyclic::Slave(i) => self.slave_request(i, now),
        }
    }

    fn global_control_request(&mut self, gc: GlobalControl) -> Request<'_> {
        self.gc_bytes = gc.to_bytes();
        self.inflight = Some(Inflight::GlobalControl);
        Request {
            da: consts::BROADCAST,
            service: Service::SdnHigh,
            dsap: Some(sap::GLOBAL_CONTROL),
            ssap: Some(sap::MASTER),
            data: &self.gc_bytes,
            // SDN: never answered.
            max_reply_len: None,
        }
    }
}

impl MasterApp for DpMaster {
    fn poll_request(&mut self, ctx: &TokenContext) -> Option<Request<'_>> {
        let now = ctx.now;
        if ctx.cycles == 0 {
            self.start_visit(now);
        }
        if let Some(next) = self.next_cyclic(now) {
            return Some(self.cyclic_request(next, now));
        }
        if ctx.high_only {
            return None;
        }
        // After the pass: at most one acyclic request per poll cycle.
        if !self.job_sent_this_visit {
            self.job_sent_this_visit = true;
            if let Some(i) = self.alarm_due() {
                return Some(self.alarm_request(i));
            }
            if self.jobs_pending() {
                return self.job_request();
            }
        }
        // Alone in the ring the token only comes back here: rather than
        // pass it to itself after every poll cycle, start the next cycle
        // at once when one more cycle as long as the last ends within the
        // token hold time and the visit's share (alone_hold_bits, by
        // default ALONE_VISIT_MAX), and a slave is due. The visit still ends with time left, so its GAP
        // poll (how a new master joins) is made.
        if ctx.alone && self.next_cycle_fits(now, ctx) && self.any_due(now) {
            self.start_poll_cycle(now);
            self.queue_cyclic_global_control(now);
            self.job_sent_this_visit = false;
            if let Some(next) = self.next_cyclic(now) {
                return Some(self.cyclic_request(next, now));
            }
        }
        None
    }

    /// Alone in the ring, with no slave due yet: the time the next one
    /// is (its Min_Slave_Interval ends), if a cycle started then still
    /// fits the visit. The station then idles with the token until then
    /// instead of passing it to itself: with one fast slave (a cycle
    /// shorter than its Min_Slave_Interval) the token would otherwise
    /// go round after almost every cycle.
    fn next_request_at(&self, ctx: &TokenContext) -> Option<Instant> {
        if !ctx.alone || ctx.high_only {
            return None;
        }
        let t = (0..self.slaves.len()).map(|i| self.due_at(i)).min()?;
        (t > ctx.now && self.next_cycle_fits(t, ctx)).then_some(t)
    }

    fn on_result(&mut self, now: Instant, r: &CycleResult<'_>) {
        match self.inflight.take() {
            Some(Inflight::Slave(i, step)) => self.slave_result(i, step, now, r),
            Some(Inflight::Job) => self.job_result(now, r),
            Some(Inflight::AlarmAck(i, k)) => self.alarm_result(i, k, now, r),
            Some(Inflight::GlobalControl) | None => {}
        }
    }

    fn on_event(&mut self, _now: Instant, event: FdlEvent) {
        // GAP polls repeat every sweep: report only what changed.
        if let FdlEvent::GapStatus { address, station } = event {
            let slot = &mut self.live[address as usize & 0x7F];
            if *slot == station {
                return;
            }
            let was_known = slot.is_some();
            *slot = station;
            if station.is_none() && !was_known {
                return;
            }
        }
        self.emit(MasterEvent::Ring(event));
    }

    fn on_late_reply(&mut self, _now: Instant, from: Option<u8>) {
        let i = from.and_then(|a| self.index.get(a as usize).copied());
        if let Some(s) = i.and_then(|i| self.slaves.get_mut(i as usize)) {
            s.stats.late_replies += 1;
        }
    }
}

#[cfg(test)]
mod tests;
