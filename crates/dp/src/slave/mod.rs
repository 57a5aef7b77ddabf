//! The DP slave: a sans-IO state machine (Wait_Prm → Wait_Cfg →
//! Data_Exch) behind [`profibus_fdl::station::passive::PassiveStation`].
//!
//! [`DpSlave`] implements the layer-2 [`Responder`]: the passive station
//! frames requests for its address, keeps the FCB rule and the min TSDR,
//! and hands each request to the slave, which answers it for a
//! [`Device`] (what the emulated product does: its ident number,
//! parameters, configuration, process data, diagnosis, DP-V1 records).
//!
//! ```
//! use profibus_dp::pdu::prm::SetPrm;
//! use profibus_dp::slave::{expect_cfg, Device, DpSlave, IoLayout, Reason, SlaveState};
//! use profibus_fdl::station::passive::{PassiveStation, Responder};
//! use profibus_fdl::{Baud, BusParams, Instant};
//!
//! /// One byte out, one byte in: the input counts the Data_Exchanges.
//! struct Counter(u8);
//! impl Device for Counter {
//!     fn ident_number(&self) -> u16 { 0x4711 }
//!     fn real_cfg(&self) -> &[u8] { &[0x30] }
//!     fn check_prm(&mut self, _: &SetPrm<'_>) -> Result<(), Reason> { Ok(()) }
//!     fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> { expect_cfg(&[0x30], cfg) }
//!     fn write_outputs(&mut self, _: Instant, _: &[u8]) {}
//!     fn read_inputs(&mut self, _: Instant, inputs: &mut [u8]) {
//!         self.0 = self.0.wrapping_add(1);
//!         inputs[0] = self.0;
//!     }
//! }
//!
//! let slave = DpSlave::new(Counter(0), 8);
//! assert_eq!(slave.state(), SlaveState::WaitPrm);
//! // Run it on a line: a driver feeds the station bytes and time.
//! let station = PassiveStation::new(slave, BusParams::defaults(Baud::B19200));
//! assert_eq!(station.app().address(), 8);
//! ```
//!
//! # Behaviour where the standard leaves a choice
//!
//! - **Data_Exchange outside Data_Exch** (or from a master that does not
//!   own the slave) is answered with **RS** ("SAP not activated"), as a
//!   real slave did in the trace of pyprofibus issue #19 and as
//!   the DPC31/VPC3 chips do with their deactivated default SAP. RS is a
//!   negative acknowledge, so masters of both kinds read it as "not
//!   ready".
//! - **Unknown SAPs** and SAPs of unsupported services (MSAC_C2, DP-V1
//!   without DPV1_Enable, Set_Slave_Add when not supported) get **RS**.
//!   A negative acknowledge carries no data and no SAP bytes: it is an
//!   SD1 frame (`10 DA SA 03 FCS 16`), as in the trace.
//! - A **Data_Exchange with the wrong output length** is not applied: the
//!   slave clears its outputs, returns to Wait_Prm (Prm_Req) and answers
//!   RS. A fail-safe master (DPV1_Status_1 Fail_Safe) may send no outputs
//!   at all: the outputs go to their safe state.
//! - **Ownership** (Lock_Req): after a locking Set_Prm only that master
//!   may parameterise, configure, exchange data and use MSAC_C1; other
//!   masters' Set_Prm and Chk_Cfg are acknowledged (SC) and ignored (a
//!   [`SlaveEvent::Refused`] tells why), Slave_Diag, Get_Cfg, Rd_Inp and
//!   Rd_Outp are answered to anyone. The slave never sets Master_Lock
//!   itself: that bit belongs to the master (IEC 61158-6-3, Slave_Diag), which sets it
//!   when Diag.Master_Add names another master. Unlock_Req releases the
//!   slave (Wait_Prm). A Set_Prm with neither Lock_Req nor Unlock_Req
//!   only updates min TSDR and the User_Prm_Data of the present
//!   parameterisation, it does not change state or owner.
//! - **Leaving Data_Exch** (watchdog, new Set_Prm, Chk_Cfg mismatch,
//!   unlock) always puts the outputs into the safe state; dropping to
//!   Wait_Prm releases the lock (Diag.Master_Add = 255).
//! - **Global_Control** is executed only in Data_Exch, from the owning
//!   master, for a matching group. Unsync wins over Sync and Unfreeze
//!   over Freeze when both are set; sync or freeze commands the device
//!   does not support are ignored. Clear_Data clears the outputs and
//!   holds them cleared until a Global_Control without Clear_Data.
//! - **Set_Slave_Add** is answered SC when the address changed and RS
//!   when it was refused (not supported, not in Wait_Prm, No_Add_Chg set
//!   earlier, wrong ident number, address above 125, refused by the
//!   device).
//! - **MSAC_C1 read/write** follows the MSAC_C1 polling scheme (IEC 61158-6-3):
//!   the request is acknowledged with SC, every poll (an empty request
//!   on the same SAPs) gets SC until the device has the answer, then the
//!   answer comes as DL. MSAC_C1 and Alarm_Ack (SAP 50) are active only
//!   in Data_Exch with DPV1_Enable, for the owning master.
//! - **DP-V1 alarms** a device raises ([`Device::take_alarm`]) wait in
//!   the core's [`AlarmQueue`]: numbered 0..=31, as many outstanding as
//!   Alarm_Mode allows, their blocks in Slave_Diag until the master's
//!   Alarm_Ack names them (in sequence order); see its module docs.

mod alarm;
mod c2;
mod device;
mod im;
mod reason;
mod state;

pub use alarm::{AckError, Alarm, AlarmQueue, QueuedAlarm, RaiseError, ALARM_QUEUE_LEN};
pub use c2::{min_send_timeout, MAX_C2_CHANNELS};

