//! DP-V1 record requests decided one at a time, over either class:
//! [`RecordOps`] gives the next [`RecordOp`] after the answer to the last;
//! [`C1Records`] runs it as MSAC_C1 jobs of the class-1 master (the path
//! of `dpctl dpv1`), [`crate::class2::Class2Run`] on a class-2
//! connection. [`ImReader`] reads I&M0..I&M4 (and writes I&M1) that way:
//! a Write of the call header `08 00 FI_Index` on index 255 selects the
//! record, the Read that follows returns the call header and its 64 bytes
//! (`shared/reference/dpv1-c2-im-alarms.md` §4.6, \[ABB\] and \[IFM\]).

use super::{DpMaster, Job, JobId, JobResult, SlaveTask, StartupTimeout};
use crate::pdu::dpv1::{Dpv1Error, MAX_DATA_LEN};
use crate::pdu::im::{CallHeader, ImRecord, CALL_HEADER_LEN, CALL_INDEX, RECORD_LEN};
use profibus_fdl::Instant;

/// A DP-V1 record request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RecordOp {
    /// Read up to `length` bytes (1..=240) of the record (slot, index).
    Read {
        /// Slot 0..=254.
        slot: u8,
        /// Index (255: the I&M call).
        index: u8,
        /// Bytes wanted.
        length: u8,
    },
    /// Write `data` (1..=240 bytes) to the record.
    Write {
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// The data.
        data: Vec<u8>,
    },
    /// Data_Transport (class 2 only): send `data` (1..=240 bytes), get
    /// data back.
    Transport {
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// The data sent.
        data: Vec<u8>,
    },
}

impl RecordOp {
    /// `read`, `write` or `transport`.
    pub fn name(&self) -> &'static str {
        match self {
            RecordOp::Read { .. } => "read",
            RecordOp::Write { .. } => "write",
            RecordOp::Transport { .. } => "transport",
        }
    }

    /// Slot and index.
    pub fn record(&self) -> (u8, u8) {
        match *self {
            RecordOp::Read { slot, index, .. }
            | RecordOp::Write { slot, index, .. }
            | RecordOp::Transport { slot, index, .. } => (slot, index),
        }
    }

    /// Bytes asked for (read) or carried (write, transport).
    pub fn len(&self) -> usize {
        match self {
            RecordOp::Read { length, .. } => *length as usize,
            RecordOp::Write { data, .. } | RecordOp::Transport { data, .. } => data.len(),
        }
    }

    /// Whether it asks for or carries no byte (which no slave accepts).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// 1..=240 bytes, or the error naming the request.
    pub fn check(&self) -> Result<(), LengthError> {
        let len = self.len();
        if len == 0 || len > MAX_DATA_LEN {
            return Err(LengthError {
                op: self.name(),
                len,
            });
        }
        Ok(())
    }
}

/// A request of no bytes or more than 240.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("a DP-V1 {op} carries 1..=240 bytes, not {len}")]
pub struct LengthError {
    /// `read`, `write` or `transport`.
    pub op: &'static str,
    /// Its length.
    pub len: usize,
}

/// The slave's answer to a [`RecordOp`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RecordAnswer {
    /// Read.res: the data read.
    Read(Vec<u8>),
    /// Write.res: the length the slave confirmed.
    Written(u8),
    /// Data_Transport response: the data returned.
    Transport(Vec<u8>),
    /// A negative response (the connection stays usable).
    Negative(Dpv1Error),
}

/// Requests decided one at a time, each after the answer to the last.
pub trait RecordOps {
    /// The next request, or `None` when done.
    fn next_op(&mut self) -> Option<RecordOp>;
    /// The answer to `op`.
    fn answered(&mut self, op: &RecordOp, answer: &RecordAnswer);
}

/// A single request ([`RecordOps`] for one read, write or transport).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SingleOp {
    sent: bool,
    /// The request.
    pub request: RecordOp,
    /// Its answer, once it came.
    pub answer: Option<RecordAnswer>,
}

impl SingleOp {
    /// `op`, once.
    pub fn new(op: RecordOp) -> SingleOp {
        SingleOp {
            sent: false,
            request: op,
            answer: None,
        }
    }
}

