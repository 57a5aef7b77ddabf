//! The class-2 master's connections, fed the bytes of the reference
//! (`shared/reference/dpv1-c2-im-alarms.md` §4.4, §4.6), not our encoder's.

use super::*;
use crate::master::records::LengthError;
use profibus_fdl::wire::StationType;

fn t(ms: u64) -> Instant {
    Instant::ZERO + Duration::from_millis(ms)
}

fn ctx(now: Instant, cycles: u32) -> TokenContext {
    TokenContext {
        now,
        high_only: false,
        hold_until: now + Duration::from_millis(10),
        cycles,
        alone: false,
    }
}

/// Send_Timeout 1 s (the reference's example), responses within 5 s.
fn master() -> Class2Master {
    Class2Master::new(Class2Config {
        send_timeout: Duration::from_secs(1),
        response_timeout: Duration::from_secs(5),
        ..Class2Config::for_baud(Baud::B1500000)
    })
}

/// What the master sends at the start of a token visit at `now`:
/// (DA, DSAP, SSAP, data, service).
fn visit(m: &mut Class2Master, now: Instant) -> Option<(u8, u8, u8, Vec<u8>, Service)> {
    m.poll_request(&ctx(now, 0)).map(|r| {
        (
            r.da,
            r.dsap.unwrap(),
            r.ssap.unwrap(),
            r.data.to_vec(),
            r.service,
        )
    })
}

fn answer(m: &mut Class2Master, now: Instant, da: u8, outcome: Outcome<'_>) {
    m.on_result(
        now,
        &CycleResult {
            da,
            service: Service::SrdLow,
            outcome,
            retries: 0,
        },
    );
}

fn dl(data: &[u8]) -> Outcome<'_> {
    Outcome::Response {
        status: ResponseStatus::Dl,
        station: StationType::Passive,
        dsap: Some(MASTER_SAP),
        ssap: Some(0x30),
        data,
    }
}

const INITIATE_REQ: [u8; 20] = [
    0x57, 0x00, 0x00, 0x00, 0x00, 0x64, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x02,
    0x00, 0x00, 0x00, 0x00,
];
const INITIATE_RES: [u8; 16] = [
    0x57, 0xF0, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x02, 0x00, 0x00, 0x00, 0x00,
];

/// Open a connection to `slave` as in the reference ([BAL]: SAP 48).
fn open(m: &mut Class2Master, slave: u8, now: Instant) -> ConnId {
    let conn = m.connect(slave, now);
    let (da, dsap, ssap, data, service) = visit(m, now).unwrap();
    assert_eq!((da, dsap, ssap), (slave, 49, 50));
    assert_eq!(data, INITIATE_REQ, "the reference's minimal Initiate.req");
    assert_eq!(service, Service::SrdLow);
    answer(m, now, slave, dl(&[0x56, 0x30, 0x00, 0x64]));
    let (_, dsap, ssap, data, _) = visit(m, now).unwrap();
    assert_eq!(
        (dsap, ssap, data.len()),
        (0x30, 50, 0),
        "polls SAP 48 empty"
    );
    answer(m, now, slave, Outcome::ShortAck);
    assert_eq!(m.poll_event(), None, "not ready yet");
    let (_, dsap, _, data, _) = visit(m, now).unwrap();
    assert_eq!((dsap, data.len()), (0x30, 0), "polls again");
    answer(m, now, slave, dl(&INITIATE_RES));
    match m.poll_event() {
        Some(Class2Event::Opened { conn: c, info, .. }) => {
            assert_eq!(c, conn);
            assert_eq!(info.sap, 48);
            assert_eq!(info.max_len_data_unit, 240);
            assert_eq!(info.poll_timeout, 100);
        }
        other => panic!("{other:?}"),
    }
    assert!(m.is_open(conn));
    conn
}

