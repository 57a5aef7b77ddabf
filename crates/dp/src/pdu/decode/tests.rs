//! Telegrams written byte by byte from the standard's layouts
//! (IEC 61158-4-3 frames; IEC 61158-6-3 data units; the examples of
//! /work/shared/reference/profibus-dp.md), never by our encoder. Master 2,
//! slave 8; FCS = sum of DA … DU modulo 256.

use super::*;

const DIAG_REQ: [u8; 11] = [
    0x68, 0x05, 0x05, 0x68, 0x88, 0x82, 0x6D, 0x3C, 0x3E, 0xF1, 0x16,
];
/// Station_Not_Ready, Prm_Req, no master, ident 0x0ED0.
const DIAG_RES: [u8; 17] = [
    0x68, 0x0B, 0x0B, 0x68, 0x82, 0x88, 0x08, 0x3E, 0x3C, 0x02, 0x05, 0x00, 0xFF, 0x0E, 0xD0, 0x70,
    0x16,
];
/// Ext_Diag, WD_On, master 2; an identifier-related block (modules 0
/// and 2) and a channel-related block (module 1, channel 1, input, wire
/// break).
const DIAG_RES_EXT: [u8; 22] = [
    0x68, 0x10, 0x10, 0x68, 0x82, 0x88, 0x08, 0x3E, 0x3C, 0x08, 0x0C, 0x00, 0x02, 0x0E, 0xD0, 0x42,
    0x05, 0x81, 0x41, 0x06, 0x8F, 0x16,
];
/// The reference's Set_Prm example [TR19]: Lock+Sync+Freeze+WD_On,
/// 30·1·10 ms, ident 0x0A35, group 1, DPV1 bytes 0, 4 user bytes.
const PRM: [u8; 25] = [
    0x68, 0x13, 0x13, 0x68, 0x88, 0x82, 0x5D, 0x3D, 0x3E, 0xB8, 0x1E, 0x01, 0x00, 0x0A, 0x35, 0x01,
    0x00, 0x00, 0x00, 0x82, 0x00, 0x00, 0x00, 0x7B, 0x16,
];
/// WD_On, 10·10 with DPV1_Enable and WD_Base_1ms: 100 ms; min TSDR 11.
const PRM_DPV1: [u8; 21] = [
    0x68, 0x0F, 0x0F, 0x68, 0x88, 0x82, 0x7D, 0x3D, 0x3E, 0x08, 0x0A, 0x0A, 0x0B, 0x0E, 0xD0, 0x00,
    0x84, 0x00, 0x00, 0x8B, 0x16,
];
/// Chk_Cfg: the BM4 example (42 C1 02 04, 82 C0 01 03), special format
/// out+in (C0 51 51), F9 and a free place.
const CHK_CFG: [u8; 24] = [
    0x68, 0x12, 0x12, 0x68, 0x88, 0x82, 0x7D, 0x3E, 0x3E, 0x42, 0xC1, 0x02, 0x04, 0x82, 0xC0, 0x01,
    0x03, 0xC0, 0x51, 0x51, 0xF9, 0x00, 0xAD, 0x16,
];
const GET_CFG_REQ: [u8; 11] = [
    0x68, 0x05, 0x05, 0x68, 0x88, 0x82, 0x5D, 0x3B, 0x3E, 0xE0, 0x16,
];
/// [TR26]: a free place, 1 byte in, 1 byte out.
const GET_CFG_RES: [u8; 14] = [
    0x68, 0x08, 0x08, 0x68, 0x82, 0x88, 0x08, 0x3E, 0x3B, 0x00, 0x10, 0x20, 0xBB, 0x16,
];
const DX_REQ: [u8; 11] = [
    0x68, 0x05, 0x05, 0x68, 0x08, 0x02, 0x7D, 0xAA, 0xBB, 0xEC, 0x16,
];
/// DH: inputs 42 and new diagnosis.
const DX_RES_DH: [u8; 10] = [0x68, 0x04, 0x04, 0x68, 0x02, 0x08, 0x0A, 0x42, 0x56, 0x16];
/// SD1 Data_Exchange without outputs.
const DX_REQ_EMPTY: [u8; 6] = [0x10, 0x08, 0x02, 0x5D, 0x67, 0x16];
const SC: [u8; 1] = [0xE5];
/// SDN high to 127: Clear_Data to groups 1 and 2.
const GLOBAL_CONTROL: [u8; 13] = [
    0x68, 0x07, 0x07, 0x68, 0xFF, 0x82, 0x46, 0x3A, 0x3E, 0x02, 0x03, 0x44, 0x16,
];
const SET_SLAVE_ADD: [u8; 15] = [
    0x68, 0x09, 0x09, 0x68, 0x88, 0x82, 0x6D, 0x37, 0x3E, 0x05, 0x0E, 0xD0, 0x00, 0xCF, 0x16,
];
/// MSAC_C1 Read slot 1 index 2, 16 bytes.
const READ_REQ: [u8; 15] = [
    0x68, 0x09, 0x09, 0x68, 0x88, 0x82, 0x6D, 0x33, 0x33, 0x5E, 0x01, 0x02, 0x10, 0x4E, 0x16,
];
const POLL: [u8; 11] = [
    0x68, 0x05, 0x05, 0x68, 0x88, 0x82, 0x5D, 0x33, 0x33, 0xCD, 0x16,
];
const READ_RES: [u8; 17] = [
    0x68, 0x0B, 0x0B, 0x68, 0x82, 0x88, 0x08, 0x33, 0x33, 0x5E, 0x01, 0x02, 0x02, 0xAB, 0xCD, 0x53,
    0x16,
];
/// Read error: DP-V1, class B code 0 (invalid index).
const READ_ERR: [u8; 15] = [
    0x68, 0x09, 0x09, 0x68, 0x82, 0x88, 0x08, 0x33, 0x33, 0xDE, 0x80, 0xB0, 0x00, 0x86, 0x16,
];
/// A diagnosis answered without SAPs (home-made slaves do that).
const DIAG_RES_NO_SAPS: [u8; 15] = [
    0x68, 0x09, 0x09, 0x68, 0x02, 0x08, 0x08, 0x02, 0x05, 0x00, 0xFF, 0x0E, 0xD0, 0xF6, 0x16,
];
const FDL_STATUS: [u8; 6] = [0x10, 0x08, 0x02, 0x49, 0x53, 0x16];
const TOKEN: [u8; 3] = [0xDC, 0x08, 0x02];