pub use device::Device;
pub use device::{
    expect_cfg, expect_user_prm_len, layout_of, ClearReason, DeviceEvent, DiagWriter, Dpv1Outcome,
    Features, IoLayout, OwnAddress, ERR_ACCESS_DENIED, ERR_CLASS_ACCESS, ERR_CLASS_APPLICATION,
    ERR_CLASS_RESOURCE, ERR_FEATURE_NOT_SUPPORTED, ERR_INVALID_INDEX, ERR_INVALID_PARAMETER,
    ERR_INVALID_RANGE, ERR_INVALID_SLOT, ERR_STATE_CONFLICT, ERR_WRITE_LENGTH,
};
pub use reason::{Reason, Service};
pub use state::{control_words, AlarmAction, AlarmEvent, SlaveEvent, SlaveState};

use crate::pdu::alarm::{AlarmMode, AlarmType};
use crate::pdu::control::{ControlCommand, GlobalControl, SetSlaveAdd};
use crate::pdu::diag::{
    StationStatus1, StationStatus2, StationStatus3, DIAG_HEADER_LEN, MAX_DIAG_LEN, NO_MASTER,
};
use crate::pdu::dpv1::{Dpv1Error, Pdu, FN_ALARM_ACK, FN_READ, FN_WRITE, MAX_DATA_LEN};
use crate::pdu::prm::{Dpv1Status1, Dpv1Status2, PrmStationStatus, SetPrm};
use crate::pdu::sap::{self, Sap};
use profibus_fdl::station::earliest;
use profibus_fdl::station::passive::{Reply, Responder};
use profibus_fdl::wire::consts::BROADCAST;
use profibus_fdl::{Baud, DataTelegram, FunctionCode, Instant, RequestKind, ResponseStatus};
use state::EventQueue;
use std::time::Duration;

/// Longest process data in one direction (and the size of the slave's
/// fixed buffers).
pub const MAX_IO_LEN: usize = 244;

/// What [`Responder::address`] reports while the device has no address
/// ([`OwnAddress::NoneYet`]): no telegram carries it, so none matches.
pub const NO_ADDRESS: u8 = 0xFF;

/// Highest address Set_Slave_Add may assign.
pub const MAX_SLAVE_ADDRESS: u8 = 125;

/// Counters of a DP slave.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SlaveStats {
    /// Data_Exchange requests answered with data (or SC) in Data_Exch.
    pub data_exchanges: u64,
    /// Slave_Diag requests answered.
    pub diag_requests: u64,
    /// Requests refused (negative acknowledge or ignored).
    pub refused: u64,
    /// Set_Prm accepted.
    pub prm_accepted: u64,
    /// Chk_Cfg accepted.
    pub cfg_accepted: u64,
    /// Watchdog expiries.
    pub watchdog_expiries: u64,
}

/// State of an MSAC_C1 read/write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum C1Job {
    /// Nothing pending.
    Idle,
    /// The request (in `c1_req[..len]`) waits while a class-2 request is
    /// pending in the device.
    Queued { len: usize },
    /// The device is preparing the answer.
    Pending {
        function: u8,
        slot: u8,
        index: u8,
        /// Requested read length, or the written length.
        len: u8,
    },
    /// The answer is in `c1_buf[..len]`.
    Ready { len: usize },
}

/// A DP slave running a [`Device`]; see the module docs.
#[derive(Debug)]
pub struct DpSlave<D> {
    device: D,
    features: Features,
    address: u8,
    state: SlaveState,
    /// The master that parameterised the slave (Diag.Master_Add).
    owner: Option<u8>,
    group_ident: u8,
    /// min TSDR from Set_Prm, bit times (0: none given yet).
    min_tsdr: u8,
    watchdog: Option<Duration>,
    wd_deadline: Option<Instant>,
    dpv1_enabled: bool,
    fail_safe: bool,
    prm_fault: bool,
    cfg_fault: bool,
    not_supported: bool,
    layout: IoLayout,
    sync_mode: bool,
    freeze_mode: bool,
    clear_mode: bool,
    /// The outputs are in their safe state (nothing delivered since).
    outputs_cleared: bool,
    /// Outputs received last (in sync mode: waiting for Sync).
    received: [u8; MAX_IO_LEN],
    /// Outputs delivered to the device (Rd_Outp).
    applied: [u8; MAX_IO_LEN],
    frozen: [u8; MAX_IO_LEN],
    /// Inputs of the last Data_Exchange response.
    last_inputs: [u8; MAX_IO_LEN],
    last_gc: Option<(u8, u8)>,
    /// New diagnosis to be announced with DH.
    diag_pending: bool,
    /// The last diagnosis had Stat_Diag.
    stat_diag: bool,
    no_add_chg: bool,
    c1: C1Job,
    c1_buf: [u8; MAX_IO_LEN],
    c1_req: [u8; MAX_IO_LEN],
    /// The I&M record the class-1 master selected.
    c1_im: im::Selection,
    /// The rate the station runs at (minimum Send_Timeout of class 2).
    baud: Option<Baud>,
    c2: c2::C2State,
    alarms: AlarmQueue,
    events: EventQueue,
    stats: SlaveStats,
}

impl<D: Device> DpSlave<D> {
    /// A slave at `address` in Wait_Prm, running `device`.
    pub fn new(device: D, address: u8) -> DpSlave<D> {
        let features = device.features();
        DpSlave {
            device,
            features,
            address,
            state: SlaveState::WaitPrm,
            owner: None,
            group_ident: 0,
            min_tsdr: 0,
            watchdog: None,
            wd_deadline: None,
            dpv1_enabled: false,
            fail_safe: false,
            prm_fault: false,
            cfg_fault: false,
            not_supported: false,
            layout: IoLayout::default(),
            sync_mode: false,
            freeze_mode: false,
            clear_mode: false,
            outputs_cleared: true,
            received: [0; MAX_IO_LEN],
            applied: [0; MAX_IO_LEN],
            frozen: [0; MAX_IO_LEN],
            last_inputs: [0; MAX_IO_LEN],
            last_gc: None,
            diag_pending: false,
            stat_diag: false,
            no_add_chg: false,
            c1: C1Job::Idle,
            c1_buf: [0; MAX_IO_LEN],
            c1_req: [0; MAX_IO_LEN],
            c1_im: None,
            baud: None,
            c2: c2::C2State::new(if features.dpv1 && features.c2_read_write {
                features.c2_max_count_channels
            } else {
                0
            }),
            alarms: AlarmQueue::new(),
            events: EventQueue::new(),
            stats: SlaveStats::default(),
        }
    }

