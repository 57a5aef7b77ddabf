//! The master side of the handshake: [`RfidClient`] sends one command
//! line and returns the whole reassembled answer, over the 16-byte
//! process images of a reader in Data_Exchange.
//!
//! The client is fed with the reader's input image, its output image (to
//! write into) and the count of completed Data_Exchange cycles of that
//! slave ([`SlaveStats::data_exchanges`]). It follows the manual's rules:
//!
//! 1. **Drain**: if the data flag is set when a command starts (an answer
//!    left over, e.g. from a command that timed out), that answer is
//!    fetched as in step 3 and dropped, because a command may be sent only
//!    while the flag is 0 (L72).
//! 2. **Send** (L72-78): the command, with CR appended when it has none,
//!    in fragments of at most 13 bytes. For each fragment the payload and
//!    the length L are written and S is incremented in the same update of
//!    the output image: the master takes the image as a whole when it
//!    builds a Data_Exchange request, so the reader never sees the new S
//!    with old data. The next fragment follows once the count of
//!    Data_Exchange cycles has grown by 2 since the write (the cycle in
//!    flight may still have carried the old image), and only while the
//!    data flag is 0.
//! 3. **Fetch** (L82-93): once the data flag is set, R is incremented
//!    (with S unchanged and L = 0, payload 0, as in the manual's example);
//!    a response is read only when E differs from E before the change
//!    (several cycles may pass, L90). Its L bytes are appended; while the
//!    flag is still set, R is incremented again. The answer is complete
//!    when a fragment arrives with the flag 0.
//!
//! A command that does not finish within the timeout fails with
//! [`RfidError::Timeout`] (which step it was in), and the client is idle
//! again: R and S keep their values (changing them would start jobs), L
//! and the payload are set to 0. Nothing is allocated per cycle: the
//! answer goes into a buffer reserved at construction (see
//! [`RfidClient::with_capacity`]).
//!
//! [`SlaveStats::data_exchanges`]: profibus_dp::master::SlaveStats::data_exchanges

use super::{CR, DATA_FLAG, HEADER_LEN, PAYLOAD_MAX, TELEGRAM_LEN};
use profibus_dp::master::{DpMaster, SlaveHandle, SlaveState};
use profibus_fdl::Instant;
use std::fmt;
use std::time::Duration;

/// Cycles after a change of the output image before it counts as sent.
const SENT_AFTER: u64 = 2;

/// Default capacity of the answer buffer.
pub const DEFAULT_ANSWER_CAPACITY: usize = 4096;

/// Where a command was when it failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Fetching an answer left over from before.
    Drain,
    /// Sending the command (or waiting for the flag to clear to send).
    Send,
    /// Waiting for the data flag.
    Answer,
    /// Fetching fragments (waiting for E to change).
    Fetch,
}

impl Stage {
    /// Words for people.
    pub fn as_str(self) -> &'static str {
        match self {
            Stage::Drain => "fetching an answer left over from before",
            Stage::Send => "sending the command",
            Stage::Answer => "waiting for the data flag",
            Stage::Fetch => "fetching the answer (waiting for E to change)",
        }
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Why a command failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RfidError {
    /// No complete answer within the timeout.
    #[error("no complete answer within {} ms ({stage})", after.as_millis())]
    Timeout {
        /// The timeout.
        after: Duration,
        /// Where the command was.
        stage: Stage,
    },
    /// The answer did not fit the answer buffer.
    #[error("the answer is longer than {0} bytes")]
    AnswerTooLong(usize),
}

/// Why a command cannot start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum StartError {
    /// A command is running.
    #[error("an RFID command is still running")]
    Busy,
    /// A CR inside the command (it would be two commands).
    #[error("the command contains a CR before its end")]
    EmbeddedCr,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Idle,
    /// Fetching a left-over answer; `Some(e)`: R changed while E was e.
    Drain(Option<u8>),
    /// Sending the fragment at `offset` (`len` bytes); `written`: the
    /// cycle count when it was written.
    Send {
        offset: usize,
        len: usize,
        written: Option<u64>,
    },
    Answer,
    /// R changed while E was `e`.
    Fetch {
        e: u8,
    },
}