fn tg(bytes: &[u8]) -> Telegram<'_> {
    let (t, n) = Telegram::parse(bytes).expect("a valid telegram");
    assert_eq!(n, bytes.len());
    t
}

fn detail(ex: &mut Exchanges, bytes: &[u8]) -> (&'static str, &'static str, Option<Detail>) {
    let dp = ex.decode(&tg(bytes)).expect("a DP telegram");
    (dp.service, dp.direction, dp.detail)
}

#[test]
fn slave_diag_request_and_response() {
    let mut ex = Exchanges::default();
    assert_eq!(detail(&mut ex, &DIAG_REQ), ("Slave_Diag", "request", None));
    let (service, dir, d) = detail(&mut ex, &DIAG_RES);
    assert_eq!((service, dir), ("Slave_Diag", "response"));
    assert_eq!(
        d,
        Some(Detail::SlaveDiag {
            status: vec!["Station_Not_Ready".into(), "Prm_Req".into()],
            master_address: None,
            ident_number: 0x0ED0,
            ext_diag: vec![],
            valid: true,
            alarms: vec![],
        })
    );
    let Some(Detail::SlaveDiag {
        status,
        master_address,
        ext_diag,
        ..
    }) = detail(&mut ex, &DIAG_RES_EXT).2
    else {
        panic!()
    };
    assert_eq!(status, ["Ext_Diag", "WD_On"]);
    assert_eq!(master_address, Some(2));
    assert_eq!(ext_diag.len(), 2, "{ext_diag:?}");
    assert!(ext_diag[0].contains("module"), "{ext_diag:?}");
    assert!(ext_diag[1].contains("channel 1"), "{ext_diag:?}");
}

