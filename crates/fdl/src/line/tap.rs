//! Passive framing of a line with time stamps: what a bus monitor sees.
//!
//! [`Tap`] takes the bytes of a line in chunks, each with the time it
//! arrived, and yields [`TapEvent`]s in line order: valid telegrams with
//! the time their first byte arrived, and the bytes the framer had to skip
//! (garbage, corrupted telegrams) with the error counters they raised.
//! `dpctl sniff` prints these events and `dpctl bus --pcap` records the
//! telegrams. Sans-IO: no clock, no allocation except for the events'
//! byte vectors.

use crate::codec::{CodecStats, Framed, Framer};
#[allow(unused_imports)]
use crate::prelude::*;
use crate::time::Instant;
use crate::wire::Hex;
use alloc::collections::VecDeque;

/// What a [`Tap`] found on the line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TapEvent {
    /// A valid telegram (start delimiter through end delimiter).
    Telegram {
        /// When its first byte arrived.
        at: Instant,
        /// The telegram bytes.
        bytes: Vec<u8>,
    },
    /// Bytes skipped because they do not form a valid telegram.
    Skipped {
        /// When the first of them arrived.
        at: Instant,
        /// The skipped bytes.
        bytes: Vec<u8>,
        /// The codec counters these bytes raised (bad FCS, garbage, …).
        errors: CodecStats,
    },
}

/// Skipped bytes as a bus monitor reports them (`dpctl sniff`): JSON
/// fields `error`, `skipped`, `raw` and the counters; text
/// `WHY: N bytes skipped: HEX`.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Skipped<'a> {
    /// Why, in words ([`Skipped::why`]).
    pub error: String,
    /// How many bytes.
    pub skipped: usize,
    /// The bytes.
    pub raw: Hex<'a>,
    /// The counters they raised.
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub errors: CodecStats,
}

impl<'a> Skipped<'a> {
    /// `bytes`, skipped with `errors`.
    pub fn new(bytes: &'a [u8], errors: CodecStats) -> Self {
        Skipped {
            error: Self::why(bytes.len(), &errors),
            skipped: bytes.len(),
            raw: Hex(bytes),
            errors,
        }
    }

    /// Why `n` bytes were skipped with `errors`, in words: the kinds of
    /// error ([`CodecStats::error_kinds`]), else `N bytes skipped`.
    pub fn why(n: usize, errors: &CodecStats) -> String {
        errors
            .error_kinds()
            .unwrap_or_else(|| format!("{n} bytes skipped"))
    }
}

impl core::fmt::Display for Skipped<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let (why, n, raw) = (&self.error, self.skipped, self.raw);
        write!(f, "{why}: {n} bytes skipped: {raw}")
    }
}

/// Frames a timed byte stream; see the module docs.
#[derive(Debug, Default)]
pub struct Tap {
    framer: Framer,
    buf: Vec<u8>,
    /// Stream position of `buf[0]`.
    base: u64,
    /// Chunks still (partly) in `buf`: stream position after the chunk's
    /// last byte, and its arrival time.
    chunks: VecDeque<(u64, Instant)>,
    /// A telegram of this length is known to start at `buf[0]`.
    ready: Option<usize>,
    /// The line went idle: abandon incomplete candidates.
    flush: bool,
}

fn delta(after: CodecStats, before: CodecStats) -> CodecStats {
    CodecStats {
        telegrams: after.telegrams - before.telegrams,
        garbage_bytes: after.garbage_bytes - before.garbage_bytes,
        bad_fcs: after.bad_fcs - before.bad_fcs,
        bad_length: after.bad_length - before.bad_length,
        bad_end_delimiter: after.bad_end_delimiter - before.bad_end_delimiter,
        bad_format: after.bad_format - before.bad_format,
        truncated: after.truncated - before.truncated,
    }
}

impl Tap {
    /// An empty tap with zeroed counters.
    pub fn new() -> Tap {
        Tap::default()
    }

    /// Codec counters so far.
    pub fn stats(&self) -> CodecStats {
        self.framer.stats()
    }

    /// Bytes received but not yet framed.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    /// Bytes that arrived at `at`.
    pub fn push(&mut self, at: Instant, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        self.buf.extend_from_slice(bytes);
        self.chunks
            .push_back((self.base + self.buf.len() as u64, at));
    }

    /// The line has been idle for longer than a telegram may pause: the
    /// next calls to [`Tap::poll`] give up incomplete candidates.
    pub fn line_idle(&mut self) {
        if !self.buf.is_empty() {
            self.flush = true;
        }
    }

    /// The next event, or `None` until more bytes arrive (or the line
    /// goes idle).
    pub fn poll(&mut self) -> Option<TapEvent> {
        if let Some(len) = self.ready.take() {
            return Some(self.take_telegram(len));
        }
        if self.buf.is_empty() {
            self.flush = false;
            return None;
        }
        let before = self.framer.stats();
        match self.framer.frame(&self.buf) {
            Framed::Telegram { skip: 0, len } => Some(self.take_telegram(len)),
            Framed::Telegram { skip, len } => {
                self.ready = Some(len);
                Some(self.take_skipped(skip, before))
            }
            Framed::NeedMore { skip } if skip > 0 => Some(self.take_skipped(skip, before)),
            Framed::NeedMore { .. } if self.flush => match self.framer.line_idle(&self.buf) {
                Framed::Telegram { skip, len } => {
                    self.ready = Some(len);
                    Some(self.take_skipped(skip, before))
                }
                Framed::NeedMore { skip } => Some(self.take_skipped(skip, before)),
            },
            Framed::NeedMore { .. } => None,
        }
    }

