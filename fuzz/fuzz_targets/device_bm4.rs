//! The `bm4` device profile's slave device in the DP slave core:
//! Set_Prm, Chk_Cfg, Data_Exchange, MSAC_C1 and raw requests, and control
//! lines, in any order at any time (see `profibus_fuzz::run_device`).
//!
//! Run: `cd fuzz && cargo +nightly fuzz run device_bm4`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_fuzz::{cached, profile_fixture, run_device, Fixture};
use std::sync::OnceLock;

static FIXTURE: OnceLock<Fixture> = OnceLock::new();

fn fixture() -> Fixture {
    profile_fixture("bm4", "example = true")
}

fuzz_target!(|data: &[u8]| {
    run_device(cached(&FIXTURE, fixture), data);
});