#[test]
fn set_prm_of_the_standard_example() {
    let mut ex = Exchanges::default();
    assert_eq!(
        detail(&mut ex, &PRM),
        (
            "Set_Prm",
            "request",
            Some(Detail::SetPrm {
                station_status: vec!["Lock_Req", "Sync_Req", "Freeze_Req", "WD_On"],
                dpv1_status: vec![],
                watchdog_ms: Some(300),
                min_tsdr: 0,
                ident_number: 0x0A35,
                groups: vec![1],
                user_prm_data: vec![0, 0, 0, 0x82, 0, 0, 0],
            })
        )
    );
    // Its short acknowledge is the Set_Prm's response.
    assert_eq!(detail(&mut ex, &SC), ("Set_Prm", "response", None));
    let dp = ex.decode(&Telegram::parse(&PRM_DPV1).unwrap().0).unwrap();
    let Some(Detail::SetPrm {
        watchdog_ms,
        min_tsdr,
        ref groups,
        ref dpv1_status,
        ..
    }) = dp.detail
    else {
        panic!()
    };
    assert_eq!(
        (watchdog_ms, min_tsdr, groups.clone()),
        (Some(100), 11, vec![])
    );
    assert!(dpv1_status.starts_with(&["DPV1_Enable"]), "{dpv1_status:?}");
    // In words, as `dpctl sniff` prints it.
    let words = dp.to_string();
    assert!(
        words.starts_with("Set_Prm request: WD_On; watchdog 100 ms; min TSDR 11; ident 0x"),
        "{words}"
    );
    assert!(words.contains("; DPV1 DPV1_Enable"), "{words}");
}

#[test]
fn chk_cfg_and_get_cfg_identifiers() {
    let mut ex = Exchanges::default();
    let Some(Detail::Cfg {
        identifiers,
        input_bytes,
        output_bytes,
        error,
    }) = detail(&mut ex, &CHK_CFG).2
    else {
        panic!()
    };
    let got: Vec<(Vec<u8>, &str, usize, usize)> = identifiers
        .iter()
        .map(|i| {
            (
                i.raw.clone(),
                i.text.as_str(),
                i.input_bytes,
                i.output_bytes,
            )
        })
        .collect();
    assert_eq!(
        got,
        [
            (
                vec![0x42, 0xC1, 0x02, 0x04],
                "2 words (consistent) in; manufacturer bytes 02 04",
                4,
                0
            ),
            (
                vec![0x82, 0xC0, 0x01, 0x03],
                "1 word (consistent) out; manufacturer bytes 01 03",
                0,
                2
            ),
            (vec![0xC0, 0x51, 0x51], "18 words out + 18 words in", 36, 36),
            (vec![0xF9], "10 words (consistent) in+out", 20, 20),
            (vec![0x00], "empty slot", 0, 0),
        ]
    );
    assert_eq!((input_bytes, output_bytes, error), (60, 58, None));
    assert_eq!(detail(&mut ex, &SC), ("Chk_Cfg", "response", None));
    assert_eq!(detail(&mut ex, &GET_CFG_REQ), ("Get_Cfg", "request", None));
    let Some(Detail::Cfg { identifiers, .. }) = detail(&mut ex, &GET_CFG_RES).2 else {
        panic!()
    };
    let texts: Vec<&str> = identifiers.iter().map(|i| i.text.as_str()).collect();
    assert_eq!(texts, ["empty slot", "1 byte in", "1 byte out"]);
}

