//! The master's side of DP-V1 alarms (class 1): alarm blocks found in a
//! slave's Slave_Diag wait here for their Alarm_Ack (MSAC_C1, SAP 50 from
//! SAP 51: `5C slot type specifier`; dpv1-c2-im-alarms.md §4.4).
//!
//! - An alarm is taken from every diagnosis read while it is in it; the
//!   slave keeps it there until it is acknowledged, so a block seen again
//!   (same type, slot and sequence number) is the same alarm.
//! - Acknowledgements go out one at a time, as an acyclic request between
//!   poll cycles (like the MSAC_C1 jobs: Data_Exchange keeps running), and
//!   in sequence-number order: the waiting alarm whose number follows the
//!   last acknowledged one most closely (numbers wrap at 32) goes first.
//!   The slave's limit of outstanding alarms (Alarm_Mode) bounds what it
//!   shows; the master holds at most 32.
//! - A negative answer, no answer, or no answer within the slave's
//!   C1_Response_Timeout while polling, is retried up to
//!   [`ALARM_ACK_TRIES`] times in all; then the alarm is reported as not
//!   acknowledged.
//! - Each alarm is reported once ([`MasterEvent::Alarm`](super::MasterEvent::Alarm)),
//!   when it is acknowledged or given up (also when the slave leaves
//!   Data_Exchange first).

use crate::pdu::alarm::{dpv1_blocks, AlarmBlock, AlarmSpecifier, AlarmType, DiagBlock};
use crate::pdu::diag::SlaveDiag;
use profibus_fdl::Instant;

/// Alarm_Ack attempts per alarm before it is reported as not
/// acknowledged.
pub const ALARM_ACK_TRIES: u8 = 3;

/// The most alarms the master keeps per slave (the sequence numbers).
const MAX_PENDING: usize = 32;

/// An alarm the master reports ([`MasterEvent::Alarm`](super::MasterEvent::Alarm)):
/// the block it read and how its acknowledgement went.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlarmNotice {
    /// Alarm_Type.
    pub alarm_type: AlarmType,
    /// Slot_Number.
    pub slot: u8,
    /// Alarm_Specifier (sequence number, Add_Ack, appears/disappears).
    pub specifier: AlarmSpecifier,
    /// Diagnostic_User_Data.
    pub data: Vec<u8>,
    /// The slave confirmed the Alarm_Ack.
    pub acknowledged: bool,
    /// Why it was not acknowledged, in words.
    pub problem: Option<String>,
}

impl AlarmNotice {
    /// The alarm block.
    pub fn block(&self) -> AlarmBlock<'_> {
        AlarmBlock {
            alarm_type: self.alarm_type,
            slot: self.slot,
            specifier: self.specifier,
            data: &self.data,
        }
    }

    /// A block just read: not acknowledged (yet).
    pub fn new(b: &AlarmBlock<'_>) -> AlarmNotice {
        AlarmNotice {
            alarm_type: b.alarm_type,
            slot: b.slot,
            specifier: b.specifier,
            data: b.data.to_vec(),
            acknowledged: false,
            problem: None,
        }
    }

    /// The same alarm: type, slot and sequence number.
    pub fn same(&self, b: &AlarmBlock<'_>) -> bool {
        self.alarm_type == b.alarm_type
            && self.slot == b.slot
            && self.specifier.seq == b.specifier.seq
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Ack {
    /// Waiting for its Alarm_Ack: attempts made, and since when the slave
    /// is polled for the answer.
    Waiting {
        tries: u8,
        polling_since: Option<Instant>,
    },
    /// Acknowledged or given up: kept while the slave still shows it.
    Settled,
}

#[derive(Debug, Clone)]
struct Pending {
    alarm: AlarmNotice,
    ack: Ack,
    /// Seen in the last diagnosis.
    seen: bool,
}

/// The alarms of one slave; see the module docs.
#[derive(Debug, Default)]
pub(crate) struct SlaveAlarms {
    pending: Vec<Pending>,
    /// The sequence number expected next (after the last acknowledged).
    next_seq: u8,
}

/// What an Alarm_Ack attempt came to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum AckOutcome {
    /// The slave echoed the Alarm_Ack.
    Confirmed,
    /// The slave accepted it and is to be polled for the answer.
    Poll,
    /// Refused, not answered, or a wrong answer: why, in words.
    Failed(String),
}

