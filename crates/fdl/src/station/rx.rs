//! The receive path every station shares: a buffer that bytes are
//! appended to as they arrive, framed in place into telegrams (no copy),
//! with an idle deadline after which an incomplete telegram is abandoned.

use crate::codec::{CodecStats, Framed, Framer};
#[allow(unused_imports)]
use crate::prelude::*;
use crate::time::Instant;
use crate::timing::Baud;
use crate::wire::{consts, frame_len, Telegram};
use core::time::Duration;

/// Receive buffer plus framer; see the module docs.
#[derive(Debug)]
pub struct RxPath {
    buf: Vec<u8>,
    start: usize,
    /// Bytes of the telegram last returned, dropped at the next call.
    consumed: usize,
    framer: Framer,
    last_rx: Instant,
    baud: Baud,
    slack: Duration,
}

impl RxPath {
    /// A receive path for a line at `baud`. An incomplete telegram is
    /// abandoned when its missing characters have not arrived `slack`
    /// after the time they would have taken on the wire.
    pub fn new(baud: Baud, slack: Duration) -> RxPath {
        RxPath {
            buf: Vec::with_capacity(4 * consts::MAX_TELEGRAM_LEN),
            start: 0,
            consumed: 0,
            framer: Framer::new(),
            last_rx: Instant::ZERO,
            baud,
            slack,
        }
    }

    /// Append bytes that arrived at `now`.
    pub fn push(&mut self, now: Instant, bytes: &[u8]) {
        self.drop_consumed();
        if self.start > 0 && self.buf.len() + bytes.len() > self.buf.capacity() {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
        self.last_rx = now;
    }

    fn drop_consumed(&mut self) {
        self.start += self.consumed;
        self.consumed = 0;
        if self.start == self.buf.len() {
            self.buf.clear();
            self.start = 0;
        }
    }

    /// The next complete, valid telegram, borrowed from the buffer.
    pub fn next_telegram(&mut self) -> Option<Telegram<'_>> {
        self.drop_consumed();
        match self.framer.frame(&self.buf[self.start..]) {
            Framed::Telegram { skip, len } => {
                self.start += skip;
                self.consumed = len;
                Telegram::parse(&self.buf[self.start..self.start + len])
                    .ok()
                    .map(|(t, _)| t)
            }
            Framed::NeedMore { skip } => {
                self.start += skip;
                None
            }
        }
    }

    /// Whether part of a telegram has arrived and the rest is awaited.
    pub fn receiving(&self) -> bool {
        self.start + self.consumed < self.buf.len()
    }

    /// Time the last bytes arrived.
    pub fn last_rx(&self) -> Instant {
        self.last_rx
    }

    /// When the pending incomplete telegram is to be abandoned.
    pub fn idle_deadline(&self) -> Option<Instant> {
        let pending = &self.buf[self.start + self.consumed..];
        if pending.is_empty() {
            return None;
        }
        let total = match frame_len(pending) {
            // SD2 before LE is seen: as long as the longest telegram.
            Ok(_) if pending[0] == consts::SD2 && pending.len() < 3 => consts::MAX_TELEGRAM_LEN,
            Ok(n) => n,
            Err(_) => pending.len(),
        };
        let missing = total.saturating_sub(pending.len()) as u64;
        Some(self.last_rx + self.baud.chars_to_duration(missing) + self.slack)
    }

    /// Abandon incomplete telegrams whose idle deadline has passed; the
    /// bytes after an abandoned start delimiter are framed again.
    pub fn handle_idle(&mut self, now: Instant) {
        while self.idle_deadline().is_some_and(|d| d <= now) {
            self.drop_consumed();
            self.framer.note_abandoned();
            self.start += 1;
            // Skip garbage up to the next candidate.
            if let Framed::NeedMore { skip } = self.framer.frame(&self.buf[self.start..]) {
                self.start += skip;
            } else {
                // A complete telegram follows; next_telegram returns it.
                break;
            }
        }
    }

    /// Error counters of the framer.
    pub fn stats(&self) -> CodecStats {
        self.framer.stats()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_in_place_and_abandons_on_idle() {
        let mut rx = RxPath::new(Baud::B19200, Duration::from_millis(1));
        let t0 = Instant::ZERO;
        rx.push(t0, &[0x68, 0x20, 0x20, 0x68, 0x01]);
        assert!(rx.next_telegram().is_none());
        assert!(rx.receiving());
        let d = rx.idle_deadline().unwrap();
        // 0x20 + 6 = 38 bytes in total, 33 missing.
        assert_eq!(
            d,
            t0 + Baud::B19200.chars_to_duration(33) + Duration::from_millis(1)
        );
        rx.push(t0, &[0xDC, 0x02, 0x01]);
        assert!(rx.next_telegram().is_none());
        rx.handle_idle(d);
        assert_eq!(rx.next_telegram(), Some(Telegram::Token { da: 2, sa: 1 }));
        assert!(!rx.receiving());
        assert_eq!(rx.stats().truncated, 1);
    }

    #[test]
    fn sd2_start_waits_for_the_longest_telegram() {
        let mut rx = RxPath::new(Baud::B12000000, Duration::ZERO);
        rx.push(Instant::ZERO, &[0x68]);
        assert_eq!(
            rx.idle_deadline(),
            Some(Instant::ZERO + Baud::B12000000.chars_to_duration(254))
        );
    }
}
