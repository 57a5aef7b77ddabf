use super::*;
use crate::config::layout::{ModuleLayout, Span};
use profibus_fdl::wire::Format;
use proptest::prelude::*;

const M: u8 = 2;
const S: u8 = 8;

/// Bytes of a data telegram.
fn data(da: u8, sa: u8, fc: FunctionCode, saps: Option<(u8, u8)>, du: &[u8]) -> Vec<u8> {
    let (dsap, ssap) = saps.unzip();
    let t = DataTelegram::new(da, sa, fc, du).with_saps(dsap, ssap);
    Telegram::Data(t).to_vec().unwrap()
}

fn req(da: u8, sap: Option<u8>, fcb: bool, fcv: bool, du: &[u8]) -> Vec<u8> {
    let fc = FunctionCode::Request {
        kind: RequestKind::SrdHigh,
        fcb,
        fcv,
    };
    data(da, M, fc, sap.map(|s| (s, sap::MASTER)), du)
}

fn resp(sa: u8, sap: Option<u8>, du: &[u8]) -> Vec<u8> {
    data(
        M,
        sa,
        FunctionCode::slave_response(ResponseStatus::Dl),
        sap.map(|s| (sap::MASTER, s)),
        du,
    )
}

const SC: [u8; 1] = [0xE5];

/// Feed telegrams 1 ms apart, starting at `t0` ms.
fn feed(m: &mut Monitor, t0: u64, telegrams: &[Vec<u8>]) -> u64 {
    let mut t = t0;
    for bytes in telegrams {
        let (tg, _) = Telegram::parse(bytes).unwrap();
        m.observe(Instant::from_nanos(t * 1_000_000), &tg);
        t += 1;
    }
    t
}

fn events(m: &mut Monitor) -> Vec<MonitorEvent> {
    std::iter::from_fn(|| m.poll_event()).collect()
}

fn info() -> Vec<SlaveInfo> {
    vec![SlaveInfo::from(SlaveLayout {
        address: S,
        name: "io".into(),
        modules: vec![
            ModuleLayout {
                name: "in 1 byte".into(),
                inputs: Span { offset: 0, len: 1 },
                outputs: Span { offset: 0, len: 0 },
            },
            ModuleLayout {
                name: "out 2 bytes".into(),
                inputs: Span { offset: 1, len: 0 },
                outputs: Span { offset: 0, len: 2 },
            },
        ],
        ..SlaveLayout::default()
    })]
}

/// Diag data unit: status bytes and master address.
fn diag_du(s1: u8, s2: u8, master: u8) -> Vec<u8> {
    vec![s1, s2 | 0x04, 0, master, 0x12, 0x34]
}

/// A whole start-up: first diag, Set_Prm, Chk_Cfg, diag ready, two
/// Data_Exchange cycles.
fn startup() -> Vec<Vec<u8>> {
    vec![
        req(S, Some(sap::SLAVE_DIAG), true, false, &[]),
        resp(S, Some(sap::SLAVE_DIAG), &diag_du(0x02, 0x01, NO_MASTER)),
        req(
            S,
            Some(sap::SET_PRM),
            false,
            true,
            &[0x88, 0, 0, 0x0B, 0, 0x12, 0x34],
        ),
        SC.to_vec(),
        req(S, Some(sap::CHK_CFG), true, true, &[0x10, 0x21]),
        SC.to_vec(),
        req(S, Some(sap::SLAVE_DIAG), false, true, &[]),
        resp(S, Some(sap::SLAVE_DIAG), &diag_du(0, 0, M)),
        req(S, None, true, true, &[0xAA, 0xBB]),
        resp(S, None, &[0x42]),
        req(S, None, false, true, &[0xAA, 0xBC]),
        resp(S, None, &[0x43]),
    ]
}