impl SlaveAlarms {
    /// Take the alarm blocks of a diagnosis (of a DP-V1 slave with alarms
    /// enabled). Settled alarms the slave no longer shows are forgotten.
    pub(crate) fn on_diag(&mut self, diag: &SlaveDiag<'_>) {
        for p in &mut self.pending {
            p.seen = false;
        }
        for b in dpv1_blocks(diag.ext_diag) {
            let DiagBlock::Alarm(block) = b else {
                continue;
            };
            if let Some(p) = self.pending.iter_mut().find(|p| p.alarm.same(&block)) {
                p.seen = true;
            } else if self.pending.len() < MAX_PENDING {
                self.pending.push(Pending {
                    alarm: AlarmNotice::new(&block),
                    ack: Ack::Waiting {
                        tries: 0,
                        polling_since: None,
                    },
                    seen: true,
                });
            } else {
                tracing::warn!("more than 32 alarms wait for their acknowledgement");
            }
        }
        self.pending
            .retain(|p| p.seen || !matches!(p.ack, Ack::Settled));
    }

    /// The alarm to acknowledge next (sequence-number order), as its
    /// index; `None` when none waits.
    pub(crate) fn next(&self) -> Option<usize> {
        let next = self.next_seq;
        self.pending
            .iter()
            .enumerate()
            .filter(|(_, p)| matches!(p.ack, Ack::Waiting { .. }))
            .min_by_key(|(_, p)| p.alarm.specifier.seq.wrapping_sub(next) % 32)
            .map(|(i, _)| i)
    }

    /// The Alarm_Ack request of alarm `i`: `5C slot type specifier`, or
    /// empty when the slave is polled for its answer.
    pub(crate) fn request(&self, i: usize, buf: &mut [u8]) -> usize {
        let p = &self.pending[i];
        match p.ack {
            Ack::Waiting {
                polling_since: Some(_),
                ..
            } => 0,
            _ => p.alarm.block().ack().emit(buf).unwrap_or(0),
        }
    }

    /// The answer to the Alarm_Ack of alarm `i`; returns the alarm to
    /// report once it is settled.
    pub(crate) fn outcome(
        &mut self,
        i: usize,
        outcome: AckOutcome,
        now: Instant,
        timeout: std::time::Duration,
    ) -> Option<AlarmNotice> {
        let p = self.pending.get_mut(i)?;
        let Ack::Waiting {
            tries,
            polling_since,
        } = &mut p.ack
        else {
            return None;
        };
        let failed = match outcome {
            AckOutcome::Confirmed => {
                p.ack = Ack::Settled;
                self.next_seq = (p.alarm.specifier.seq + 1) % 32;
                return Some(AlarmNotice {
                    acknowledged: true,
                    ..p.alarm.clone()
                });
            }
            AckOutcome::Poll => {
                let since = *polling_since.get_or_insert(now);
                if now < since + timeout {
                    return None;
                }
                "no answer to Alarm_Ack within the C1 response timeout".to_string()
            }
            AckOutcome::Failed(why) => why,
        };
        *tries += 1;
        *polling_since = None;
        let n = *tries;
        tracing::debug!(tries = n, %failed, "Alarm_Ack failed");
        if n < ALARM_ACK_TRIES {
            return None;
        }
        p.ack = Ack::Settled;
        Some(AlarmNotice {
            problem: Some(format!(
                "not acknowledged after {ALARM_ACK_TRIES} attempts: {failed}"
            )),
            ..p.alarm.clone()
        })
    }

    /// The slave left Data_Exchange: every waiting alarm is given up
    /// (the slave empties its queue); returns them to report.
    pub(crate) fn abandon(&mut self, why: &str) -> Vec<AlarmNotice> {
        let out = self
            .pending
            .iter()
            .filter(|p| matches!(p.ack, Ack::Waiting { .. }))
            .map(|p| AlarmNotice {
                problem: Some(format!("not acknowledged: {why}")),
                ..p.alarm.clone()
            })
            .collect();
        self.pending.clear();
        self.next_seq = 0;
        out
    }

    /// Whether an Alarm_Ack response (`5C slot type specifier`) echoes
    /// the acknowledgement of alarm `i`.
    pub(crate) fn answers(&self, i: usize, slot: u8, alarm_type: u8, specifier: u8) -> bool {
        self.pending.get(i).is_some_and(|p| {
            let a = &p.alarm;
            (a.slot, a.alarm_type.code(), a.specifier.byte()) == (slot, alarm_type, specifier)
        })
    }

    /// Whether an alarm waits for its acknowledgement.
    pub(crate) fn waiting(&self) -> bool {
        self.next().is_some()
    }
}
