//! Baud-rate search of a passive station (GSD `Auto_Baud_supp`), sans-IO.
//!
//! A slave with auto-baud listens at one rate after the other, from
//! 12 Mbit/s down to 9.6 kbit/s (only the rates the device supports, its
//! GSD's `*_supp` keywords, see [`AutoBaud::with_rates`]), until a valid telegram with a frame
//! check sequence (SD1, SD2 or SD3: start delimiter, length, FCS and end
//! delimiter all right) decodes, and then locks to that rate. A master
//! always produces such telegrams (FDL Status requests of its GAP poll,
//! requests to its slaves), and at a wrong rate they arrive as garbage
//! that fails these checks. Tokens and short acknowledges carry no FCS and
//! do not lock the search.
//!
//! The station's driver owns the port: it sets [`AutoBaud::baud`], feeds
//! what it reads to [`AutoBaud::handle_rx`] and calls
//! [`AutoBaud::handle_timeout`] at [`AutoBaud::poll_timeout`]; whenever
//! the rate changes it reconfigures the port.

use crate::codec::{Framed, Framer};
#[allow(unused_imports)]
use crate::prelude::*;
use crate::time::Instant;
use crate::timing::Baud;
use crate::wire::Telegram;
use core::time::Duration;

/// The rates in the order they are tried: fastest first.
pub const SEARCH_ORDER: [Baud; 11] = [
    Baud::B12000000,
    Baud::B6000000,
    Baud::B3000000,
    Baud::B1500000,
    Baud::B500000,
    Baud::B187500,
    Baud::B93750,
    Baud::B45450,
    Baud::B31250,
    Baud::B19200,
    Baud::B9600,
];

/// A set of baud rates (the rates a device supports, from its GSD's
/// `*_supp` keywords).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BaudSet(u16);

impl BaudSet {
    /// Every rate of PROFIBUS-DP.
    pub const ALL: BaudSet = BaudSet((1 << SEARCH_ORDER.len()) - 1);

    /// No rate.
    pub const EMPTY: BaudSet = BaudSet(0);

    fn bit(baud: Baud) -> u16 {
        let i = SEARCH_ORDER.iter().position(|&b| b == baud).unwrap_or(0);
        1 << i
    }

    /// Whether `baud` is in the set.
    pub fn contains(self, baud: Baud) -> bool {
        self.0 & Self::bit(baud) != 0
    }

    /// The set with `baud` added.
    pub fn with(self, baud: Baud) -> BaudSet {
        BaudSet(self.0 | Self::bit(baud))
    }

    /// Whether the set is empty.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The rates in search order (fastest first).
    pub fn iter(self) -> impl Iterator<Item = Baud> {
        SEARCH_ORDER.into_iter().filter(move |&b| self.contains(b))
    }

    /// The fastest rate of the set ([`Baud::B12000000`] for an empty set).
    pub fn fastest(self) -> Baud {
        self.iter().next().unwrap_or(SEARCH_ORDER[0])
    }
}

impl Default for BaudSet {
    fn default() -> BaudSet {
        BaudSet::ALL
    }
}

impl FromIterator<Baud> for BaudSet {
    fn from_iter<I: IntoIterator<Item = Baud>>(iter: I) -> BaudSet {
        iter.into_iter().fold(BaudSet::EMPTY, BaudSet::with)
    }
}

/// Least time spent listening at one rate.
pub const MIN_DWELL: Duration = Duration::from_millis(100);

/// The search; see the module docs.
#[derive(Debug)]
pub struct AutoBaud {
    idx: usize,
    since: Instant,
    framer: Framer,
    buf: Vec<u8>,
    locked: Option<Baud>,
    min_dwell: Duration,
    rates: BaudSet,
}

impl AutoBaud {
    /// A search starting now at the fastest rate.
    pub fn new(now: Instant) -> AutoBaud {
        Self::with_dwell(now, MIN_DWELL)
    }

    /// A search that listens at least `min_dwell` at each rate (and at
    /// least as long as two of the longest telegrams take at that rate).
    pub fn with_dwell(now: Instant, min_dwell: Duration) -> AutoBaud {
        AutoBaud {
            idx: 0,
            since: now,
            framer: Framer::new(),
            buf: Vec::with_capacity(1024),
            locked: None,
            min_dwell,
            rates: BaudSet::ALL,
        }
    }