#[test]
fn follows_a_startup_into_data_exchange() {
    let mut m = Monitor::new(info(), MonitorOptions::default());
    feed(&mut m, 0, &startup());
    let states: Vec<(Option<SlaveState>, SlaveState)> = events(&mut m)
        .into_iter()
        .filter_map(|e| match e {
            MonitorEvent::SlaveState {
                address: S,
                master: M,
                from,
                to,
            } => Some((from, to)),
            _ => None,
        })
        .collect();
    use SlaveState::*;
    assert_eq!(
        states,
        [
            (None, SetPrm),
            (Some(SetPrm), ChkCfg),
            (Some(ChkCfg), CheckDiag),
            (Some(CheckDiag), DataExchange)
        ]
    );
    let st = m.status();
    let s = &st.slaves[0];
    assert_eq!(s.state, Some(DataExchange));
    assert_eq!(s.master, Some(M));
    assert_eq!(s.inputs, [0x43]);
    assert_eq!(s.outputs, [0xAA, 0xBC]);
    assert_eq!(s.counters.data_exchanges, 2);
    assert_eq!(s.counters.retries, 0);
    assert_eq!(s.counters.errors, 0);
    // Data_Exchange requests at 8 ms and 10 ms.
    assert_eq!(s.cycle_us.last, 2000);
    assert_eq!(
        s.modules,
        [
            ModuleData {
                name: "in 1 byte".into(),
                inputs: vec![0x43],
                outputs: vec![]
            },
            ModuleData {
                name: "out 2 bytes".into(),
                inputs: vec![],
                outputs: vec![0xAA, 0xBC]
            }
        ]
    );
    assert!(s.diag[0].contains("station status"), "{:?}", s.diag);
    assert_eq!(st.cycles, 2);
}

#[test]
fn diagnosis_in_words_and_restart() {
    let mut m = Monitor::new(info(), MonitorOptions::default());
    let t = feed(&mut m, 0, &startup());
    events(&mut m);
    // The slave restarted (watchdog): Data_Exchange refused with RS, the
    // master reads a diagnosis with Prm_Req and Cfg_Fault.
    let rs = data(
        M,
        S,
        FunctionCode::slave_response(ResponseStatus::Rs),
        None,
        &[],
    );
    feed(
        &mut m,
        t,
        &[
            req(S, None, true, true, &[1, 2]),
            rs,
            req(S, Some(sap::SLAVE_DIAG), true, false, &[]),
            resp(S, Some(sap::SLAVE_DIAG), &diag_du(0x04, 0x01, NO_MASTER)),
        ],
    );
    let ev = events(&mut m);
    assert!(ev.iter().any(|e| matches!(
        e,
        MonitorEvent::Fault {
            address: S,
            service: "Data_Exchange",
            reason: ErrorKind::Negative(ResponseStatus::Rs)
        }
    )));
    let words = ev
        .iter()
        .find_map(|e| match e {
            MonitorEvent::Diag { words, .. } => Some(words.join("; ")),
            _ => None,
        })
        .unwrap();
    assert!(
        words.contains("Cfg_Fault") && words.contains("Prm_Req"),
        "{words}"
    );
    assert_eq!(m.slave_state(S), Some(SlaveState::SetPrm));
    let c = m.slave_counters(S).unwrap();
    assert_eq!(c.restarts, 1);
    assert_eq!(c.errors, 1);
}

#[test]
fn retries_with_the_same_fcb_and_no_reply() {
    let mut m = Monitor::new(info(), MonitorOptions::default());
    let t = feed(&mut m, 0, &startup());
    events(&mut m);
    // Next request FCB=1 (last was 0); no reply; repeated with FCB=1.
    feed(
        &mut m,
        t,
        &[
            req(S, None, true, true, &[1, 2]),
            req(S, None, true, true, &[1, 2]),
            resp(S, None, &[7]),
            // A correct toggle is not a retry.
            req(S, None, false, true, &[1, 2]),
            resp(S, None, &[8]),
        ],
    );
    let c = m.slave_counters(S).unwrap();
    assert_eq!(c.retries, 1);
    assert_eq!(c.errors, 1);
    assert_eq!(c.data_exchanges, 4);
    assert_eq!(m.slave_state(S), Some(SlaveState::DataExchange));
    let ev = events(&mut m);
    assert_eq!(
        ev,
        [MonitorEvent::Fault {
            address: S,
            service: "Data_Exchange",
            reason: ErrorKind::NoReply
        }]
    );
    // The retry does not count as a cycle: intervals stay at 2 ms, 3 ms.
    let s = &m.status().slaves[0];
    assert_eq!(s.cycle_us.max, 3000, "{:?}", s.cycle_us);
}