/// The master side of the reader's handshake; see the module docs.
#[derive(Debug, Clone)]
pub struct RfidClient {
    timeout: Duration,
    state: State,
    started: Instant,
    command: Vec<u8>,
    answer: Vec<u8>,
    capacity: usize,
    drained: usize,
    restarts_seen: Option<u64>,
}

impl RfidClient {
    /// An idle client giving up a command after `timeout`.
    pub fn new(timeout: Duration) -> RfidClient {
        RfidClient::with_capacity(timeout, DEFAULT_ANSWER_CAPACITY)
    }

    /// An idle client whose answers may be up to `capacity` bytes long.
    pub fn with_capacity(timeout: Duration, capacity: usize) -> RfidClient {
        RfidClient {
            timeout,
            state: State::Idle,
            started: Instant::ZERO,
            command: Vec::with_capacity(64),
            answer: Vec::with_capacity(capacity),
            capacity,
            drained: 0,
            restarts_seen: None,
        }
    }

    /// No command is running.
    pub fn is_idle(&self) -> bool {
        self.state == State::Idle
    }

    /// Bytes of left-over answers dropped before the last command.
    pub fn drained(&self) -> usize {
        self.drained
    }

    /// The command line being sent (with its CR).
    pub fn command(&self) -> &[u8] {
        &self.command
    }

    /// Start sending `command` (a CR is appended when it does not end
    /// with one).
    pub fn start(&mut self, now: Instant, command: &[u8]) -> Result<(), StartError> {
        if !self.is_idle() {
            return Err(StartError::Busy);
        }
        let body = command.strip_suffix(&[CR]).unwrap_or(command);
        if body.contains(&CR) {
            return Err(StartError::EmbeddedCr);
        }
        self.command.clear();
        self.command.extend_from_slice(body);
        self.command.push(CR);
        self.answer.clear();
        self.drained = 0;
        self.started = now;
        self.state = State::Drain(None);
        Ok(())
    }

    /// Drive the handshake: `cycle` is the reader's count of completed
    /// Data_Exchange cycles, `inputs`/`outputs` its process images (16
    /// bytes each). Returns the reassembled answer (with its CRs) once.
    pub fn poll(
        &mut self,
        now: Instant,
        cycle: u64,
        inputs: &[u8],
        outputs: &mut [u8],
    ) -> Option<Result<&[u8], RfidError>> {
        if self.state == State::Idle {
            return None;
        }
        if inputs.len() < TELEGRAM_LEN || outputs.len() < TELEGRAM_LEN {
            return self.check_timeout(now, outputs).map(Err);
        }
        let flag = inputs[0] & DATA_FLAG != 0;
        let e = inputs[1];
        let len = (inputs[2] as usize).min(PAYLOAD_MAX);
        let payload = &inputs[HEADER_LEN..HEADER_LEN + len];
        loop {
            match self.state {
                State::Idle => return None,
                State::Drain(None) => {
                    if !flag {
                        self.state = State::Send {
                            offset: 0,
                            len: 0,
                            written: None,
                        };
                        continue;
                    }
                    fetch(outputs);
                    self.state = State::Drain(Some(e));
                }
                State::Drain(Some(before)) => {
                    if e != before {
                        self.drained += len;
                        self.state = State::Drain(None);
                        continue;
                    }
                }
                State::Send {
                    offset,
                    written: None,
                    ..
                } => {
                    if !flag {
                        let n = (self.command.len() - offset).min(PAYLOAD_MAX);
                        let frag = &self.command[offset..offset + n];
                        outputs[2] = n as u8;
                        outputs[HEADER_LEN..HEADER_LEN + n].copy_from_slice(frag);
                        outputs[HEADER_LEN + n..TELEGRAM_LEN].fill(0);
                        outputs[1] = outputs[1].wrapping_add(1);
                        self.state = State::Send {
                            offset,
                            len: n,
                            written: Some(cycle),
                        };
                    }
                }
                State::Send {
                    offset,
                    len: n,
                    written: Some(w),
                } => {
                    if cycle >= w + SENT_AFTER {
                        let offset = offset + n;
                        self.state = if offset >= self.command.len() {
                            State::Answer
                        } else {
                            State::Send {
                                offset,
                                len: 0,
                                written: None,
                            }
                        };
                        continue;
                    }
                }
                State::Answer => {
                    if flag {
                        fetch(outputs);
                        self.state = State::Fetch { e };
                    }
                }
                State::Fetch { e: before } => {
                    if e != before {
                        if self.answer.len() + len > self.capacity {
                            self.finish(outputs);
                            return Some(Err(RfidError::AnswerTooLong(self.capacity)));
                        }
                        self.answer.extend_from_slice(payload);
                        if flag {
                            fetch(outputs);
                            self.state = State::Fetch { e };
                        } else {
                            self.finish(outputs);
                            return Some(Ok(&self.answer));
                        }
                    }
                }
            }
            break;
        }
        self.check_timeout(now, outputs).map(Err)
    }

