//! Helpers for `#[serde(serialize_with = "…")]` (feature `serde`): the
//! shapes the JSON lines of `dpctl` use, shared by every crate that
//! derives `Serialize` on its events.

use crate::wire::Hex;
use core::fmt::Display;
use core::time::Duration;
use serde::Serializer;

/// Bytes as spaced hex text, `"01 0A FF"`.
pub fn hex<T: AsRef<[u8]> + ?Sized, S: Serializer>(bytes: &T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(&Hex(bytes.as_ref()))
}

/// Bytes as hex text without spaces, `"010AFF"`.
pub fn hex_compact<T: AsRef<[u8]> + ?Sized, S: Serializer>(
    bytes: &T,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.collect_str(&format_args!("{:#}", Hex(bytes.as_ref())))
}

/// Optional bytes as spaced hex text, or `null`.
pub fn opt_hex<T: AsRef<[u8]>, S: Serializer>(bytes: &Option<T>, s: S) -> Result<S::Ok, S::Error> {
    match bytes {
        Some(b) => hex(b, s),
        None => s.serialize_none(),
    }
}

/// A value as its `Display` text.
pub fn display<T: Display + ?Sized, S: Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(v)
}

/// A duration in whole milliseconds.
pub fn millis<S: Serializer>(d: &Duration, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_u64(d.as_millis() as u64)
}

/// An optional duration in whole milliseconds, or `null`.
pub fn opt_millis<S: Serializer>(d: &Option<Duration>, s: S) -> Result<S::Ok, S::Error> {
    match d {
        Some(d) => millis(d, s),
        None => s.serialize_none(),
    }
}

impl serde::Serialize for Hex<'_> {
    /// Spaced hex text, as `Display` shows it.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl serde::Serialize for crate::Instant {
    /// Seconds since the clock's start, as a float.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_f64(self.as_nanos() as f64 / 1e9)
    }
}

impl serde::Serialize for crate::Baud {
    /// Bits per second.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u32(self.bps())
    }
}

impl serde::Serialize for crate::StationType {
    /// The station type in words.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.describe())
    }
}
