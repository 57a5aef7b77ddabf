//! Arbitrary bytes through both class-2 PDU parsers of
//! `profibus_dp::pdu::c2` (`C2Pdu::parse_request`, what a slave decodes;
//! `C2Pdu::parse_response`, what a master decodes).
//!
//! Input layout: byte 0 sizes a second, short output buffer; the rest is
//! the PDU. Checks besides no panic, for each parser: a decoded PDU names
//! the function byte it was decoded from; its words (`Debug`, abort and
//! negative-response texts) can be made; what it emits parses back to the
//! same PDU; it emits nothing only when it came from more than 244 bytes
//! (the most a PDU carries); into a buffer shorter than its encoding it
//! emits nothing, into one just long enough the same bytes.

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::pdu::c2::{C2ParseError, C2Pdu};

/// The largest encoding: an Initiate with two 255-byte address blocks.
const BIG: usize = 16 + 2 * 255;

/// The slave's parser (requests) or the master's (responses).
fn parse(response: bool, du: &[u8]) -> Result<C2Pdu<'_>, C2ParseError> {
    if response {
        C2Pdu::parse_response(du)
    } else {
        C2Pdu::parse_request(du)
    }
}

fn check(sel: u8, du: &[u8], response: bool) {
    let pdu = match parse(response, du) {
        Ok(p) => p,
        Err(e) => {
            assert!(!e.to_string().is_empty());
            return;
        }
    };
    assert_eq!(pdu.function(), du[0], "{pdu:?} from {du:02X?}");
    let _ = format!("{pdu:?}");
    match pdu {
        C2Pdu::Abort(a) => {
            assert!(!a.describe().is_empty());
            let _ = a.msac_c2_reason();
        }
        C2Pdu::Error(e) => assert!(!e.describe().is_empty()),
        _ => {}
    }
    let mut buf = [0u8; BIG];
    let Some(n) = pdu.emit(&mut buf) else {
        assert!(
            du.len() > 244,
            "{pdu:?} from {} bytes emits nothing",
            du.len()
        );
        return;
    };
    assert!(n <= BIG);
    let again = parse(response, &buf[..n])
        .unwrap_or_else(|e| panic!("{pdu:?} emitted {:02X?}: {e}", &buf[..n]));
    assert_eq!(again, pdu, "emitted {:02X?}", &buf[..n]);
    let cap = sel as usize % (n + 1);
    let mut short = vec![0u8; cap];
    match pdu.emit(&mut short) {
        None => assert!(cap < n, "{pdu:?}: nothing into {cap} bytes, needs {n}"),
        Some(m) => {
            assert_eq!((m, cap), (n, n), "{pdu:?} into {cap} bytes");
            assert_eq!(&short[..], &buf[..n]);
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&sel, du)) = data.split_first() else {
        return;
    };
    if du.is_empty() {
        assert_eq!(C2Pdu::parse_request(du), Err(C2ParseError::Empty));
        assert_eq!(C2Pdu::parse_response(du), Err(C2ParseError::Empty));
        return;
    }
    check(sel, du, false);
    check(sel, du, true);
});
