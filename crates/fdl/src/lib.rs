//! `profibus-fdl`: PROFIBUS FDL, the data link layer (IEC 61158-4-3 /
//! EN 50170 part 2).
//!
//! How the parts fit:
//!
//! - [`wire`]: zero-copy telegram parsing and emitting (SD1/SD2/SD3, token,
//!   short acknowledge), FC decoding, FCS. No I/O, no allocation.
//! - [`codec`]: frames telegrams out of a byte stream that arrives in
//!   arbitrary fragments, resynchronises after garbage and counts errors;
//!   `FdlCodec` (feature `tokio-codec`, in the default `transport`) is the
//!   same framer as a tokio-util codec. With `default-features = false`
//!   the crate needs no async runtime at all.
//! - [`timing`]: baud rates, bus parameters (TSL, TSDR, TID1/TID2, TTR …)
//!   and the bit-time arithmetic every timer is built on.
//! - [`time`]: the [`time::Instant`] the sans-IO cores take as "now".
//! - [`station`]: sans-IO FDL stations behind the byte-level
//!   [`station::Station`] trait: the passive responder (DP slave side) and
//!   the active station (token ring, GAP, requester; DP master side).
//! - [`medium`]: a sans-IO model of the RS-485 line (broadcast, pacing at
//!   the baud rate, collisions, fault injection) shared by `dpctl bus` and
//!   the in-process simulator; `medium::MediumArgs` (feature `clap`) are
//!   its options as command-line flags.
//! - [`pcap`]: pcap files of telegrams (link type 257, PROFIBUS DL).
//! - `transport` (feature `transport`, on by default; tokio): serial
//!   ports and ptys as one async byte stream, `transport::Port`.
//! - [`tap`]: passive framing of a timed byte stream into telegrams and
//!   skipped bytes (bus monitors, pcap recording).
//! - `listen` (feature `transport`): the passive driver of bus monitors:
//!   reads a line (never writes) and hands the [`tap`]'s events on
//!   (`dpctl sniff`, `dpctl monitor`).
//! - [`rng`]: the small seeded generator behind fault injection.
//! - [`sim`]: the in-process simulated bus on virtual time (stations on a
//!   [`medium`]).
//! - `ser` (feature `serde`): helpers for `#[serde(serialize_with)]`
//!   (hex text, durations in ms, `Display` as a string); with the feature
//!   the events and counters of this crate implement `serde::Serialize`.
//! - `driver` (feature `transport`): the thin tokio shell that runs a
//!   station on a byte stream.
//! - `runner` (feature `transport`): a slave's station on a port with the
//!   baud-rate search (`autobaud`), searching again after silence or a
//!   lost master, rebuilding the station at the new rate.
//!
//! Protocol state machines above this layer are sans-IO: they take received
//! telegrams and the current time and return bytes to send and the next
//! deadline; thin tokio drivers connect them to a transport.

pub mod autobaud;
pub mod codec;
#[cfg(feature = "transport")]
pub mod driver;
#[cfg(feature = "transport")]
pub mod listen;
pub mod medium;
pub mod pcap;
pub mod rng;
#[cfg(feature = "transport")]
pub mod runner;
#[cfg(feature = "serde")]
pub mod ser;
pub mod sim;
pub mod station;
pub mod tap;
#[cfg(test)]
mod testing;
pub mod time;
pub mod timing;
#[cfg(feature = "transport")]
pub mod transport;
pub mod wire;

#[cfg(feature = "tokio-codec")]
pub use codec::FdlCodec;
pub use codec::{CodecStats, Framer, RawTelegram};
pub use time::Instant;
pub use timing::{Baud, BusParams};
pub use wire::{
    DataTelegram, FunctionCode, ParseError, RequestKind, ResponseStatus, StationType, Telegram,
};
