//! A sans-IO model of an RS-485 multidrop line.
//!
//! [`Medium`] is what the stations of one bus share: every character one
//! station transmits reaches every other station, in order, and not the
//! transmitter itself (an RS-485 transceiver's receiver is off while it
//! sends). The model has no clock and no I/O: drivers pass "now" as an
//! [`Instant`] (time starts at [`Instant::ZERO`]) and ask for what is due.
//! The same model runs under `dpctl bus` (real time, ptys) and the
//! in-process simulator (virtual time), so both behave alike.
//!
//! # Use
//!
//! ```
//! # use profibus_fdl::line::medium::{Medium, MediumConfig};
//! # use profibus_fdl::{Baud, Instant};
//! let mut m = Medium::new(3, MediumConfig::paced(Baud::B19200));
//! m.transmit(Instant::ZERO, 0, &[0x10, 0x02, 0x01, 0x49, 0x4C, 0x16]);
//! // Wake up at `m.poll_timeout()`, then collect what is due:
//! let t = m.poll_timeout().unwrap();
//! let d = m.poll_delivery(t).unwrap(); // the first character
//! assert_eq!((d.from, &d.bytes[..]), (Some(0), &[0x10][..]));
//! // ... hand `d.bytes` to every station except `d.from`.
//! // A driver that wakes later gets everything that has arrived since:
//! let d = m.poll_delivery(t + Baud::B19200.chars_to_duration(5)).unwrap();
//! assert_eq!(&d.bytes[..], &[0x02, 0x01, 0x49, 0x4C, 0x16][..]);
//! ```
//!
//! # Timing
//!
//! Without a baud rate ([`MediumConfig::baud`] = `None`) the line has no
//! duration: a transmission is delivered at `now` in one chunk.
//!
//! With a baud rate, a transmission occupies the line for 11 bit times per
//! character from its start, and every character is delivered when it has
//! fully arrived (its stop bit has crossed the wire). [`Medium::poll_delivery`]
//! hands out all characters of one transmission that have arrived by `now`
//! in one chunk, so a driver that wakes late gets them together, never
//! with an idle gap inside: a receiver that frames by line idle time (as
//! slave ASICs do) sees chunk boundaries of one transmission exactly one
//! character time apart, with no idle between the stop bit of one and the
//! start bit of the next, and sees the idle time between transmissions as
//! it was on the wire. A receiver also sees the start of a reply at the
//! right time (slot-time checks), however long the reply. Bytes written by
//! a station while its own transmission is still on the line extend that
//! transmission (a UART's FIFO). Character end times are computed from the
//! start of the transmission with integer arithmetic
//! (`origin + baud.bits_to_duration(bits)`), never by adding up rounded
//! per-character durations, so 2000 characters at 19.2 kbit/s end at
//! exactly `Baud::B19200.chars_to_duration(2000)`. With
//! [`Medium::with_whole_transmissions`] each transmission is delivered in
//! one piece when its last character has arrived instead (for receivers
//! that run behind a scheduler; see there); one longer than
//! [`WHOLE_MAX`] characters (a station sending without a pause for longer
//! than any telegram) goes out in pieces of at least [`WHOLE_MAX`]
//! characters as they arrive, each ending where a telegram ends.
//!
//! A station that starts while another one is sending either garbles the
//! line ([`Collisions::Garble`], as on a real line: the overlapping
//! characters of both transmissions are corrupted, and the collision is
//! counted) or waits until the line is free ([`Collisions::Serialize`]).
//!
//! # Faults
//!
//! Fault injection changes what the receivers get; every receiver sees the
//! same corrupted line. `drop` loses a character (it still occupies the
//! line), `flip_ber` flips each of the 8 data bits with that probability
//! (a pty does not carry the parity bit, so the codec's FCS and framing
//! checks must catch it), and noise puts bursts of 1 to
//! [`NOISE_BURST_MAX`] random characters on the idle line at
//! `noise_rate` bursts per second of idle time (a Poisson process). Drops,
//! flips, noise and garbling draw from separate generators derived from
//! the seed, so the drop and flip counts depend only on the sequence of
//! characters carried, not on how they were timed or split into writes.

#[allow(unused_imports)]
use crate::prelude::*;
use crate::rng::{splitmix64, Rng};
use crate::time::Instant;
use crate::timing::Baud;
use crate::wire::consts::BITS_PER_CHAR;
use crate::wire::frame_len;
use alloc::collections::VecDeque;
use bytes::Bytes;
use core::fmt;

/// Longest noise burst in characters; burst lengths are uniform in
/// `1..=NOISE_BURST_MAX`.
pub const NOISE_BURST_MAX: u64 = 16;

/// With [`Medium::with_whole_transmissions`]: the longest transmission
/// delivered in one piece at its end. Longer than any telegram (255
/// characters) and a token gathered with one. A longer transmission is
/// delivered in pieces as it crosses the wire, so that a receiver's
/// buffer (a pty holds about 12 KiB) never has to take more than the line
/// carried since the last piece, however long the station sends: a piece
/// is due when the first telegram that ends at least this many characters
/// after the last piece has arrived, and takes every whole telegram that
/// has arrived by then. Pieces end where telegrams end (framed by their
/// start delimiters and lengths, [`frame_len`]; a byte that starts no
/// telegram is a unit of its own), so a receiver framing by idle time
/// never sees a pause inside a telegram even when the driver delivers
/// late; a telegram cut off by the end of the transmission ends the
/// piece there.
pub const WHOLE_MAX: usize = 512;