    /// The search limited to `rates` (a device's GSD `*_supp` rates): it
    /// never listens, and so never locks, at another rate. An empty set
    /// means every rate.
    pub fn with_rates(mut self, rates: BaudSet) -> AutoBaud {
        self.rates = if rates.is_empty() {
            BaudSet::ALL
        } else {
            rates
        };
        self.idx = self.next_idx(SEARCH_ORDER.len() - 1);
        self
    }

    /// The rates searched.
    pub fn rates(&self) -> BaudSet {
        self.rates
    }

    /// The index of the first searched rate after `idx` (wrapping).
    fn next_idx(&self, idx: usize) -> usize {
        (1..=SEARCH_ORDER.len())
            .map(|k| (idx + k) % SEARCH_ORDER.len())
            .find(|&i| self.rates.contains(SEARCH_ORDER[i]))
            .unwrap_or(0)
    }

    /// The rate to listen at now (the locked rate once locked).
    pub fn baud(&self) -> Baud {
        self.locked.unwrap_or(SEARCH_ORDER[self.idx])
    }

    /// The rate found, if any.
    pub fn locked(&self) -> Option<Baud> {
        self.locked
    }

    /// How long the search stays at `baud`.
    pub fn dwell(&self, baud: Baud) -> Duration {
        self.min_dwell.max(baud.chars_to_duration(2 * 256))
    }

    /// Bytes read at the current rate. Returns the rate when a valid
    /// telegram decoded and the search locked.
    pub fn handle_rx(&mut self, _now: Instant, bytes: &[u8]) -> Option<Baud> {
        if self.locked.is_some() {
            return self.locked;
        }
        self.buf.extend_from_slice(bytes);
        let mut start = 0;
        loop {
            match self.framer.frame(&self.buf[start..]) {
                Framed::Telegram { skip, len } => {
                    let at = start + skip;
                    if let Ok((Telegram::Data(_), _)) = Telegram::parse(&self.buf[at..at + len]) {
                        self.locked = Some(SEARCH_ORDER[self.idx]);
                        self.buf.clear();
                        return self.locked;
                    }
                    start = at + len;
                }
                Framed::NeedMore { skip } => {
                    start += skip;
                    break;
                }
            }
        }
        self.buf.drain(..start);
        // A partial telegram never needs more than the longest one.
        if self.buf.len() > 2 * crate::wire::consts::MAX_TELEGRAM_LEN {
            let cut = self.buf.len() - crate::wire::consts::MAX_TELEGRAM_LEN;
            self.buf.drain(..cut);
        }
        None
    }

    /// When to give up the current rate (none once locked).
    pub fn poll_timeout(&self) -> Option<Instant> {
        match self.locked {
            Some(_) => None,
            None => Some(self.since + self.dwell(self.baud())),
        }
    }

    /// Time has advanced: after the dwell time the search moves to the
    /// next rate (wrapping around) and returns it.
    pub fn handle_timeout(&mut self, now: Instant) -> Option<Baud> {
        if self.poll_timeout().is_some_and(|t| t <= now) {
            self.idx = self.next_idx(self.idx);
            self.since = now;
            self.buf.clear();
            self.framer = Framer::new();
            return Some(self.baud());
        }
        None
    }

    /// Start searching again from the fastest rate (e.g. after the
    /// watchdog expired).
    pub fn restart(&mut self, now: Instant) {
        *self = Self::with_dwell(now, self.min_dwell).with_rates(self.rates);
    }
}

/// When a station that found its rate searches again because the line
/// went quiet: no valid telegram for [`Relisten::after`] (a master always
/// sends, so silence means the rate changed or the master went away).
/// Sans-IO: the driver reports the station's telegram count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Relisten {
    /// How long a silence makes the search start again.
    pub after: Duration,
    count: u64,
    since: Instant,
}

/// The silence after which a locked station searches again.
pub const RELISTEN_AFTER: Duration = Duration::from_secs(10);

impl Relisten {
    /// Watching from `now`, searching again after `after` of silence.
    pub fn new(now: Instant, after: Duration) -> Relisten {
        Relisten {
            after,
            count: 0,
            since: now,
        }
    }

    /// `telegrams`: the valid telegrams the station has framed so far.
    /// True when none came for [`Relisten::after`].
    pub fn is_silent(&mut self, now: Instant, telegrams: u64) -> bool {
        if telegrams != self.count {
            self.count = telegrams;
            self.since = now;
            return false;
        }
        now >= self.deadline()
    }

