//! The in-process simulated bus on virtual time.
//!
//! [`SimBus`] connects sans-IO [`Station`]s through a [`Medium`] (the same
//! line model `dpctl bus` uses: broadcast to all but the sender, pacing at
//! a baud rate, collisions, fault injection) and advances a virtual clock
//! from event to event. Nothing sleeps: a second of bus time at 12 Mbit/s
//! with 125 stations runs as fast as the stations compute, and every run
//! with the same seed is identical.
//!
//! ```
//! use profibus_fdl::line::medium::MediumConfig;
//! use profibus_fdl::sim::SimBus;
//! use profibus_fdl::station::active::{ActiveConfig, ActiveStation, MasterApp, TokenContext, Request, CycleResult};
//! use profibus_fdl::{Baud, BusParams, Instant};
//! use core::time::Duration;
//!
//! struct Idle;
//! impl MasterApp for Idle {
//!     fn poll_request(&mut self, _: &TokenContext) -> Option<Request<'_>> { None }
//!     fn on_result(&mut self, _: Instant, _: &CycleResult<'_>) {}
//! }
//! let params = BusParams::defaults(Baud::B1500000);
//! let mut bus = SimBus::new(MediumConfig::paced(Baud::B1500000));
//! let m = bus.add(ActiveStation::new(ActiveConfig::new(2, params), Idle));
//! bus.run_for(Duration::from_millis(20));
//! let tokens = bus.station::<ActiveStation<Idle>>(m).stats().tokens;
//! assert!(tokens > 10, "{tokens}");
//! ```

use crate::line::medium::{Medium, MediumConfig, MediumStats};
#[allow(unused_imports)]
use crate::prelude::*;
use crate::station::Station;
use crate::time::Instant;
use core::any::Any;
use core::time::Duration;

/// A station the simulator can hand back by its concrete type.
pub trait SimStation: Station + Any {
    /// As `Any`, for downcasting.
    fn as_any(&self) -> &dyn Any;
    /// As mutable `Any`, for downcasting.
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

impl<T: Station + Any> SimStation for T {
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// Index of a station on a [`SimBus`].
pub type StationId = usize;

/// Observer of everything delivered on the line: (arrival time, sender or
/// `None` for noise, bytes).
pub type Tap = Box<dyn FnMut(Instant, Option<StationId>, &[u8])>;

struct Slot {
    station: Box<dyn SimStation>,
    online: bool,
}

/// Stations on a simulated line with a virtual clock; see the module docs.
pub struct SimBus {
    cfg: MediumConfig,
    medium: Option<Medium>,
    slots: Vec<Slot>,
    now: Instant,
    tap: Option<Tap>,
    whole: bool,
}

/// Steps at one instant after which the simulator concludes a station
/// keeps asking to be woken without making progress.
const STALL_LIMIT: u32 = 1_000_000;

impl SimBus {
    /// An empty bus whose line behaves as `cfg` says.
    pub fn new(cfg: MediumConfig) -> SimBus {
        SimBus {
            cfg,
            medium: None,
            slots: Vec::new(),
            now: Instant::ZERO,
            tap: None,
            whole: false,
        }
    }

    /// Deliver each transmission in one piece when its last character has
    /// arrived, as a paced `dpctl bus` does
    /// ([`Medium::with_whole_transmissions`]), instead of character by
    /// character.
    pub fn with_whole_transmissions(mut self) -> SimBus {
        self.whole = true;
        self
    }

    /// Attach a station (before the first step).
    ///
    /// # Panics
    /// When the bus already ran: the line model is built for a fixed
    /// number of stations.
    pub fn add<S: Station + Any>(&mut self, station: S) -> StationId {
        assert!(self.medium.is_none(), "add stations before running the bus");
        self.slots.push(Slot {
            station: Box::new(station),
            online: true,
        });
        self.slots.len() - 1
    }

    /// Observe every delivery on the line.
    pub fn set_tap(&mut self, tap: Tap) {
        self.tap = Some(tap);
    }

    /// The station `id` as its concrete type.
    ///
    /// # Panics
    /// When `id` holds a station of another type.
    pub fn station<S: Any>(&self, id: StationId) -> &S {
        (*self.slots[id].station)
            .as_any()
            .downcast_ref()
            .expect("station type")
    }