    /// Arrival time of the byte at stream position `pos`.
    fn time_of(&self, pos: u64) -> Instant {
        self.chunks
            .iter()
            .find(|&&(end, _)| end > pos)
            .map(|&(_, at)| at)
            .unwrap_or(Instant::ZERO)
    }

    fn consume(&mut self, n: usize) -> (Instant, Vec<u8>) {
        let at = self.time_of(self.base);
        let bytes: Vec<u8> = self.buf.drain(..n).collect();
        self.base += n as u64;
        while self
            .chunks
            .front()
            .is_some_and(|&(end, _)| end <= self.base)
        {
            self.chunks.pop_front();
        }
        if self.buf.is_empty() {
            self.flush = false;
        }
        (at, bytes)
    }

    fn take_telegram(&mut self, len: usize) -> TapEvent {
        let (at, bytes) = self.consume(len);
        TapEvent::Telegram { at, bytes }
    }

    fn take_skipped(&mut self, skip: usize, before: CodecStats) -> TapEvent {
        let mut errors = delta(self.framer.stats(), before);
        // A telegram found behind the skipped bytes is not an error.
        errors.telegrams = 0;
        let (at, bytes) = self.consume(skip);
        TapEvent::Skipped { at, bytes, errors }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn skipped_bytes_in_words() {
        let errors = CodecStats {
            bad_fcs: 1,
            ..CodecStats::default()
        };
        let s = Skipped::new(&[0x68, 0x01], errors);
        assert_eq!(s.to_string(), "bad FCS: 2 bytes skipped: 68 01");
        let quiet = Skipped::new(&[0xFF], CodecStats::default());
        assert_eq!(quiet.error, "1 bytes skipped");
    }

    use super::*;

    const STATUS: [u8; 6] = [0x10, 0x02, 0x01, 0x49, 0x4C, 0x16];

    fn t(n: u64) -> Instant {
        Instant::from_nanos(n)
    }

    fn all(tap: &mut Tap) -> Vec<TapEvent> {
        core::iter::from_fn(|| tap.poll()).collect()
    }

    #[test]
    fn telegrams_carry_the_time_of_their_first_byte() {
        let mut tap = Tap::new();
        tap.push(t(10), &STATUS[..1]);
        assert!(tap.poll().is_none());
        tap.push(t(20), &STATUS[1..]);
        tap.push(t(30), &[0xE5, 0xDC]);
        tap.push(t(40), &[0x02, 0x01]);
        let ev = all(&mut tap);
        assert_eq!(
            ev,
            vec![
                TapEvent::Telegram {
                    at: t(10),
                    bytes: STATUS.to_vec()
                },
                TapEvent::Telegram {
                    at: t(30),
                    bytes: vec![0xE5]
                },
                TapEvent::Telegram {
                    at: t(30),
                    bytes: vec![0xDC, 0x02, 0x01]
                },
            ]
        );
        assert_eq!(tap.stats().telegrams, 3);
        assert_eq!(tap.pending(), 0);
    }

    #[test]
    fn skipped_bytes_come_with_their_errors() {
        let mut tap = Tap::new();
        let mut bad = STATUS;
        bad[4] ^= 0x01;
        tap.push(t(1), &[0x00, 0x42]);
        tap.push(t(2), &bad);
        tap.push(t(3), &STATUS);
        let ev = all(&mut tap);
        let TapEvent::Skipped { at, bytes, errors } = &ev[0] else {
            panic!("{ev:?}")
        };
        assert_eq!(*at, t(1));
        // Two garbage bytes, then the corrupted telegram: its start is a
        // bad FCS, its other bytes are garbage (0x16 … none is a delimiter).
        assert_eq!(bytes.len(), 2 + 6);
        assert_eq!(errors.bad_fcs, 1);
        assert_eq!(errors.telegrams, 0);
        assert!(errors.garbage_bytes >= 2);
        assert_eq!(
            ev[1],
            TapEvent::Telegram {
                at: t(3),
                bytes: STATUS.to_vec()
            }
        );
        assert_eq!(ev.len(), 2);
        assert_eq!(tap.stats().telegrams, 1);
    }

    #[test]
    fn idle_line_gives_up_a_false_start() {
        let mut tap = Tap::new();
        tap.push(t(5), &[0x68, 0xF0, 0xF0, 0x68]);
        tap.push(t(6), &STATUS);
        assert!(tap.poll().is_none());
        tap.line_idle();
        let ev = all(&mut tap);
        assert!(matches!(&ev[0], TapEvent::Skipped { errors, .. } if errors.truncated == 1));
        assert_eq!(
            ev.last(),
            Some(&TapEvent::Telegram {
                at: t(6),
                bytes: STATUS.to_vec()
            })
        );
        // An incomplete telegram at the end is abandoned too.
        tap.push(t(7), &STATUS[..3]);
        assert!(tap.poll().is_none());
        tap.line_idle();
        let ev = all(&mut tap);
        let skipped: usize = ev
            .iter()
            .map(|e| match e {
                TapEvent::Skipped { bytes, .. } => bytes.len(),
                TapEvent::Telegram { .. } => panic!("{e:?}"),
            })
            .sum();
        assert_eq!(skipped, 3);
        assert_eq!(tap.pending(), 0);
    }
}
