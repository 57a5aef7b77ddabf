//! Arbitrary request sequences never panic the slave, never produce an
//! oversized response, and never leave outputs set outside Data_Exch.

use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{
    expect_cfg, ClearReason, Device, DpSlave, Dpv1Outcome, Features, IoLayout, Reason, SlaveState,
};
use profibus_fdl::station::passive::{PassiveStation, Reply, Responder};
use profibus_fdl::station::Station;
use profibus_fdl::{
    Baud, BusParams, DataTelegram, FunctionCode, Instant, RequestKind, ResponseStatus,
};
use proptest::prelude::*;
use std::time::Duration;

const CFG: [u8; 3] = [0x21, 0x12, 0x00];

#[derive(Default)]
struct Dev {
    outputs: [u8; 2],
    pending: u8,
}

impl Device for Dev {
    fn ident_number(&self) -> u16 {
        0x4711
    }
    fn real_cfg(&self) -> &[u8] {
        &CFG
    }
    fn features(&self) -> Features {
        Features {
            sync: true,
            freeze: true,
            set_slave_add: true,
            dpv1: true,
            c1_read_write: true,
            alarms: true,
            fail_safe: true,
            max_diag_len: 32,
            c1_max_data_len: 240,
            c2_read_write: true,
            c2_max_data_len: 240,
            c2_max_count_channels: 2,
            max_initiate_pdu_length: 0,
            im: true,
        }
    }
    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        if prm.user_prm_data.len() > 5 {
            Err("too long".into())
        } else {
            Ok(())
        }
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        expect_cfg(&CFG, cfg)
    }
    fn write_outputs(&mut self, _: Instant, o: &[u8]) {
        self.outputs.copy_from_slice(o);
    }
    fn read_inputs(&mut self, _: Instant, i: &mut [u8]) {
        i.fill(0x5A);
    }
    fn clear_outputs(&mut self, _: Instant, _: ClearReason) {
        self.outputs = [0; 2];
    }
    fn diagnosis(&mut self, _: Instant, d: &mut profibus_dp::slave::DiagWriter<'_>) {
        d.device(&[1; 40]);
        d.identifier(&[0xFF]);
    }
    fn take_new_diag(&mut self) -> bool {
        true
    }
    fn dpv1_read(&mut self, _: Instant, _: u8, _: u8, out: &mut [u8]) -> Dpv1Outcome {
        self.pending = 2;
        out.fill(7);
        Dpv1Outcome::Pending
    }
    fn dpv1_poll(&mut self, _: Instant, out: &mut [u8]) -> Dpv1Outcome {
        self.pending = self.pending.saturating_sub(1);
        if self.pending == 0 {
            Dpv1Outcome::Done(out.len() + 10)
        } else {
            Dpv1Outcome::Pending
        }
    }
    fn dpv1_write(&mut self, _: Instant, _: u8, _: u8, d: &[u8]) -> Dpv1Outcome {
        Dpv1Outcome::Done(d.len() * 3)
    }
    fn im_read(&mut self, number: u8, out: &mut [u8; 64]) -> bool {
        out.fill(number);
        number <= 1
    }
    fn im_write(
        &mut self,
        _: Instant,
        _: u8,
        _: &[u8; 64],
    ) -> Result<(), profibus_dp::pdu::dpv1::Dpv1Error> {
        Ok(())
    }
}

#[derive(Debug, Clone)]
struct Req {
    da: u8,
    sa: u8,
    kind: RequestKind,
    saps: Option<(u8, Option<u8>)>,
    data: Vec<u8>,
    dt_ms: u64,
}

fn good_prm() -> Vec<u8> {
    vec![0xB8, 20, 1, 11, 0x47, 0x11, 1, 0xC0, 0xFC, 0x00]
}

