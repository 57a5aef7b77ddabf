//! The capture reader: arbitrary files never panic and reading ends; the
//! sans-IO decoder (`profibus_fdl::capture::read`) fed the file in pieces
//! of 1–17 bytes (the first input byte) gives the same records and the
//! same error as fed it whole; the `Read`-based `PcapReader` reads to an
//! end or an error.
//!
//! Run: `cargo +nightly fuzz run pcap_read`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_fdl::capture::pcap::PcapReader;
use profibus_fdl::capture::read::{CaptureDecoder, ReadError, Record};

fn decode(file: &[u8], piece: usize) -> (Vec<Record>, Option<ReadError>) {
    let mut d = CaptureDecoder::new();
    let mut out = vec![];
    for p in file.chunks(piece) {
        d.push(p);
        loop {
            match d.next_record() {
                Ok(Some(r)) => out.push(r),
                Ok(None) => break,
                Err(e) => return (out, Some(e)),
            }
        }
    }
    (out, d.finish().err())
}

fuzz_target!(|data: &[u8]| {
    let Some((&k, file)) = data.split_first() else {
        return;
    };
    let whole = decode(file, file.len().max(1));
    let pieces = decode(file, k as usize % 17 + 1);
    assert_eq!(whole, pieces);
    if let Some(e) = &whole.1 {
        assert!(e.offset <= file.len() as u64);
    }
    if let Ok(r) = PcapReader::new(file) {
        for p in r {
            if p.is_err() {
                break;
            }
        }
    }
});
