//! The RS-485 line: [`medium`], a sans-IO model of the shared medium
//! (broadcast, pacing at the baud rate, collisions, fault injection), and
//! [`tap`], the passive framing of a timed byte stream into telegrams and
//! skipped bytes (bus monitors, recording).

pub mod medium;
pub mod tap;