/// Class 2: Initiate (1 s), polls, requests, I&M calls, Idle, Abort.
fn class2() -> impl Strategy<Value = (Option<(u8, Option<u8>)>, Vec<u8>)> {
    let on = |data: Vec<u8>| (47u8..=48).prop_map(move |s| (Some((s, Some(50))), data.clone()));
    prop_oneof![
        2 => Just((Some((49u8, Some(50u8))), vec![
            0x57, 0, 0, 0, 0x00, 0x64, 0x01, 0, 0, 0, 0, 0, 0, 2, 0, 2, 0, 0, 0, 0
        ])),
        3 => on(vec![]),
        1 => on(vec![0x5E, 0, 255, 68]),
        1 => on(vec![0x5F, 0, 255, 4, 8, 0, 0xFD, 0xE8]),
        1 => on(vec![0x51, 1, 2, 1, 7]),
        1 => on(vec![0x48, 0]),
        1 => on(vec![0x58, 0, 0x20, 0]),
    ]
}

/// A request that a master could plausibly send (to reach every state).
fn plausible() -> impl Strategy<Value = Req> {
    let service = prop_oneof![
        3 => Just((Some((61u8, Some(62u8))), good_prm())),
        3 => Just((Some((62, Some(62))), CFG.to_vec())),
        6 => proptest::collection::vec(any::<u8>(), 2..=2).prop_map(|o| (None, o)),
        1 => proptest::collection::vec(any::<u8>(), 0..4).prop_map(|o| (None, o)),
        2 => Just((Some((60, Some(62))), vec![])),
        1 => Just((Some((59, Some(62))), vec![])),
        1 => Just((Some((56, Some(62))), vec![])),
        1 => Just((Some((57, Some(62))), vec![])),
        1 => Just((Some((51, Some(51))), vec![0x5E, 1, 2, 240])),
        1 => Just((Some((51, Some(51))), vec![0x5F, 1, 2, 2, 9, 9])),
        2 => Just((Some((51, Some(51))), vec![])),
        1 => Just((Some((50, Some(51))), vec![0x5C, 1, 2, 0x0C])),
        1 => Just((Some((55, Some(62))), vec![9, 0x47, 0x11, 0])),
        1 => Just((Some((61, Some(62))), vec![0x40, 0, 0, 0, 0x47, 0x11, 0])),
        1 => class2(),
    ];
    (
        prop_oneof![6 => Just(2u8), 1 => Just(3u8)],
        prop_oneof![3 => Just(RequestKind::SrdHigh), 1 => Just(RequestKind::SrdLow)],
        service,
        0u64..60,
    )
        .prop_map(|(sa, kind, (saps, data), dt_ms)| Req {
            da: 8,
            sa,
            kind,
            saps,
            data,
            dt_ms,
        })
}

/// Global_Control broadcasts.
fn global_control() -> impl Strategy<Value = Req> {
    (
        prop_oneof![Just(2u8), Just(3u8)],
        0u8..=0x3F,
        prop_oneof![Just(0u8), Just(1u8), Just(2u8)],
        0u64..60,
    )
        .prop_map(|(sa, c, g, dt_ms)| Req {
            da: 127,
            sa,
            kind: RequestKind::SdnHigh,
            saps: Some((58, Some(62))),
            data: vec![c, g],
            dt_ms,
        })
}

/// Anything.
fn arbitrary() -> impl Strategy<Value = Req> {
    let kind = prop_oneof![
        Just(RequestKind::SrdHigh),
        Just(RequestKind::SdaHigh),
        Just(RequestKind::SdnLow),
        (0u8..=255).prop_map(RequestKind::from_code),
    ];
    let saps = prop_oneof![
        (any::<u8>(), proptest::option::of(any::<u8>())).prop_map(|(d, s)| Some((d, s))),
        Just(None),
    ];
    (
        prop_oneof![4 => Just(8u8), 1 => Just(127u8), 1 => 0u8..=127],
        0u8..=127,
        kind,
        saps,
        proptest::collection::vec(any::<u8>(), 0..=246),
        0u64..2000,
    )
        .prop_map(|(da, sa, kind, saps, data, dt_ms)| Req {
            da,
            sa,
            kind,
            saps,
            data,
            dt_ms,
        })
}