    /// The device.
    pub fn device(&self) -> &D {
        &self.device
    }

    /// The device, mutable (e.g. to change its inputs or diagnosis).
    pub fn device_mut(&mut self) -> &mut D {
        &mut self.device
    }

    /// The DP state.
    pub fn state(&self) -> SlaveState {
        self.state
    }

    /// The master that parameterised (and owns) the slave.
    pub fn master(&self) -> Option<u8> {
        self.owner
    }

    /// The cyclic layout of the accepted configuration.
    pub fn layout(&self) -> IoLayout {
        self.layout
    }

    /// The outputs last delivered to the device.
    pub fn outputs(&self) -> &[u8] {
        &self.applied[..self.layout.outputs]
    }

    /// The inputs sent with the last Data_Exchange response.
    pub fn inputs(&self) -> &[u8] {
        &self.last_inputs[..self.layout.inputs]
    }

    /// Sync mode is active (a Sync command was received).
    pub fn sync_mode(&self) -> bool {
        self.sync_mode
    }

    /// Freeze mode is active (a Freeze command was received).
    pub fn freeze_mode(&self) -> bool {
        self.freeze_mode
    }

    /// The watchdog time in force.
    pub fn watchdog(&self) -> Option<Duration> {
        self.watchdog
    }

    /// Counters.
    pub fn stats(&self) -> SlaveStats {
        self.stats
    }

    /// The DP-V1 alarm queue (outstanding and waiting alarms).
    pub fn alarms(&self) -> &AlarmQueue {
        &self.alarms
    }

    /// Raise a DP-V1 alarm (what [`Device::take_alarm`] hands over): it
    /// is queued with the next sequence number and goes into Slave_Diag,
    /// announced with "data high", once the limit of outstanding alarms
    /// allows. Refused outside Data_Exch, when the master did not enable
    /// the type, when 32 alarms wait, or with more than 59 bytes of data.
    pub fn raise_alarm(&mut self, alarm: Alarm) -> Result<QueuedAlarm, RaiseError> {
        let raised = if self.state == SlaveState::DataExch {
            self.alarms.raise(alarm.clone())
        } else {
            Err(RaiseError::Inactive)
        };
        match raised {
            Ok((q, outstanding)) => {
                if outstanding {
                    self.diag_pending = true;
                }
                self.event(SlaveEvent::Alarm(AlarmEvent::new(
                    AlarmAction::Raised,
                    &q.alarm,
                    Some(q.seq),
                    None,
                )));
                Ok(q)
            }
            Err(e) => {
                self.event(SlaveEvent::Alarm(AlarmEvent::new(
                    AlarmAction::Refused,
                    &alarm,
                    None,
                    Some(e.to_string()),
                )));
                Err(e)
            }
        }
    }

    /// Take the alarms the device raised.
    fn take_device_alarms(&mut self) {
        while let Some(a) = self.device.take_alarm() {
            let _ = self.raise_alarm(a);
        }
    }

    /// The next event for the application (core events first, then the
    /// device's).
    pub fn poll_event(&mut self) -> Option<SlaveEvent> {
        self.events
            .pop()
            .or_else(|| self.device.poll_event().map(SlaveEvent::Device))
    }

    fn event(&mut self, e: SlaveEvent) {
        self.events.push(e);
    }

    fn refuse(&mut self, master: u8, service: Service, reason: Reason) {
        self.stats.refused += 1;
        self.event(SlaveEvent::Refused {
            master,
            service,
            reason,
        });
    }

    fn clear_outputs(&mut self, now: Instant, why: ClearReason) {
        self.received.fill(0);
        self.applied.fill(0);
        self.outputs_cleared = true;
        self.device.clear_outputs(now, why);
        self.event(SlaveEvent::OutputsCleared { reason: why });
    }

    /// Change state; leaving Data_Exch clears the outputs (for `why`),
    /// entering Wait_Prm releases the lock.
    fn enter(&mut self, now: Instant, to: SlaveState, why: ClearReason) {
        let from = self.state;
        if from == SlaveState::DataExch && to != SlaveState::DataExch {
            self.clear_outputs(now, why);
            self.sync_mode = false;
            self.freeze_mode = false;
            self.clear_mode = false;
            self.last_gc = None;
            self.c1 = C1Job::Idle;
            self.c1_im = None;
            self.alarms.reset();
        }
        if to == SlaveState::WaitPrm {
            self.owner = None;
            self.watchdog = None;
            self.wd_deadline = None;
            self.dpv1_enabled = false;
            self.fail_safe = false;
            self.group_ident = 0;
        }
        if from != to {
            self.state = to;
            self.device.state_changed(now, to);
            self.event(SlaveEvent::State { from, to });
        }
    }

    /// The device restarted its bus interface: back to Wait_Prm with no
    /// master, parameters, configuration or pending diagnosis.
    fn restart(&mut self, now: Instant) {
        self.enter(now, SlaveState::WaitPrm, ClearReason::LeftDataExchange);
        self.prm_fault = false;
        self.cfg_fault = false;
        self.not_supported = false;
        self.diag_pending = false;
        self.stat_diag = false;
        self.layout = IoLayout::default();
        self.c1 = C1Job::Idle;
        self.c1_im = None;
        self.c2_reset();
    }