impl RecordOps for SingleOp {
    fn next_op(&mut self) -> Option<RecordOp> {
        (!std::mem::replace(&mut self.sent, true)).then(|| self.request.clone())
    }

    fn answered(&mut self, _: &RecordOp, answer: &RecordAnswer) {
        self.answer = Some(answer.clone());
    }
}

/// Why [`C1Records`] stopped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum C1RecordsError {
    /// The slave did not reach Data_Exchange.
    #[error(transparent)]
    Startup(#[from] StartupTimeout),
    /// The master's job queue is full.
    #[error("job queue full")]
    QueueFull,
    /// A request that needs class 2.
    #[error("Data_Transport is a class-2 service (MSAC_C2): use --class2")]
    ClassTwoOnly,
    /// A request of no bytes or more than 240.
    #[error(transparent)]
    Length(#[from] LengthError),
    /// A request failed other than with a negative response (no
    /// response, timeout, the slave left Data_Exchange).
    #[error("slave {slave} slot {slot} index {index}: {op} failed: {why}")]
    Failed {
        /// The slave.
        slave: u8,
        /// `read` or `write`.
        op: &'static str,
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// [`JobResult::describe`].
        why: String,
    },
}

/// Runs a [`RecordOps`] as MSAC_C1 jobs of the class-1 master on a slave
/// in Data_Exchange (a [`SlaveTask`] for [`super::TaskRun`]).
#[derive(Debug)]
pub struct C1Records<O> {
    slave: u8,
    ops: O,
    current: Option<(RecordOp, JobId)>,
    done: bool,
}

impl<O: RecordOps> C1Records<O> {
    /// Run `ops` on `slave`.
    pub fn new(slave: u8, ops: O) -> C1Records<O> {
        C1Records {
            slave,
            ops,
            current: None,
            done: false,
        }
    }

    /// The requests and their answers.
    pub fn ops(&self) -> &O {
        &self.ops
    }

    /// The requests and their answers.
    pub fn into_ops(self) -> O {
        self.ops
    }
}

impl<O: RecordOps> SlaveTask for C1Records<O> {
    type Error = C1RecordsError;

    fn busy(&self) -> bool {
        self.current.is_some()
    }

    fn step(&mut self, m: &mut DpMaster, _: Instant, in_dx: bool) -> Result<bool, C1RecordsError> {
        if let Some((op, id)) = self.current.take() {
            let Some(result) = m.take_result(id) else {
                self.current = Some((op, id));
                return Ok(false);
            };
            let answer = match (&op, result) {
                (RecordOp::Read { .. }, JobResult::Data(d)) => RecordAnswer::Read(d),
                (_, JobResult::Done) => RecordAnswer::Written(op.len() as u8),
                (_, JobResult::Dpv1Error(e)) => RecordAnswer::Negative(e),
                (_, other) => {
                    let (slot, index) = op.record();
                    return Err(C1RecordsError::Failed {
                        slave: self.slave,
                        op: op.name(),
                        slot,
                        index,
                        why: other.describe(),
                    });
                }
            };
            self.ops.answered(&op, &answer);
        }
        if self.done {
            return Ok(true);
        }
        if !in_dx {
            return Ok(false);
        }
        let Some(op) = self.ops.next_op() else {
            self.done = true;
            return Ok(true);
        };
        op.check()?;
        let job = match op.clone() {
            RecordOp::Read {
                slot,
                index,
                length,
            } => Job::Dpv1Read {
                address: self.slave,
                slot,
                index,
                length,
            },
            RecordOp::Write { slot, index, data } => Job::Dpv1Write {
                address: self.slave,
                slot,
                index,
                data,
            },
            RecordOp::Transport { .. } => return Err(C1RecordsError::ClassTwoOnly),
        };
        let id = m.submit(job).ok_or(C1RecordsError::QueueFull)?;
        self.current = Some((op, id));
        Ok(false)
    }
}

/// How one I&M record read went.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ImRead {
    /// The 64 record bytes (after the call header).
    Record([u8; RECORD_LEN]),
    /// The slave refused (the selecting write or the read).
    Refused(Dpv1Error),
    /// An answer that is not the record: in words.
    Invalid(String),
}

