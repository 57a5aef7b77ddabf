//! The soak's reference receiver: what each station sent (recorded by
//! [`Recorded`]) against what the line delivered from it, framed with the
//! stack's own framer.

use profibus_fdl::codec::{Framed, Framer};
use profibus_fdl::station::Station;
use profibus_fdl::Instant;
use serde::Serialize;
use std::cell::RefCell;
use std::rc::Rc;

/// Recent transmissions kept per station for the comparison.
const RING: usize = 8;
/// Longest telegram.
const MAX_LEN: usize = 256;
/// Unframed bytes the reference receiver may hold per source before it
/// counts as growing without bound.
pub(super) const PENDING_LIMIT: usize = 4 * MAX_LEN;

/// What the reference receiver saw on the line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Integrity {
    /// Transmissions (telegrams) the stations sent.
    pub sent: u64,
    /// Telegrams that arrived exactly as sent.
    pub intact: u64,
    /// Transmissions that did not arrive intact (dropped characters,
    /// flipped bits, collisions with noise): `sent - intact`.
    pub corrupted: u64,
    /// Of those, rejected by the framer (bad FCS, length, end delimiter,
    /// format, or incomplete).
    pub rejected: u64,
    /// Telegrams with valid framing and FCS that no station sent in that
    /// form: corruptions the 8-bit FCS cannot see. Counted, never taken
    /// as sent.
    pub undetected: u64,
    /// Of `undetected`, token telegrams (SD4 `DC DA SA`): they have no
    /// FCS at all, so any bit error in DA or SA that keeps both addresses
    /// valid, or a bit error that turns another byte into SD4, forges
    /// one. A forged token the master receives while it holds the real
    /// one makes it drop its own (duplicate token, see
    /// `SoakReport::token_ring`).
    pub forged_tokens: u64,
    /// Telegrams with valid framing and FCS made of noise alone.
    pub noise_telegrams: u64,
    /// Of `noise_telegrams`, token telegrams.
    pub noise_tokens: u64,
    /// Framer rejections on the transmissions' bytes (a corrupted
    /// transmission may raise several, or share one with its neighbour).
    pub framer_errors: u64,
}

struct Source {
    ring: [[u8; MAX_LEN]; RING],
    lens: [usize; RING],
    next: usize,
    buf: Vec<u8>,
    framer: Framer,
}

impl Source {
    fn new() -> Source {
        Source {
            ring: [[0; MAX_LEN]; RING],
            lens: [0; RING],
            next: 0,
            buf: Vec::with_capacity(PENDING_LIMIT + MAX_LEN),
            framer: Framer::new(),
        }
    }

    fn sent(&self, t: &[u8]) -> bool {
        (0..RING).any(|i| &self.ring[i][..self.lens[i]] == t)
    }
}

/// Transmissions and deliveries of every station (index = station id;
/// the last source is the noise).
pub(super) struct Ledger {
    sources: Vec<Source>,
    noise: Source,
    sent: u64,
    intact: u64,
    undetected: u64,
    forged_tokens: u64,
    noise_telegrams: u64,
    noise_tokens: u64,
}

impl Ledger {
    pub(super) fn new(stations: usize) -> Ledger {
        Ledger {
            sources: (0..stations).map(|_| Source::new()).collect(),
            noise: Source::new(),
            sent: 0,
            intact: 0,
            undetected: 0,
            forged_tokens: 0,
            noise_telegrams: 0,
            noise_tokens: 0,
        }
    }

    fn transmitted(&mut self, station: usize, bytes: &[u8]) {
        let s = &mut self.sources[station];
        let n = bytes.len().min(MAX_LEN);
        s.ring[s.next][..n].copy_from_slice(&bytes[..n]);
        s.lens[s.next] = n;
        s.next = (s.next + 1) % RING;
        self.sent += 1;
    }

    /// Bytes the line delivered from `from` (`None`: noise).
    pub(super) fn delivered(&mut self, from: Option<usize>, bytes: &[u8]) {
        let s = match from {
            Some(i) => &mut self.sources[i],
            None => &mut self.noise,
        };
        s.buf.extend_from_slice(bytes);
        loop {
            match s.framer.frame(&s.buf) {
                Framed::Telegram { skip, len } => {
                    let t = &s.buf[skip..skip + len];
                    let token = t.first() == Some(&profibus_fdl::wire::consts::SD4);
                    match from {
                        None => {
                            self.noise_telegrams += 1;
                            self.noise_tokens += u64::from(token);
                        }
                        Some(_) if s.sent(t) => self.intact += 1,
                        Some(_) => {
                            self.undetected += 1;
                            self.forged_tokens += u64::from(token);
                        }
                    }
                    s.buf.drain(..skip + len);
                }
                Framed::NeedMore { skip } => {
                    s.buf.drain(..skip);
                    break;
                }
            }
        }
        if s.buf.len() > PENDING_LIMIT {
            // A candidate that never completes: give it up, as a
            // receiver does when the line goes idle.
            s.framer.note_abandoned();
            s.buf.clear();
        }
    }

    /// Bytes held unframed (largest source).
    pub(super) fn pending(&self) -> usize {
        self.sources
            .iter()
            .chain([&self.noise])
            .map(|s| s.buf.len())
            .max()
            .unwrap_or(0)
    }

    pub(super) fn integrity(&self) -> Integrity {
        let corrupted = self.sent.saturating_sub(self.intact);
        Integrity {
            sent: self.sent,
            intact: self.intact,
            corrupted,
            rejected: corrupted.saturating_sub(self.undetected),
            undetected: self.undetected,
            forged_tokens: self.forged_tokens,
            noise_telegrams: self.noise_telegrams,
            noise_tokens: self.noise_tokens,
            framer_errors: self.sources.iter().map(|s| s.framer.stats().errors()).sum(),
        }
    }
}

/// A station whose transmissions are recorded in the [`Ledger`].
pub(super) struct Recorded<S> {
    inner: S,
    index: usize,
    ledger: Rc<RefCell<Ledger>>,
}

impl<S> Recorded<S> {
    pub(super) fn new(inner: S, index: usize, ledger: Rc<RefCell<Ledger>>) -> Recorded<S> {
        Recorded {
            inner,
            index,
            ledger,
        }
    }
    pub(super) fn inner(&self) -> &S {
        &self.inner
    }
    pub(super) fn inner_mut(&mut self) -> &mut S {
        &mut self.inner
    }
}

impl<S: Station> Station for Recorded<S> {
    fn handle_rx(&mut self, now: Instant, bytes: &[u8]) {
        self.inner.handle_rx(now, bytes)
    }
    fn handle_timeout(&mut self, now: Instant) {
        self.inner.handle_timeout(now)
    }
    fn poll_transmit(&mut self, now: Instant) -> Option<&[u8]> {
        let bytes = self.inner.poll_transmit(now)?;
        self.ledger.borrow_mut().transmitted(self.index, bytes);
        Some(bytes)
    }
    fn poll_timeout(&self) -> Option<Instant> {
        self.inner.poll_timeout()
    }
}