    /// Build the Slave_Diag data unit into `out` (needs at least 6 bytes);
    /// returns its length (0 when `out` is too short).
    pub fn diagnosis(&mut self, now: Instant, out: &mut [u8]) -> usize {
        let limit = (self.features.max_diag_len as usize)
            .clamp(DIAG_HEADER_LEN, MAX_DIAG_LEN)
            .min(out.len());
        if limit < DIAG_HEADER_LEN {
            return 0;
        }
        let (head, rest) = out.split_at_mut(DIAG_HEADER_LEN);
        let mut w = DiagWriter::new(&mut rest[..limit - DIAG_HEADER_LEN]);
        // The outstanding DP-V1 alarms first (device-related blocks).
        let disturbed = self.alarms.write(&mut w);
        self.device.diagnosis(now, &mut w);
        let (ext_len, ext_diag, stat_diag, overflow) = w.finish();
        let ext_diag = ext_diag || disturbed;
        let mut s1 = StationStatus1::empty();
        s1.set(
            StationStatus1::STATION_NOT_READY,
            self.state != SlaveState::DataExch,
        );
        s1.set(StationStatus1::CFG_FAULT, self.cfg_fault);
        s1.set(StationStatus1::PRM_FAULT, self.prm_fault);
        s1.set(StationStatus1::NOT_SUPPORTED, self.not_supported);
        s1.set(StationStatus1::EXT_DIAG, ext_diag);
        let mut s2 = StationStatus2::ALWAYS_ONE;
        s2.set(StationStatus2::PRM_REQ, self.state == SlaveState::WaitPrm);
        s2.set(StationStatus2::STAT_DIAG, stat_diag);
        s2.set(StationStatus2::WD_ON, self.watchdog.is_some());
        s2.set(StationStatus2::FREEZE_MODE, self.freeze_mode);
        s2.set(StationStatus2::SYNC_MODE, self.sync_mode);
        let mut s3 = StationStatus3::empty();
        s3.set(StationStatus3::EXT_DIAG_OVERFLOW, overflow);
        let id = self.device.ident_number().to_be_bytes();
        head.copy_from_slice(&[
            s1.bits(),
            s2.bits(),
            s3.bits(),
            self.owner.unwrap_or(NO_MASTER),
            id[0],
            id[1],
        ]);
        self.stat_diag = stat_diag;
        DIAG_HEADER_LEN + ext_len
    }

    fn is_owner(&self, master: u8) -> bool {
        self.owner == Some(master)
    }

    // ----- services -------------------------------------------------------

    fn data_exchange(&mut self, now: Instant, from: u8, du: &[u8], out: &mut [u8]) -> Reply {
        if self.state != SlaveState::DataExch {
            self.refuse(from, Service::DataExchange, Reason::NotInDataExch);
            return NEGATIVE_RS;
        }
        if !self.is_owner(from) {
            self.refuse(from, Service::DataExchange, Reason::LockedToAnother);
            return NEGATIVE_RS;
        }
        let want = self.layout.outputs;
        if du.len() == want {
            self.received[..want].copy_from_slice(du);
            if !self.clear_mode && !self.sync_mode {
                self.deliver(now);
            }
        } else if du.is_empty() && self.fail_safe {
            if !self.outputs_cleared {
                self.clear_outputs(now, ClearReason::FailSafe);
            }
        } else {
            self.refuse(
                from,
                Service::DataExchange,
                Reason::OutputLength {
                    got: du.len(),
                    configured: want,
                },
            );
            self.enter(now, SlaveState::WaitPrm, ClearReason::LeftDataExchange);
            return NEGATIVE_RS;
        }
        let n = self.layout.inputs;
        if out.len() < n {
            return Reply::Silence;
        }
        self.produce_inputs(now, &mut out[..n]);
        self.last_inputs[..n].copy_from_slice(&out[..n]);
        if self.device.take_new_diag() {
            self.diag_pending = true;
        }
        self.stats.data_exchanges += 1;
        let status = if self.diag_pending {
            ResponseStatus::Dh
        } else {
            ResponseStatus::Dl
        };
        if n == 0 && status == ResponseStatus::Dl {
            return Reply::ShortAck;
        }
        Reply::Data {
            status,
            dsap: None,
            ssap: None,
            len: n,
        }
    }

    /// Hand the received outputs to the device.
    fn deliver(&mut self, now: Instant) {
        let n = self.layout.outputs;
        self.applied[..n].copy_from_slice(&self.received[..n]);
        self.outputs_cleared = false;
        self.device.write_outputs(now, &self.applied[..n]);
    }

    /// The inputs as Data_Exchange reports them (frozen or live).
    fn produce_inputs(&mut self, now: Instant, out: &mut [u8]) {
        if self.freeze_mode {
            out.copy_from_slice(&self.frozen[..out.len()]);
        } else {
            self.device.read_inputs(now, out);
        }
    }

    fn set_prm(&mut self, now: Instant, from: u8, du: &[u8]) -> Reply {
        if let Some(owner) = self.owner {
            if owner != from {
                self.refuse(from, Service::Sap(Sap::SetPrm), Reason::LockedTo { owner });
                return Reply::ShortAck;
            }
        }
        let prm = match SetPrm::parse(du) {
            Ok(p) => p,
            Err(e) => {
                self.prm_fault(now, from, e.into(), false);
                return Reply::ShortAck;
            }
        };
        let status = prm.station_status;
        if status.contains(PrmStationStatus::UNLOCK_REQ) {
            self.enter(now, SlaveState::WaitPrm, ClearReason::LeftDataExchange);
            self.event(SlaveEvent::Unlocked { master: from });
            return Reply::ShortAck;
        }
        if let Err(reason) = self.check_prm(&prm) {
            let not_supported = reason.is_not_supported();
            self.prm_fault(now, from, reason, not_supported);
            return Reply::ShortAck;
        }
        if let Err(reason) = self.device.check_prm(&prm) {
            self.prm_fault(now, from, reason, false);
            return Reply::ShortAck;
        }
        if prm.min_tsdr != 0 {
            self.min_tsdr = prm.min_tsdr;
        }
        let locked = status.contains(PrmStationStatus::LOCK_REQ);
        if !locked {
            // Lock_Req = Unlock_Req = 0: min TSDR and the slave-specific
            // parameters are updated, nothing else.
            self.event(SlaveEvent::PrmAccepted {
                master: from,
                locked: false,
                watchdog: self.watchdog,
                min_tsdr: self.min_tsdr,
                group_ident: self.group_ident,
            });
            return Reply::ShortAck;
        }
        let dpv1 = self.features.dpv1;
        let (s1, s2, s3) = prm.dpv1_status().filter(|_| dpv1).unwrap_or_default();
        self.stats.prm_accepted += 1;
        self.prm_fault = false;
        self.cfg_fault = false;
        self.not_supported = false;
        self.enter(now, SlaveState::WaitCfg, ClearReason::LeftDataExchange);
        self.owner = Some(from);
        self.group_ident = prm.group_ident;
        self.watchdog = prm.watchdog(dpv1).filter(|d| !d.is_zero());
        self.wd_deadline = self.watchdog.map(|d| now + d);
        self.dpv1_enabled = s1.contains(Dpv1Status1::DPV1_ENABLE);
        self.fail_safe = s1.contains(Dpv1Status1::FAIL_SAFE);
        if self.dpv1_enabled && self.features.alarms {
            self.alarms.open(s2, AlarmMode::from_status_3(s3));
        } else {
            self.alarms.reset();
        }
        self.event(SlaveEvent::PrmAccepted {
            master: from,
            locked: true,
            watchdog: self.watchdog,
            min_tsdr: self.min_tsdr,
            group_ident: self.group_ident,
        });
        Reply::ShortAck
    }