const BITS: u64 = BITS_PER_CHAR as u64;
/// Flag in a carried character: lost on the way (drop).
const DROPPED: u16 = 0x100;
/// Flag in a carried character: already corrupted by a collision.
const GARBLED: u16 = 0x200;

/// What happens when a station starts transmitting while the line is busy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Collisions {
    /// The overlapping characters of both transmissions are corrupted, as
    /// on a real line, and a collision is counted.
    #[default]
    Garble,
    /// The late transmitter waits until the line is free (as if it had
    /// perfect carrier sense); nothing is corrupted.
    Serialize,
}

/// Configuration of a [`Medium`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MediumConfig {
    /// Pace the line at this rate (11 bit per character, one transmitter
    /// at a time); `None` delivers everything at once.
    pub baud: Option<Baud>,
    /// Probability of losing each character (0..=1).
    pub drop: f64,
    /// Probability of flipping each of the 8 data bits of a character
    /// (bit error rate, 0..=1).
    pub flip_ber: f64,
    /// Noise bursts per second of idle line (≥ 0).
    pub noise_rate: f64,
    /// Seed of the fault-injection generators.
    pub seed: u64,
    /// Behaviour of overlapping transmissions (paced lines only).
    pub collisions: Collisions,
}

impl Default for MediumConfig {
    /// Unpaced, no faults, seed 0, garbling collisions.
    fn default() -> Self {
        MediumConfig {
            baud: None,
            drop: 0.0,
            flip_ber: 0.0,
            noise_rate: 0.0,
            seed: 0,
            collisions: Collisions::Garble,
        }
    }
}

impl MediumConfig {
    /// A fault-free line paced at `baud`.
    pub fn paced(baud: Baud) -> Self {
        MediumConfig {
            baud: Some(baud),
            ..Self::default()
        }
    }

    /// Check that the probabilities lie in 0..=1 and the noise rate is a
    /// finite non-negative number.
    pub fn validate(&self) -> Result<(), MediumConfigError> {
        for (name, p) in [("drop", self.drop), ("flip", self.flip_ber)] {
            if !(0.0..=1.0).contains(&p) {
                return Err(MediumConfigError::Probability(name, p));
            }
        }
        if !(self.noise_rate >= 0.0 && self.noise_rate.is_finite()) {
            return Err(MediumConfigError::NoiseRate(self.noise_rate));
        }
        Ok(())
    }
}

/// A [`MediumConfig`] value out of range.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum MediumConfigError {
    /// A probability outside 0..=1.
    #[error("{0} probability {1} outside 0..=1")]
    Probability(&'static str, f64),
    /// A negative, infinite or NaN noise rate.
    #[error("noise rate {0} must be a finite number ≥ 0 (bursts per second)")]
    NoiseRate(f64),
}

/// Bytes that arrive at the receivers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Delivery {
    /// The transmitting station (it does not receive its own bytes);
    /// `None` for noise, which every station receives.
    pub from: Option<usize>,
    /// When the last of these bytes has fully arrived.
    pub at: Instant,
    /// The bytes as received (after fault injection); never empty.
    pub bytes: Bytes,
}

impl Delivery {
    /// Whether station `station` receives this delivery.
    pub fn reaches(&self, station: usize) -> bool {
        self.from != Some(station)
    }
}

/// Counters of what a [`Medium`] carried and injected.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MediumStats {
    /// Transmissions started by stations (extensions not counted).
    pub transmissions: u64,
    /// Characters written by stations.
    pub chars: u64,
    /// Characters lost (drop).
    pub dropped: u64,
    /// Data bits flipped (flip).
    pub bits_flipped: u64,
    /// Noise bursts put on the idle line.
    pub noise_bursts: u64,
    /// Characters in those bursts.
    pub noise_chars: u64,
    /// Transmissions that started while another was on the line
    /// ([`Collisions::Garble`]).
    pub collisions: u64,
    /// Characters corrupted by collisions.
    pub garbled_chars: u64,
    /// Transmissions that waited for a busy line
    /// ([`Collisions::Serialize`]).
    pub deferred: u64,
}

impl fmt::Display for MediumStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "transmissions {}, chars {}, dropped {}, bits flipped {}, noise bursts {} ({} chars), collisions {} ({} chars garbled), deferred {}",
            self.transmissions,
            self.chars,
            self.dropped,
            self.bits_flipped,
            self.noise_bursts,
            self.noise_chars,
            self.collisions,
            self.garbled_chars,
            self.deferred
        )
    }
}

/// One transmission on a paced line. Character `k` occupies
/// `[origin + bits(start_bits + 11k), origin + bits(start_bits + 11(k+1)))`.
#[derive(Debug, Clone)]
struct Tx {
    from: Option<usize>,
    origin: Instant,
    start_bits: u64,
    /// Characters as received: low 8 bits the byte, plus flags.
    chars: Vec<u16>,
    /// Characters already handed out.
    delivered: usize,
}

