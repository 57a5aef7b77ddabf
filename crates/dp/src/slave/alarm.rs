//! The slave's DP-V1 alarm queue: alarms a device raises wait here, the
//! outstanding ones travel in Slave_Diag as alarm blocks until the master
//! acknowledges each with Alarm_Ack (SAP 50).
//!
//! - **Sequence numbers** count 0..=31 over all alarm types and wrap
//!   (Alarm_Specifier bits 7..3; dpv1-c2-im-alarms.md §4.4, \[CP5613\],
//!   \[VPC3\]). The queue holds at most 32 alarms, so no two alarms in it
//!   share a number.
//! - **Outstanding alarms**: Alarm_Mode in DPV1_Status_3 (bits 2..0) limits
//!   how many alarms may wait for their acknowledgement (§4.5): 0 = type
//!   mode, one per alarm type; 1..=7 = sequence mode, 2/4/8/12/16/24/32 in
//!   total. Alarms beyond the limit stay queued, invisible to the master,
//!   until an earlier one is acknowledged.
//! - **In Slave_Diag**: every outstanding alarm's block (header, type,
//!   slot, specifier, data), oldest first, before the device's own blocks,
//!   as far as they fit into `Max_Diag_Data_Len`; an alarm that does not
//!   fit waits for the next diagnosis (it is not lost, so Ext_Diag_Overflow
//!   is not set for it). The sources at hand do not say whether a
//!   diagnosis may carry more than one alarm; this stack sends all the
//!   outstanding ones so that the master sees them at once and
//!   acknowledges them in order. Ext_Diag (Station_Status_1) is set while
//!   an outstanding alarm says its slot is disturbed (specifier "appears"
//!   or "disappears, other faults remain").
//! - **Acknowledgement**: an Alarm_Ack names slot, type and specifier (its
//!   sequence number). It must name an outstanding alarm, and in sequence
//!   mode the oldest one (the master acknowledges in sequence-number
//!   order); anything else is answered negatively and the alarm stays.
//! - The queue is only open in Data_Exch with DPV1_Enable and the alarm
//!   type enabled in DPV1_Status_2 by the owning master; leaving
//!   Data_Exch (a new Set_Prm, the watchdog, a fault) empties it.

use crate::pdu::alarm::{
    AlarmChange, AlarmLimit, AlarmMode, AlarmSpecifier, AlarmType, MAX_ALARM_DATA_LEN,
};
use crate::pdu::prm::Dpv1Status2;
use crate::slave::DiagWriter;
use std::collections::VecDeque;

/// The most alarms the queue holds (the sequence numbers 0..=31).
pub const ALARM_QUEUE_LEN: usize = 32;

/// An alarm a device raises ([`Device::take_alarm`](super::Device::take_alarm),
/// [`DpSlave::raise_alarm`](super::DpSlave::raise_alarm)).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Alarm {
    /// The alarm type (diagnostic, process, pull, plug, …).
    pub alarm_type: AlarmType,
    /// The slot it concerns (0 = the device, 1.. its modules).
    pub slot: u8,
    /// Appears, disappears, disappears with the slot still disturbed.
    pub change: AlarmChange,
    /// Add_Ack: the master's user must confirm it as well (e.g. by a
    /// write), beyond Alarm_Ack.
    pub add_ack: bool,
    /// Diagnostic_User_Data, at most [`MAX_ALARM_DATA_LEN`] bytes.
    pub data: Vec<u8>,
}

/// An alarm in the queue, with its sequence number.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QueuedAlarm {
    /// The alarm.
    pub alarm: Alarm,
    /// Its sequence number, 0..=31.
    pub seq: u8,
}

impl QueuedAlarm {
    /// The Alarm_Specifier: seq, Add_Ack, appears/disappears.
    pub fn specifier(&self) -> AlarmSpecifier {
        AlarmSpecifier {
            seq: self.seq,
            add_ack: self.alarm.add_ack,
            change: self.alarm.change,
        }
    }
}

/// Why an alarm was not queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RaiseError {
    /// Not in Data_Exch with DPV1_Enable from a master that enabled alarms.
    #[error("no alarms now: the slave is not in Data_Exch with DP-V1 alarms enabled")]
    Inactive,
    /// The master did not enable this type in DPV1_Status_2.
    #[error("the master did not enable {} alarms (DPV1_Status_2)", .0.word())]
    NotEnabled(AlarmType),
    /// 32 alarms wait already.
    #[error("the alarm queue is full (32 alarms wait for their acknowledgement)")]
    Full,
    /// More than 59 bytes of data.
    #[error("{0} bytes of alarm data, at most 59 fit into an alarm block")]
    TooLong(usize),
}

/// Why an Alarm_Ack was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum AckError {
    /// No outstanding alarm has this slot, type and sequence number.
    #[error("no {} alarm of slot {slot} with seq {seq} is outstanding", .alarm_type.word())]
    NotOutstanding {
        /// Slot of the Alarm_Ack.
        slot: u8,
        /// Type of the Alarm_Ack.
        alarm_type: AlarmType,
        /// Sequence number of the Alarm_Ack.
        seq: u8,
    },
    /// Sequence mode: an alarm with an earlier number is outstanding.
    #[error("out of order: seq {seq} acknowledged while seq {expected} is outstanding")]
    OutOfOrder {
        /// Sequence number of the Alarm_Ack.
        seq: u8,
        /// The oldest outstanding alarm's.
        expected: u8,
    },
}