#[test]
fn data_exchange_global_control_and_set_slave_add() {
    let mut ex = Exchanges::default();
    assert_eq!(
        detail(&mut ex, &DX_REQ),
        (
            "Data_Exchange",
            "request",
            Some(Detail::Outputs {
                outputs: vec![0xAA, 0xBB],
                modules: vec![],
            })
        )
    );
    assert_eq!(
        detail(&mut ex, &DX_RES_DH),
        (
            "Data_Exchange",
            "response",
            Some(Detail::Inputs {
                inputs: vec![0x42],
                new_diag: true,
                modules: vec![],
            })
        )
    );
    // A slave without inputs answers with a short acknowledge.
    assert_eq!(detail(&mut ex, &DX_REQ_EMPTY).0, "Data_Exchange");
    assert_eq!(detail(&mut ex, &SC), ("Data_Exchange", "response", None));
    assert_eq!(
        detail(&mut ex, &GLOBAL_CONTROL),
        (
            "Global_Control",
            "request",
            Some(Detail::GlobalControl {
                command: vec!["Clear_Data"],
                groups: vec![1, 2]
            })
        )
    );
    assert_eq!(
        detail(&mut ex, &SET_SLAVE_ADD).2,
        Some(Detail::SetSlaveAdd {
            new_address: 5,
            ident_number: 0x0ED0,
            no_add_chg: false
        })
    );
}

#[test]
fn dpv1_read_poll_and_error() {
    let mut ex = Exchanges::default();
    let dpv1 = |pdu, slot, index, length, data: Option<Vec<u8>>, error: Option<&str>| {
        Some(Detail::Dpv1 {
            pdu,
            slot,
            index,
            length,
            data,
            error: error.map(String::from),
            text: None,
        })
    };
    assert_eq!(
        detail(&mut ex, &READ_REQ),
        (
            "MSAC_C1",
            "request",
            dpv1("Read", Some(1), Some(2), Some(16), None, None)
        )
    );
    assert_eq!(detail(&mut ex, &SC), ("MSAC_C1", "response", None));
    assert_eq!(
        detail(&mut ex, &POLL).2,
        dpv1("Poll", None, None, None, None, None)
    );
    assert_eq!(
        detail(&mut ex, &READ_RES).2,
        dpv1(
            "Read",
            Some(1),
            Some(2),
            Some(2),
            Some(vec![0xAB, 0xCD]),
            None
        )
    );
    let Some(Detail::Dpv1 { pdu, error, .. }) = detail(&mut ex, &READ_ERR).2 else {
        panic!()
    };
    assert_eq!(pdu, "Error");
    assert!(error.unwrap().contains("invalid index"));
}

#[test]
fn a_response_follows_the_request_it_answers() {
    // Without SAPs, a diagnosis answer is read as the Slave_Diag it
    // answers …
    let mut ex = Exchanges::default();
    detail(&mut ex, &DIAG_REQ);
    let (service, _, d) = detail(&mut ex, &DIAG_RES_NO_SAPS);
    assert_eq!(service, "Slave_Diag");
    assert!(matches!(
        d,
        Some(Detail::SlaveDiag {
            ident_number: 0x0ED0,
            ..
        })
    ));
    // … and without a request, as Data_Exchange inputs.
    let d = decode(&tg(&DIAG_RES_NO_SAPS), None).unwrap();
    assert_eq!(d.service, "Data_Exchange");
    // A token ends the exchange: a short acknowledge after it answers
    // nothing known.
    detail(&mut ex, &PRM);
    assert_eq!(ex.decode(&tg(&TOKEN)), None);
    assert_eq!(ex.decode(&tg(&SC)), None);
    // FDL status is no DP telegram.
    assert_eq!(ex.decode(&tg(&FDL_STATUS)), None);
}

