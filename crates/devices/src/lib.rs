//! `profibus-devices`: device profiles.
