//! Streaming telegram framing for byte streams (serial lines, ptys).
//!
//! Framing never depends on inter-character timing (ptys and USB adapters
//! do not preserve it): [`Framer`] finds telegrams by start delimiter and
//! length, validates them with [`Telegram::parse`], and after garbage or a
//! corrupted telegram resynchronises by dropping one byte and scanning for
//! the next start delimiter, so the next valid telegram is never lost.
//!
//! One case needs help from the driver: a garbage byte that looks like the
//! start of a long SD2 telegram makes the framer wait for bytes that may
//! never come. When the line has been idle for longer than a telegram can
//! pause (TSYN, or a few milliseconds on a pty), the driver calls
//! [`Framer::line_idle`], which abandons the pending candidate.
//!
//! [`Framer::next_telegram`] frames straight out of a `BytesMut` receive
//! buffer; its items are [`RawTelegram`]s: a validated telegram as a
//! `Bytes` slice of the receive buffer, not a copy. `profibus_io::FdlCodec`
//! is the same framer as a `tokio_util` `Decoder`/`Encoder`.

#[allow(unused_imports)]
use crate::prelude::*;
use crate::wire::{ParseError, Telegram};
use bytes::{Buf, Bytes, BytesMut};

/// Error counters of a [`Framer`], by kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct CodecStats {
    /// Valid telegrams framed.
    pub telegrams: u64,
    /// Bytes skipped because they could not start a telegram.
    pub garbage_bytes: u64,
    /// Candidates rejected for a wrong FCS.
    pub bad_fcs: u64,
    /// Candidates rejected for LE ≠ LEr, LE out of range or a bad repeated
    /// start delimiter.
    pub bad_length: u64,
    /// Candidates rejected for a missing end delimiter.
    pub bad_end_delimiter: u64,
    /// Candidates rejected for other format errors (address extension
    /// without SAP byte, token with an invalid address).
    pub bad_format: u64,
    /// Incomplete candidates abandoned at [`Framer::line_idle`] or at the
    /// end of the stream.
    pub truncated: u64,
}

impl CodecStats {
    /// Total number of rejected candidates and abandoned fragments.
    pub fn errors(&self) -> u64 {
        self.bad_fcs + self.bad_length + self.bad_end_delimiter + self.bad_format + self.truncated
    }

    /// The kinds of error counted, in words (`bad FCS`, `2× bad length`,
    /// `3 garbage bytes`), or `None` when there are none: why a
    /// [`TapEvent::Skipped`](crate::line::tap::TapEvent::Skipped) was skipped.
    pub fn error_kinds(&self) -> Option<String> {
        let mut parts = vec![];
        for (n, what) in [
            (self.bad_fcs, "bad FCS"),
            (self.bad_length, "bad length"),
            (self.bad_end_delimiter, "missing end delimiter"),
            (self.bad_format, "bad format"),
            (self.truncated, "truncated"),
        ] {
            match n {
                0 => {}
                1 => parts.push(what.to_string()),
                n => parts.push(format!("{n}× {what}")),
            }
        }
        if self.garbage_bytes > 0 {
            parts.push(format!("{} garbage bytes", self.garbage_bytes));
        }
        (!parts.is_empty()).then(|| parts.join(", "))
    }
}

impl core::fmt::Display for CodecStats {
    /// Every counter: `N telegrams, N garbage bytes, N bad FCS, …`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} telegrams, {} garbage bytes, {} bad FCS, {} bad length, {} missing end delimiter, {} bad format, {} truncated",
            self.telegrams,
            self.garbage_bytes,
            self.bad_fcs,
            self.bad_length,
            self.bad_end_delimiter,
            self.bad_format,
            self.truncated
        )
    }
}

/// What [`Framer::frame`] found at the start of a buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framed {
    /// Drop `skip` bytes of garbage, then a valid telegram of `len` bytes
    /// starts.
    Telegram {
        /// Garbage bytes before the telegram.
        skip: usize,
        /// Length of the telegram.
        len: usize,
    },
    /// Drop `skip` bytes of garbage; the rest is the incomplete start of a
    /// candidate telegram (or empty).
    NeedMore {
        /// Garbage bytes before the candidate.
        skip: usize,
    },
}