/// Reads I&M0..I&M4 (after writing I&M1, if asked) through the call on
/// index 255 of a slot; see the module docs. A record whose selecting
/// write is refused is not read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImReader {
    slot: u8,
    write: Option<ImRecord>,
    /// Steps done: I&M1's write (when asked), then per record the
    /// selecting write and the read.
    step: usize,
    /// How writing I&M1 went (`None`: not asked, or not yet).
    pub written: Option<Result<(), Dpv1Error>>,
    /// I&M0..I&M4, as far as read.
    pub records: [Option<ImRead>; 5],
}

impl ImReader {
    /// Read I&M0..4 of `slot` (0: the device), after writing `write`.
    pub fn new(slot: u8, write: Option<ImRecord>) -> ImReader {
        ImReader {
            slot,
            write,
            step: 0,
            written: None,
            records: Default::default(),
        }
    }

    /// I&M0 when it was read.
    pub fn im0(&self) -> Option<crate::pdu::im::Im0> {
        match &self.records[0] {
            Some(ImRead::Record(b)) => crate::pdu::im::Im0::parse(b).ok(),
            _ => None,
        }
    }

    /// (record number, read step) of step `s` after the write.
    fn record_step(&self, s: usize) -> (usize, bool) {
        (s / 2, s % 2 == 1)
    }

    fn first(&self) -> usize {
        usize::from(self.write.is_some())
    }
}

impl RecordOps for ImReader {
    fn next_op(&mut self) -> Option<RecordOp> {
        let (slot, index) = (self.slot, CALL_INDEX);
        if let (0, Some(w)) = (self.step, self.write) {
            let mut data = CallHeader::im(w.number).bytes().to_vec();
            data.extend_from_slice(&w.bytes);
            return Some(RecordOp::Write { slot, index, data });
        }
        loop {
            let (n, read) = self.record_step(self.step - self.first());
            if n > 4 {
                return None;
            }
            if read && self.records[n].is_some() {
                // The selecting write was refused.
                self.step += 1;
                continue;
            }
            return Some(if read {
                RecordOp::Read {
                    slot,
                    index,
                    length: (CALL_HEADER_LEN + RECORD_LEN) as u8,
                }
            } else {
                RecordOp::Write {
                    slot,
                    index,
                    data: CallHeader::im(n as u8).bytes().to_vec(),
                }
            });
        }
    }