    /// The standard checks of a Set_Prm (EN 50170 part 3: Station_Status,
    /// the watchdog factors, the DPV1_Status bytes against the slave's
    /// features).
    fn check_prm(&self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        let f = self.features;
        let own = self.device.ident_number();
        if prm.ident_number != own {
            return Err(Reason::IdentNumber {
                got: prm.ident_number,
                own,
            });
        }
        let st = prm.station_status;
        if st.bits() & 0x07 != 0 {
            return Err(Reason::ReservedStationStatus {
                station_status: st.bits(),
            });
        }
        if st.contains(PrmStationStatus::WD_ON) && (prm.wd_fact_1 == 0 || prm.wd_fact_2 == 0) {
            return Err(Reason::WatchdogFactor {
                wd_fact_1: prm.wd_fact_1,
                wd_fact_2: prm.wd_fact_2,
            });
        }
        if st.contains(PrmStationStatus::SYNC_REQ) && !f.sync {
            return Err(Reason::SyncReqUnsupported);
        }
        if st.contains(PrmStationStatus::FREEZE_REQ) && !f.freeze {
            return Err(Reason::FreezeReqUnsupported);
        }
        if f.dpv1 {
            let Some((s1, s2, s3)) = prm.dpv1_status() else {
                return Err(Reason::Dpv1StatusMissing {
                    user_prm_len: prm.user_prm_data.len(),
                });
            };
            if s1.bits() & 0x18 != 0 {
                return Err(Reason::ReservedDpv1Status1 {
                    status_1: s1.bits(),
                });
            }
            let dpv2 = Dpv1Status1::PUBLISHER_ENABLE
                | Dpv1Status1::DIS_STOP_CONTROL
                | Dpv1Status1::DIS_START_CONTROL;
            if s1.intersects(dpv2) {
                return Err(Reason::Dpv2Unsupported);
            }
            if s1.contains(Dpv1Status1::FAIL_SAFE) && !f.fail_safe {
                return Err(Reason::FailSafeUnsupported);
            }
            let alarms = s2.bits() & !Dpv1Status2::CHECK_CFG_MODE.bits();
            if alarms & 0x02 != 0 {
                return Err(Reason::ReservedDpv1Status2 {
                    status_2: s2.bits(),
                });
            }
            if alarms != 0 && !(f.alarms && s1.contains(Dpv1Status1::DPV1_ENABLE)) {
                return Err(Reason::AlarmsUnsupported {
                    status_2: s2.bits(),
                });
            }
            if s3 & 0x60 != 0 {
                return Err(Reason::ReservedDpv1Status3 { status_3: s3 });
            }
            if s3 & 0x90 != 0 {
                return Err(Reason::IsochronousUnsupported);
            }
        }
        Ok(())
    }

    fn prm_fault(&mut self, now: Instant, from: u8, reason: Reason, not_supported: bool) {
        self.enter(now, SlaveState::WaitPrm, ClearReason::LeftDataExchange);
        self.device.prm_refused(now, &reason);
        self.prm_fault = true;
        self.not_supported = not_supported;
        self.event(SlaveEvent::PrmFault {
            master: from,
            reason,
            not_supported,
        });
    }

    fn chk_cfg(&mut self, now: Instant, from: u8, du: &[u8]) -> Reply {
        if self.state == SlaveState::WaitPrm {
            self.refuse(from, Service::Sap(Sap::ChkCfg), Reason::NotParameterised);
            return Reply::ShortAck;
        }
        if !self.is_owner(from) {
            self.refuse(from, Service::Sap(Sap::ChkCfg), Reason::LockedToAnother);
            return Reply::ShortAck;
        }
        let checked = self.device.check_cfg(du).and_then(|l| {
            if l.inputs > MAX_IO_LEN || l.outputs > MAX_IO_LEN {
                Err(Reason::LayoutTooLong {
                    inputs: l.inputs,
                    outputs: l.outputs,
                })
            } else {
                Ok(l)
            }
        });
        match checked {
            Ok(layout) => {
                self.stats.cfg_accepted += 1;
                self.cfg_fault = false;
                if self.state == SlaveState::DataExch && layout != self.layout {
                    self.clear_outputs(now, ClearReason::LeftDataExchange);
                }
                self.layout = layout;
                self.event(SlaveEvent::CfgAccepted {
                    master: from,
                    inputs: layout.inputs,
                    outputs: layout.outputs,
                });
                self.enter(now, SlaveState::DataExch, ClearReason::LeftDataExchange);
            }
            Err(reason) => {
                self.cfg_fault = true;
                self.event(SlaveEvent::CfgFault {
                    master: from,
                    reason,
                });
                self.enter(now, SlaveState::WaitPrm, ClearReason::LeftDataExchange);
            }
        }
        Reply::ShortAck
    }