/// Sans-IO telegram framer with error statistics.
#[derive(Debug, Clone, Default)]
pub struct Framer {
    stats: CodecStats,
}

impl Framer {
    /// A framer with zeroed statistics.
    pub fn new() -> Self {
        Self::default()
    }

    /// Error counters so far.
    pub fn stats(&self) -> CodecStats {
        self.stats
    }

    /// Find the next telegram in `buf`. Never needs more than one pass over
    /// the bytes it skips.
    pub fn frame(&mut self, buf: &[u8]) -> Framed {
        let mut skip = 0;
        while skip < buf.len() {
            match Telegram::parse(&buf[skip..]) {
                Ok((_, len)) => {
                    self.stats.telegrams += 1;
                    return Framed::Telegram { skip, len };
                }
                Err(ParseError::Truncated { .. }) => return Framed::NeedMore { skip },
                Err(e) => {
                    self.count(e);
                    skip += 1;
                }
            }
        }
        Framed::NeedMore { skip }
    }

    /// The line went idle with `pending` bytes left unframed (the
    /// incomplete candidate from [`Framed::NeedMore`]): abandon the
    /// candidate and frame what follows its first byte. Returns the number
    /// of bytes to drop from the front of `pending`, or the first complete
    /// telegram after them.
    pub fn line_idle(&mut self, pending: &[u8]) -> Framed {
        if pending.is_empty() {
            return Framed::NeedMore { skip: 0 };
        }
        self.stats.truncated += 1;
        match self.frame(&pending[1..]) {
            Framed::Telegram { skip, len } => Framed::Telegram {
                skip: skip + 1,
                len,
            },
            Framed::NeedMore { skip } => Framed::NeedMore { skip: skip + 1 },
        }
    }

    /// Count an incomplete candidate that the caller abandons (its own
    /// idle handling instead of [`Framer::line_idle`]).
    pub fn note_abandoned(&mut self) {
        self.stats.truncated += 1;
    }

    fn count(&mut self, e: ParseError) {
        match e {
            ParseError::BadStartDelimiter(_) => self.stats.garbage_bytes += 1,
            ParseError::FcsMismatch { .. } => self.stats.bad_fcs += 1,
            ParseError::LengthMismatch { .. }
            | ParseError::LengthOutOfRange(_)
            | ParseError::BadRepeatedDelimiter(_) => self.stats.bad_length += 1,
            ParseError::MissingEndDelimiter(_) => self.stats.bad_end_delimiter += 1,
            ParseError::MissingAddressExtension | ParseError::BadTokenAddress { .. } => {
                self.stats.bad_format += 1
            }
            ParseError::Truncated { .. } => self.stats.truncated += 1,
        }
    }
}

/// A validated telegram held as a `Bytes` slice of the receive buffer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawTelegram(Bytes);

impl RawTelegram {
    /// Wrap bytes that [`Telegram::parse`] accepted. Returns `None` when
    /// they are not exactly one valid telegram.
    pub fn new(bytes: Bytes) -> Option<Self> {
        match Telegram::parse(&bytes) {
            Ok((_, n)) if n == bytes.len() => Some(Self(bytes)),
            _ => None,
        }
    }

    /// The borrowed, typed view (re-reads the fields in place; no copy).
    pub fn telegram(&self) -> Telegram<'_> {
        // Validated at construction.
        Telegram::parse(&self.0)
            .map(|(t, _)| t)
            .unwrap_or(Telegram::ShortAck)
    }

    /// The telegram bytes, start delimiter through end delimiter.
    pub fn as_bytes(&self) -> &[u8] {
        &self.0
    }

    /// The underlying `Bytes`.
    pub fn into_bytes(self) -> Bytes {
        self.0
    }
}

impl Framer {
    /// Take the next telegram off the front of a receive buffer: drops the
    /// garbage before it and returns it as a `Bytes` slice (no copy), or
    /// `None` when the buffer holds no complete telegram yet (garbage is
    /// dropped either way). The building block of byte-stream codecs such as
    /// `profibus_io::FdlCodec`.
    pub fn next_telegram(&mut self, src: &mut BytesMut) -> Option<RawTelegram> {
        let framed = self.frame(src);
        Self::take(framed, src)
    }

