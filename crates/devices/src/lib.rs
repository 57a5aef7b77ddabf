//! `profibus-devices`: device profiles.

pub mod generic;