    /// When the line counts as silent if no telegram comes before.
    pub fn deadline(&self) -> Instant {
        self.since + self.after
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::fdl_status;

    #[test]
    fn walks_the_rates_and_locks_on_a_valid_telegram() {
        let t0 = Instant::ZERO;
        let mut ab = AutoBaud::new(t0);
        assert_eq!(ab.baud(), Baud::B12000000);
        // Garbage, a token and an SC do not lock.
        assert_eq!(
            ab.handle_rx(t0, &[0x00, 0xFF, 0x13, 0xDC, 0x02, 0x01, 0xE5]),
            None
        );
        let due = ab.poll_timeout().unwrap();
        assert_eq!(due, t0 + MIN_DWELL);
        assert_eq!(ab.handle_timeout(due), Some(Baud::B6000000));
        // Walk down to 19.2k; the slow rates listen longer.
        let mut now = due;
        while ab.baud() != Baud::B19200 {
            now = ab.poll_timeout().unwrap();
            ab.handle_timeout(now);
        }
        assert_eq!(
            ab.poll_timeout(),
            Some(now + Baud::B19200.chars_to_duration(512))
        );
        // A telegram split over two reads, after garbage.
        let t = fdl_status(5, 1);
        assert_eq!(ab.handle_rx(now, &[0x68, 0x10, 0x99]), None);
        assert_eq!(ab.handle_rx(now, &t[..3]), None);
        assert_eq!(ab.handle_rx(now, &t[3..]), Some(Baud::B19200));
        assert_eq!(ab.poll_timeout(), None);
        assert_eq!(ab.baud(), Baud::B19200);
        ab.restart(now);
        assert_eq!((ab.baud(), ab.locked()), (Baud::B12000000, None));
    }

    #[test]
    fn wraps_around_and_bounds_its_buffer() {
        let mut ab = AutoBaud::with_dwell(Instant::ZERO, Duration::from_millis(1));
        let mut now = Instant::ZERO;
        for _ in 0..SEARCH_ORDER.len() {
            now = ab.poll_timeout().unwrap();
            ab.handle_timeout(now);
        }
        assert_eq!(ab.baud(), Baud::B12000000);
        for _ in 0..100 {
            ab.handle_rx(now, &[0x68; 64]);
        }
        assert!(ab.buf.len() <= 2 * crate::wire::consts::MAX_TELEGRAM_LEN);
        assert_eq!(ab.locked(), None);
    }

    #[test]
    fn keeps_to_the_devices_rates() {
        // A BK3000 (GSD: 9.6k … 1.5M; manual p. 24: 1.5 Mbit/s at most).
        let bk3000: BaudSet = [
            Baud::B9600,
            Baud::B19200,
            Baud::B93750,
            Baud::B187500,
            Baud::B500000,
            Baud::B1500000,
        ]
        .into_iter()
        .collect();
        let mut ab =
            AutoBaud::with_dwell(Instant::ZERO, Duration::from_millis(1)).with_rates(bk3000);
        assert_eq!(ab.baud(), Baud::B1500000, "starts at its fastest rate");
        let mut seen = vec![ab.baud()];
        let mut now = Instant::ZERO;
        for _ in 0..2 * SEARCH_ORDER.len() {
            now = ab.poll_timeout().unwrap();
            seen.push(ab.handle_timeout(now).unwrap());
        }
        for fast in [
            Baud::B12000000,
            Baud::B6000000,
            Baud::B3000000,
            Baud::B45450,
            Baud::B31250,
        ] {
            assert!(!seen.contains(&fast), "listened at {fast:?}: {seen:?}");
        }
        assert_eq!(
            &seen[..7],
            &[
                Baud::B1500000,
                Baud::B500000,
                Baud::B187500,
                Baud::B93750,
                Baud::B19200,
                Baud::B9600,
                Baud::B1500000
            ]
        );
        ab.restart(now);
        assert_eq!(ab.baud(), Baud::B1500000, "a new search keeps the set");
        // The empty set means all rates.
        let all = AutoBaud::new(Instant::ZERO).with_rates(BaudSet::EMPTY);
        assert_eq!(all.baud(), Baud::B12000000);
        assert_eq!(BaudSet::ALL.iter().count(), SEARCH_ORDER.len());
    }

    #[test]
    fn relisten_after_silence_only() {
        let t0 = Instant::ZERO;
        let mut r = Relisten::new(t0, Duration::from_secs(10));
        assert!(!r.is_silent(t0 + Duration::from_secs(9), 0));
        assert!(
            !r.is_silent(t0 + Duration::from_secs(9), 3),
            "telegrams came"
        );
        assert!(!r.is_silent(t0 + Duration::from_secs(18), 3));
        assert!(r.is_silent(t0 + Duration::from_secs(19), 3));
    }
}
