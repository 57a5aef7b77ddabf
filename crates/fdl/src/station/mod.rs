//! FDL stations as sans-IO state machines.
//!
//! A station has no I/O and no clock of its own. A driver (the tokio
//! driver in `profibus_io::driver`, the virtual-time simulator in
//! [`crate::sim`], a fuzzer) feeds it through the [`Station`] trait:
//!
//! 1. bytes received from the line with the time they arrived
//!    ([`Station::handle_rx`]),
//! 2. the passing of time ([`Station::handle_timeout`], called at or after
//!    [`Station::poll_timeout`]),
//!
//! and after every call drains [`Station::poll_transmit`], writing what it
//! returns to the line.
//!
//! Two kinds of stations exist:
//!
//! - [`passive::PassiveStation`]: a responder (DP slave side). It frames
//!   requests addressed to it, keeps the FCB rule, answers FDL Status
//!   itself and hands everything else to a [`passive::Responder`].
//! - [`active::ActiveStation`]: a master. It joins the logical token ring,
//!   passes the token, polls the GAP, claims a lost token, detects address
//!   collisions and duplicate tokens, and while it holds the token runs
//!   message cycles (requests with FCB/FCV, slot-time timeout and retries)
//!   for an [`active::MasterApp`].

#[allow(unused_imports)]
use crate::prelude::*;
pub mod active;
pub mod autobaud;
pub mod echo;
pub mod passive;

mod rx;

pub use rx::RxPath;

use crate::time::Instant;

/// The byte-level interface between a sans-IO station and its driver.
pub trait Station {
    /// `bytes` arrived from the line; `now` is the time the last of them
    /// arrived.
    fn handle_rx(&mut self, now: Instant, bytes: &[u8]);

    /// Time has advanced to `now`. Drivers call this when
    /// [`Station::poll_timeout`] is due; extra calls are harmless.
    fn handle_timeout(&mut self, now: Instant);

    /// Bytes the station sends now, if any. The station considers them on
    /// the line once returned; the driver writes them at once.
    fn poll_transmit(&mut self, now: Instant) -> Option<&[u8]>;

    /// When the station next needs [`Station::handle_timeout`].
    fn poll_timeout(&self) -> Option<Instant>;

    /// Whether the station awaits an answer to what it sent last (a
    /// reply to its request, the first frame of its successor after a
    /// token pass): a driver may watch the line closely until it comes.
    fn awaits_answer(&self) -> bool {
        false
    }
}

impl<S: Station + ?Sized> Station for Box<S> {
    fn handle_rx(&mut self, now: Instant, bytes: &[u8]) {
        (**self).handle_rx(now, bytes)
    }
    fn handle_timeout(&mut self, now: Instant) {
        (**self).handle_timeout(now)
    }
    fn poll_transmit(&mut self, now: Instant) -> Option<&[u8]> {
        (**self).poll_transmit(now)
    }
    fn poll_timeout(&self) -> Option<Instant> {
        (**self).poll_timeout()
    }
    fn awaits_answer(&self) -> bool {
        (**self).awaits_answer()
    }
}

/// The earlier of two optional deadlines.
pub fn earliest(a: Option<Instant>, b: Option<Instant>) -> Option<Instant> {
    match (a, b) {
        (Some(x), Some(y)) => Some(x.min(y)),
        (x, None) => x,
        (None, y) => y,
    }
}