    fn global_control(&mut self, now: Instant, from: u8, du: &[u8]) {
        const GC: Service = Service::Sap(Sap::GlobalControl);
        if self.state != SlaveState::DataExch || !self.is_owner(from) {
            return;
        }
        let Ok(gc) = GlobalControl::parse(du) else {
            self.refuse(from, GC, Reason::ControlLength);
            return;
        };
        if !gc.addresses(self.group_ident) {
            return;
        }
        let cmd = gc.command;
        let f = self.features;
        let clear = cmd.contains(ControlCommand::CLEAR_DATA);
        if clear && !self.clear_mode {
            self.clear_outputs(now, ClearReason::ClearData);
        }
        self.clear_mode = clear;
        if cmd.intersects(ControlCommand::SYNC | ControlCommand::UNSYNC) {
            if !f.sync {
                self.refuse(from, GC, Reason::SyncUnsupported);
            } else if cmd.contains(ControlCommand::UNSYNC) {
                self.sync_mode = false;
            } else {
                self.sync_mode = true;
                if !self.clear_mode {
                    self.deliver(now);
                }
            }
        }
        if cmd.intersects(ControlCommand::FREEZE | ControlCommand::UNFREEZE) {
            if !f.freeze {
                self.refuse(from, GC, Reason::FreezeUnsupported);
            } else if cmd.contains(ControlCommand::UNFREEZE) {
                self.freeze_mode = false;
            } else {
                let n = self.layout.inputs;
                self.device.read_inputs(now, &mut self.frozen[..n]);
                self.freeze_mode = true;
            }
        }
        let key = (cmd.bits(), gc.group_select);
        let action = cmd.intersects(ControlCommand::SYNC | ControlCommand::FREEZE);
        if action || self.last_gc != Some(key) {
            self.last_gc = Some(key);
            self.event(SlaveEvent::GlobalControl {
                master: from,
                command: cmd,
                group_select: gc.group_select,
            });
        }
    }

    fn set_slave_add(&mut self, from: u8, du: &[u8]) -> Reply {
        let refused = |s: &mut Self, reason: Reason| {
            s.refuse(from, Service::Sap(Sap::SetSlaveAdd), reason);
            false
        };
        let ok = if !self.features.set_slave_add {
            refused(self, Reason::SetSlaveAddUnsupported)
        } else if self.state != SlaveState::WaitPrm {
            refused(self, Reason::OnlyInWaitPrm)
        } else if self.no_add_chg {
            refused(self, Reason::NoAddChg)
        } else {
            match SetSlaveAdd::parse(du) {
                Err(e) => refused(self, e.into()),
                Ok(s) if s.ident_number != self.device.ident_number() => refused(
                    self,
                    Reason::IdentNumber {
                        got: s.ident_number,
                        own: self.device.ident_number(),
                    },
                ),
                Ok(s) if s.new_address > MAX_SLAVE_ADDRESS => refused(
                    self,
                    Reason::AddressAbove125 {
                        address: s.new_address,
                    },
                ),
                Ok(s) => {
                    match self
                        .device
                        .set_address(s.new_address, s.no_add_chg, s.rem_slave_data)
                    {
                        Err(reason) => refused(self, reason),
                        Ok(()) => {
                            let old = self.address;
                            self.address = s.new_address;
                            self.no_add_chg = s.no_add_chg;
                            self.event(SlaveEvent::AddressChanged {
                                old,
                                new: s.new_address,
                                no_add_chg: s.no_add_chg,
                            });
                            true
                        }
                    }
                }
            }
        };
        if ok {
            Reply::ShortAck
        } else {
            NEGATIVE_RS
        }
    }

    /// MSAC_C1 read/write (SAP 51).
    fn msac_c1(&mut self, now: Instant, req: &DataTelegram<'_>, out: &mut [u8]) -> Option<Reply> {
        let (from, du) = (req.sa, req.data);
        if !(self.features.dpv1
            && self.features.c1_read_write
            && self.dpv1_enabled
            && self.state == SlaveState::DataExch
            && self.is_owner(from))
        {
            self.refuse(from, Service::Sap(Sap::MsacC1), Reason::C1Inactive);
            return None;
        }
        if !du.is_empty() {
            if self.c2.device_busy() {
                self.c1_req[..du.len()].copy_from_slice(du);
                self.c1 = C1Job::Queued { len: du.len() };
            } else {
                self.c1_start(now, du);
            }
            return Some(Reply::ShortAck);
        }
        // A poll.
        if let C1Job::Queued { len } = self.c1 {
            if !self.c2.device_busy() {
                let req = self.c1_req;
                self.c1_start(now, &req[..len]);
            }
        }
        if let C1Job::Pending {
            function,
            slot,
            index,
            len,
        } = self.c1
        {
            let outcome = {
                let n = if function == FN_READ { len as usize } else { 0 };
                self.device.dpv1_poll(now, &mut self.c1_buf[4..4 + n])
            };
            self.c1_finish(function, slot, index, len, outcome);
        }
        match self.c1 {
            C1Job::Ready { len } if len <= out.len() => {
                out[..len].copy_from_slice(&self.c1_buf[..len]);
                self.c1 = C1Job::Idle;
                Some(Reply::Data {
                    status: ResponseStatus::Dl,
                    dsap: req.ssap,
                    ssap: req.dsap,
                    len,
                })
            }
            _ => Some(Reply::ShortAck),
        }
    }