#[test]
fn silent_slave_goes_offline() {
    let mut m = Monitor::new(info(), MonitorOptions::default());
    let t = feed(&mut m, 0, &startup());
    let t = feed(
        &mut m,
        t,
        &[
            req(S, None, true, true, &[1, 2]),
            req(S, None, true, true, &[1, 2]),
            vec![0xDC, M, M],
        ],
    );
    assert_eq!(m.slave_state(S), Some(SlaveState::Offline));
    // A corrupt reply counts as an error too.
    feed(
        &mut m,
        t,
        &[req(S, Some(sap::SLAVE_DIAG), true, false, &[])],
    );
    m.observe_skipped(
        Instant::from_nanos((t + 1) * 1_000_000),
        &CodecStats::default(),
    );
    assert_eq!(m.slave_counters(S).unwrap().errors, 3);
    assert_eq!(m.bus_counters().corrupt, 1);
}

#[test]
fn token_ring_live_list_and_operating_state() {
    let mut m = Monitor::new(vec![], MonitorOptions::default());
    let gc = |c: u8| {
        data(
            127,
            M,
            FunctionCode::request(RequestKind::SdnHigh),
            Some((sap::GLOBAL_CONTROL, sap::MASTER)),
            &[c, 0],
        )
    };
    let mut t = 0;
    for _ in 0..3 {
        t = feed(&mut m, t, &[vec![0xDC, 3, M], vec![0xDC, M, 3], gc(0x02)]);
    }
    assert_eq!(m.masters().collect::<Vec<_>>(), [2, 3]);
    let ev = events(&mut m);
    assert!(ev.contains(&MonitorEvent::MasterJoined { master: 2 }));
    assert!(ev.contains(&MonitorEvent::MasterJoined { master: 3 }));
    assert!(ev.contains(&MonitorEvent::Operating {
        master: M,
        state: OperatingState::Clear
    }));
    assert_eq!(
        ev.iter()
            .filter(|e| matches!(e, MonitorEvent::MasterJoined { .. }))
            .count(),
        2
    );
    // Master 3 drops out: only master 2 passes the token to itself.
    for _ in 0..500 {
        t = feed(&mut m, t, &[vec![0xDC, M, M], gc(0)]);
    }
    assert_eq!(m.masters().collect::<Vec<_>>(), [2]);
    let ev = events(&mut m);
    assert!(ev.contains(&MonitorEvent::MasterLeft { master: 3 }));
    assert!(ev.contains(&MonitorEvent::Operating {
        master: M,
        state: OperatingState::Operate
    }));
    let st = m.status();
    assert_eq!(st.operating, Some(OperatingState::Operate));
    assert_eq!(st.masters[0].rotation_us.last, 2000);
    // GAP polls of absent stations are no errors.
    feed(
        &mut m,
        t,
        &[
            data(
                20,
                M,
                FunctionCode::request(RequestKind::FdlStatus),
                None,
                &[],
            ),
            vec![0xDC, M, M],
        ],
    );
    assert!(m.status().slaves.is_empty());
    assert_eq!(m.bus_counters().no_reply, 0);
}

#[test]
fn another_masters_slave_is_locked() {
    let mut m = Monitor::new(info(), MonitorOptions::default());
    feed(
        &mut m,
        0,
        &[
            req(S, Some(sap::SLAVE_DIAG), true, false, &[]),
            resp(S, Some(sap::SLAVE_DIAG), &diag_du(0x80, 0, 5)),
        ],
    );
    assert_eq!(m.slave_state(S), Some(SlaveState::Locked));
}

#[derive(Debug)]
struct FirstByte;

impl ImageDecoder for FirstByte {
    fn decode(&self, image: Image, bytes: &[u8]) -> Vec<Reading> {
        bytes
            .first()
            .map(|b| Reading {
                name: format!("{image:?}0"),
                value: ReadingValue::Int(*b as i64),
                unit: Some("V".into()),
            })
            .into_iter()
            .collect()
    }
}

#[test]
fn decoder_names_the_channels() {
    let mut m = Monitor::new(info(), MonitorOptions::default());
    m.set_decoder(S, Box::new(FirstByte));
    feed(&mut m, 0, &startup());
    let ch = m.status().slaves[0].channels.clone().unwrap();
    assert_eq!(ch.inputs[0].to_string(), "Inputs0=67 V");
    assert_eq!(ch.outputs[0].to_string(), "Outputs0=170 V");
}

