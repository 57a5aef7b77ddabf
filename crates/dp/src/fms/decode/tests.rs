use super::*;
use crate::fms::client::default_initiate;
use crate::fms::lli::{ABORT_TIMEOUT, LLI_ABORT, LLI_IDLE};
use crate::fms::pdu::{
    GetOdRequest, IdentifyResponse, InitiateResponse, ServiceError, StatusResponse,
    ACCESS_OBJECT_NON_EXISTENT, ERROR_CLASS_ACCESS, LOGICAL_READY, PHYSICAL_OPERATIONAL,
};
use core::time::Duration;

fn data(p: FmsPdu, request: bool) -> FmsTelegram {
    let t = describe(&p.to_vec().unwrap(), request);
    assert_eq!(t.lli, "data", "{t}");
    assert!(t.is_ok());
    t
}

#[test]
fn confirmed_requests_give_service_invoke_id_and_index() {
    let t = data(
        FmsPdu::Request {
            invoke_id: 3,
            request: Request::Read {
                index: 2022,
                subindex: None,
            },
        },
        true,
    );
    assert_eq!(t.to_string(), "FMS Read.req invoke 3 index 2022");
    assert_eq!(
        (t.pdu, t.service, t.invoke_id, t.index, t.subindex),
        (Some("read_req"), Some("Read"), Some(3), Some(2022), None)
    );
    let t = data(
        FmsPdu::Request {
            invoke_id: 4,
            request: Request::Read {
                index: 2022,
                subindex: Some(2),
            },
        },
        true,
    );
    assert_eq!(t.to_string(), "FMS Read.req invoke 4 index 2022 subindex 2");
    assert_eq!(t.subindex, Some(2));
    let t = data(
        FmsPdu::Request {
            invoke_id: 5,
            request: Request::Write {
                index: 2041,
                subindex: None,
                data: vec![0, 0x20, 0],
            },
        },
        true,
    );
    assert_eq!(
        t.to_string(),
        "FMS Write.req invoke 5 index 2041 data 00 20 00"
    );
    assert_eq!(
        (t.pdu, t.index, t.data.as_deref()),
        (Some("write_req"), Some(2041), Some(&[0, 0x20, 0][..]))
    );
    let t = data(
        FmsPdu::Request {
            invoke_id: 6,
            request: Request::GetOd(GetOdRequest {
                long_form: true,
                from_index: true,
                index: 2000,
            }),
        },
        true,
    );
    assert_eq!(
        t.to_string(),
        "FMS Get-OD.req invoke 6 index 2000 onwards, long form"
    );
    assert_eq!(
        (t.pdu, t.long_form, t.from_index),
        (Some("get_od_req"), Some(true), Some(true))
    );
    for (request, word, text) in [
        (Request::Status, "status_req", "FMS Status.req invoke 7"),
        (
            Request::Identify,
            "identify_req",
            "FMS Identify.req invoke 7",
        ),
    ] {
        let t = data(
            FmsPdu::Request {
                invoke_id: 7,
                request,
            },
            true,
        );
        assert_eq!((t.pdu, t.to_string().as_str()), (Some(word), text));
    }
}