    /// Start an MSAC_C1 job. Lengths are checked here, before the device
    /// sees the request: a Read asks for 1 ..= C1_Max_Data_Len bytes
    /// (otherwise "access: invalid range", 0xB7), a Write carries
    /// 1 ..= C1_Max_Data_Len bytes (otherwise "access: write length
    /// error", 0xB1); C1_Max_Data_Len is at most 240 (4-byte header + 240
    /// = 244). Slot and index belong to the device, which answers "invalid
    /// slot" (0xB2) before "invalid index" (0xB0).
    fn c1_start(&mut self, now: Instant, du: &[u8]) {
        let function = du[0];
        let limit = (self.features.c1_max_data_len as usize).clamp(1, MAX_DATA_LEN);
        match Pdu::parse_request(du) {
            Ok(Pdu::ReadReq { length, .. }) if length == 0 || length as usize > limit => self
                .c1_error(Dpv1Error::dpv1(
                    FN_READ,
                    ERR_CLASS_ACCESS,
                    ERR_INVALID_RANGE,
                )),
            Ok(Pdu::WriteReq { data, .. }) if data.is_empty() || data.len() > limit => self
                .c1_error(Dpv1Error::dpv1(
                    FN_WRITE,
                    ERR_CLASS_ACCESS,
                    ERR_WRITE_LENGTH,
                )),
            Ok(Pdu::ReadReq {
                slot,
                index,
                length,
            }) => {
                let n = (length as usize).min(MAX_DATA_LEN);
                let out = &mut self.c1_buf[4..4 + n];
                let outcome = if im::is_call(self.features.im, slot, index) {
                    im::read(&mut self.device, self.c1_im, out)
                } else {
                    self.device.dpv1_read(now, slot, index, out)
                };
                self.c1_finish(FN_READ, slot, index, n as u8, outcome);
            }
            Ok(Pdu::WriteReq { slot, index, data }) => {
                let outcome = if im::is_call(self.features.im, slot, index) {
                    im::write(&mut self.device, now, &mut self.c1_im, data)
                } else {
                    self.device.dpv1_write(now, slot, index, data)
                };
                self.c1_finish(FN_WRITE, slot, index, data.len() as u8, outcome);
            }
            Ok(_) => self.c1_error(Dpv1Error::dpv1(function, ERR_CLASS_APPLICATION, 9)),
            Err(crate::pdu::dpv1::Dpv1ParseError::LengthByte { .. }) => self.c1_error(
                Dpv1Error::dpv1(function, ERR_CLASS_ACCESS, ERR_WRITE_LENGTH),
            ),
            Err(_) => self.c1_error(Dpv1Error::dpv1(
                function,
                ERR_CLASS_APPLICATION,
                ERR_FEATURE_NOT_SUPPORTED,
            )),
        }
    }

    fn c1_error(&mut self, e: Dpv1Error) {
        let len = Pdu::Error(e).emit(&mut self.c1_buf).unwrap_or(0);
        self.c1 = C1Job::Ready { len };
    }

    fn c1_finish(&mut self, function: u8, slot: u8, index: u8, len: u8, outcome: Dpv1Outcome) {
        match outcome {
            Dpv1Outcome::Pending => {
                self.c1 = C1Job::Pending {
                    function,
                    slot,
                    index,
                    len,
                }
            }
            Dpv1Outcome::Error(mut e) => {
                e.function = function | 0x80;
                self.c1_error(e)
            }
            Dpv1Outcome::Done(n) => {
                let n = if function == FN_READ {
                    n.min(len as usize)
                } else {
                    n.min(255)
                };
                self.c1_buf[..4].copy_from_slice(&[function, slot, index, n as u8]);
                let total = if function == FN_READ { 4 + n } else { 4 };
                self.c1 = C1Job::Ready { len: total };
            }
        }
    }

    /// MSAC_C1 Alarm_Ack (SAP 50).
    fn alarm_ack(&mut self, now: Instant, req: &DataTelegram<'_>, out: &mut [u8]) -> Option<Reply> {
        let (from, du) = (req.sa, req.data);
        if !(self.features.dpv1
            && self.features.alarms
            && self.dpv1_enabled
            && self.state == SlaveState::DataExch
            && self.is_owner(from))
        {
            self.refuse(from, Service::Sap(Sap::AlarmAck), Reason::AlarmsInactive);
            return None;
        }
        let pdu = match Pdu::parse_request(du) {
            Ok(Pdu::AlarmAck {
                slot,
                alarm_type,
                specifier,
            }) => {
                let echo = Pdu::AlarmAck {
                    slot,
                    alarm_type,
                    specifier,
                };
                let t = AlarmType::from_code(alarm_type);
                match self.alarms.ack(slot, t, specifier) {
                    Ok(q) => {
                        // The next alarm may be outstanding now.
                        self.diag_pending = true;
                        self.event(SlaveEvent::Alarm(AlarmEvent::new(
                            AlarmAction::Acknowledged,
                            &q.alarm,
                            Some(q.seq),
                            None,
                        )));
                        echo
                    }
                    Err(e @ AckError::OutOfOrder { .. }) => {
                        self.refuse(from, Service::Sap(Sap::AlarmAck), Reason::AlarmAck(e));
                        Pdu::Error(Dpv1Error::dpv1(
                            FN_ALARM_ACK,
                            ERR_CLASS_ACCESS,
                            ERR_STATE_CONFLICT,
                        ))
                    }
                    // Not one of the queue's: the device's own alarms.
                    Err(e) => match self.device.alarm_ack(now, slot, alarm_type, specifier >> 3) {
                        Ok(()) => echo,
                        Err(mut d) => {
                            self.refuse(from, Service::Sap(Sap::AlarmAck), Reason::AlarmAck(e));
                            d.function = FN_ALARM_ACK | 0x80;
                            Pdu::Error(d)
                        }
                    },
                }
            }
            _ => Pdu::Error(Dpv1Error::dpv1(FN_ALARM_ACK, ERR_CLASS_ACCESS, 8)),
        };
        let len = pdu.emit(out)?;
        Some(Reply::Data {
            status: ResponseStatus::Dl,
            dsap: req.ssap,
            ssap: req.dsap,
            len,
        })
    }

    fn expire_watchdog(&mut self, now: Instant) {
        let (Some(after), Some(master)) = (self.watchdog, self.owner) else {
            self.wd_deadline = None;
            return;
        };
        self.stats.watchdog_expiries += 1;
        self.event(SlaveEvent::WatchdogExpired { master, after });
        self.enter(now, SlaveState::WaitPrm, ClearReason::Watchdog);
    }
}

/// RS ("SAP not activated"): a negative acknowledge without data and
/// without SAP bytes (an SD1 frame, as in the trace of pyprofibus issue #19).
fn rs(_req: &DataTelegram<'_>) -> Reply {
    NEGATIVE_RS
}

const NEGATIVE_RS: Reply = Reply::Data {
    status: ResponseStatus::Rs,
    dsap: None,
    ssap: None,
    len: 0,
};