fn closed(m: &mut Class2Master) -> (Option<Class2Error>, Option<Abort>) {
    loop {
        match m.poll_event() {
            Some(Class2Event::Closed {
                error, abort_sent, ..
            }) => return (error, abort_sent),
            Some(_) => continue,
            None => panic!("not closed"),
        }
    }
}

#[test]
fn initiate_read_im0_idle_and_close_with_the_reference_bytes() {
    let mut m = master();
    let conn = open(&mut m, 8, t(0));
    // Read I&M0 the reference's way: the call header, then the read.
    m.request(
        conn,
        RecordOp::Write {
            slot: 0,
            index: 255,
            data: vec![0x08, 0x00, 0xFD, 0xE8],
        },
    )
    .unwrap();
    m.request(
        conn,
        RecordOp::Read {
            slot: 0,
            index: 255,
            length: 68,
        },
    )
    .unwrap();
    let (_, dsap, ssap, data, _) = visit(&mut m, t(10)).unwrap();
    assert_eq!((dsap, ssap), (0x30, 50));
    assert_eq!(data, [0x5F, 0x00, 0xFF, 0x04, 0x08, 0x00, 0xFD, 0xE8]);
    answer(&mut m, t(10), 8, Outcome::ShortAck);
    let (_, _, _, data, _) = visit(&mut m, t(20)).unwrap();
    assert!(data.is_empty(), "a poll");
    answer(&mut m, t(20), 8, dl(&[0x5F, 0x00, 0xFF, 0x04]));
    assert!(matches!(
        m.poll_event(),
        Some(Class2Event::Answer {
            answer: RecordAnswer::Written(4),
            ..
        })
    ));
    let (_, _, _, data, _) = visit(&mut m, t(30)).unwrap();
    assert_eq!(data, [0x5E, 0x00, 0xFF, 0x44]);
    let mut res = vec![0x5E, 0x00, 0xFF, 0x44, 0x08, 0x00, 0xFD, 0xE8];
    res.extend([0x20; 64]);
    answer(&mut m, t(30), 8, dl(&res));
    match m.poll_event() {
        Some(Class2Event::Answer {
            op,
            answer: RecordAnswer::Read(d),
            ..
        }) => {
            assert_eq!(op.record(), (0, 255));
            assert_eq!(d.len(), 68);
            assert_eq!(&d[..4], &[0x08, 0x00, 0xFD, 0xE8]);
        }
        other => panic!("{other:?}"),
    }
    // Nothing to send: no Idle before half of Send_Timeout (500 ms).
    assert_eq!(visit(&mut m, t(400)), None);
    let (_, dsap, _, data, _) = visit(&mut m, t(531)).unwrap();
    assert_eq!((dsap, data), (0x30, vec![0x48, 0x00]), "Idle");
    answer(&mut m, t(531), 8, dl(&[0x48, 0x00]));
    assert_eq!(visit(&mut m, t(600)), None, "Idle answered");
    assert!(m.is_open(conn));
    m.close(conn);
    let (_, dsap, _, data, _) = visit(&mut m, t(700)).unwrap();
    assert_eq!((dsap, data), (0x30, vec![0x58, 0x00, 0x20, 0x00]));
    answer(&mut m, t(700), 8, Outcome::ShortAck);
    let (error, sent) = closed(&mut m);
    assert_eq!(error, None);
    assert_eq!(sent.unwrap().describe(), "aborted by user: reason 0");
    assert_eq!(m.connections(), 0);
    assert_eq!(
        m.request(
            conn,
            RecordOp::Read {
                slot: 0,
                index: 1,
                length: 1
            }
        ),
        Err(Class2Error::NotOpen(conn))
    );
}

