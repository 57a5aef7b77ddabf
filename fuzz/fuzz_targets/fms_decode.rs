//! Arbitrary bytes through the FMS telegram decoder of `dpctl sniff`
//! (`profibus_dp::fms::decode::describe`) and the stream decoder that
//! tells FMS from DP (`Exchanges::decode_layer`).
//!
//! The first byte picks the direction (bit 0: request) and the slave's
//! SAP (bits 1..: SAP 0..=63); the rest is the data unit. Checks besides
//! no panic: the line is never empty; a data unit the LLI parser takes is
//! never `malformed` and one it refuses always is, with its reason; an
//! FMS PDU inside names its `pdu`; the stream decoder calls an SRD on a
//! connection SAP FMS exactly when the data unit starts with an LLI or
//! FMS type octet, and never on a DP SAP.

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::fms::decode::{describe, starts_lli_pdu};
use profibus_dp::fms::lli::LliPdu;
use profibus_dp::pdu::decode::{Exchanges, Layer};
use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus, Telegram};

fuzz_target!(|data: &[u8]| {
    let Some((&head, du)) = data.split_first() else {
        return;
    };
    let request = head & 1 != 0;
    let sap = (head >> 1) & 0x3F;
    let t = describe(du, request);
    assert!(!t.to_string().is_empty());
    match LliPdu::parse(du) {
        _ if du.is_empty() => assert_eq!(t.lli, if request { "poll" } else { "empty" }),
        Ok(p) => {
            assert_ne!(t.lli, "malformed", "{p:?}");
            assert!(t.is_ok());
            let carries_fms = !matches!(p, LliPdu::Abort { .. } | LliPdu::Idle);
            assert_eq!(t.pdu.is_some(), carries_fms, "{p:?}: {t}");
        }
        Err(e) => {
            assert_eq!(t.lli, "malformed");
            assert_eq!(t.error, Some(e.to_string()));
            assert!(t.to_string().starts_with("FMS malformed: "));
        }
    }
    // The same data unit on the wire: SRD low from station 3 (LSAP 33)
    // to station 5 on `sap`, or its answer.
    if du.len() > 244 {
        return;
    }
    let fc = if request {
        FunctionCode::Request {
            kind: RequestKind::SrdLow,
            fcb: false,
            fcv: false,
        }
    } else {
        FunctionCode::slave_response(ResponseStatus::Dl)
    };
    let (da, sa, dsap, ssap) = if request {
        (5, 3, sap, 33)
    } else {
        (3, 5, 33, sap)
    };
    let tg = Telegram::Data(DataTelegram::new(da, sa, fc, du).with_saps(Some(dsap), Some(ssap)));
    let layer = Exchanges::default().decode_layer(&tg);
    let fms = matches!(layer, Some(Layer::Fms(_)));
    assert_eq!(
        fms,
        sap <= 48 && starts_lli_pdu(du),
        "SAP {sap} {du:02X?}: {layer:?}"
    );
});