fn req() -> impl Strategy<Value = Req> {
    prop_oneof![6 => plausible(), 2 => global_control(), 1 => arbitrary()]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn slave_core_survives_any_requests(reqs in proptest::collection::vec(req(), 1..60)) {
        let mut s = DpSlave::new(Dev::default(), 8);
        let mut now = Instant::ZERO;
        for r in &reqs {
            now += Duration::from_millis(r.dt_ms);
            if s.poll_timeout().is_some_and(|t| t <= now) {
                s.handle_timeout(now);
            }
            let t = DataTelegram {
                da: r.da,
                sa: r.sa,
                fc: FunctionCode::Request { kind: r.kind, fcb: false, fcv: false },
                dsap: r.saps.map(|s| s.0),
                ssap: r.saps.and_then(|s| s.1),
                data: &r.data,
                format: None,
            };
            let before = s.state();
            let owner = s.master();
            let broadcast = r.da == 127 || !r.kind.expects_reply();
            let mut buf = [0u8; 246];
            let out: &mut [u8] = if broadcast { &mut [] } else { &mut buf };
            let reply = s.on_request(now, &t, out);
            if let Reply::Data { len, status, .. } = reply {
                prop_assert!(!broadcast, "a broadcast or SDN was answered");
                prop_assert!(len <= 244, "response of {len} bytes");
                if t.dsap.is_none() && t.ssap.is_none() && r.kind.expects_reply() && r.da != 127 {
                    // Data_Exchange: positive only in Data_Exch from the owner.
                    if before != SlaveState::DataExch || owner != Some(r.sa) {
                        prop_assert_eq!(status, ResponseStatus::Rs);
                    }
                }
            }
            if s.state() != SlaveState::DataExch {
                prop_assert_eq!(s.device().outputs, [0, 0], "outputs left set outside Data_Exch");
                prop_assert!(s.outputs().iter().all(|&b| b == 0));
            }
            while s.poll_event().is_some() {}
        }
    }

    #[test]
    fn passive_station_with_slave_survives_any_bytes(
        chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..80), 0..30)
    ) {
        let mut st = PassiveStation::new(
            DpSlave::new(Dev::default(), 8),
            BusParams::defaults(Baud::B19200),
        );
        let mut now = Instant::ZERO;
        for c in &chunks {
            now += Duration::from_micros(700);
            st.handle_rx(now, c);
            while let Some(t) = st.poll_timeout() {
                if t > now { break; }
                st.handle_timeout(t);
                if let Some(b) = st.poll_transmit(t) {
                    prop_assert!(b.len() <= 255);
                }
            }
        }
    }
}

#[test]
fn request_strategy_reaches_data_exch() {
    // The property above only tests what it reaches: check that a good
    // share of the generated sequences get to Data_Exch.
    use proptest::strategy::ValueTree;
    use proptest::test_runner::TestRunner;
    let mut runner = TestRunner::deterministic();
    let mut hits = 0;
    for _ in 0..200 {
        let reqs = proptest::collection::vec(req(), 1..60)
            .new_tree(&mut runner)
            .unwrap()
            .current();
        let mut s = DpSlave::new(Dev::default(), 8);
        let mut now = Instant::ZERO;
        let mut reached = false;
        for r in &reqs {
            now += Duration::from_millis(r.dt_ms);
            s.handle_timeout(now);
            let t = DataTelegram {
                da: r.da,
                sa: r.sa,
                fc: FunctionCode::request(r.kind),
                dsap: r.saps.map(|s| s.0),
                ssap: r.saps.and_then(|s| s.1),
                data: &r.data,
                format: None,
            };
            let mut buf = [0u8; 246];
            s.on_request(now, &t, &mut buf);
            reached |= s.state() == SlaveState::DataExch;
        }
        hits += reached as u32;
    }
    assert!(hits > 60, "only {hits} of 200 sequences reached Data_Exch");
}
