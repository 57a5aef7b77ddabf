//! The reader's side of the 16-byte handshake (manual chapter 2, L42-170),
//! as plain code: [`ReaderLink::request`] takes the output data of each
//! Data_Exchange, [`ReaderLink::response`] writes its input data.
//!
//! - **Receiving** (chapter 2.2): every change of the send-job number S is
//!   a send job; its L payload bytes (at most 13) are appended to the
//!   command line, which ends at CR. A line may span several jobs, and one
//!   job may end one line and begin the next. Complete lines wait in a
//!   queue ([`ReaderLink::take_command`]). A job sent while the data flag
//!   is set is **ignored**: the manual allows sending only while the flag
//!   is 0 (L72), so the reader takes no bytes then; S is still taken as the
//!   new reference, and the caller is told ([`Received::Ignored`]).
//! - **Answering** (chapter 2.3): the data flag (status bit 3) is set while
//!   answer bytes wait. A change of the receive-request number R asks for
//!   one fragment; it is delivered not in the response of that
//!   Data_Exchange but of the next one (L86), with up to 13 bytes, the
//!   length in byte 3, unused payload bytes 0, and the receive-acknowledge
//!   number E changed. A fragment ends at the end of an answer line: the
//!   bytes after a CR go into the next fragment. This is what the manual's
//!   example shows: the two lines of the `VER` answer (19 and 23 bytes)
//!   travel as 13 + 6 and 13 + 10 bytes, not as 13 + 13 + 13 + 3. E takes the value of R (the manual's example shows
//!   E = R throughout); should that not change E (R jumped to the current
//!   E) it is E + 1 instead, because the master sees data only by a change
//!   of E (L90).
//! - R of the first request after power-up or a reset is the reference,
//!   not a change: a master that kept its output image while the reader
//!   started afresh does not ask for a fragment of the next answer before
//!   it has seen the data flag. S, in contrast, counts from 0: a command
//!   already in the image when the reader starts is a send job.
//! - A change of R while nothing waits and no command runs asks for
//!   nothing ("only if R changed **and** the flag is set", L82) and is
//!   forgotten. While a command runs (its answer will come) it is kept:
//!   the fragment is delivered once the answer is there, at the earliest in
//!   the second Data_Exchange after the change. A further change of R
//!   before the delivery starts the wait again.
//! - Between deliveries the response repeats the last fragment (E, L and
//!   payload unchanged) with the current data flag, so a master that reads
//!   only after E changed never sees a fragment twice.

use super::{CR, DATA_FLAG, HEADER_LEN, PAYLOAD_MAX, TELEGRAM_LEN};
use std::collections::VecDeque;

/// Longest command line the reader takes (without the CR). A longer line
/// is answered with the buffer-overflow error.
pub const MAX_LINE: usize = 255;

/// Most complete command lines waiting to be executed; lines beyond are
/// dropped (and answered with the buffer-overflow error).
pub const MAX_QUEUED: usize = 8;

/// A complete command line from the master.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Line {
    /// The bytes before the CR.
    Text(Vec<u8>),
    /// The line was longer than [`MAX_LINE`] or the queue was full.
    Overflow,
}

/// What a request did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Received {
    /// S unchanged: no send job.
    Nothing,
    /// A send job: `bytes` payload bytes taken, `lines` command lines
    /// completed by them.
    Job {
        /// Payload bytes taken (L, at most 13).
        bytes: usize,
        /// Command lines completed (CR seen).
        lines: usize,
    },
    /// A send job while the data flag was set: its bytes were not taken.
    Ignored,
}

/// Where the one-cycle delay of a fetch stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fetch {
    /// No fragment asked for.
    Idle,
    /// R changed in the current Data_Exchange: its response carries no
    /// data.
    Requested,
    /// The next response with data available delivers a fragment.
    Due,
}

/// Counters of the handshake.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Send jobs taken.
    pub jobs: u64,
    /// Send jobs ignored because the data flag was set.
    pub ignored_jobs: u64,
    /// Fragments delivered.
    pub fragments: u64,
}

/// The reader's side of the handshake; see the module docs.
#[derive(Debug, Clone)]
pub struct ReaderLink {
    /// R of the last request; `None` until the first request after
    /// power-up or a reset.
    last_r: Option<u8>,
    last_s: u8,
    line: Vec<u8>,
    line_overflow: bool,
    lines: VecDeque<Line>,
    answer: Vec<u8>,
    sent: usize,
    fetch: Fetch,
    response: [u8; TELEGRAM_LEN],
    stats: LinkStats,
}

