//! Arbitrary bytes through the FMS PDU parser of
//! `profibus_dp::fms::pdu` (`FmsPdu::parse`, what both an FMS client and
//! server decode).
//!
//! Checks besides no panic: an error has words; a decoded PDU names the
//! type octet it came from, can be described, and what it encodes parses
//! back to the same PDU within `MAX_PDU_LEN` bytes.

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::fms::pdu::{FmsPdu, MAX_PDU_LEN};

fuzz_target!(|data: &[u8]| {
    let pdu = match FmsPdu::parse(data) {
        Ok(p) => p,
        Err(e) => {
            assert!(!e.to_string().is_empty());
            return;
        }
    };
    assert_eq!(pdu.pdu_type() as u8, data[0], "{pdu:?} from {data:02X?}");
    assert!(!pdu.describe().is_empty());
    let bytes = pdu
        .to_vec()
        .unwrap_or_else(|| panic!("{pdu:?} from {} bytes encodes to nothing", data.len()));
    assert!(bytes.len() <= MAX_PDU_LEN);
    let again = FmsPdu::parse(&bytes).unwrap_or_else(|e| panic!("{pdu:?} -> {bytes:02X?}: {e}"));
    assert_eq!(again, pdu, "encoded {bytes:02X?}");
});
