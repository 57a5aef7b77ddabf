//! `profibus-fdl`: PROFIBUS FDL, the data link layer (IEC 61158-4-3 /
//! EN 50170 part 2), sans-IO.
//!
//! How the parts fit (the path names the layer):
//!
//! - [`wire`]: zero-copy telegram parsing and emitting (SD1/SD2/SD3, token,
//!   short acknowledge), FC decoding, FCS. No I/O, no allocation.
//! - [`codec`]: frames telegrams out of a byte stream that arrives in
//!   arbitrary fragments, resynchronises after garbage and counts errors.
//! - [`timing`]: baud rates, bus parameters (TSL, TSDR, TID1/TID2, TTR …)
//!   and the bit-time arithmetic every timer is built on.
//! - [`time`]: the [`time::Instant`] the sans-IO cores take as "now".
//! - [`station`]: sans-IO FDL stations behind the byte-level
//!   [`station::Station`] trait: the passive responder (DP slave side), the
//!   active station (token ring, GAP, requester; DP master side) and the
//!   baud-rate search of a passive station ([`station::autobaud`]).
//! - [`line`](mod@line): the RS-485 line: [`line::medium`], a sans-IO model of the
//!   medium (broadcast, pacing at the baud rate, collisions, fault
//!   injection) shared by the virtual bus and the simulator, and
//!   [`line::tap`], passive framing of a timed byte stream into telegrams
//!   and skipped bytes (bus monitors).
//! - [`sim`]: the in-process simulated bus on virtual time (stations on a
//!   medium).
//! - [`capture`] (feature `std`): pcap files of telegrams (link type 257,
//!   PROFIBUS DL).
//! - [`rng`]: the small seeded generator behind fault injection.
//! - `ser` (feature `serde`): helpers for `#[serde(serialize_with)]`
//!   (hex text, durations in ms, `Display` as a string); with the feature
//!   the events and counters of this crate implement `serde::Serialize`.
//!
//! Nothing here does I/O or reads a clock: a core takes received bytes
//! and the current time and returns bytes to send, the next deadline and
//! events. The tokio drivers, serial ports, ptys and the virtual bus hub
//! are in the `profibus-io` crate.
//!
//! # `no_std`
//!
//! Without the default feature `std` the crate is `#![no_std]` and needs
//! only `alloc` (stations keep their telegrams in `Vec`s). Porting a DP
//! slave to a microcontroller UART then needs, besides a global
//! allocator:
//!
//! - a time source that yields [`time::Instant`] (nanoseconds since any
//!   fixed point; a free-running timer is enough);
//! - a UART driver at one of the [`timing::Baud`] rates with 11-bit
//!   characters (8 data bits, even parity, 1 stop bit) and an RS-485
//!   driver-enable line, switched on while the station's bytes go out;
//! - a loop that feeds received bytes and the time to the station
//!   ([`station::Station`]), writes what it returns, and wakes again at
//!   its deadline (at the latest);
//! - for a `tracing` subscriber, none: without one the log calls cost
//!   nothing.
//!
//! `capture` (pcap files) and the wall-clock seed of the medium's fault
//! injection need `std`.

#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]

extern crate alloc;

/// What `std`'s prelude would bring, from `alloc` (the crate is `no_std`
/// without the feature `std`).
#[allow(unused_imports)]
mod prelude {
    pub(crate) use alloc::borrow::ToOwned;
    pub(crate) use alloc::boxed::Box;
    pub(crate) use alloc::format;
    pub(crate) use alloc::string::{String, ToString};
    pub(crate) use alloc::vec;
    pub(crate) use alloc::vec::Vec;
}

#[cfg(feature = "std")]
pub mod capture;
pub mod codec;
pub mod line;
mod math;
pub mod rng;
#[cfg(feature = "serde")]
pub mod ser;
pub mod sim;
pub mod station;
#[cfg(test)]
mod testing;
pub mod time;
pub mod timing;
pub mod wire;

pub use codec::{CodecStats, Framer, RawTelegram};
pub use time::Instant;
pub use timing::{Baud, BusParams};
pub use wire::{
    DataTelegram, FunctionCode, ParseError, RequestKind, ResponseStatus, StationType, Telegram,
};