/// The queue; see the module docs.
#[derive(Debug)]
pub struct AlarmQueue {
    queue: VecDeque<QueuedAlarm>,
    next_seq: u8,
    enables: Dpv1Status2,
    mode: AlarmMode,
    open: bool,
}

impl Default for AlarmQueue {
    fn default() -> Self {
        AlarmQueue::new()
    }
}

impl AlarmQueue {
    /// A closed, empty queue.
    pub fn new() -> AlarmQueue {
        AlarmQueue {
            queue: VecDeque::with_capacity(ALARM_QUEUE_LEN),
            next_seq: 0,
            enables: Dpv1Status2::empty(),
            mode: AlarmMode::default(),
            open: false,
        }
    }

    /// Open the queue for the alarm types `enables` (the alarm bits of
    /// DPV1_Status_2) with `mode` (from an accepted Set_Prm).
    pub fn open(&mut self, enables: Dpv1Status2, mode: AlarmMode) {
        self.reset();
        self.enables = enables.difference(Dpv1Status2::CHECK_CFG_MODE);
        self.mode = mode;
        self.open = !self.enables.is_empty();
    }

    /// Close and empty it (the slave left Data_Exch).
    pub fn reset(&mut self) {
        self.queue.clear();
        self.next_seq = 0;
        self.open = false;
    }

    /// Whether alarms may be raised.
    pub fn is_open(&self) -> bool {
        self.open
    }

    /// The alarm mode in force.
    pub fn mode(&self) -> AlarmMode {
        self.mode
    }

    /// Queue `alarm`; returns it with its sequence number, and whether it
    /// is outstanding at once (then the diagnosis changed).
    pub fn raise(&mut self, alarm: Alarm) -> Result<(QueuedAlarm, bool), RaiseError> {
        if !self.open {
            return Err(RaiseError::Inactive);
        }
        let enabled = alarm
            .alarm_type
            .enable()
            .is_some_and(|e| self.enables.contains(e.bit()));
        if !enabled {
            return Err(RaiseError::NotEnabled(alarm.alarm_type));
        }
        if alarm.data.len() > MAX_ALARM_DATA_LEN {
            return Err(RaiseError::TooLong(alarm.data.len()));
        }
        if self.queue.len() >= ALARM_QUEUE_LEN {
            return Err(RaiseError::Full);
        }
        let q = QueuedAlarm {
            alarm,
            seq: self.next_seq,
        };
        self.next_seq = (self.next_seq + 1) % 32;
        self.queue.push_back(q.clone());
        let outstanding = self.is_outstanding(self.queue.len() - 1);
        Ok((q, outstanding))
    }

    /// Whether the alarm at `i` is outstanding (visible to the master).
    fn is_outstanding(&self, i: usize) -> bool {
        match self.mode.limit() {
            // Type mode: the first alarm of each type.
            AlarmLimit::OnePerType => {
                let t = self.queue[i].alarm.alarm_type;
                !self.queue.range(..i).any(|q| q.alarm.alarm_type == t)
            }
            AlarmLimit::Total(n) => i < n as usize,
        }
    }

    /// The outstanding alarms, oldest first.
    pub fn outstanding(&self) -> impl Iterator<Item = &QueuedAlarm> + '_ {
        (0..self.queue.len())
            .filter(|&i| self.is_outstanding(i))
            .map(|i| &self.queue[i])
    }

    /// All queued alarms, oldest first (outstanding or waiting).
    pub fn queued(&self) -> impl Iterator<Item = &QueuedAlarm> + '_ {
        self.queue.iter()
    }

    /// Write the outstanding alarms' blocks into `diag` as far as they
    /// fit; returns whether one of them says its slot is disturbed (for
    /// Ext_Diag).
    pub fn write(&self, diag: &mut DiagWriter<'_>) -> bool {
        let mut disturbed = false;
        for q in self.outstanding() {
            if diag.remaining() < 4 + q.alarm.data.len() {
                break;
            }
            diag.dpv1_block(
                q.alarm.alarm_type.code(),
                q.alarm.slot,
                q.specifier().byte(),
                &q.alarm.data,
            );
            disturbed |= matches!(
                q.alarm.change,
                AlarmChange::Appears | AlarmChange::DisappearsStillFaulty
            );
        }
        disturbed
    }

    /// An Alarm_Ack for `slot`, `alarm_type`, `specifier`: removes the
    /// alarm it names (returned), or says why not.
    pub fn ack(
        &mut self,
        slot: u8,
        alarm_type: AlarmType,
        specifier: u8,
    ) -> Result<QueuedAlarm, AckError> {
        let seq = specifier >> 3;
        let found = (0..self.queue.len()).find(|&i| {
            let q = &self.queue[i];
            q.seq == seq
                && q.alarm.slot == slot
                && q.alarm.alarm_type == alarm_type
                && self.is_outstanding(i)
        });
        let Some(i) = found else {
            return Err(AckError::NotOutstanding {
                slot,
                alarm_type,
                seq,
            });
        };
        if matches!(self.mode.limit(), AlarmLimit::Total(_)) && i != 0 {
            return Err(AckError::OutOfOrder {
                seq,
                expected: self.queue[0].seq,
            });
        }
        Ok(self.queue.remove(i).expect("index found above"))
    }
}
