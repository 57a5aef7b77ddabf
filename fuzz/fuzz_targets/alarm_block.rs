//! Arbitrary bytes through the DP-V1 alarm/status block decoder
//! (`profibus_dp::pdu::alarm`) and the I&M parsers (`profibus_dp::pdu::im`).
//!
//! The bytes are read (1) as a run of device-related blocks with
//! `DiagBlock::parse`, (2) as an extended diagnosis with `dpv1_blocks`,
//! (3) as a call header followed by an I&M record. Checks besides no
//! panic: every block decoded consumes its header's length and at least 4
//! bytes; it emits, and what it emits decodes to the same block (an alarm
//! block to the very bytes it came from); its words and its Alarm_Ack can
//! be made; every Alarm_Specifier byte survives decoding and encoding; a
//! call header re-encodes to `08 00 FI_Index` and names I&M0..4 exactly
//! for 65000..=65004; I&M0 and I&M1..4 records re-encode to their 64
//! bytes; a software revision read from text prints back to itself.

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::pdu::alarm::{dpv1_blocks, AlarmMode, AlarmSpecifier, DiagBlock};
use profibus_dp::pdu::im::{CallHeader, Im0, ImRecord, ImSupported, SoftwareRevision, RECORD_LEN};

fn check_block(block: DiagBlock<'_>, raw: &[u8]) {
    let mut buf = [0u8; 64];
    let n = match block {
        DiagBlock::Alarm(a) => {
            assert!(!a.describe().is_empty());
            let _ = a.ack();
            let _ = a.alarm_type.word();
            let _ = a.alarm_type.enable();
            let n = a.emit(&mut buf).expect("a decoded alarm block emits");
            assert_eq!(&buf[..n], raw, "{a:?}");
            n
        }
        DiagBlock::Status(s) => s.emit(&mut buf).expect("a decoded status block emits"),
    };
    let (again, rest) = DiagBlock::parse(&buf[..n]).expect("an emitted block decodes");
    assert!(rest.is_empty());
    assert_eq!(again, block, "emitted {:02X?}", &buf[..n]);
}

fuzz_target!(|data: &[u8]| {
    // (1) A run of blocks.
    let mut rest = data;
    while !rest.is_empty() {
        match DiagBlock::parse(rest) {
            Ok((block, tail)) => {
                let used = rest.len() - tail.len();
                assert!(used >= 4 && used == (rest[0] & 0x3F) as usize);
                check_block(block, &rest[..used]);
                rest = tail;
            }
            Err(e) => {
                assert!(!e.to_string().is_empty());
                break;
            }
        }
    }
    // (2) As the extended diagnosis after the 6 standard bytes.
    for block in dpv1_blocks(data) {
        if let DiagBlock::Alarm(a) = block {
            let _ = a.describe();
        }
    }
    for &b in data.iter().take(8) {
        assert_eq!(AlarmSpecifier::from_byte(b).byte(), b);
        let _ = AlarmMode::from_status_3(b).limit();
    }
    // (3) I&M: call header, then a record.
    match CallHeader::parse(data) {
        Err(e) => assert!(!e.to_string().is_empty()),
        Ok((head, record)) => {
            assert_eq!(head.bytes(), [0x08, 0x00, data[2], data[3]]);
            let n = head.im_number();
            assert_eq!(n.is_some(), (65000..=65004).contains(&head.fi_index));
            if let Some(n) = n {
                assert_eq!(CallHeader::im(n), head);
            }
            match Im0::parse(record) {
                Ok(im0) => {
                    assert_eq!(&im0.bytes()[..], record);
                    let _ = (im0.order_id(), im0.serial_number());
                    let _ = im0.software_revision.to_string();
                    assert!(im0.im_supported.describe().contains("0x"));
                }
                Err(e) => assert!(record.len() != RECORD_LEN, "{e}"),
            }
            for number in 1..=4 {
                match ImRecord::parse(number, record) {
                    Ok(r) => {
                        assert_eq!(&r.bytes[..], record);
                        assert!(!r.fields().is_empty());
                    }
                    Err(e) => assert!(record.len() != RECORD_LEN, "{e}"),
                }
            }
        }
    }
    if data.len() >= 2 {
        let s = ImSupported(u16::from_be_bytes([data[0], data[1]]));
        let _ = s.describe();
    }
    let text = String::from_utf8_lossy(data);
    if let Some(r) = SoftwareRevision::parse(&text) {
        assert_eq!(SoftwareRevision::parse(&r.to_string()), Some(r), "{text:?}");
    }
});