#[test]
fn an_abort_from_the_slave_closes_the_connection_in_words() {
    for (byte, words) in [
        (0x13, "aborted by MSAC_C2: connection timeout (TO)"),
        (0x11, "aborted by MSAC_C2: sequence error (SE)"),
        (0x16, "aborted by MSAC_C2: Send_Timeout too small (STO)"),
        (0x1F, "aborted by MSAC_C2: resource error (RES)"),
        (0x05, "aborted by FDL: reason 5"),
    ] {
        let mut m = master();
        let conn = open(&mut m, 8, t(0));
        m.request(
            conn,
            RecordOp::Read {
                slot: 1,
                index: 2,
                length: 4,
            },
        )
        .unwrap();
        visit(&mut m, t(10)).unwrap();
        answer(&mut m, t(10), 8, dl(&[0x58, 0x00, byte, 0x00]));
        let (error, sent) = closed(&mut m);
        assert_eq!(sent, None, "an abort is not answered with one");
        assert_eq!(
            error.unwrap().to_string(),
            format!("slave 8 aborted the connection: {words}")
        );
        assert!(!m.is_open(conn));
    }
}

#[test]
fn a_slave_that_falls_silent_is_reported_after_send_timeout() {
    let mut m = master();
    let conn = open(&mut m, 8, t(0));
    m.request(
        conn,
        RecordOp::Read {
            slot: 1,
            index: 2,
            length: 4,
        },
    )
    .unwrap();
    let mut now = 10;
    while now <= 1000 {
        visit(&mut m, t(now)).unwrap();
        answer(&mut m, t(now), 8, Outcome::NoResponse);
        now += 100;
    }
    assert_eq!(m.poll_event(), None, "still inside Send_Timeout");
    m.handle_time(t(1100));
    let (error, _) = closed(&mut m);
    assert_eq!(
        error.unwrap().to_string(),
        "slave 8 does not answer: silent for longer than the Send_Timeout of 1000 ms"
    );
}

#[test]
fn an_answer_that_never_comes_is_a_timeout_and_an_abort_to() {
    let mut m = master();
    let conn = open(&mut m, 8, t(0));
    m.request(
        conn,
        RecordOp::Transport {
            slot: 1,
            index: 2,
            data: vec![1],
        },
    )
    .unwrap();
    let (_, _, _, data, _) = visit(&mut m, t(10)).unwrap();
    assert_eq!(data, [0x51, 0x01, 0x02, 0x01, 0x01]);
    let mut now = 10;
    while now < 5000 {
        answer(&mut m, t(now), 8, Outcome::ShortAck);
        now += 200;
        visit(&mut m, t(now)).unwrap();
    }
    answer(&mut m, t(now), 8, Outcome::ShortAck);
    let (_, _, _, data, _) = visit(&mut m, t(5100)).unwrap();
    assert_eq!(data, [0x58, 0x00, 0x13, 0x00], "Abort MSAC_C2 TO");
    answer(&mut m, t(5100), 8, Outcome::NoResponse);
    let (error, sent) = closed(&mut m);
    assert_eq!(
        error.unwrap().to_string(),
        "slave 8: no answer to the transport within 5000 ms"
    );
    assert_eq!(sent.unwrap().msac_c2_reason(), Some(AbortReason::Timeout));
}

#[test]
fn a_slave_without_class_2_refuses_sap_49() {
    let mut m = master();
    m.connect(9, t(0));
    visit(&mut m, t(0)).unwrap();
    answer(
        &mut m,
        t(0),
        9,
        Outcome::Response {
            status: ResponseStatus::Rs,
            station: StationType::Passive,
            dsap: None,
            ssap: None,
            data: &[],
        },
    );
    let (error, sent) = closed(&mut m);
    assert_eq!(sent, None);
    assert_eq!(
        error.unwrap().to_string(),
        "slave 9 refused class 2 (SAP 49, MSAC_C2 Initiate): SAP not activated (RS)"
    );
}

#[test]
fn a_negative_initiate_response_refuses_the_connection() {
    let mut m = master();
    m.connect(9, t(0));
    visit(&mut m, t(0)).unwrap();
    answer(&mut m, t(0), 9, dl(&[0x56, 0x30, 0x00, 0x64]));
    visit(&mut m, t(0)).unwrap();
    answer(&mut m, t(0), 9, dl(&[0xD7, 0x80, 0xC3, 0x00]));
    let (error, _) = closed(&mut m);
    let e = error.unwrap().to_string();
    assert!(
        e.starts_with("slave 9 refused the connection: ")
            && e.contains("resource: unavailable (DP-V1, Error_Code_1 0xC3"),
        "{e}"
    );
}