impl Tx {
    fn at_bits(&self, baud: Baud, bits: u64) -> Instant {
        self.origin + baud.bits_to_duration(self.start_bits + bits)
    }
    fn char_start(&self, baud: Baud, k: usize) -> Instant {
        self.at_bits(baud, BITS * k as u64)
    }
    fn char_end(&self, baud: Baud, k: usize) -> Instant {
        self.at_bits(baud, BITS * (k as u64 + 1))
    }
    fn start(&self, baud: Baud) -> Instant {
        self.char_start(baud, 0)
    }
    fn end(&self, baud: Baud) -> Instant {
        self.char_start(baud, self.chars.len())
    }
    /// End of the next character to deliver (of the last one of the next
    /// piece when delivering whole transmissions; see [`WHOLE_MAX`]).
    fn next_event(&self, baud: Baud, whole: bool) -> Option<Instant> {
        if self.delivered >= self.chars.len() {
            return None;
        }
        let k = if whole {
            self.piece_end() - 1
        } else {
            self.delivered
        };
        Some(self.char_end(baud, k))
    }

    /// Where the telegram (or garbage byte) at character `k` ends; `None`
    /// when the transmission ends inside it (so far).
    fn unit_end(&self, k: usize) -> Option<usize> {
        let mut head = [0u8; 3];
        let n = (self.chars.len() - k).min(3);
        for (h, &c) in head.iter_mut().zip(&self.chars[k..k + n]) {
            *h = c as u8;
        }
        let len = match frame_len(&head[..n]) {
            // An SD2 header not seen whole yet.
            Ok(_) if head[0] == crate::wire::consts::SD2 && n < 3 => return None,
            Ok(len) => len,
            Err(_) => 1,
        };
        (k + len <= self.chars.len()).then_some(k + len)
    }

    /// End of the next piece of a whole-transmission delivery: the end of
    /// the first telegram that ends at least [`WHOLE_MAX`] characters
    /// after the last piece, or the transmission's end.
    fn piece_end(&self) -> usize {
        let mut k = self.delivered;
        while k < self.delivered + WHOLE_MAX {
            match self.unit_end(k) {
                Some(e) => k = e,
                None => return self.chars.len(),
            }
        }
        k.min(self.chars.len())
    }
}

/// The shared line of one bus; see the module docs.
#[derive(Debug, Clone)]
pub struct Medium {
    stations: usize,
    cfg: MediumConfig,
    /// Paced line: transmissions not yet fully delivered, by start time.
    txs: Vec<Tx>,
    /// Unpaced line: deliveries waiting to be polled.
    ready: VecDeque<Delivery>,
    drop_rng: Rng,
    flip_rng: Rng,
    noise_rng: Rng,
    garble_rng: Rng,
    /// Data bits still to pass before the next flipped one.
    bits_to_flip: u64,
    next_noise: Instant,
    /// Latest time seen (time never runs backwards inside the model).
    now: Instant,
    /// End of the last transmission that has been removed.
    last_end: Instant,
    /// Deliver each transmission in one piece at its end.
    whole: bool,
    stats: MediumStats,
}

impl Medium {
    /// A line shared by `stations` stations (indices `0..stations`).
    /// Probabilities outside 0..=1 are clamped and a bad noise rate counts
    /// as 0; use [`MediumConfig::validate`] to reject them instead.
    pub fn new(stations: usize, mut cfg: MediumConfig) -> Medium {
        let clamp = |p: f64| if p.is_nan() { 0.0 } else { p.clamp(0.0, 1.0) };
        cfg.drop = clamp(cfg.drop);
        cfg.flip_ber = clamp(cfg.flip_ber);
        if !(cfg.noise_rate >= 0.0 && cfg.noise_rate.is_finite()) {
            cfg.noise_rate = 0.0;
        }
        let mut sm = cfg.seed;
        let drop_rng = Rng::new(splitmix64(&mut sm));
        let mut flip_rng = Rng::new(splitmix64(&mut sm));
        let mut noise_rng = Rng::new(splitmix64(&mut sm));
        let garble_rng = Rng::new(splitmix64(&mut sm));
        let bits_to_flip = flip_rng.geometric(cfg.flip_ber);
        let next_noise = Instant::from_nanos(noise_rng.exponential_nanos(cfg.noise_rate));
        Medium {
            stations,
            cfg,
            txs: Vec::new(),
            ready: VecDeque::new(),
            drop_rng,
            flip_rng,
            noise_rng,
            garble_rng,
            bits_to_flip,
            next_noise,
            now: Instant::ZERO,
            last_end: Instant::ZERO,
            whole: false,
            stats: MediumStats::default(),
        }
    }

    /// Deliver each transmission of a paced line in one piece when its
    /// last character has arrived, instead of character by character.
    ///
    /// For receivers in real time behind a scheduler (`dpctl bus`): a
    /// process that is woken late, or reads late, would otherwise get the
    /// characters of one telegram in pieces with pauses between them,
    /// which a receiver framing by idle time takes for the end of the
    /// telegram. The price: the first character of a reply arrives only
    /// when the whole reply has crossed the wire, so a master's wait for
    /// an answer must cover that answer's wire time (see
    /// `station::active::ActiveConfig::whole_telegrams`; the simulator
    /// does this with `sim::SimBus::with_whole_transmissions`). On virtual time (the
    /// simulator) every receiver is on time and character-wise delivery
    /// is exact. A transmission longer than [`WHOLE_MAX`] characters is
    /// delivered in pieces as it arrives (see there), so a receiver gets
    /// a station that sends without a pause at the line's rate, not in one
    /// burst at its end.
    pub fn with_whole_transmissions(mut self) -> Medium {
        self.whole = true;
        self
    }