    /// Drive the handshake with the images of `slave` in `master` (a
    /// gateway's loop); nothing is allocated. When the reader leaves
    /// Data_Exchange or the master starts it up again while a command
    /// runs, the command starts over ([`RfidClient::restart`]).
    pub fn poll_master(
        &mut self,
        now: Instant,
        master: &mut DpMaster,
        slave: SlaveHandle,
    ) -> Option<Result<&[u8], RfidError>> {
        let view = master.slave(slave);
        let mut inputs = [0u8; TELEGRAM_LEN];
        let in_dx = view.state == SlaveState::DataExchange && view.inputs.len() >= TELEGRAM_LEN;
        if in_dx {
            inputs.copy_from_slice(&view.inputs[..TELEGRAM_LEN]);
        }
        let cycle = view.stats.data_exchanges;
        let restarts = view.stats.restarts;
        let restarted = self.restarts_seen.is_some_and(|r| r != restarts);
        self.restarts_seen = Some(restarts);
        let outputs = master.outputs_mut(slave);
        if !in_dx || restarted {
            self.restart(outputs);
        }
        if !in_dx {
            return self.check_timeout(now, outputs).map(Err);
        }
        self.poll(now, cycle, &inputs, outputs)
    }

    /// The reader started afresh (a new start-up of its DP interface
    /// drops what it had received and its answer, and counts R, S and E
    /// from 0): send the running command again from its start. L and the
    /// payload of `outputs` are set to 0 at once, so that the reader takes
    /// no stale fragment when it sees S differ from its new reference; an
    /// S of 255 becomes 0 (the next job's S + 1 must differ from 0). The
    /// timeout keeps running.
    pub fn restart(&mut self, outputs: &mut [u8]) {
        if self.state == State::Idle || outputs.len() < TELEGRAM_LEN {
            return;
        }
        self.state = State::Drain(None);
        self.answer.clear();
        outputs[2..TELEGRAM_LEN].fill(0);
        if outputs[1] == 0xFF {
            outputs[1] = 0;
        }
    }

    fn stage(&self) -> Stage {
        match self.state {
            State::Drain(_) => Stage::Drain,
            State::Send { .. } | State::Idle => Stage::Send,
            State::Answer => Stage::Answer,
            State::Fetch { .. } => Stage::Fetch,
        }
    }

    fn check_timeout(&mut self, now: Instant, outputs: &mut [u8]) -> Option<RfidError> {
        if self.state == State::Idle || now.saturating_duration_since(self.started) < self.timeout {
            return None;
        }
        let stage = self.stage();
        self.finish(outputs);
        Some(RfidError::Timeout {
            after: self.timeout,
            stage,
        })
    }

    /// Idle again: L and the payload 0, R and S as they are.
    fn finish(&mut self, outputs: &mut [u8]) {
        self.state = State::Idle;
        if outputs.len() >= TELEGRAM_LEN {
            outputs[2..TELEGRAM_LEN].fill(0);
        }
    }
}

/// Ask for a fragment: R + 1, S unchanged, L and the payload 0.
fn fetch(outputs: &mut [u8]) {
    outputs[0] = outputs[0].wrapping_add(1);
    outputs[2..TELEGRAM_LEN].fill(0);
}
