//! The pcap/pcapng reader: arbitrary files never panic and reading ends.
//!
//! Run: `cargo +nightly fuzz run pcap_read`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_fdl::capture::pcap::PcapReader;

fuzz_target!(|data: &[u8]| {
    if let Ok(r) = PcapReader::new(data) {
        for p in r {
            if p.is_err() {
                break;
            }
        }
    }
});