    /// The configuration in force (after clamping).
    pub fn config(&self) -> &MediumConfig {
        &self.cfg
    }

    /// Number of stations on the line.
    pub fn stations(&self) -> usize {
        self.stations
    }

    /// Counters of what was carried and injected so far.
    pub fn stats(&self) -> MediumStats {
        self.stats
    }

    /// Station `from` writes `bytes` at `now`.
    ///
    /// # Panics
    /// If `from` is not a station index (`from >= stations`).
    pub fn transmit(&mut self, now: Instant, from: usize, bytes: &[u8]) {
        assert!(
            from < self.stations,
            "station {from} is not on a medium with {} stations",
            self.stations
        );
        if bytes.is_empty() {
            return;
        }
        let now = self.advance(now);
        self.stats.chars += bytes.len() as u64;
        let Some(baud) = self.cfg.baud else {
            self.stats.transmissions += 1;
            let bytes = if self.cfg.drop == 0.0 && self.cfg.flip_ber == 0.0 {
                Bytes::copy_from_slice(bytes)
            } else {
                let v: Vec<u8> = bytes
                    .iter()
                    .map(|&b| self.inject(b))
                    .filter(|c| c & DROPPED == 0)
                    .map(|c| c as u8)
                    .collect();
                if v.is_empty() {
                    return;
                }
                Bytes::from(v)
            };
            self.ready.push_back(Delivery {
                from: Some(from),
                at: now,
                bytes,
            });
            return;
        };
        let chars: Vec<u16> = bytes.iter().map(|&b| self.inject(b)).collect();

        // The station still holds the line (or waits for it): extend.
        if let Some(i) = self
            .txs
            .iter()
            .position(|t| t.from == Some(from) && t.end(baud) > now)
        {
            self.txs[i].chars.extend_from_slice(&chars);
            match self.cfg.collisions {
                Collisions::Serialize => self.reflow(i + 1),
                Collisions::Garble => self.garble_overlaps(baud),
            }
            return;
        }

        self.stats.transmissions += 1;
        let busy = self.busy_until() > now;
        let tx = match (busy, self.cfg.collisions) {
            (true, Collisions::Serialize) => {
                self.stats.deferred += 1;
                let last = self.txs.last().expect("a busy line has a transmission");
                Tx {
                    from: Some(from),
                    origin: last.origin,
                    start_bits: last.start_bits + BITS * last.chars.len() as u64,
                    chars,
                    delivered: 0,
                }
            }
            (busy, _) => {
                if busy {
                    self.stats.collisions += 1;
                }
                Tx {
                    from: Some(from),
                    origin: now,
                    start_bits: 0,
                    chars,
                    delivered: 0,
                }
            }
        };
        self.txs.push(tx);
        if busy && self.cfg.collisions == Collisions::Garble {
            self.garble_overlaps(baud);
        }
    }