    /// The line went idle: abandon an incomplete candidate at the front of
    /// `src` and return the first telegram after it, if any (see
    /// [`Framer::line_idle`]).
    pub fn next_after_idle(&mut self, src: &mut BytesMut) -> Option<RawTelegram> {
        let framed = self.line_idle(src);
        Self::take(framed, src)
    }

    /// The stream ended: the next telegram in `src`, abandoning incomplete
    /// candidates (they can never complete) until one is found or `src` is
    /// empty.
    pub fn next_at_end(&mut self, src: &mut BytesMut) -> Option<RawTelegram> {
        if let Some(t) = self.next_telegram(src) {
            return Some(t);
        }
        while !src.is_empty() {
            if let Some(t) = self.next_after_idle(src) {
                return Some(t);
            }
        }
        None
    }

    fn take(framed: Framed, src: &mut BytesMut) -> Option<RawTelegram> {
        match framed {
            Framed::Telegram { skip, len } => {
                src.advance(skip);
                Some(RawTelegram(src.split_to(len).freeze()))
            }
            Framed::NeedMore { skip } => {
                src.advance(skip);
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn error_kinds_and_counters_in_words() {
        let mut s = super::CodecStats::default();
        assert_eq!(s.error_kinds(), None);
        s.bad_fcs = 1;
        s.bad_length = 2;
        s.garbage_bytes = 3;
        assert_eq!(
            s.error_kinds().unwrap(),
            "bad FCS, 2× bad length, 3 garbage bytes"
        );
        s.telegrams = 9;
        assert_eq!(
            s.to_string(),
            "9 telegrams, 3 garbage bytes, 1 bad FCS, 2 bad length, 0 missing end delimiter, 0 bad format, 0 truncated"
        );
    }

    use super::*;
    use crate::testing::fdl_status;
    use bytes::BytesMut;

    #[test]
    fn fragments_one_byte_at_a_time() {
        let mut codec = Framer::new();
        let mut buf = BytesMut::new();
        let mut out = vec![];
        let stream: Vec<u8> = [
            fdl_status(3, 1),
            vec![0xE5],
            vec![0xDC, 2, 1],
            fdl_status(4, 1),
        ]
        .concat();
        for b in stream {
            buf.extend_from_slice(&[b]);
            while let Some(t) = codec.next_telegram(&mut buf) {
                out.push(t);
            }
        }
        assert_eq!(out.len(), 4);
        assert_eq!(out[1].telegram(), Telegram::ShortAck);
        assert_eq!(out[2].telegram(), Telegram::Token { da: 2, sa: 1 });
        assert_eq!(codec.stats().errors(), 0);
    }

    #[test]
    fn resyncs_after_corrupted_telegram() {
        let mut codec = Framer::new();
        let mut bad = fdl_status(3, 1);
        bad[4] ^= 1; // FCS
        let mut buf = BytesMut::from(&[bad, vec![0x00, 0x42], fdl_status(5, 1)].concat()[..]);
        let t = codec.next_telegram(&mut buf).unwrap();
        assert_eq!(t.as_bytes(), &fdl_status(5, 1)[..]);
        let s = codec.stats();
        assert_eq!(s.bad_fcs, 1);
        assert!(s.garbage_bytes >= 2);
    }

    #[test]
    fn idle_line_abandons_a_false_sd2_start() {
        let mut codec = Framer::new();
        // "68 F0 F0 68" announces 246 more bytes; the valid telegram after it
        // is held back until the line goes idle.
        let mut buf =
            BytesMut::from(&[vec![0x68, 0xF0, 0xF0, 0x68], fdl_status(9, 1)].concat()[..]);
        assert!(codec.next_telegram(&mut buf).is_none());
        let t = codec.next_after_idle(&mut buf).unwrap();
        assert_eq!(t.as_bytes(), &fdl_status(9, 1)[..]);
        assert_eq!(codec.stats().truncated, 1);
    }
}