#[test]
fn a_negative_response_keeps_the_connection_open() {
    let mut m = master();
    let conn = open(&mut m, 8, t(0));
    m.request(
        conn,
        RecordOp::Read {
            slot: 3,
            index: 9,
            length: 4,
        },
    )
    .unwrap();
    visit(&mut m, t(10)).unwrap();
    answer(&mut m, t(10), 8, dl(&[0xDE, 0x80, 0xB0, 0x00]));
    match m.poll_event() {
        Some(Class2Event::Answer {
            answer: RecordAnswer::Negative(e),
            ..
        }) => assert!(e
            .describe()
            .starts_with("read failed: access: invalid index")),
        other => panic!("{other:?}"),
    }
    assert!(m.is_open(conn));
}

#[test]
fn an_answer_to_another_request_aborts_with_re() {
    let mut m = master();
    let conn = open(&mut m, 8, t(0));
    m.request(
        conn,
        RecordOp::Read {
            slot: 3,
            index: 9,
            length: 4,
        },
    )
    .unwrap();
    visit(&mut m, t(10)).unwrap();
    answer(&mut m, t(10), 8, dl(&[0x5F, 0x03, 0x09, 0x04]));
    let (_, _, _, data, _) = visit(&mut m, t(20)).unwrap();
    assert_eq!(data, [0x58, 0x00, 0x14, 0x00], "Abort MSAC_C2 RE");
    answer(&mut m, t(20), 8, Outcome::ShortAck);
    let (error, _) = closed(&mut m);
    assert_eq!(
        error.unwrap().to_string(),
        "slave 8 answered the read with Write.res (function 0x5F): connection aborted \
         (invalid response PDU)"
    );
}

#[test]
fn two_slaves_at_once_take_turns_and_a_late_token_sends_nothing() {
    let mut m = master();
    let a = m.connect(8, t(0));
    let b = m.connect(9, t(0));
    let mut late = ctx(t(0), 0);
    late.high_only = true;
    assert!(m.poll_request(&late).is_none(), "low priority");
    // One cycle per connection and visit.
    let first = m.poll_request(&ctx(t(0), 0)).map(|r| r.da).unwrap();
    answer(&mut m, t(0), first, dl(&[0x56, 0x30, 0x00, 0x64]));
    let second = m.poll_request(&ctx(t(0), 1)).map(|r| r.da).unwrap();
    answer(&mut m, t(0), second, dl(&[0x56, 0x2F, 0x00, 0x64]));
    assert_eq!((first, second), (8, 9));
    assert!(m.poll_request(&ctx(t(0), 2)).is_none(), "visit done");
    for _ in 0..2 {
        let r = m
            .poll_request(&ctx(t(1), 0))
            .map(|r| (r.da, r.dsap))
            .unwrap();
        answer(&mut m, t(1), r.0, dl(&INITIATE_RES));
        assert_eq!(r.1, Some(if r.0 == 8 { 0x30 } else { 0x2F }));
    }
    assert!(m.is_open(a) && m.is_open(b));
    m.request(
        b,
        RecordOp::Read {
            slot: 0,
            index: 1,
            length: 1,
        },
    )
    .unwrap();
    let r = m.poll_request(&ctx(t(2), 0)).map(|r| r.da).unwrap();
    assert_eq!(r, 9, "only b has work");
    assert_eq!(
        m.request(
            a,
            RecordOp::Write {
                slot: 0,
                index: 1,
                data: vec![]
            }
        ),
        Err(Class2Error::Length(LengthError {
            op: "write",
            len: 0
        }))
    );
}