    /// When [`Medium::poll_delivery`] has something next: the next
    /// delivery or noise event (possibly in the past). `None` when nothing
    /// is pending and no noise is configured.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let mut t = self.ready.front().map(|d| d.at);
        if let Some(baud) = self.cfg.baud {
            for tx in &self.txs {
                if let Some(e) = tx.next_event(baud, self.whole) {
                    t = Some(t.map_or(e, |t| t.min(e)));
                }
            }
        }
        if self.next_noise != Instant::NEVER {
            t = Some(t.map_or(self.next_noise, |t| t.min(self.next_noise)));
        }
        t
    }

    /// The next delivery due at or before `now`, in time order; call until
    /// `None`.
    pub fn poll_delivery(&mut self, now: Instant) -> Option<Delivery> {
        let now = self.advance(now);
        if let Some(d) = self.ready.pop_front() {
            return Some(d);
        }
        let baud = self.cfg.baud?;
        loop {
            let (i, first) = self
                .txs
                .iter()
                .enumerate()
                .filter_map(|(i, t)| t.next_event(baud, self.whole).map(|e| (i, e)))
                .min_by_key(|&(i, e)| (e, i))?;
            if first > now {
                return None;
            }
            // Everything of this transmission that has arrived, but nothing
            // later than another transmission's next character (deliveries
            // stay in time order when transmissions overlap).
            let limit = self
                .txs
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .filter_map(|(_, t)| t.next_event(baud, self.whole))
                .fold(now, Instant::min);
            let whole = self.whole;
            let tx = &mut self.txs[i];
            let mut end = if whole {
                tx.piece_end()
            } else {
                tx.delivered + 1
            };
            if whole {
                // And every whole telegram that has arrived since.
                while let Some(e) = (end < tx.chars.len()).then(|| tx.unit_end(end)).flatten() {
                    if tx.char_end(baud, e - 1) > limit {
                        break;
                    }
                    end = e;
                }
            } else {
                while end < tx.chars.len() && tx.char_end(baud, end) <= limit {
                    end += 1;
                }
            }
            let at = tx.char_end(baud, end - 1);
            let range = tx.delivered..end;
            tx.delivered = end;
            let bytes: Vec<u8> = tx.chars[range]
                .iter()
                .filter(|&&c| c & DROPPED == 0)
                .map(|&c| c as u8)
                .collect();
            let from = tx.from;
            if tx.delivered == tx.chars.len() {
                let end = tx.end(baud);
                self.last_end = self.last_end.max(end);
                self.txs.remove(i);
            }
            if !bytes.is_empty() {
                return Some(Delivery {
                    from,
                    at,
                    bytes: Bytes::from(bytes),
                });
            }
        }
    }

    /// End on the wire of what station `from` has written so far, while
    /// it is still sending (paced lines; `None` when it is not). A driver
    /// that stops taking bytes from a station that is far ahead makes it
    /// wait for the line as a UART's full transmit FIFO does.
    pub fn sending_until(&self, from: usize) -> Option<Instant> {
        let baud = self.cfg.baud?;
        self.txs
            .iter()
            .filter(|t| t.from == Some(from))
            .map(|t| t.end(baud))
            .max()
    }

    /// End of the current transmission (of the last one queued, with
    /// [`Collisions::Serialize`]); in the past when the line is idle.
    pub fn busy_until(&self) -> Instant {
        match self.cfg.baud {
            None => self.last_end.max(self.now),
            Some(baud) => self
                .txs
                .iter()
                .map(|t| t.end(baud))
                .fold(self.last_end, Instant::max),
        }
    }

    /// Move the model's time to `now` (never backwards) and put due noise
    /// bursts on the line.
    fn advance(&mut self, now: Instant) -> Instant {
        let now = now.max(self.now);
        self.now = now;
        while self.next_noise <= now && self.next_noise != Instant::NEVER {
            let t = self.next_noise;
            let busy = self.busy_until();
            if self.cfg.baud.is_some() && busy > t {
                // Noise only counts idle time: start afresh at the end of
                // the transmission (the exponential is memoryless).
                self.next_noise = busy + self.noise_gap();
                continue;
            }
            let n = self.noise_rng.range_inclusive(1, NOISE_BURST_MAX) as usize;
            let chars: Vec<u16> = (0..n).map(|_| self.noise_rng.next_u8() as u16).collect();
            self.stats.noise_bursts += 1;
            self.stats.noise_chars += n as u64;
            match self.cfg.baud {
                None => {
                    self.ready.push_back(Delivery {
                        from: None,
                        at: t,
                        bytes: chars.iter().map(|&c| c as u8).collect(),
                    });
                    self.next_noise = t + self.noise_gap();
                }
                Some(baud) => {
                    let tx = Tx {
                        from: None,
                        origin: t,
                        start_bits: 0,
                        chars,
                        delivered: 0,
                    };
                    let end = tx.end(baud);
                    self.txs.push(tx);
                    self.next_noise = end + self.noise_gap();
                }
            }
        }
        now
    }

    fn noise_gap(&mut self) -> core::time::Duration {
        core::time::Duration::from_nanos(self.noise_rng.exponential_nanos(self.cfg.noise_rate))
    }

    /// Apply drop and flip to one character.
    fn inject(&mut self, b: u8) -> u16 {
        let mut c = b as u16;
        if self.cfg.drop > 0.0 && self.drop_rng.chance(self.cfg.drop) {
            self.stats.dropped += 1;
            c |= DROPPED;
        }
        if self.cfg.flip_ber > 0.0 {
            let mut bit = 0u64;
            loop {
                if self.bits_to_flip >= 8 - bit {
                    self.bits_to_flip -= 8 - bit;
                    break;
                }
                bit += self.bits_to_flip;
                c ^= 1 << bit;
                self.stats.bits_flipped += 1;
                bit += 1;
                self.bits_to_flip = self.flip_rng.geometric(self.cfg.flip_ber);
            }
        }
        c
    }

    /// [`Collisions::Serialize`]: transmissions from index `from` on start
    /// where the previous one ends.
    fn reflow(&mut self, from: usize) {
        for j in from.max(1)..self.txs.len() {
            let (prev, rest) = self.txs.split_at_mut(j);
            let p = &prev[j - 1];
            rest[0].origin = p.origin;
            rest[0].start_bits = p.start_bits + BITS * p.chars.len() as u64;
        }
    }

    /// [`Collisions::Garble`]: corrupt every undelivered character that
    /// overlaps another station's transmission.
    fn garble_overlaps(&mut self, baud: Baud) {
        let spans: Vec<(Option<usize>, Instant, Instant)> = self
            .txs
            .iter()
            .map(|t| (t.from, t.start(baud), t.end(baud)))
            .collect();
        for (i, tx) in self.txs.iter_mut().enumerate() {
            for (j, &(from, s, e)) in spans.iter().enumerate() {
                if i == j || from == tx.from || e <= spans[i].1 || s >= spans[i].2 {
                    continue;
                }
                for k in tx.delivered..tx.chars.len() {
                    let c = tx.chars[k];
                    if c & GARBLED != 0 {
                        continue;
                    }
                    let (cs, ce) = (tx.char_start(baud, k), tx.char_end(baud, k));
                    if cs < e && ce > s {
                        let x = self.garble_rng.range_inclusive(1, 255) as u16;
                        tx.chars[k] = (c ^ x) | GARBLED;
                        self.stats.garbled_chars += 1;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::consts::MAX_TELEGRAM_LEN;
    use core::time::Duration;

    fn drain(m: &mut Medium, until: Instant) -> Vec<Delivery> {
        let mut out = vec![];
        while let Some(t) = m.poll_timeout() {
            if t > until {
                break;
            }
            while let Some(d) = m.poll_delivery(t) {
                out.push(d);
            }
        }
        out
    }

    fn at(d: Duration) -> Instant {
        Instant::ZERO + d
    }

    fn before(t: Instant, d: Duration) -> Instant {
        Instant::from_nanos(t.as_nanos() - d.as_nanos() as u64)
    }

    #[test]
    fn unpaced_delivers_at_once_to_others() {
        let mut m = Medium::new(4, MediumConfig::default());
        let now = Instant::from_nanos(5);
        m.transmit(now, 2, b"abc");
        m.transmit(now, 1, b"de");
        assert_eq!(m.poll_timeout(), Some(now));
        let a = m.poll_delivery(now).unwrap();
        let b = m.poll_delivery(now).unwrap();
        assert!(m.poll_delivery(now).is_none());
        assert_eq!((a.from, a.at, &a.bytes[..]), (Some(2), now, &b"abc"[..]));
        assert_eq!((b.from, &b.bytes[..]), (Some(1), &b"de"[..]));
        assert!(!a.reaches(2) && a.reaches(0) && a.reaches(1) && a.reaches(3));
        assert_eq!(m.poll_timeout(), None);
    }

    #[test]
    fn pacing_2000_chars_at_19200_is_exact() {
        let b = Baud::B19200;
        let mut m = Medium::new(2, MediumConfig::paced(b));
        let data: Vec<u8> = (0..2000u32).map(|i| i as u8).collect();
        m.transmit(Instant::ZERO, 0, &data);
        assert_eq!(m.busy_until(), at(b.chars_to_duration(2000)));
        let ds = drain(&mut m.clone(), Instant::NEVER);
        // Woken at every character's end: one character each.
        assert_eq!(ds.len(), 2000);
        for (k, d) in ds.iter().enumerate() {
            assert_eq!(d.at, at(b.chars_to_duration(k as u64 + 1)));
            assert_eq!(&d.bytes[..], &data[k..=k]);
        }
        // Woken once at the end: everything in one chunk.
        let end = at(b.chars_to_duration(2000));
        assert!(m
            .poll_delivery(before(end, Duration::from_nanos(1)))
            .is_some());
        let d = m.poll_delivery(end).unwrap();
        assert_eq!(d.at, end);
        assert_eq!(d.at - Instant::ZERO, Duration::from_nanos(1_145_833_334));
        assert_eq!(&d.bytes[..], &data[1999..]);
        assert!(m.poll_delivery(Instant::NEVER).is_none());
    }

    #[test]
    fn a_late_poll_gets_everything_arrived_in_one_chunk_never_with_a_gap() {
        // An 11-byte write at 19.2 kbit/s polled 6.5 ms later (after 11
        // characters = 6.3 ms): all 11 bytes at once, at the last one's end.
        let b = Baud::B19200;
        let mut m = Medium::new(2, MediumConfig::paced(b));
        let data = [
            0x68, 0x05, 0x05, 0x68, 0x88, 0x82, 0x6D, 0x3C, 0x3E, 0x87, 0x16,
        ];
        m.transmit(Instant::ZERO, 1, &data);
        let d = m.poll_delivery(at(Duration::from_micros(6500))).unwrap();
        assert_eq!(&d.bytes[..], &data[..]);
        assert_eq!(d.at, at(b.chars_to_duration(11)));
        assert!(m.poll_delivery(Instant::NEVER).is_none());
        // Polled at arbitrary times: each chunk holds the characters that
        // arrived since the previous one, so consecutive chunks touch (no
        // idle between the last character of one and the first of the next).
        let mut m = Medium::new(2, MediumConfig::paced(b));
        m.transmit(Instant::ZERO, 1, &data);
        let mut got = vec![];
        for us in [600, 610, 2000, 2001, 5000, 9000] {
            while let Some(d) = m.poll_delivery(at(Duration::from_micros(us))) {
                got.extend_from_slice(&d.bytes);
                // The chunk ends where its last character ends.
                assert_eq!(d.at, at(b.chars_to_duration(got.len() as u64)));
            }
        }
        assert_eq!(got, data);
    }

    #[test]
    fn whole_transmissions_arrive_in_one_piece_at_their_end() {
        let b = Baud::B19200;
        let mut m = Medium::new(3, MediumConfig::paced(b)).with_whole_transmissions();
        let data = [
            0x68, 0x05, 0x05, 0x68, 0x88, 0x82, 0x6D, 0x3C, 0x3E, 0x87, 0x16,
        ];
        m.transmit(Instant::ZERO, 1, &data[..4]);
        // More bytes while the line is busy extend the transmission.
        m.transmit(at(b.chars_to_duration(2)), 1, &data[4..]);
        let end = at(b.chars_to_duration(11));
        assert_eq!(m.poll_timeout(), Some(end));
        assert!(m
            .poll_delivery(before(end, Duration::from_nanos(1)))
            .is_none());
        let d = m.poll_delivery(end).unwrap();
        assert_eq!((d.at, &d.bytes[..]), (end, &data[..]));
        // The next transmission after an idle gap keeps the gap.
        let t = end + b.bits_to_duration(37);
        m.transmit(t, 0, &[0xDC, 0x02, 0x02]);
        let d = m.poll_delivery(Instant::NEVER).unwrap();
        assert_eq!(d.at, t + b.chars_to_duration(3));
        assert_eq!(m.poll_timeout(), None);
    }

    /// SD2 telegrams of 1 to 60 data bytes, back to back, and the
    /// offsets where each ends.
    fn telegrams(n: usize) -> (Vec<u8>, Vec<usize>) {
        let (mut out, mut ends) = (vec![], vec![]);
        for i in 0..n {
            let data: Vec<u8> = (0..1 + i % 60).map(|k| (i * 7 + k) as u8).collect();
            let le = data.len() as u8 + 3;
            let mut t = vec![0x68, le, le, 0x68, 3, 2, 0x5D];
            t.extend_from_slice(&data);
            let fcs = t[4..].iter().fold(0u8, |a, b| a.wrapping_add(*b));
            t.extend_from_slice(&[fcs, 0x16]);
            out.extend(t);
            ends.push(out.len());
        }
        (out, ends)
    }

    #[test]
    fn a_transmission_longer_than_whole_max_arrives_in_whole_telegrams_as_it_crosses() {
        let b = Baud::B12000000;
        let mut m = Medium::new(2, MediumConfig::paced(b)).with_whole_transmissions();
        // About 150 000 characters written at once: one transmission of
        // 0.14 s.
        let (data, ends) = telegrams(4000);
        m.transmit(Instant::ZERO, 0, &data);
        let ds = drain(&mut m, Instant::NEVER);
        let all: Vec<u8> = ds.iter().flat_map(|d| d.bytes.to_vec()).collect();
        assert_eq!(all, data);
        let mut count = 0;
        for (k, d) in ds.iter().enumerate() {
            count += d.bytes.len();
            // Each piece when its last character has crossed, ending where
            // a telegram ends; at least WHOLE_MAX long (but the last), and
            // at most a telegram longer when polled on time.
            assert_eq!(d.at, at(b.chars_to_duration(count as u64)));
            assert!(ends.binary_search(&count).is_ok(), "piece ends at {count}");
            assert!(d.bytes.len() < WHOLE_MAX + MAX_TELEGRAM_LEN);
            if k + 1 < ds.len() {
                assert!(d.bytes.len() >= WHOLE_MAX);
            }
        }
        // A late poll gets every whole telegram that has arrived, in one
        // piece; the rest still follows in pieces.
        let t0 = at(Duration::from_secs(1));
        m.transmit(t0, 0, &data);
        let late = t0 + b.chars_to_duration(3000);
        let d = m.poll_delivery(late).unwrap();
        let upto = ends[ends.partition_point(|&e| e <= 3000) - 1];
        assert_eq!(&d.bytes[..], &data[..upto]);
        assert!(m.poll_delivery(late).is_none());
        let next = ends[ends.partition_point(|&e| e < upto + WHOLE_MAX)];
        assert_eq!(
            m.poll_timeout(),
            Some(t0 + b.chars_to_duration(next as u64))
        );
        // A transmission cut inside a telegram: the piece ends there.
        let t1 = at(Duration::from_secs(2));
        m = Medium::new(2, MediumConfig::paced(b)).with_whole_transmissions();
        assert!(ends.binary_search(&1000).is_err());
        m.transmit(t1, 0, &data[..1000]);
        let ds = drain(&mut m, Instant::NEVER);
        assert_eq!(ds.last().unwrap().at, t1 + b.chars_to_duration(1000));
        assert_eq!(ds.iter().map(|d| d.bytes.len()).sum::<usize>(), 1000);
        assert_eq!(m.stats().transmissions, 1);
    }

    #[test]
    fn writes_while_holding_the_line_extend_the_transmission() {
        let b = Baud::B19200;
        let mut m = Medium::new(3, MediumConfig::paced(b));
        let data: Vec<u8> = (0..2000u32).map(|i| (i * 7) as u8).collect();
        // 1 byte per write, each written a little later while the line is
        // still busy: still one transmission ending at exactly 2000 chars.
        let mut ds = vec![];
        for (i, c) in data.chunks(1).enumerate() {
            let now = at(b.chars_to_duration(i as u64 / 2));
            while let Some(d) = m.poll_delivery(now) {
                ds.push(d);
            }
            m.transmit(now, 1, c);
        }
        ds.extend(drain(&mut m, Instant::NEVER));
        let all: Vec<u8> = ds.iter().flat_map(|d| d.bytes.to_vec()).collect();
        assert_eq!(all, data);
        // Every chunk ends at its last character's exact end.
        let mut count = 0;
        for d in &ds {
            count += d.bytes.len() as u64;
            assert_eq!(d.at, at(b.chars_to_duration(count)));
        }
        assert_eq!(m.stats().transmissions, 1);
        assert_eq!(m.stats().collisions, 0);
    }

    #[test]
    fn serialize_queues_concurrent_writers() {
        let b = Baud::B19200;
        let cfg = MediumConfig {
            collisions: Collisions::Serialize,
            ..MediumConfig::paced(b)
        };
        let mut m = Medium::new(3, cfg);
        m.transmit(Instant::ZERO, 0, &[1; 1000]);
        m.transmit(Instant::ZERO, 1, &[2; 600]);
        m.transmit(at(b.chars_to_duration(5)), 2, &[3; 200]);
        // Station 0 writes more while it still holds the line: its
        // transmission grows and the queued ones move back.
        m.transmit(at(b.chars_to_duration(10)), 0, &[1; 200]);
        assert_eq!(m.busy_until(), at(b.chars_to_duration(2000)));
        let ds = drain(&mut m, Instant::NEVER);
        // Per station: first and last character's arrival, characters.
        let mut summary: Vec<(Option<usize>, Instant, Instant, usize)> = vec![];
        for d in &ds {
            match summary.last_mut() {
                Some(s) if s.0 == d.from => {
                    s.2 = d.at;
                    s.3 += d.bytes.len();
                }
                _ => summary.push((d.from, d.at, d.at, d.bytes.len())),
            }
        }
        let c = |n| at(b.chars_to_duration(n));
        assert_eq!(
            summary,
            vec![
                // The model's time was already at 10 characters.
                (Some(0), c(10), c(1200), 1200),
                (Some(1), c(1201), c(1800), 600),
                (Some(2), c(1801), c(2000), 200),
            ]
        );
        for d in &ds {
            let v = d.from.unwrap() as u8 + 1;
            assert!(d.bytes.iter().all(|&x| x == v));
        }
        let s = m.stats();
        assert_eq!((s.deferred, s.collisions, s.transmissions), (2, 0, 3));
    }

    #[test]
    fn garble_corrupts_the_overlap_of_both() {
        let b = Baud::B1500000;
        let mut m = Medium::new(3, MediumConfig::paced(b));
        let a = [0x11u8; 10];
        let c = [0x22u8; 5];
        m.transmit(Instant::ZERO, 0, &a);
        // B starts 1 ns after A's character 3 started: A's characters 3..=8
        // overlap B's five characters [33 bit + 1 ns, 88 bit + 1 ns).
        let t = at(b.bits_to_duration(33)) + Duration::from_nanos(1);
        let mut early = vec![];
        while let Some(d) = m.poll_delivery(t) {
            early.push(d);
        }
        m.transmit(t, 1, &c);
        let mut ds = early;
        ds.extend(drain(&mut m, Instant::NEVER));
        let from_a: Vec<u8> = ds
            .iter()
            .filter(|d| d.from == Some(0))
            .flat_map(|d| d.bytes.to_vec())
            .collect();
        let from_b: Vec<u8> = ds
            .iter()
            .filter(|d| d.from == Some(1))
            .flat_map(|d| d.bytes.to_vec())
            .collect();
        let damaged: Vec<bool> = from_a.iter().map(|&x| x != 0x11).collect();
        assert_eq!(
            damaged,
            [false, false, false, true, true, true, true, true, true, false]
        );
        assert!(from_b.iter().all(|&x| x != 0x22));
        let s = m.stats();
        assert_eq!((s.collisions, s.garbled_chars), (1, 11));
        // Time order is kept across both transmissions.
        assert!(ds.windows(2).all(|w| w[0].at <= w[1].at));
    }

    #[test]
    fn no_collision_when_the_line_became_free() {
        let b = Baud::B12000000;
        let mut m = Medium::new(2, MediumConfig::paced(b));
        m.transmit(Instant::ZERO, 0, &[1, 2, 3]);
        let end = m.busy_until();
        m.transmit(end, 1, &[4]);
        let ds = drain(&mut m, Instant::NEVER);
        let bytes: Vec<u8> = ds.iter().flat_map(|d| d.bytes.to_vec()).collect();
        assert_eq!(bytes, [1, 2, 3, 4]);
        assert_eq!(m.stats().collisions, 0);
        assert_eq!(m.stats().transmissions, 2);
    }

    #[test]
    fn noise_only_on_idle_line() {
        let b = Baud::B187500;
        let cfg = MediumConfig {
            noise_rate: 2000.0,
            seed: 9,
            collisions: Collisions::Serialize,
            ..MediumConfig::paced(b)
        };
        let mut m = Medium::new(2, cfg);
        let mut station_spans: Vec<(Instant, Instant)> = vec![];
        let mut noise_chars: Vec<(Instant, Instant)> = vec![];
        let mut first_at = None;
        let mut now = Instant::ZERO;
        let step = Duration::from_millis(2);
        let end = at(Duration::from_secs(2));
        let char_time = b.chars_to_duration(1);
        while now < end {
            m.transmit(now, 0, &[0xAA; 20]);
            now += step;
            while let Some(t) = m.poll_timeout().filter(|&t| t <= now) {
                while let Some(d) = m.poll_delivery(t) {
                    let start = before(d.at, char_time * d.bytes.len() as u32);
                    match d.from {
                        None => noise_chars.push((start, d.at)),
                        Some(_) => {
                            let (first, n) = first_at.get_or_insert((start, 0));
                            *n += d.bytes.len();
                            if *n == 20 {
                                station_spans.push((*first, d.at));
                                first_at = None;
                            }
                        }
                    }
                }
            }
        }
        let s = m.stats();
        assert!(s.noise_bursts > 300, "{s}");
        assert!(station_spans.len() > 900);
        for (ns, ne) in &noise_chars {
            for (ss, se) in &station_spans {
                // Start times are estimated from delivery times and may be
                // 1 ns early (bit times round up to whole nanoseconds).
                let (ns, ne, ss, se) = (ns.as_nanos(), ne.as_nanos(), ss.as_nanos(), se.as_nanos());
                assert!(
                    ne <= ss + 1 || ns + 1 >= se,
                    "noise {ns}..{ne} overlaps {ss}..{se}"
                );
            }
        }
    }
}