#[test]
fn responses_give_their_values() {
    let t = data(
        FmsPdu::Response {
            invoke_id: 3,
            response: Response::Read(vec![0x00, 0x12, 0x34]),
        },
        false,
    );
    assert_eq!(t.to_string(), "FMS Read.resp invoke 3 data 00 12 34");
    assert_eq!(
        (t.pdu, t.data.as_deref()),
        (Some("read_resp"), Some(&[0, 0x12, 0x34][..]))
    );
    let t = data(
        FmsPdu::Response {
            invoke_id: 5,
            response: Response::Write,
        },
        false,
    );
    assert_eq!(
        (t.pdu, t.to_string().as_str()),
        (Some("write_resp"), "FMS Write.resp invoke 5")
    );
    let t = data(
        FmsPdu::Response {
            invoke_id: 1,
            response: Response::Status(StatusResponse {
                logical: LOGICAL_READY,
                physical: PHYSICAL_OPERATIONAL,
                local_detail: [0, 0, 1],
            }),
        },
        false,
    );
    assert_eq!(
        t.to_string(),
        "FMS Status.resp invoke 1: ready for communication, operational \
         (logical 0x00, physical 0x10, detail 00 00 01)"
    );
    assert_eq!(
        (t.pdu, t.logical_status, t.physical_status),
        (Some("status_resp"), Some(0), Some(0x10))
    );
    let t = data(
        FmsPdu::Response {
            invoke_id: 2,
            response: Response::Identify(IdentifyResponse {
                vendor: "Beckhoff".into(),
                model: "BK3000".into(),
                revision: "B9".into(),
            }),
        },
        false,
    );
    assert_eq!(
        t.to_string(),
        "FMS Identify.resp invoke 2: vendor \"Beckhoff\" model \"BK3000\" revision \"B9\""
    );
    assert_eq!(
        (
            t.vendor.as_deref(),
            t.model.as_deref(),
            t.revision.as_deref()
        ),
        (Some("Beckhoff"), Some("BK3000"), Some("B9"))
    );
    let t = data(
        FmsPdu::Response {
            invoke_id: 6,
            response: Response::GetOd {
                more_follows: true,
                descriptions: vec![vec![0x07, 0xD0, 8], vec![]],
            },
        },
        false,
    );
    assert_eq!(
        t.to_string(),
        "FMS Get-OD.resp invoke 6: 2 descriptions, more follow"
    );
    assert_eq!(t.more_follows, Some(true));
    assert_eq!(
        t.descriptions,
        Some(vec!["07 D0 08".to_string(), String::new()])
    );
}

#[test]
fn errors_rejects_and_reports_are_decoded() {
    let t = data(
        FmsPdu::Error {
            invoke_id: 3,
            service: Service::Read,
            error: ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_OBJECT_NON_EXISTENT),
        },
        false,
    );
    assert_eq!(
        t.to_string(),
        "FMS Error invoke 3 (Read) class 6 code 7 additional 0: object does not exist"
    );
    assert_eq!(
        (t.pdu, t.service, t.error_class, t.error_code),
        (Some("error"), Some("Read"), Some(6), Some(7))
    );
    assert_eq!(t.error.as_deref(), Some("object does not exist"));
    let t = data(
        FmsPdu::Reject {
            original_invoke_id: 9,
            pdu_type: 1,
            code: 5,
        },
        false,
    );
    assert_eq!(t.to_string(), "FMS Reject invoke 9 (PDU type 1) code 5");
    assert_eq!(
        (
            t.pdu,
            t.original_invoke_id,
            t.rejected_pdu_type,
            t.reject_code
        ),
        (Some("reject"), Some(9), Some(1), Some(5))
    );
    let t = data(
        FmsPdu::InformationReport {
            index: 1000,
            data: vec![1, 2],
        },
        true,
    );
    assert_eq!(
        (t.pdu, t.index, t.to_string().as_str()),
        (
            Some("information_report"),
            Some(1000),
            "FMS Information-Report index 1000 data 01 02"
        )
    );
}