#[cfg(feature = "serde")]
#[test]
fn status_serialises_like_dpctl_master() {
    let mut m = Monitor::new(info(), MonitorOptions::default());
    m.set_decoder(S, Box::new(FirstByte));
    feed(&mut m, 0, &startup());
    let v = serde_json::to_value(m.status()).unwrap();
    let s = &v["slaves"][0];
    assert_eq!(s["address"], 8);
    assert_eq!(s["state"], "data_exchange");
    assert_eq!(s["inputs"], "43");
    assert_eq!(s["outputs"], "AA BC");
    assert_eq!(s["data_exchanges"], 2);
    assert_eq!(s["channels"]["inputs"]["Inputs0"], 67);
    assert_eq!(v["cycle_us"]["max"], 2000);
    let e = serde_json::to_value(MonitorEvent::SlaveState {
        address: 8,
        master: 2,
        from: None,
        to: SlaveState::DataExchange,
    })
    .unwrap();
    assert_eq!(
        e,
        serde_json::json!({"event": "state", "slave": 8, "master": 2, "from": null, "to": "data_exchange"})
    );
}

/// A telegram from a few building blocks that make real sequences likely.
fn telegram() -> impl Strategy<Value = Vec<u8>> {
    let addr = prop_oneof![Just(S), Just(M), Just(3u8), Just(127u8), 0u8..=127];
    let sap = prop_oneof![
        Just(None),
        (51u8..=62).prop_map(Some),
        any::<u8>().prop_map(Some)
    ];
    prop_oneof![
        Just(SC.to_vec()),
        (addr.clone(), addr.clone()).prop_map(|(d, s)| vec![0xDC, d, s]),
        (
            addr.clone(),
            addr,
            any::<u8>(),
            sap,
            proptest::collection::vec(any::<u8>(), 0..12)
        )
            .prop_map(|(da, sa, fc, sap, du)| {
                data(
                    da,
                    sa,
                    FunctionCode::from_byte(fc),
                    sap.map(|s| (s, s)),
                    &du,
                )
            }),
    ]
}

proptest! {
    #[test]
    fn arbitrary_streams_never_panic(
        stream in proptest::collection::vec((telegram(), 0u64..5_000_000, any::<bool>()), 0..200)
    ) {
        let mut m = Monitor::new(info(), MonitorOptions::default());
        let mut t = 0u64;
        for (bytes, dt, skip) in stream {
            t += dt;
            let at = Instant::from_nanos(t);
            if skip {
                m.observe_skipped(at, &CodecStats::default());
            }
            if let Ok((tg, _)) = Telegram::parse(&bytes) {
                m.observe(at, &tg);
            }
            while m.poll_event().is_some() {}
        }
        let st = m.status();
        prop_assert!(st.slaves.iter().all(|s| s.counters.retries <= s.counters.requests));
    }

    #[test]
    fn arbitrary_bytes_through_the_tap_never_panic(
        chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..64), 0..40)
    ) {
        let mut tap = profibus_fdl::line::tap::Tap::new();
        let mut m = Monitor::new(vec![], MonitorOptions::default());
        for (i, c) in chunks.iter().enumerate() {
            tap.push(Instant::from_nanos(i as u64 * 1000), c);
            if i % 3 == 0 {
                tap.line_idle();
            }
            while let Some(ev) = tap.poll() {
                match ev {
                    profibus_fdl::line::tap::TapEvent::Telegram { at, bytes } => {
                        if let Ok((tg, _)) = Telegram::parse(&bytes) {
                            m.observe(at, &tg);
                        }
                    }
                    profibus_fdl::line::tap::TapEvent::Skipped { at, errors, .. } => m.observe_skipped(at, &errors),
                }
            }
        }
        let _ = m.status();
    }
}