impl<D: Device> Responder for DpSlave<D> {
    fn address(&self) -> u8 {
        match self.device.own_address() {
            OwnAddress::Slave => self.address,
            OwnAddress::NoneYet => NO_ADDRESS,
            OwnAddress::Set(a) => a,
        }
    }

    fn min_tsdr(&self) -> u32 {
        self.min_tsdr as u32
    }

    fn on_request(&mut self, now: Instant, req: &DataTelegram<'_>, out: &mut [u8]) -> Reply {
        let FunctionCode::Request { kind, .. } = req.fc else {
            return Reply::Silence;
        };
        if self.device.take_restart() {
            self.restart(now);
        }
        self.take_device_alarms();
        if self.device.own_address() == OwnAddress::NoneYet {
            return Reply::Silence;
        }
        let from = req.sa;
        if self.owner == Some(from) {
            if let Some(wd) = self.watchdog {
                self.wd_deadline = Some(now + wd);
            }
        }
        if req.da == BROADCAST || !kind.expects_reply() {
            if req.dsap == Some(sap::GLOBAL_CONTROL) {
                self.global_control(now, from, req.data);
            }
            return Reply::Silence;
        }
        // The DP SAPs (and the default SAP of Data_Exchange) serve SRD
        // only: EN 50170 Vol. 2 maps every DDLM service but Global_Control
        // onto SRD, and slave ASICs (SPC3, VPC3+) activate the DP SAPs for
        // SRD alone. An SDA or MSRD is answered "SAP not activated" (RS)
        // and nothing is executed.
        if !matches!(kind, RequestKind::SrdLow | RequestKind::SrdHigh) {
            let service = match req.dsap.map(|s| (s, sap::name(s))) {
                Some((s, Some(_))) => Service::Sap(Sap::from_code(s)),
                _ => Service::DataExchange,
            };
            self.refuse(from, service, Reason::SrdOnly);
            return NEGATIVE_RS;
        }
        match (req.dsap, req.ssap) {
            (None, None) => self.data_exchange(now, from, req.data, out),
            (Some(dsap), Some(_)) => match dsap {
                sap::SLAVE_DIAG => {
                    self.stats.diag_requests += 1;
                    let len = self.diagnosis(now, out);
                    if self.is_owner(from) {
                        self.diag_pending = self.stat_diag;
                    }
                    Reply::Data {
                        status: ResponseStatus::Dl,
                        dsap: req.ssap,
                        ssap: req.dsap,
                        len,
                    }
                }
                sap::SET_PRM => self.set_prm(now, from, req.data),
                sap::CHK_CFG => self.chk_cfg(now, from, req.data),
                sap::GET_CFG => {
                    let cfg = self.device.real_cfg();
                    let len = cfg.len().min(MAX_IO_LEN).min(out.len());
                    out[..len].copy_from_slice(&cfg[..len]);
                    Reply::Data {
                        status: ResponseStatus::Dl,
                        dsap: req.ssap,
                        ssap: req.dsap,
                        len,
                    }
                }
                sap::GLOBAL_CONTROL => {
                    self.global_control(now, from, req.data);
                    Reply::ShortAck
                }
                sap::RD_INP | sap::RD_OUTP if self.state == SlaveState::DataExch => {
                    let len = if dsap == sap::RD_INP {
                        self.layout.inputs
                    } else {
                        self.layout.outputs
                    };
                    if out.len() < len {
                        return Reply::Silence;
                    }
                    if dsap == sap::RD_INP {
                        self.produce_inputs(now, &mut out[..len]);
                    } else {
                        out[..len].copy_from_slice(&self.applied[..len]);
                    }
                    Reply::Data {
                        status: ResponseStatus::Dl,
                        dsap: req.ssap,
                        ssap: req.dsap,
                        len,
                    }
                }
                sap::RD_INP | sap::RD_OUTP => {
                    self.refuse(from, Service::of_dsap(Some(dsap)), Reason::NotInDataExch);
                    rs(req)
                }
                sap::SET_SLAVE_ADD => self.set_slave_add(from, req.data),
                sap::MSAC_C1 => self.msac_c1(now, req, out).unwrap_or_else(|| rs(req)),
                sap::ALARM_ACK => self.alarm_ack(now, req, out).unwrap_or_else(|| rs(req)),
                sap::MSAC_C2_INITIATE => self.c2_resource_manager(now, req, out),
                0..=crate::pdu::c2::MAX_CONNECTION_SAP if self.c2_offered() => {
                    self.c2_connection(now, req, out)
                }
                // Other SAPs are the device's (FMS LSAPs …), else refused.
                _ => match self.device.fdl_request(
                    now,
                    from,
                    dsap,
                    req.ssap.unwrap_or(0),
                    req.data,
                    out,
                ) {
                    Some(len) => Reply::Data {
                        status: ResponseStatus::Dl,
                        dsap: req.ssap,
                        ssap: req.dsap,
                        len: len.min(out.len()),
                    },
                    None if dsap <= crate::pdu::c2::MAX_CONNECTION_SAP => {
                        self.c2_connection(now, req, out)
                    }
                    None => {
                        self.stats.refused += 1;
                        rs(req)
                    }
                },
            },
            // One SAP without the other: not a DP request.
            _ => {
                self.stats.refused += 1;
                rs(req)
            }
        }
    }

    fn set_baud(&mut self, baud: Baud) {
        self.baud = Some(baud);
    }

    fn poll_timeout(&self) -> Option<Instant> {
        earliest(
            earliest(self.wd_deadline, self.device.poll_timeout()),
            self.c2.deadline(),
        )
    }

    fn handle_timeout(&mut self, now: Instant) {
        if self.device.take_restart() {
            self.restart(now);
        }
        if self.wd_deadline.is_some_and(|t| t <= now) {
            self.wd_deadline = None;
            self.expire_watchdog(now);
        }
        if self.device.poll_timeout().is_some_and(|t| t <= now) {
            self.device.handle_timeout(now);
        }
        if self.c2.deadline().is_some_and(|t| t <= now) {
            self.c2_expire(now);
        }
        self.take_device_alarms();
    }
}

#[cfg(test)]
mod tests;