#[test]
fn lli_pdus_carry_the_initiate_and_the_connection() {
    let initiate = default_initiate();
    let bytes = LliPdu::Associate {
        monitoring: Some(Duration::from_millis(500)),
        initiate,
    }
    .to_vec()
    .unwrap();
    let t = describe(&bytes, true);
    assert_eq!(
        (t.lli, t.pdu, t.monitoring_ms),
        ("associate", Some("initiate_req"), Some(500))
    );
    assert_eq!(t.max_pdu, Some([0, 241, 0, 241]));
    assert_eq!(
        t.to_string(),
        "LLI Associate (monitoring 500 ms): FMS Initiate.req OD version 0, profile 00 00, \
         max PDU send 0/241 receive 0/241, features 00 00 00 00 00 00"
    );
    let bytes = LliPdu::Associate {
        monitoring: None,
        initiate,
    }
    .to_vec()
    .unwrap();
    assert_eq!(describe(&bytes, true).monitoring_ms, Some(0));

    let ok = InitiateResponse {
        version_od: 1,
        profile: [0, 0],
        access_protection: false,
        password: 0,
        access_groups: 0,
    };
    let t = describe(&LliPdu::Associated(Ok(ok)).to_vec().unwrap(), false);
    assert_eq!(
        (t.lli, t.pdu, t.version_od),
        ("associate_res", Some("initiate_resp"), Some(1))
    );
    assert_eq!(
        t.to_string(),
        "LLI Associate.resp: FMS Initiate.resp OD version 1, profile 00 00"
    );
    let t = describe(&LliPdu::Associated(Err(3)).to_vec().unwrap(), false);
    assert_eq!(
        (t.pdu, t.error_code, t.to_string().as_str()),
        (
            Some("initiate_error"),
            Some(3),
            "LLI Associate.resp: FMS Initiate error code 3"
        )
    );

    let t = describe(&[LLI_ABORT, ABORT_TIMEOUT, 0], false);
    assert_eq!((t.lli, t.reason, t.detail), ("abort", Some(1), Some(0)));
    assert_eq!(
        t.to_string(),
        "LLI Abort reason 1 detail 0: connection monitoring: the peer fell silent"
    );
    let t = describe(&[LLI_IDLE], true);
    assert_eq!(
        (t.lli, t.pdu, t.to_string().as_str()),
        ("idle", None, "LLI Idle")
    );
    assert_eq!(describe(&[], true).to_string(), "LLI poll");
    assert_eq!(describe(&[], false).lli, "empty");
    assert_eq!(describe(&[], false).to_string(), "LLI no data");
}

#[test]
fn garbled_data_units_are_flagged_with_the_reason() {
    for (du, why) in [
        (
            &[1, 3, 9][..],
            "unknown FMS service 9 in a confirmed request PDU",
        ),
        (
            &[1, 3, 2, 0x07],
            "FMS Read request is 4 bytes long, needs 5",
        ),
        (&[0x99], "unknown FMS PDU type 153"),
        (&[LLI_ABORT, 1], "LLI PDU 0x12 is 2 bytes long, needs 3"),
        (&[LLI_IDLE, 0], "FMS LLI Idle has 1 bytes too many"),
        (
            &[0x10, 0, 50, 1, 1, 0],
            "LLI Associate carries confirmed request, not an Initiate",
        ),
    ] {
        let t = describe(du, true);
        assert_eq!(t.lli, "malformed", "{du:02X?}");
        assert!(!t.is_ok());
        assert_eq!(t.error.as_deref(), Some(why));
        assert_eq!(t.to_string(), format!("FMS malformed: {why}"));
        assert_eq!(t.pdu, None);
    }
    // Every prefix of every valid PDU, and every single octet: no panic.
    let all = [
        LliPdu::Associate {
            monitoring: Some(Duration::from_millis(100)),
            initiate: default_initiate(),
        }
        .to_vec()
        .unwrap(),
        b"\x02\x04\x01\x08Beckhoff\x06BK3000\x02B9".to_vec(),
        vec![2, 5, 4, 0xFF, 2, 2, 1, 2, 0],
    ];
    for p in &all {
        for n in 0..=p.len() {
            let _ = describe(&p[..n], n % 2 == 0).to_string();
        }
    }
    for b in 0..=255u8 {
        let _ = describe(&[b], true).to_string();
        let _ = describe(&[b, 0, 0, 0, 0, 0, 0, 0, 0], false).to_string();
    }
}

#[test]
fn the_first_octet_tells_fms_from_dpv1() {
    // FMS and LLI type octets …
    for b in [1, 2, 3, 4, 5, 6, 7, 8, 0x10, 0x11, 0x12, 0x13] {
        assert!(starts_lli_pdu(&[b]), "{b:#04X}");
    }
    // … and none of the DP-V1 function numbers (with and without the
    // error bit), nor nothing.
    for b in [
        0x48, 0x51, 0x57, 0x58, 0x5E, 0x5F, 0xC8, 0xD1, 0xD7, 0xDE, 0xDF,
    ] {
        assert!(!starts_lli_pdu(&[b]), "{b:#04X}");
    }
    assert!(!starts_lli_pdu(&[]));
}