#[test]
fn format_is_irrelevant() {
    // An SD3 diag response is the same service as an SD2 one.
    let t = Telegram::Data(DataTelegram {
        da: M,
        sa: S,
        fc: FunctionCode::slave_response(ResponseStatus::Dl),
        dsap: Some(sap::MASTER),
        ssap: Some(sap::SLAVE_DIAG),
        data: &diag_du(0x02, 0x01, NO_MASTER),
        format: Some(Format::Sd3),
    });
    let mut buf = [0u8; 32];
    let n = t.emit(&mut buf).unwrap();
    let mut m = Monitor::new(info(), MonitorOptions::default());
    feed(
        &mut m,
        0,
        &[
            req(S, Some(sap::SLAVE_DIAG), true, false, &[]),
            buf[..n].to_vec(),
        ],
    );
    assert_eq!(m.slave_state(S), Some(SlaveState::SetPrm));
}

#[test]
fn slaves_leave_data_exchange_when_their_master_stops() {
    let mut m = Monitor::new(info(), MonitorOptions::default());
    let t = feed(&mut m, 0, &startup());
    events(&mut m);
    // Half the master timeout of silence: still exchanging data.
    m.tick(Instant::from_nanos((t + 500) * 1_000_000));
    assert_eq!(m.slave_state(S), Some(SlaveState::DataExchange));
    assert!(events(&mut m).is_empty());
    // The master stopped: after the master timeout the slave is no
    // longer in Data_Exchange, once.
    m.tick(Instant::from_nanos((t + 1_100) * 1_000_000));
    assert_eq!(m.slave_state(S), Some(SlaveState::Offline));
    assert_eq!(
        events(&mut m),
        [MonitorEvent::SlaveState {
            address: S,
            master: M,
            from: Some(SlaveState::DataExchange),
            to: SlaveState::Offline,
        }]
    );
    m.tick(Instant::from_nanos((t + 3_000) * 1_000_000));
    assert!(events(&mut m).is_empty());
    // A new start-up of the master brings it back.
    let t = feed(&mut m, t + 4_000, &startup());
    assert_eq!(m.slave_state(S), Some(SlaveState::DataExchange));
    m.tick(Instant::from_nanos((t + 10) * 1_000_000));
    assert_eq!(m.slave_state(S), Some(SlaveState::DataExchange));
}

#[test]
fn alarms_are_seen_in_the_diagnosis_and_their_acknowledgement_on_the_wire() {
    let mut layout = info().remove(0).layout;
    layout.dpv1 = true;
    let mut m = Monitor::new(vec![SlaveInfo::from(layout)], MonitorOptions::default());
    let mut t = feed(&mut m, 0, &startup());
    events(&mut m);
    // Diagnosis with a process alarm block (§4.5 layout: length 5, type
    // 2, slot 1, seq 3 << 3 | appears = 0x19, one data byte).
    let mut du = diag_du(0x08, 0, M);
    du.extend([0x05, 0x02, 0x01, 0x19, 0x7F]);
    t = feed(
        &mut m,
        t,
        &[
            req(S, Some(sap::SLAVE_DIAG), true, true, &[]),
            resp(S, Some(sap::SLAVE_DIAG), &du),
        ],
    );
    let alarms = |m: &mut Monitor| -> Vec<AlarmReport> {
        events(m)
            .into_iter()
            .filter_map(|e| match e {
                MonitorEvent::Alarm(a) => Some(a),
                _ => None,
            })
            .collect()
    };
    let seen = alarms(&mut m);
    assert_eq!(seen.len(), 1, "{seen:?}");
    assert_eq!(
        (seen[0].alarm_type, seen[0].seq, seen[0].acknowledged),
        ("process", 3, false)
    );
    assert_eq!(seen[0].data, [0x7F]);
    // The master's Alarm_Ack (SAP 51 → 50) and the slave's echo.
    let fc = FunctionCode::Request {
        kind: RequestKind::SrdHigh,
        fcb: false,
        fcv: true,
    };
    let ack = [0x5C, 0x01, 0x02, 0x19];
    feed(
        &mut m,
        t,
        &[
            data(S, M, fc, Some((sap::ALARM_ACK, sap::MSAC_C1)), &ack),
            data(
                M,
                S,
                FunctionCode::slave_response(ResponseStatus::Dl),
                Some((sap::MSAC_C1, sap::ALARM_ACK)),
                &ack,
            ),
        ],
    );
    let acked = alarms(&mut m);
    assert_eq!(acked.len(), 1, "{acked:?}");
    assert!(acked[0].acknowledged);
    assert_eq!((acked[0].slot, acked[0].data.clone()), (1, vec![0x7F]));
}