#[cfg(feature = "serde")]
#[test]
fn serialises_flat_under_its_service() {
    let mut ex = Exchanges::default();
    let j = |ex: &mut Exchanges, b: &[u8]| serde_json::to_value(ex.decode(&tg(b))).unwrap();
    let v = j(&mut ex, &PRM);
    assert_eq!(v["service"], "Set_Prm");
    assert_eq!(v["ident_number"], 0x0A35);
    assert_eq!(v["watchdog_ms"], 300);
    assert_eq!(v["groups"], serde_json::json!([1]));
    assert_eq!(v["user_prm_data"], "00 00 00 82 00 00 00");
    let v = j(&mut ex, &SC);
    assert_eq!(
        v,
        serde_json::json!({"service": "Set_Prm", "direction": "response"})
    );
    let v = j(&mut ex, &CHK_CFG);
    assert_eq!(v["identifiers"][3]["text"], "10 words (consistent) in+out");
    assert_eq!(v["identifiers"][3]["raw"], "F9");
    j(&mut ex, &DIAG_REQ);
    let v = j(&mut ex, &DIAG_RES);
    assert_eq!(
        v["status"],
        serde_json::json!(["Station_Not_Ready", "Prm_Req"])
    );
    assert_eq!(v["master_address"], serde_json::Value::Null);
    assert_eq!(v["ident_number"], 0x0ED0);
}

proptest::proptest! {
    /// Any telegram, with any request before it, decodes without panic.
    #[test]
    fn any_telegram_decodes_without_panic(
        req in proptest::collection::vec(proptest::num::u8::ANY, 0..40),
        du in proptest::collection::vec(proptest::num::u8::ANY, 0..40),
        dsap in proptest::option::of(0u8..64),
        resp in proptest::bool::ANY,
    ) {
        let mut ex = Exchanges::default();
        let fc = if resp {
            FunctionCode::slave_response(ResponseStatus::Dl)
        } else {
            FunctionCode::Request { kind: RequestKind::SrdHigh, fcb: true, fcv: true }
        };
        let saps = dsap.map(|s| (s, crate::pdu::sap::MASTER));
        let t = DataTelegram::new(8, 2, FunctionCode::Request {
            kind: RequestKind::SrdHigh, fcb: false, fcv: true,
        }, &req).with_saps(dsap, saps.map(|s| s.1));
        ex.decode(&Telegram::Data(t));
        let t = DataTelegram::new(2, 8, fc, &du).with_saps(saps.map(|s| s.1), dsap);
        let _ = ex.decode(&Telegram::Data(t));
        let _ = ex.decode(&Telegram::ShortAck);
    }
}

/// An SD2 frame `68 L L 68 DA SA FC DSAP SSAP DU FCS 16` with the SAP
/// extension bits set; FCS = sum of DA … DU modulo 256 (IEC 61158-4-3).
fn sd2(da: u8, sa: u8, fc: u8, dsap: u8, ssap: u8, du: &[u8]) -> Vec<u8> {
    let mut body = vec![da | 0x80, sa | 0x80, fc, dsap, ssap];
    body.extend_from_slice(du);
    let l = body.len() as u8;
    let fcs = body.iter().fold(0u8, |a, b| a.wrapping_add(*b));
    let mut t = vec![0x68, l, l, 0x68];
    t.extend(body);
    t.extend([fcs, 0x16]);
    t
}

fn text_of(ex: &mut Exchanges, t: &[u8]) -> (&'static str, Option<String>, Option<String>) {
    let (t, _) = Telegram::parse(t).unwrap();
    match ex.decode(&t).unwrap() {
        DpTelegram {
            detail: Some(Detail::Dpv1 {
                pdu, text, error, ..
            }),
            ..
        } => (pdu, text, error),
        other => panic!("{other:?}"),
    }
}