    /// The station `id` as its concrete type, mutable.
    ///
    /// # Panics
    /// When `id` holds a station of another type.
    pub fn station_mut<S: Any>(&mut self, id: StationId) -> &mut S {
        (*self.slots[id].station)
            .as_any_mut()
            .downcast_mut()
            .expect("station type")
    }

    /// Switch a station off (it hears and sends nothing, like a pulled
    /// plug) or on again.
    pub fn set_online(&mut self, id: StationId, online: bool) {
        self.slots[id].online = online;
    }

    /// Replace a station (a device restarting with a fresh state).
    pub fn replace<S: Station + Any>(&mut self, id: StationId, station: S) {
        self.slots[id].station = Box::new(station);
    }

    /// Virtual time now.
    pub fn now(&self) -> Instant {
        self.now
    }

    /// Counters of the line.
    pub fn medium_stats(&self) -> MediumStats {
        self.medium.as_ref().map(|m| m.stats()).unwrap_or_default()
    }

    fn medium(&mut self) -> &mut Medium {
        let n = self.slots.len();
        let (cfg, whole) = (self.cfg, self.whole);
        self.medium.get_or_insert_with(|| {
            let m = Medium::new(n, cfg);
            if whole {
                m.with_whole_transmissions()
            } else {
                m
            }
        })
    }

    fn next_event(&mut self) -> Option<Instant> {
        let mut next = self.medium().poll_timeout();
        for s in &self.slots {
            if s.online {
                if let Some(t) = s.station.poll_timeout() {
                    next = Some(next.map_or(t, |n: Instant| n.min(t)));
                }
            }
        }
        next
    }

    /// Process everything due at the next event time. Returns false when
    /// nothing is scheduled at all.
    pub fn step(&mut self) -> bool {
        let Some(next) = self.next_event() else {
            return false;
        };
        self.advance(next.max(self.now));
        true
    }

    fn advance(&mut self, now: Instant) {
        self.now = now;
        self.medium();
        let mut rounds = 0u32;
        loop {
            let mut progress = false;
            let medium = self.medium.as_mut().expect("medium");
            while let Some(d) = medium.poll_delivery(now) {
                progress = true;
                if let Some(tap) = self.tap.as_mut() {
                    tap(d.at, d.from, &d.bytes);
                }
                for (j, s) in self.slots.iter_mut().enumerate() {
                    if s.online && d.reaches(j) {
                        s.station.handle_rx(d.at, &d.bytes);
                    }
                }
            }
            for s in self.slots.iter_mut().filter(|s| s.online) {
                if s.station.poll_timeout().is_some_and(|t| t <= now) {
                    s.station.handle_timeout(now);
                }
            }
            for (j, s) in self.slots.iter_mut().enumerate() {
                if !s.online {
                    continue;
                }
                while let Some(bytes) = s.station.poll_transmit(now) {
                    progress = true;
                    medium.transmit(now, j, bytes);
                }
            }
            let due = medium.poll_timeout().is_some_and(|t| t <= now);
            if !progress && !due {
                break;
            }
            rounds += 1;
            assert!(
                rounds < STALL_LIMIT,
                "simulated bus stalled at {now}: a station keeps transmitting"
            );
        }
    }

    /// Run until virtual time `t` (events after `t` stay pending).
    pub fn run_until(&mut self, t: Instant) {
        let mut same = 0u32;
        let mut last = self.now;
        while let Some(next) = self.next_event() {
            if next > t {
                break;
            }
            if next <= last {
                same += 1;
                assert!(
                    same < STALL_LIMIT,
                    "simulated bus stalled at {last}: a station's deadline does not advance"
                );
            } else {
                same = 0;
                last = next;
            }
            self.advance(next.max(self.now));
        }
        self.now = self.now.max(t);
    }

    /// Run for `d` of virtual time.
    pub fn run_for(&mut self, d: Duration) {
        let t = self.now + d;
        self.run_until(t);
    }

    /// Run until `done` holds (checked after every event) or `limit` of
    /// virtual time passed; returns whether `done` held.
    pub fn run_while(&mut self, limit: Duration, mut done: impl FnMut(&SimBus) -> bool) -> bool {
        let end = self.now + limit;
        while !done(self) {
            match self.next_event() {
                Some(next) if next <= end => self.advance(next.max(self.now)),
                _ => {
                    self.now = self.now.max(end);
                    return done(self);
                }
            }
        }
        true
    }
}