    fn answered(&mut self, _: &RecordOp, answer: &RecordAnswer) {
        let step = self.step;
        self.step += 1;
        if step == 0 && self.write.is_some() {
            self.written = Some(match answer {
                RecordAnswer::Negative(e) => Err(*e),
                _ => Ok(()),
            });
            return;
        }
        let (n, read) = self.record_step(step - self.first());
        let Some(slot) = self.records.get_mut(n) else {
            return;
        };
        *slot = match (read, answer) {
            (_, RecordAnswer::Negative(e)) => Some(ImRead::Refused(*e)),
            (false, _) => None,
            (true, RecordAnswer::Read(d)) => Some(match CallHeader::parse(d) {
                Ok((h, rest)) if h.im_number() == Some(n as u8) && rest.len() == RECORD_LEN => {
                    let mut b = [0; RECORD_LEN];
                    b.copy_from_slice(rest);
                    ImRead::Record(b)
                }
                Ok((h, rest)) => ImRead::Invalid(format!(
                    "call header FI_Index {} with {} bytes, not I&M{n} with 64",
                    h.fi_index,
                    rest.len()
                )),
                Err(e) => ImRead::Invalid(e.to_string()),
            }),
            (true, other) => Some(ImRead::Invalid(format!("unexpected answer {other:?}"))),
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feed `ops` answers: `answer(op)` for each request in turn.
    fn drive(
        ops: &mut impl RecordOps,
        mut answer: impl FnMut(&RecordOp) -> RecordAnswer,
    ) -> Vec<RecordOp> {
        let mut seen = Vec::new();
        while let Some(op) = ops.next_op() {
            let a = answer(&op);
            ops.answered(&op, &a);
            seen.push(op);
            assert!(seen.len() < 20, "runs away");
        }
        seen
    }

    fn read_res(n: u8, fill: u8) -> RecordAnswer {
        let mut d = vec![0x08, 0x00, 0xFD, 0xE8 + n];
        d.extend([fill; 64]);
        RecordAnswer::Read(d)
    }

    #[test]
    fn im_reader_selects_then_reads_each_record_as_the_reference_does() {
        let mut r = ImReader::new(0, None);
        let mut selected = 0;
        let seen = drive(&mut r, |op| match op {
            RecordOp::Write { data, .. } => {
                selected = data[3] - 0xE8;
                if selected == 4 {
                    // I&M4 not served.
                    RecordAnswer::Negative(Dpv1Error::dpv1(0x5F, 0xB, 0))
                } else {
                    RecordAnswer::Written(4)
                }
            }
            _ => read_res(selected, b'A' + selected),
        });
        // The reference's bytes for I&M0: write 5F 00 FF 04 08 00 FD E8,
        // then read 5E 00 FF 44.
        assert_eq!(
            seen[0],
            RecordOp::Write {
                slot: 0,
                index: 255,
                data: vec![0x08, 0x00, 0xFD, 0xE8]
            }
        );
        assert_eq!(
            seen[1],
            RecordOp::Read {
                slot: 0,
                index: 255,
                length: 0x44
            }
        );
        assert_eq!(seen.len(), 9, "I&M4's read is skipped: {seen:?}");
        assert!(matches!(r.records[3], Some(ImRead::Record(b)) if b[0] == b'D'));
        assert!(matches!(r.records[4], Some(ImRead::Refused(_))));
        assert_eq!(r.written, None);
    }

    #[test]
    fn im_reader_writes_im1_first_and_flags_a_wrong_record() {
        let im1 = ImRecord::im1("pump 3", "hall B").unwrap();
        let mut r = ImReader::new(0, Some(im1));
        let seen = drive(&mut r, |op| match op {
            RecordOp::Write { data, .. } => RecordAnswer::Written(data.len() as u8),
            // Always I&M0's header: wrong for records 1..4.
            _ => read_res(0, b' '),
        });
        match &seen[0] {
            RecordOp::Write { data, index, .. } => {
                assert_eq!(*index, 255);
                assert_eq!(data.len(), 68);
                assert_eq!(&data[..4], &[0x08, 0x00, 0xFD, 0xE9]);
                assert_eq!(&data[14..20], b"pump 3");
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(r.written, Some(Ok(())));
        assert!(matches!(r.records[0], Some(ImRead::Record(_))));
        assert_eq!(
            r.records[1],
            Some(ImRead::Invalid(
                "call header FI_Index 65000 with 64 bytes, not I&M1 with 64".into()
            ))
        );
    }

    #[test]
    fn single_op_once_and_lengths() {
        let mut s = SingleOp::new(RecordOp::Read {
            slot: 1,
            index: 2,
            length: 3,
        });
        assert!(s.next_op().is_some());
        assert!(s.next_op().is_none());
        let empty = RecordOp::Transport {
            slot: 0,
            index: 0,
            data: vec![],
        };
        assert_eq!(
            empty.check().unwrap_err().to_string(),
            "a DP-V1 transport carries 1..=240 bytes, not 0"
        );
    }

    #[test]
    fn class_1_runs_ops_as_jobs_and_refuses_data_transport() {
        let mut m = crate::master::tests::master(); // slave 8
        let mut t = C1Records::new(
            8,
            SingleOp::new(RecordOp::Transport {
                slot: 0,
                index: 1,
                data: vec![1],
            }),
        );
        assert_eq!(t.step(&mut m, Instant::ZERO, false), Ok(false));
        assert_eq!(
            t.step(&mut m, Instant::ZERO, true),
            Err(C1RecordsError::ClassTwoOnly)
        );
        let mut t = C1Records::new(
            8,
            SingleOp::new(RecordOp::Read {
                slot: 0,
                index: 1,
                length: 4,
            }),
        );
        assert_eq!(t.step(&mut m, Instant::ZERO, true), Ok(false));
        assert!(t.busy(), "submitted");
    }
}