#[test]
fn class_2_connection_and_im0() {
    let mut ex = Exchanges::default();
    // Initiate.req of the reference (Send_Timeout 1 s) to the RM on SAP 49.
    let init = [
        0x57, 0, 0, 0, 0x00, 0x64, 0x01, 0, 0, 0, 0, 0, 0, 2, 0, 2, 0, 0, 0, 0,
    ];
    let (pdu, text, _) = text_of(&mut ex, &sd2(8, 2, 0x6D, 49, 50, &init));
    assert_eq!(pdu, "Initiate");
    assert_eq!(
        text.unwrap(),
        "Send_Timeout 1000 ms, features 0x0100, profile 0x0000"
    );
    let (pdu, text, _) = text_of(&mut ex, &sd2(2, 8, 0x08, 50, 49, &[0x56, 0x30, 0x00, 0x64]));
    assert_eq!(pdu, "Resource_Manager");
    assert_eq!(text.unwrap(), "connection SAP 48, Poll_Timeout 100");
    // Write the I&M0 call header on slot 0 index 255, then the answer.
    let call = [0x5F, 0x00, 0xFF, 0x04, 0x08, 0x00, 0xFD, 0xE8];
    let (pdu, text, _) = text_of(&mut ex, &sd2(8, 2, 0x7D, 48, 50, &call));
    assert_eq!((pdu, text.as_deref()), ("Write", Some("I&M0 call")));
    let mut res = vec![0x5E, 0x00, 0xFF, 0x44, 0x08, 0x00, 0xFD, 0xE8];
    let mut im0 = [b' '; 64];
    im0[10..12].copy_from_slice(&[0x01, 0x1E]);
    im0[12..19].copy_from_slice(b"6ES7-XY");
    im0[48..50].copy_from_slice(&[0, 3]);
    im0[50..54].copy_from_slice(&[b'V', 2, 1, 0]);
    im0[62..64].copy_from_slice(&[0x00, 0x02]);
    res.extend_from_slice(&im0);
    let (pdu, text, _) = text_of(&mut ex, &sd2(2, 8, 0x08, 50, 48, &res));
    assert_eq!(pdu, "Read");
    assert_eq!(
        text.unwrap(),
        "I&M0 call: manufacturer 286, order \"6ES7-XY\", serial \"\", hardware 3, \
         software V2.1.0, I&M1 (0x0002)"
    );
    // Abort by the MSAC_C2 instance, reason TO; a negative Data_Transport.
    let (pdu, text, _) = text_of(&mut ex, &sd2(8, 2, 0x6D, 48, 50, &[0x58, 0, 0x13, 0]));
    assert_eq!(pdu, "Abort");
    assert_eq!(text.unwrap(), "aborted by MSAC_C2: connection timeout (TO)");
    let (pdu, _, error) = text_of(&mut ex, &sd2(2, 8, 0x08, 50, 48, &[0xD1, 0x80, 0xA9, 0]));
    assert_eq!(pdu, "Error");
    assert!(error
        .unwrap()
        .starts_with("data transport failed: application: feature not supported"));
}

#[test]
fn alarm_blocks_of_a_dpv1_slave() {
    let mut ex = Exchanges::default();
    // Ext_Diag, master 2, ident 0x0ED0, a diagnostic alarm slot 2 seq 1
    // appears with 3 bytes of data.
    let du = [
        0x08, 0x0C, 0x00, 0x02, 0x0E, 0xD0, 0x07, 0x01, 0x02, 0x09, 0xAA, 0xBB, 0xCC,
    ];
    let res = sd2(2, 8, 0x08, 62, 60, &du);
    let alarms = |ex: &mut Exchanges| {
        detail(ex, &DIAG_REQ);
        let (t, _) = Telegram::parse(&res).unwrap();
        match ex.decode(&t).unwrap().detail {
            Some(Detail::SlaveDiag { alarms, .. }) => alarms,
            other => panic!("{other:?}"),
        }
    };
    // Before a DP-V1 Set_Prm the block is plain device diagnosis.
    assert!(alarms(&mut ex).is_empty());
    detail(&mut ex, &PRM_DPV1);
    let a = alarms(&mut ex);
    assert_eq!(
        a,
        vec![AlarmInfo {
            alarm_type: "diagnostic",
            type_code: 1,
            slot: 2,
            specifier: "appears",
            seq: 1,
            add_ack: false,
            data: vec![0xAA, 0xBB, 0xCC],
        }]
    );
    // An Alarm_Ack to SAP 50 from SAP 51.
    let (pdu, _, _) = text_of(&mut ex, &sd2(8, 2, 0x6D, 50, 51, &[0x5C, 2, 1, 0x09]));
    assert_eq!(pdu, "Alarm_Ack");
}