impl Default for ReaderLink {
    fn default() -> ReaderLink {
        ReaderLink::new()
    }
}

impl ReaderLink {
    /// The state after power-up: R, S and E are 0, nothing waits.
    pub fn new() -> ReaderLink {
        ReaderLink {
            last_r: None,
            last_s: 0,
            line: Vec::with_capacity(MAX_LINE),
            line_overflow: false,
            lines: VecDeque::with_capacity(MAX_QUEUED),
            answer: Vec::with_capacity(256),
            sent: 0,
            fetch: Fetch::Idle,
            response: [0; TELEGRAM_LEN],
            stats: LinkStats::default(),
        }
    }

    /// Back to the state after power-up (a new start-up of the DP
    /// interface): the numbers are 0, received and unsent bytes are
    /// dropped.
    pub fn reset(&mut self) {
        let stats = self.stats;
        *self = ReaderLink::new();
        self.stats = stats;
    }

    /// Answer bytes wait: the data flag is set.
    pub fn data_waiting(&self) -> bool {
        self.sent < self.answer.len()
    }

    /// Counters.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// The request (output data) of a Data_Exchange; `busy` says that a
    /// command is executing or queued (its answer will come), which keeps
    /// a change of R pending. Requests shorter than 3 bytes are ignored.
    pub fn request(&mut self, req: &[u8], busy: bool) -> Received {
        if req.len() < HEADER_LEN {
            return Received::Nothing;
        }
        let (r, s, l) = (req[0], req[1], req[2] as usize);
        let mut got = Received::Nothing;
        if s != self.last_s {
            self.last_s = s;
            got = if self.data_waiting() {
                self.stats.ignored_jobs += 1;
                Received::Ignored
            } else {
                self.stats.jobs += 1;
                let n = l.min(PAYLOAD_MAX).min(req.len() - HEADER_LEN);
                let lines = self.take_bytes(&req[HEADER_LEN..HEADER_LEN + n]);
                Received::Job { bytes: n, lines }
            };
        }
        let last_r = self.last_r.replace(r);
        if last_r.is_some_and(|l| l != r) {
            let busy = busy || !self.lines.is_empty();
            self.fetch = if self.data_waiting() || busy {
                Fetch::Requested
            } else {
                Fetch::Idle
            };
        }
        got
    }

    fn take_bytes(&mut self, bytes: &[u8]) -> usize {
        let mut lines = 0;
        for &b in bytes {
            if b == CR {
                let line = if self.line_overflow || self.lines.len() >= MAX_QUEUED {
                    Line::Overflow
                } else {
                    Line::Text(self.line.clone())
                };
                if self.lines.len() < MAX_QUEUED {
                    self.lines.push_back(line);
                } else if let Some(last) = self.lines.back_mut() {
                    *last = Line::Overflow;
                }
                self.line.clear();
                self.line_overflow = false;
                lines += 1;
            } else if self.line.len() < MAX_LINE {
                self.line.push(b);
            } else {
                self.line_overflow = true;
            }
        }
        lines
    }

    /// The oldest complete command line.
    pub fn take_command(&mut self) -> Option<Line> {
        self.lines.pop_front()
    }

    /// Complete command lines waiting.
    pub fn commands_waiting(&self) -> usize {
        self.lines.len()
    }

    /// Queue answer bytes: the data flag is set from the next response on.
    pub fn push_answer(&mut self, bytes: &[u8]) {
        if self.sent > 0 && self.sent == self.answer.len() {
            self.answer.clear();
            self.sent = 0;
        }
        self.answer.extend_from_slice(bytes);
    }

    /// Answer bytes not yet delivered.
    pub fn pending_answer(&self) -> &[u8] {
        &self.answer[self.sent..]
    }

    /// The response (input data) of the Data_Exchange whose request was
    /// the last one given to [`ReaderLink::request`]. Writes at most 16
    /// bytes; a longer buffer's tail is left alone.
    pub fn response(&mut self, out: &mut [u8]) {
        match self.fetch {
            Fetch::Idle => {}
            Fetch::Requested => self.fetch = Fetch::Due,
            Fetch::Due if self.data_waiting() => {
                self.deliver();
                self.fetch = Fetch::Idle;
            }
            Fetch::Due => {}
        }
        self.response[0] = if self.data_waiting() { DATA_FLAG } else { 0 };
        let n = out.len().min(TELEGRAM_LEN);
        out[..n].copy_from_slice(&self.response[..n]);
    }