#[test]
fn send_timeout_in_ten_ms_units_and_defaults_per_rate() {
    let mut c = Class2Config::for_baud(Baud::B1500000);
    assert_eq!(c.send_timeout, Duration::from_secs(2));
    assert_eq!(c.send_timeout_units(), 200);
    assert_eq!(c.idle_after(), Duration::from_secs(1));
    c.send_timeout = Duration::from_millis(1005);
    assert_eq!(c.send_timeout_units(), 101, "rounded up");
    assert_eq!(
        Class2Config::for_baud(Baud::B500000).send_timeout,
        Duration::from_secs(4)
    );
    assert_eq!(
        Class2Config::for_baud(Baud::B187500).send_timeout,
        Duration::from_secs(8)
    );
}

#[test]
fn a_run_opens_sends_its_request_and_closes() {
    let mut m = master();
    let op = RecordOp::Read {
        slot: 1,
        index: 2,
        length: 2,
    };
    let mut run = Class2Run::new(8, SingleOp::new(op));
    assert!(run.tick(&mut m, t(0)).is_continue());
    // Initiate, RM, Initiate.res.
    visit(&mut m, t(0)).unwrap();
    answer(&mut m, t(0), 8, dl(&[0x56, 0x30, 0x00, 0x64]));
    visit(&mut m, t(1)).unwrap();
    answer(&mut m, t(1), 8, dl(&INITIATE_RES));
    assert!(run.tick(&mut m, t(1)).is_continue());
    assert_eq!(run.opened().map(|o| o.sap), Some(48));
    let (_, _, _, data, _) = visit(&mut m, t(2)).unwrap();
    assert_eq!(data, [0x5E, 0x01, 0x02, 0x02]);
    answer(&mut m, t(2), 8, dl(&[0x5E, 0x01, 0x02, 0x02, 0xCA, 0xFE]));
    assert!(run.tick(&mut m, t(2)).is_continue());
    let (_, _, _, data, _) = visit(&mut m, t(3)).unwrap();
    assert_eq!(data, [0x58, 0x00, 0x20, 0x00], "closed after the answer");
    answer(&mut m, t(3), 8, Outcome::ShortAck);
    assert!(run.tick(&mut m, t(3)).is_break());
    let ops = run.finish().unwrap();
    assert_eq!(ops.answer, Some(RecordAnswer::Read(vec![0xCA, 0xFE])));
}

/// A resource manager that acknowledges Initiate.req without data and
/// gives its reply on a poll of SAP 49 (Felser's manual; the scripted
/// slave tests/interop/raw_c2_slave.py by default): the master polls SAP
/// 49 with empty SRDs, never sends Initiate.req a second time (that would
/// ask for a second connection), then polls the assigned SAP.
#[test]
fn rm_reply_on_a_poll_of_sap_49_after_a_short_acknowledge() {
    let mut m = master();
    let conn = m.connect(8, t(0));
    let (_, dsap, _, data, _) = visit(&mut m, t(0)).unwrap();
    assert_eq!((dsap, data), (49, INITIATE_REQ.to_vec()));
    answer(&mut m, t(0), 8, Outcome::ShortAck);
    for k in 1..=2 {
        let (_, dsap, ssap, data, _) = visit(&mut m, t(k)).unwrap();
        assert_eq!((dsap, ssap, data.len()), (49, 50, 0), "poll {k} of SAP 49");
        if k == 1 {
            answer(&mut m, t(k), 8, Outcome::ShortAck);
        } else {
            answer(&mut m, t(k), 8, dl(&[0x56, 0x30, 0x00, 0x64]));
        }
    }
    let (_, dsap, _, data, _) = visit(&mut m, t(3)).unwrap();
    assert_eq!(
        (dsap, data.len()),
        (0x30, 0),
        "polls SAP 48 for Initiate.res"
    );
    answer(&mut m, t(3), 8, dl(&INITIATE_RES));
    assert!(matches!(m.poll_event(), Some(Class2Event::Opened { .. })));
    assert!(m.is_open(conn));
}