/// Bytes of a data telegram master 2 → slave 8 (request) or back.
fn tel(request: bool, sap: Option<u8>, du: &[u8]) -> Vec<u8> {
    use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus};
    let (da, sa, fc) = if request {
        let fc = FunctionCode::Request {
            kind: RequestKind::SrdHigh,
            fcb: true,
            fcv: true,
        };
        (8, 2, fc)
    } else {
        (2, 8, FunctionCode::slave_response(ResponseStatus::Dl))
    };
    let saps = sap.map(|s| {
        if request {
            (s, sap::MASTER)
        } else {
            (sap::MASTER, s)
        }
    });
    let (dsap, ssap) = saps.unzip();
    Telegram::Data(DataTelegram::new(da, sa, fc, du).with_saps(dsap, ssap))
        .to_vec()
        .unwrap()
}

#[test]
fn data_exchange_split_by_the_modules_of_the_chk_cfg_seen() {
    let mut ex = Exchanges::default();
    // Chk_Cfg: 1 byte in (0x10), 2 words in+out (0x71), 1 byte out (0x20).
    detail(&mut ex, &tel(true, Some(sap::CHK_CFG), &[0x10, 0x71, 0x20]));
    let (_, _, out) = detail(&mut ex, &tel(true, None, &[1, 2, 3, 4, 5]));
    let Some(Detail::Outputs { modules, .. }) = out else {
        panic!("{out:?}")
    };
    let got: Vec<(usize, &str, &[u8])> = modules
        .iter()
        .map(|m| (m.slot, m.name.as_str(), m.data.as_slice()))
        .collect();
    assert_eq!(
        got,
        [
            (2, "2 words in+out", &[1, 2, 3, 4][..]),
            (3, "1 byte out", &[5][..])
        ]
    );
    let dp = ex.decode(&tg(&tel(false, None, &[9, 8, 7, 6, 5]))).unwrap();
    let Some(Detail::Inputs { modules, .. }) = &dp.detail else {
        panic!("{dp:?}")
    };
    assert_eq!(modules.len(), 2);
    assert_eq!((modules[0].slot, modules[0].data.as_slice()), (1, &[9][..]));
    assert_eq!(dp.to_string(), "Data_Exchange response: inputs 09 08 07 06 05; 1 1 byte in: 09; 2 2 words in+out: 08 07 06 05");
    // A bus file's modules win over what the wire says.
    let mut ex = Exchanges::default();
    let layout = vec![ModuleLayout {
        name: "valve".into(),
        inputs: Span::default(),
        outputs: Span { offset: 0, len: 2 },
    }];
    ex.set_slave(8, None, layout);
    detail(&mut ex, &tel(true, Some(sap::CHK_CFG), &[0x10]));
    let (_, _, out) = detail(&mut ex, &tel(true, None, &[1, 2]));
    let Some(Detail::Outputs { modules, .. }) = out else {
        panic!()
    };
    assert_eq!(modules[0].name, "valve");
}