    fn deliver(&mut self) {
        let rest = &self.answer[self.sent..];
        let line_end = rest
            .iter()
            .position(|&b| b == CR)
            .map_or(rest.len(), |p| p + 1);
        let n = line_end.min(PAYLOAD_MAX);
        let e = self.response[1];
        let r = self.last_r.unwrap_or(e);
        self.response[1] = if r != e { r } else { e.wrapping_add(1) };
        self.response[2] = n as u8;
        let payload = &mut self.response[HEADER_LEN..];
        payload[..n].copy_from_slice(&rest[..n]);
        payload[n..].fill(0);
        self.sent += n;
        self.stats.fragments += 1;
        if self.sent == self.answer.len() {
            self.answer.clear();
            self.sent = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(r: u8, s: u8, payload: &[u8]) -> [u8; 16] {
        let mut t = [0u8; 16];
        t[0] = r;
        t[1] = s;
        t[2] = payload.len() as u8;
        t[3..3 + payload.len()].copy_from_slice(payload);
        t
    }

    fn dx(l: &mut ReaderLink, request: &[u8; 16]) -> [u8; 16] {
        l.request(request, false);
        let mut out = [0u8; 16];
        l.response(&mut out);
        out
    }

    #[test]
    fn a_line_over_several_jobs_and_two_lines_in_one_job() {
        let mut l = ReaderLink::new();
        assert_eq!(
            l.request(&req(0, 1, b"WD 0 00112233"), false),
            Received::Job {
                bytes: 13,
                lines: 0
            }
        );
        // S unchanged: the same bytes are not taken again.
        assert_eq!(
            l.request(&req(0, 1, b"WD 0 00112233"), false),
            Received::Nothing
        );
        assert_eq!(
            l.request(&req(0, 2, b"4455\rVER\r"), false),
            Received::Job { bytes: 9, lines: 2 }
        );
        assert_eq!(
            l.take_command(),
            Some(Line::Text(b"WD 0 001122334455".to_vec()))
        );
        assert_eq!(l.take_command(), Some(Line::Text(b"VER".to_vec())));
        assert_eq!(l.take_command(), None);
        // L = 0: a job without bytes; L above 13 is cut to 13.
        assert_eq!(
            l.request(&req(0, 3, b""), false),
            Received::Job { bytes: 0, lines: 0 }
        );
        let mut t = req(0, 4, b"ABCDEFGHIJKLM");
        t[2] = 200;
        assert_eq!(
            l.request(&t, false),
            Received::Job {
                bytes: 13,
                lines: 0
            }
        );
    }

    #[test]
    fn too_long_a_line_is_an_overflow() {
        let mut l = ReaderLink::new();
        let chunk = [b'A'; 13];
        for s in 1..=20u8 {
            l.request(&req(0, s, &chunk), false);
        }
        l.request(&req(0, 21, b"\r"), false);
        assert_eq!(l.take_command(), Some(Line::Overflow));
        l.request(&req(0, 22, b"GT\r"), false);
        assert_eq!(l.take_command(), Some(Line::Text(b"GT".to_vec())));
    }

    #[test]
    fn delivery_one_cycle_after_the_change_of_r_with_e_changed() {
        let mut l = ReaderLink::new();
        l.request(&req(0, 1, b"X\r"), false);
        assert_eq!(l.take_command(), Some(Line::Text(b"X".to_vec())));
        l.push_answer(b"0123456789ABCDEFG\r");
        let mut out = [0u8; 16];
        l.response(&mut out);
        assert_eq!(out[..3], [0x08, 0, 0], "flag set, nothing delivered");
        // R changes: this response carries nothing yet.
        let o = dx(&mut l, &req(1, 1, b""));
        assert_eq!(o[..3], [0x08, 0, 0]);
        let o = dx(&mut l, &req(1, 1, b""));
        assert_eq!(o[..3], [0x08, 1, 13]);
        assert_eq!(&o[3..], b"0123456789ABC");
        // No new change of R: the fragment is repeated, nothing consumed.
        let o2 = dx(&mut l, &req(1, 1, b""));
        assert_eq!(o, o2);
        dx(&mut l, &req(2, 1, b""));
        let o = dx(&mut l, &req(2, 1, b""));
        assert_eq!(o[..3], [0x00, 2, 5], "last fragment: flag drops");
        assert_eq!(&o[3..8], b"DEFG\r");
        assert_eq!(o[8..], [0; 8], "unused payload bytes are 0");
        // A change of R with nothing waiting asks for nothing.
        dx(&mut l, &req(3, 1, b""));
        l.push_answer(b"Z\r");
        let o = dx(&mut l, &req(3, 1, b""));
        assert_eq!(o[..3], [0x08, 2, 5], "the old change of R was forgotten");
    }

    #[test]
    fn a_job_while_the_flag_is_set_is_ignored() {
        let mut l = ReaderLink::new();
        l.push_answer(b"A\r");
        assert_eq!(l.request(&req(0, 1, b"VER\r"), false), Received::Ignored);
        assert_eq!(l.take_command(), None);
        assert_eq!(l.stats().ignored_jobs, 1);
        // Fetch the answer; the same S again is no new job.
        dx(&mut l, &req(1, 1, b""));
        dx(&mut l, &req(1, 1, b""));
        assert!(!l.data_waiting());
        assert_eq!(l.request(&req(1, 1, b"VER\r"), false), Received::Nothing);
        assert_eq!(
            l.request(&req(1, 2, b"VER\r"), false),
            Received::Job { bytes: 4, lines: 1 }
        );
    }

    #[test]
    fn a_change_of_r_while_busy_waits_for_the_answer() {
        let mut l = ReaderLink::new();
        l.request(&req(0, 1, b"RD 0\r"), false);
        l.take_command();
        // The master changes R before the flag is set (a slow command).
        l.request(&req(1, 1, b""), true);
        let mut o = [0u8; 16];
        l.response(&mut o);
        for _ in 0..5 {
            l.request(&req(1, 1, b""), true);
            l.response(&mut o);
            assert_eq!(o[..3], [0, 0, 0], "still executing");
        }
        l.push_answer(b"00112233\r");
        l.request(&req(1, 1, b""), false);
        l.response(&mut o);
        assert_eq!(o[..3], [0, 1, 9], "delivered at once, flag clear");
    }

    #[test]
    fn e_changes_even_when_r_jumps_to_e() {
        let mut l = ReaderLink::new();
        dx(&mut l, &req(0, 0, b""));
        l.push_answer(b"A\r");
        dx(&mut l, &req(4, 0, b""));
        let o = dx(&mut l, &req(4, 0, b""));
        assert_eq!(o[..3], [0, 4, 2], "E = R");
        // A new master whose image starts with R = 3 (nothing waits: the
        // change is forgotten), then counts up to 4 = E.
        dx(&mut l, &req(3, 0, b""));
        l.push_answer(b"B\r");
        dx(&mut l, &req(4, 0, b""));
        let o = dx(&mut l, &req(4, 0, b""));
        assert_eq!(o[..3], [0, 5, 2], "E + 1, so that E changes");
        l.push_answer(b"C\r");
        dx(&mut l, &req(0xFF, 0, b""));
        let o = dx(&mut l, &req(0xFF, 0, b""));
        assert_eq!(o[1], 0xFF);
        l.push_answer(b"D\r");
        dx(&mut l, &req(0, 0, b""));
        let o = dx(&mut l, &req(0, 0, b""));
        assert_eq!(o[1], 0, "numbers wrap");
    }

    #[test]
    fn the_first_r_after_a_reset_is_the_reference() {
        let mut l = ReaderLink::new();
        dx(&mut l, &req(0, 0, b""));
        l.reset();
        // The master kept R = 5 and sends a command (S differs from 0).
        let o = dx(&mut l, &req(5, 1, b"GT\r"));
        assert_eq!(l.take_command(), Some(Line::Text(b"GT".to_vec())));
        l.push_answer(b"0102030405060708090A\r");
        // No fetch was asked for: nothing is delivered until R changes.
        assert_eq!(o[..3], [0, 0, 0]);
        let o = dx(&mut l, &req(5, 1, b""));
        assert_eq!(o[..3], [0x08, 0, 0]);
        dx(&mut l, &req(6, 1, b""));
        let o = dx(&mut l, &req(6, 1, b""));
        assert_eq!(o[..3], [0x08, 6, 13]);
    }

    #[test]
    fn reset_forgets_everything() {
        let mut l = ReaderLink::new();
        l.request(&req(3, 7, b"VE"), false);
        l.push_answer(b"A\r");
        l.reset();
        assert!(!l.data_waiting());
        // S = 7 differs from the fresh reference 0: a job, with L = 0.
        assert_eq!(
            l.request(&req(3, 7, b""), false),
            Received::Job { bytes: 0, lines: 0 }
        );
        assert_eq!(l.stats().jobs, 2);
    }
}