#[test]
fn diagnosis_words_from_the_gsd_found_by_ident() {
    use crate::config::gsd::ParseOptions;
    let text =
        "#Profibus_DP\nGSD_Revision=1\nIdent_Number=0x1234\nProtocol_Ident=0\nStation_Type=0\n\
        Unit_Diag_Bit(0)=\"Sensor missing\"\n";
    let g = Gsd::parse(text, ParseOptions { lenient: true })
        .unwrap()
        .gsd;
    // Ext_Diag with a device block: header 02, bit 0 set.
    let du = [0x08, 0x04, 0x00, 2, 0x12, 0x34, 0x02, 0x01];
    let mut ex = Exchanges::default();
    detail(&mut ex, &tel(true, Some(sap::SLAVE_DIAG), &[]));
    let plain = detail(&mut ex, &tel(false, Some(sap::SLAVE_DIAG), &du)).2;
    let Some(Detail::SlaveDiag { ext_diag, .. }) = plain else {
        panic!()
    };
    assert!(
        !ext_diag.iter().any(|w| w.contains("Sensor missing")),
        "{ext_diag:?}"
    );
    ex.add_gsd(g);
    detail(&mut ex, &tel(true, Some(sap::SLAVE_DIAG), &[]));
    let named = detail(&mut ex, &tel(false, Some(sap::SLAVE_DIAG), &du)).2;
    let Some(Detail::SlaveDiag { ext_diag, .. }) = named else {
        panic!()
    };
    assert_eq!(ext_diag, ["device: Sensor missing"]);
}

/// FMS on a connection SAP: client 3 (LSAP 33) and server 5 (LSAP 40),
/// SRD low (FC 0x4C) answered with DL (0x08); the data units in the
/// (unverified) encoding of `fms::pdu` and `fms::lli`.
#[test]
fn fms_on_a_connection_sap_is_told_from_class_2() {
    let mut ex = Exchanges::default();
    let fms = |ex: &mut Exchanges, t: &[u8]| match ex.decode_layer(&tg(t)) {
        Some(Layer::Fms(f)) => f,
        other => panic!("{other:?}"),
    };
    // Before any FMS on it, a poll on SAP 40 is class 2's.
    let poll = sd2(5, 3, 0x4C, 40, 33, &[]);
    assert!(matches!(ex.decode_layer(&tg(&poll)), Some(Layer::Dp(_))));
    let read = sd2(5, 3, 0x4C, 40, 33, &[1, 3, 2, 0x07, 0xE6]);
    let f = fms(&mut ex, &read);
    assert_eq!(
        (f.pdu, f.invoke_id, f.index),
        (Some("read_req"), Some(3), Some(2022))
    );
    let f = fms(
        &mut ex,
        &sd2(3, 5, 0x08, 33, 40, &[2, 3, 2, 0x00, 0x12, 0x34]),
    );
    assert_eq!(f.to_string(), "FMS Read.resp invoke 3 data 00 12 34");
    // Now the connection is known: a poll and a short acknowledge are its.
    assert_eq!(fms(&mut ex, &poll).lli, "poll");
    assert_eq!(fms(&mut ex, &SC).lli, "empty");
    // A DP-V1 PDU on the same SAP is class 2's again, and so is the next poll.
    let c2 = sd2(5, 3, 0x4C, 40, 33, &[0x5E, 0, 1, 4]);
    assert!(matches!(ex.decode_layer(&tg(&c2)), Some(Layer::Dp(_))));
    assert!(matches!(ex.decode_layer(&tg(&poll)), Some(Layer::Dp(_))));
    // Garbage with an FMS type octet is FMS, flagged.
    let f = fms(&mut ex, &sd2(5, 3, 0x4C, 40, 33, &[1, 3, 9]));
    assert_eq!(f.lli, "malformed");
    // A DP SAP is never FMS, whatever its data unit.
    assert!(matches!(
        ex.decode_layer(&tg(&sd2(5, 3, 0x4C, 51, 33, &[1, 3, 2, 0x07, 0xE6]))),
        Some(Layer::Dp(_))
    ));
    // Data_Exchange and tokens go on as before.
    assert!(matches!(ex.decode_layer(&tg(&DX_REQ)), Some(Layer::Dp(_))));
    assert_eq!(ex.decode_layer(&tg(&TOKEN)), None);
}
