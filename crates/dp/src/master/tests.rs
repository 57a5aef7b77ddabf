//! Unit tests of the master core driven directly through `MasterApp`.

use super::*;
use crate::pdu::diag::{StationStatus1 as S1, StationStatus2 as S2};
use profibus_fdl::timing::{Baud, BusParams};
use profibus_fdl::wire::StationType;

/// A master with one slave; no cyclic Global_Control, so that the tests
/// of the poll sequence see only the slave's requests.
pub(crate) fn master() -> DpMaster {
    master_with(MasterOptions {
        global_control_interval: None,
        ..MasterOptions::default()
    })
}

fn master_with(options: MasterOptions) -> DpMaster {
    let mut s = SlaveParams::new(8, 0x1234, vec![0x11, 0x21]); // 2 in, 2 out
    s.initial_outputs = vec![0xA0, 0xA1];
    DpMaster::new(&MasterConfig {
        address: 2,
        params: BusParams::defaults(Baud::B1500000),
        slaves: vec![s],
        options,
    })
    .unwrap()
}

fn ctx(now: u64, cycles: u32) -> TokenContext {
    TokenContext {
        now: Instant::from_nanos(now),
        high_only: false,
        hold_until: Instant::from_nanos(u64::MAX),
        cycles,
        alone: false,
    }
}

/// The next request of a fresh token visit, as (dsap, data).
pub(crate) fn next(m: &mut DpMaster, now: u64) -> Option<(Option<u8>, Vec<u8>)> {
    m.poll_request(&ctx(now, 0))
        .map(|r| (r.dsap, r.data.to_vec()))
}

fn answer(m: &mut DpMaster, now: u64, outcome: Outcome<'_>) {
    m.on_result(
        Instant::from_nanos(now),
        &CycleResult {
            da: 8,
            service: Service::SrdHigh,
            outcome,
            retries: 0,
        },
    );
}

/// A data response without SAPs (Data_Exchange).
pub(crate) fn data_resp(status: ResponseStatus, data: &[u8]) -> Outcome<'_> {
    Outcome::Response {
        status,
        station: StationType::Passive,
        dsap: None,
        ssap: None,
        data,
    }
}

pub(crate) fn diag_resp(data: &[u8]) -> Outcome<'_> {
    Outcome::Response {
        status: ResponseStatus::Dl,
        station: StationType::Passive,
        dsap: Some(sap::MASTER),
        ssap: Some(sap::SLAVE_DIAG),
        data,
    }
}

fn states(m: &mut DpMaster) -> Vec<SlaveState> {
    let mut v = vec![];
    while let Some(e) = m.poll_event() {
        if let MasterEvent::StateChanged { to, .. } = e {
            v.push(to);
        }
    }
    v
}

pub(crate) const FRESH: [u8; 6] = [0x02, 0x05, 0x00, 0xFF, 0x12, 0x34];
pub(crate) const READY: [u8; 6] = [0x00, 0x0C, 0x00, 0x02, 0x12, 0x34];

pub(crate) fn bring_up(m: &mut DpMaster) {
    assert_eq!(next(m, 1).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(m, 1, diag_resp(&FRESH));
    let (dsap, prm) = next(m, 2).unwrap();
    assert_eq!(dsap, Some(sap::SET_PRM));
    assert_eq!(&prm[4..6], &[0x12, 0x34]);
    answer(m, 2, Outcome::ShortAck);
    assert_eq!(next(m, 3).unwrap(), (Some(sap::CHK_CFG), vec![0x11, 0x21]));
    answer(m, 3, Outcome::ShortAck);
    assert_eq!(next(m, 4).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(m, 4, diag_resp(&READY));
}

#[test]
fn start_up_sequence_reaches_data_exchange() {
    let mut m = master();
    bring_up(&mut m);
    assert_eq!(
        states(&mut m),
        vec![
            SlaveState::SetPrm,
            SlaveState::ChkCfg,
            SlaveState::CheckDiag,
            SlaveState::DataExchange
        ]
    );
    let (dsap, out) = next(&mut m, 5).unwrap();
    assert_eq!((dsap, out), (None, vec![0xA0, 0xA1]));
    answer(&mut m, 5, data_resp(ResponseStatus::Dl, &[7, 9]));
    assert_eq!(m.inputs(8), Some(&[7u8, 9][..]));
    assert!(m.set_outputs(8, &[1, 2]));
    assert_eq!(next(&mut m, 6).unwrap().1, vec![1, 2]);
}

#[test]
fn data_high_triggers_diag_read_and_prm_req_restarts() {
    let mut m = master();
    bring_up(&mut m);
    next(&mut m, 5).unwrap();
    answer(&mut m, 5, data_resp(ResponseStatus::Dh, &[0, 0]));
    assert_eq!(next(&mut m, 6).unwrap().0, Some(sap::SLAVE_DIAG));
    // The slave lost its parameters (watchdog): Prm_Req.
    answer(&mut m, 6, diag_resp(&[0x02, 0x05, 0x00, 0xFF, 0x12, 0x34]));
    states(&mut m);
    assert_eq!(m.slave_state(8), Some(SlaveState::Diag));
    assert_eq!(m.slave_stats(8).unwrap().restarts, 1);
}

#[test]
fn cfg_fault_is_reported_in_words() {
    let mut m = master();
    next(&mut m, 1).unwrap();
    answer(&mut m, 1, diag_resp(&FRESH));
    next(&mut m, 2).unwrap();
    answer(&mut m, 2, Outcome::ShortAck);
    next(&mut m, 3).unwrap();
    answer(&mut m, 3, Outcome::ShortAck);
    next(&mut m, 4).unwrap();
    let fault = [
        (S1::CFG_FAULT | S1::STATION_NOT_READY).bits(),
        (S2::ALWAYS_ONE | S2::PRM_REQ).bits(),
        0,
        0xFF,
        0x12,
        0x34,
    ];
    answer(&mut m, 4, diag_resp(&fault));
    let mut reasons = vec![];
    while let Some(e) = m.poll_event() {
        if let MasterEvent::Fault { reason, .. } = e {
            reasons.push(reason.to_string());
        }
    }
    assert_eq!(
        reasons,
        vec!["Station_Not_Ready, Cfg_Fault, Prm_Req".to_string()]
    );
    assert_eq!(m.slave_state(8), Some(SlaveState::Diag));
}

#[test]
fn lost_slave_is_reprobed_and_reparameterised() {
    let mut m = master();
    bring_up(&mut m);
    for k in 0..3 {
        next(&mut m, 10 + k).unwrap();
        answer(&mut m, 10 + k, Outcome::NoResponse);
    }
    assert_eq!(m.slave_state(8), Some(SlaveState::Offline));
    // Not probed again before the reprobe interval.
    let t = 13 + 1;
    assert!(next(&mut m, t).is_none());
    let later = t + MasterOptions::default().reprobe_interval.as_nanos() as u64;
    assert_eq!(next(&mut m, later).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(&mut m, later, diag_resp(&FRESH));
    assert_eq!(next(&mut m, later + 1).unwrap().0, Some(sap::SET_PRM));
}

#[test]
fn clear_state_sends_zero_outputs_and_global_control() {
    let mut m = master();
    bring_up(&mut m);
    m.set_operating_state(OperatingState::Clear);
    let r = m.poll_request(&ctx(5, 0)).unwrap();
    assert_eq!(
        (r.da, r.service, r.dsap, r.data.to_vec()),
        (
            127,
            Service::SdnHigh,
            Some(sap::GLOBAL_CONTROL),
            vec![0x02, 0x00]
        )
    );
    m.on_result(
        Instant::from_nanos(5),
        &CycleResult {
            da: 127,
            service: Service::SdnHigh,
            outcome: Outcome::Sent,
            retries: 0,
        },
    );
    let r = m.poll_request(&ctx(6, 1)).unwrap();
    assert_eq!(r.data, &[0, 0]);
}

#[test]
fn dpv1_read_polls_until_the_answer() {
    let mut m = master();
    bring_up(&mut m);
    let id = m
        .submit(Job::Dpv1Read {
            address: 8,
            slot: 1,
            index: 2,
            length: 4,
        })
        .unwrap();
    // Visit: data exchange first, then the job.
    next(&mut m, 5).unwrap();
    answer(&mut m, 5, Outcome::ShortAck);
    let r = m.poll_request(&ctx(6, 1)).unwrap();
    assert_eq!((r.dsap, r.data.to_vec()), (Some(51), vec![0x5E, 1, 2, 4]));
    answer(&mut m, 6, Outcome::ShortAck);
    assert!(
        m.poll_request(&ctx(7, 2)).is_none(),
        "one job request per visit"
    );
    next(&mut m, 8).unwrap();
    answer(&mut m, 8, Outcome::ShortAck);
    let r = m.poll_request(&ctx(9, 1)).unwrap();
    assert_eq!((r.dsap, r.data.len()), (Some(51), 0), "empty poll");
    answer(
        &mut m,
        9,
        Outcome::Response {
            status: ResponseStatus::Dl,
            station: StationType::Passive,
            dsap: Some(51),
            ssap: Some(51),
            data: &[0x5E, 1, 2, 2, 0xBE, 0xEF],
        },
    );
    assert_eq!(m.take_result(id), Some(JobResult::Data(vec![0xBE, 0xEF])));
}

#[test]
fn locked_by_another_master_is_left_alone() {
    let mut m = master();
    next(&mut m, 1).unwrap();
    answer(&mut m, 1, diag_resp(&[0x00, 0x0C, 0x00, 0x05, 0x12, 0x34]));
    assert_eq!(m.slave_state(8), Some(SlaveState::Locked));
    assert!(next(&mut m, 2).is_none());
}

#[test]
fn an_invalid_diagnosis_is_counted_read_again_and_never_acted_on() {
    let mut m = master();
    bring_up(&mut m);
    states(&mut m);
    next(&mut m, 5).unwrap();
    answer(&mut m, 5, data_resp(ResponseStatus::Dh, &[0, 0]));
    // The observed failure: 20 bytes of process data, a late
    // Data_Exchange reply without SAPs, taken as Slave_Diag (Master_Lock
    // set, ident 0). Then a 3-byte answer with the Slave_Diag SAPs.
    let bogus = [
        0x80, 0x00, 0x00, 0x00, 0x00, 0x00, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14,
    ];
    let short = [0x00, 0x0C, 0x00];
    for (t, outcome) in [
        (6, data_resp(ResponseStatus::Dl, &bogus)),
        (7, diag_resp(&short)),
    ] {
        assert_eq!(next(&mut m, t).unwrap().0, Some(sap::SLAVE_DIAG));
        answer(&mut m, t, outcome);
        assert_eq!(m.slave_state(8), Some(SlaveState::DataExchange));
    }
    assert_eq!(m.slave_stats(8).unwrap().invalid_diags, 2);
    assert_eq!(m.slave_stats(8).unwrap().always_one_clear, 0);
    assert_eq!(
        m.diag(8),
        Some(&READY[..]),
        "the last valid diagnosis is kept"
    );
    while let Some(e) = m.poll_event() {
        assert!(
            !matches!(
                e,
                MasterEvent::Fault { .. } | MasterEvent::StateChanged { .. }
            ),
            "{e:?}"
        );
    }
    // Read again; a valid answer lets data exchange go on.
    assert_eq!(next(&mut m, 8).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(&mut m, 8, diag_resp(&READY));
    assert_eq!(next(&mut m, 9).unwrap().0, None);
}

#[test]
fn an_invalid_diagnosis_at_start_up_is_not_taken_for_a_lock_or_an_ident() {
    let mut m = master();
    // Master_Lock by master 5 and a foreign ident, but no SAPs: a stray
    // reply, not a diagnosis.
    assert_eq!(next(&mut m, 1).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(
        &mut m,
        1,
        data_resp(ResponseStatus::Dl, &[0x80, 0x0C, 0x00, 0x05, 0x00, 0x00]),
    );
    assert_eq!(m.slave_state(8), Some(SlaveState::Diag));
    assert!(m.poll_event().is_none());
    assert_eq!(next(&mut m, 2).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(&mut m, 2, diag_resp(&FRESH));
    assert_eq!(next(&mut m, 3).unwrap().0, Some(sap::SET_PRM));
    assert_eq!(m.slave_stats(8).unwrap().invalid_diags, 1);
}

#[test]
fn a_diagnosis_with_the_always_one_bit_clear_is_acted_on_and_counted() {
    // A slave core that never sets bit 2 of Station_Status_2 (as in
    // `02 08 00 02 00 2B`): its answers carry the Slave_Diag SAPs and 6
    // bytes, so they are diagnoses; the master parameterises the slave
    // and exchanges data, and counts each as a warning.
    let mut m = master();
    assert_eq!(next(&mut m, 1).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(&mut m, 1, diag_resp(&[0x02, 0x01, 0x00, 0xFF, 0x12, 0x34]));
    assert_eq!(next(&mut m, 2).unwrap().0, Some(sap::SET_PRM));
    answer(&mut m, 2, Outcome::ShortAck);
    assert_eq!(next(&mut m, 3).unwrap().0, Some(sap::CHK_CFG));
    answer(&mut m, 3, Outcome::ShortAck);
    assert_eq!(next(&mut m, 4).unwrap().0, Some(sap::SLAVE_DIAG));
    let ready = [0x00, 0x08, 0x00, 0x02, 0x12, 0x34];
    answer(&mut m, 4, diag_resp(&ready));
    assert_eq!(m.slave_state(8), Some(SlaveState::DataExchange));
    assert_eq!(m.diag(8), Some(&ready[..]));
    let (dsap, _) = next(&mut m, 5).unwrap();
    assert_eq!(dsap, None, "Data_Exchange");
    answer(&mut m, 5, data_resp(ResponseStatus::Dl, &[1, 2]));
    let stats = m.slave_stats(8).unwrap();
    assert_eq!((stats.always_one_clear, stats.invalid_diags), (2, 0));
    assert_eq!(stats.data_exchanges, 1);
    assert_eq!(stats.restarts, 0, "no loop back to the start-up");
}

#[test]
fn operate_is_announced_with_global_control_cyclically_by_default() {
    let mut m = master_with(MasterOptions::default());
    // Start-up, skipping the Global_Control announcements in between.
    for (t, want, outcome) in [
        (1, sap::SLAVE_DIAG, diag_resp(&FRESH)),
        (2, sap::SET_PRM, Outcome::ShortAck),
        (3, sap::CHK_CFG, Outcome::ShortAck),
        (4, sap::SLAVE_DIAG, diag_resp(&READY)),
    ] {
        let mut dsap = next(&mut m, t).unwrap().0;
        while dsap == Some(sap::GLOBAL_CONTROL) {
            m.on_result(
                Instant::from_nanos(t),
                &CycleResult {
                    da: 127,
                    service: Service::SdnHigh,
                    outcome: Outcome::Sent,
                    retries: 0,
                },
            );
            dsap = m.poll_request(&ctx(t, 1)).unwrap().dsap;
        }
        assert_eq!(dsap, Some(want));
        answer(&mut m, t, outcome);
    }
    assert_eq!(m.slave_state(8), Some(SlaveState::DataExchange));
    let (mut gcs, mut sent) = (vec![], 0);
    // One second of token visits, 1 ms apart.
    for k in 0..1000u64 {
        let now = 10 + k * 1_000_000;
        while let Some(r) = m.poll_request(&ctx(now, 0)) {
            let (da, service, data) = (r.da, r.service, r.data.to_vec());
            let outcome = if da == 127 {
                gcs.push((now, data));
                Outcome::Sent
            } else {
                Outcome::ShortAck
            };
            m.on_result(
                Instant::from_nanos(now),
                &CycleResult {
                    da,
                    service,
                    outcome,
                    retries: 0,
                },
            );
            sent += 1;
            if sent % 4 == 0 {
                break;
            }
        }
    }
    // Operate (Control_Command 0, all groups) at least every 100 ms.
    assert!(gcs.len() >= 9, "{} Global_Control in 1 s", gcs.len());
    assert!(gcs.iter().all(|(_, d)| d == &[0x00, 0x00]));
    for w in gcs.windows(2) {
        assert!(w[1].0 - w[0].0 <= 101_000_000, "gap {:?}", w[1].0 - w[0].0);
    }
    // In Clear, the same announcement carries Clear_Data.
    m.set_operating_state(OperatingState::Clear);
    let r = m.poll_request(&ctx(2_000_000_000, 0)).unwrap();
    assert_eq!((r.da, r.data.to_vec()), (127, vec![0x02, 0x00]));
}

#[test]
fn a_slave_that_answers_again_is_started_up_within_one_pass() {
    let mut m = master();
    // One token visit: every start-up step follows the previous one.
    let visit = |m: &mut DpMaster, cycle: u32| {
        m.poll_request(&ctx(10 + cycle as u64, cycle))
            .map(|r| r.dsap)
    };
    assert_eq!(visit(&mut m, 0), Some(Some(sap::SLAVE_DIAG)));
    answer(&mut m, 10, diag_resp(&FRESH));
    assert_eq!(visit(&mut m, 1), Some(Some(sap::SET_PRM)));
    answer(&mut m, 11, Outcome::ShortAck);
    assert_eq!(visit(&mut m, 2), Some(Some(sap::CHK_CFG)));
    answer(&mut m, 12, Outcome::ShortAck);
    assert_eq!(visit(&mut m, 3), Some(Some(sap::SLAVE_DIAG)));
    answer(&mut m, 13, diag_resp(&READY));
    assert_eq!(
        visit(&mut m, 4),
        Some(None),
        "Data_Exchange in the same pass"
    );
    assert_eq!(m.slave_state(8), Some(SlaveState::DataExchange));
    answer(&mut m, 14, data_resp(ResponseStatus::Dl, &[1, 2]));
    // The pass is over: nothing more in this visit.
    assert_eq!(visit(&mut m, 5), None);
    assert_eq!(m.inputs(8), Some(&[1u8, 2][..]));

    // A step that does not succeed waits for the next pass: a slave still
    // not ready after Chk_Cfg is asked again in the next pass only.
    let mut m = master();
    assert_eq!(visit(&mut m, 0), Some(Some(sap::SLAVE_DIAG)));
    answer(&mut m, 10, diag_resp(&FRESH));
    visit(&mut m, 1);
    answer(&mut m, 11, Outcome::ShortAck);
    visit(&mut m, 2);
    answer(&mut m, 12, Outcome::ShortAck);
    assert_eq!(visit(&mut m, 3), Some(Some(sap::SLAVE_DIAG)));
    let not_ready = [0x02, 0x0C, 0x00, 0x02, 0x12, 0x34];
    answer(&mut m, 13, diag_resp(&not_ready));
    assert_eq!(visit(&mut m, 4), None);
    assert_eq!(m.slave_state(8), Some(SlaveState::CheckDiag));
}

/// A slave that acknowledges Set_Prm and Chk_Cfg and then reports
/// Cfg_Fault (with Prm_Req, as it waits for parameters again) until it
/// is `fixed`; its real configuration is 4 words out (0xE3).
struct CfgFaultSlave {
    checked: bool,
    fixed: bool,
}

impl CfgFaultSlave {
    fn answer(&mut self, dsap: Option<u8>) -> Outcome<'static> {
        const FAULT: [u8; 6] = [0x06, 0x05, 0x00, 0xFF, 0x12, 0x34];
        match dsap {
            Some(sap::SLAVE_DIAG) if self.checked && self.fixed => diag_resp(&READY),
            Some(sap::SLAVE_DIAG) if self.checked => diag_resp(&FAULT),
            Some(sap::SLAVE_DIAG) => diag_resp(&FRESH),
            Some(sap::CHK_CFG) => {
                self.checked = true;
                Outcome::ShortAck
            }
            Some(sap::GET_CFG) => Outcome::Response {
                status: ResponseStatus::Dl,
                station: StationType::Passive,
                dsap: Some(sap::MASTER),
                ssap: Some(sap::GET_CFG),
                data: &[0xE3],
            },
            Some(_) => Outcome::ShortAck,
            None => data_resp(ResponseStatus::Dl, &[0, 0]),
        }
    }
}

/// Run `m` against `slave` from `from` for `ms` milliseconds of virtual
/// time, a token visit every millisecond with up to 5 requests (a pass
/// with a start-up chain); returns the requests by DSAP.
fn run_ms(m: &mut DpMaster, slave: &mut CfgFaultSlave, from: u64, ms: u64) -> Vec<Option<u8>> {
    let mut sent = vec![];
    for k in 0..ms {
        let t = (from + k) * 1_000_000;
        for _ in 0..5 {
            let Some((dsap, _)) = next(m, t) else {
                break;
            };
            sent.push(dsap);
            let outcome = slave.answer(dsap);
            answer(m, t, outcome);
        }
    }
    sent
}

#[test]
fn a_persistent_cfg_fault_backs_off_is_reported_once_and_shows_the_real_cfg() {
    let mut m = master();
    let mut slave = CfgFaultSlave {
        checked: false,
        fixed: false,
    };
    // 10 s of virtual time: the start-up is retried, but with a back-off
    // (10 ms doubling to 1 s: 17 start-ups), not every poll (thousands).
    let sent = run_ms(&mut m, &mut slave, 0, 10_000);
    let startups = sent.iter().filter(|d| **d == Some(sap::SET_PRM)).count();
    assert!((10..=20).contains(&startups), "{startups} start-ups");
    assert_eq!(
        sent.iter().filter(|d| **d == Some(sap::GET_CFG)).count(),
        1,
        "Get_Cfg once per new fault"
    );
    let stats = m.slave_stats(8).unwrap();
    assert_eq!(stats.failed_startups, startups as u64);
    // One line per change: the first start-up's states, the fault, the
    // configurations; nothing for the retries.
    let mut lines = vec![];
    while let Some(e) = m.poll_event() {
        lines.push(e);
    }
    let count = |f: fn(&MasterEvent) -> bool| lines.iter().filter(|e| f(e)).count();
    assert_eq!(count(|e| matches!(e, MasterEvent::Fault { .. })), 1);
    assert_eq!(count(|e| matches!(e, MasterEvent::CfgMismatch { .. })), 1);
    assert!(
        count(|e| matches!(e, MasterEvent::StateChanged { .. })) <= 4,
        "{lines:?}"
    );
    assert_eq!(m.actual_cfg(8), Some(&[0xE3][..]));
    let report = MasterReport::new(&mut m, MasterEvent::CfgMismatch { address: 8 }, None);
    assert_eq!(
        report.to_string(),
        "slave 8 configuration mismatch: configured [11] 2 bytes in, [21] 2 bytes out; \
         the slave has [E3] 4 words (consistent) out"
    );

    // Fixed: in Data_Exchange within the longest back-off, and the fault's
    // end is reported with its count.
    slave.fixed = true;
    run_ms(&mut m, &mut slave, 10_000, 1_100);
    assert_eq!(m.slave_state(8), Some(SlaveState::DataExchange));
    let ended: Vec<_> = std::iter::from_fn(|| m.poll_event())
        .filter_map(|e| match e {
            MasterEvent::FaultEnded { repeats, .. } => Some(repeats),
            _ => None,
        })
        .collect();
    assert_eq!(ended, vec![startups as u64]);
}

// ----- DP-V1 alarms ----------------------------------------------------

/// A master with one DP-V1 slave with diagnostic and process alarms.
fn alarm_master() -> DpMaster {
    let mut s = SlaveParams::new(8, 0x1234, vec![0x11, 0x21]);
    s.dpv1 = true;
    s.user_prm_data = vec![0x00, 0x00, 0x00];
    s.alarms = crate::pdu::prm::Dpv1Status2::DIAGNOSTIC_ALARM
        | crate::pdu::prm::Dpv1Status2::PROCESS_ALARM;
    s.alarm_mode = crate::pdu::alarm::AlarmMode(1);
    DpMaster::new(&MasterConfig {
        address: 2,
        params: BusParams::defaults(Baud::B1500000),
        slaves: vec![s],
        options: MasterOptions {
            global_control_interval: None,
            ..MasterOptions::default()
        },
    })
    .unwrap()
}

/// The acyclic request after the poll cycle of a visit, as (dsap, ssap,
/// data).
fn acyclic(m: &mut DpMaster, now: u64) -> Option<(Option<u8>, Option<u8>, Vec<u8>)> {
    assert_eq!(next(m, now).unwrap().0, None, "Data_Exchange first");
    answer(m, now, data_resp(ResponseStatus::Dl, &[0, 0]));
    m.poll_request(&ctx(now, 1))
        .map(|r| (r.dsap, r.ssap, r.data.to_vec()))
}

fn ack_resp(data: &[u8]) -> Outcome<'_> {
    Outcome::Response {
        status: ResponseStatus::Dl,
        station: StationType::Passive,
        dsap: Some(sap::MSAC_C1),
        ssap: Some(sap::ALARM_ACK),
        data,
    }
}

fn alarms(m: &mut DpMaster) -> Vec<AlarmNotice> {
    std::iter::from_fn(|| m.poll_event())
        .filter_map(|e| match e {
            MasterEvent::Alarm { alarm, .. } => Some(alarm),
            _ => None,
        })
        .collect()
}

/// Diagnosis of slave 8 in Data_Exchange with master 2, Ext_Diag, and
/// two alarm blocks written from the layout of dpv1-c2-im-alarms.md §4.5
/// (header = length, type, slot, specifier = seq << 3 | appears):
/// a process alarm of slot 3 with seq 2, then a diagnostic alarm of slot
/// 2 with seq 1 and 3 bytes of data.
const TWO_ALARMS: [u8; 17] = [
    0x08, 0x0C, 0x00, 0x02, 0x12, 0x34, // header
    0x04, 0x02, 0x03, 0x11, // process, slot 3, seq 2, appears
    0x07, 0x01, 0x02, 0x09, 0xAA, 0xBB, 0xCC, // diagnostic, slot 2, seq 1, appears
];

#[test]
fn set_prm_enables_the_alarms_and_their_mode() {
    let mut m = alarm_master();
    assert_eq!(next(&mut m, 1).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(&mut m, 1, diag_resp(&FRESH));
    let (_, prm) = next(&mut m, 2).unwrap();
    // DPV1_Enable, diagnostic + process enables (0x20 | 0x40), mode 1.
    assert_eq!(&prm[7..], &[0x80, 0x60, 0x01]);
}

#[test]
fn alarms_are_acknowledged_in_sequence_order_while_data_exchange_runs() {
    let mut m = alarm_master();
    bring_up(&mut m);
    next(&mut m, 5).unwrap();
    answer(&mut m, 5, data_resp(ResponseStatus::Dh, &[0, 0]));
    assert_eq!(next(&mut m, 6).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(&mut m, 6, diag_resp(&TWO_ALARMS));
    // Seq 1 first, though its block comes second: 5C slot type specifier,
    // from SAP 51 to SAP 50.
    let ack = acyclic(&mut m, 7).unwrap();
    assert_eq!(
        ack,
        (
            Some(sap::ALARM_ACK),
            Some(sap::MSAC_C1),
            vec![0x5C, 0x02, 0x01, 0x09]
        )
    );
    answer(&mut m, 7, ack_resp(&[0x5C, 0x02, 0x01, 0x09]));
    let done = alarms(&mut m);
    assert_eq!(done.len(), 1);
    assert!(done[0].acknowledged);
    assert_eq!(
        (done[0].specifier.seq, &done[0].data[..]),
        (1, &[0xAA, 0xBB, 0xCC][..])
    );
    // Then seq 2; the acknowledged one is not acknowledged twice.
    let (_, _, ack) = acyclic(&mut m, 8).unwrap();
    assert_eq!(ack, vec![0x5C, 0x03, 0x02, 0x11]);
    answer(&mut m, 8, ack_resp(&[0x5C, 0x03, 0x02, 0x11]));
    let done = alarms(&mut m);
    assert_eq!(done.len(), 1);
    assert_eq!(done[0].specifier.seq, 2);
    assert_eq!(acyclic(&mut m, 9), None, "nothing left to acknowledge");
    assert_eq!(m.slave_stats(8).unwrap().data_exchanges, 4);
}

#[test]
fn an_unacknowledged_alarm_is_retried_then_reported() {
    let mut m = alarm_master();
    bring_up(&mut m);
    next(&mut m, 5).unwrap();
    answer(&mut m, 5, data_resp(ResponseStatus::Dh, &[0, 0]));
    next(&mut m, 6).unwrap();
    answer(&mut m, 6, diag_resp(&TWO_ALARMS[..10]));
    // No answer, then a negative DP-V1 response, then RS.
    let (_, _, ack) = acyclic(&mut m, 7).unwrap();
    assert_eq!(ack, vec![0x5C, 0x03, 0x02, 0x11]);
    answer(&mut m, 7, Outcome::NoResponse);
    assert!(alarms(&mut m).is_empty(), "retried");
    assert!(acyclic(&mut m, 8).is_some());
    answer(&mut m, 8, ack_resp(&[0xDC, 0x80, 0xB5, 0x00]));
    assert!(alarms(&mut m).is_empty(), "retried");
    assert!(acyclic(&mut m, 9).is_some());
    answer(&mut m, 9, data_resp(ResponseStatus::Rs, &[]));
    let done = alarms(&mut m);
    assert_eq!(done.len(), 1, "reported after {ALARM_ACK_TRIES} attempts");
    assert!(!done[0].acknowledged);
    let why = done[0].problem.as_deref().unwrap();
    assert!(why.contains("after 3 attempts"), "{why}");
    assert_eq!(acyclic(&mut m, 10), None, "given up");
    assert_eq!(m.slave_state(8), Some(SlaveState::DataExchange));
}

#[test]
fn waiting_alarms_are_reported_unacknowledged_when_the_slave_leaves_data_exchange() {
    let mut m = alarm_master();
    bring_up(&mut m);
    next(&mut m, 5).unwrap();
    answer(&mut m, 5, data_resp(ResponseStatus::Dh, &[0, 0]));
    next(&mut m, 6).unwrap();
    answer(&mut m, 6, diag_resp(&TWO_ALARMS));
    // The slave restarts (RS to Data_Exchange) before any Alarm_Ack.
    assert_eq!(next(&mut m, 7).unwrap().0, None);
    answer(&mut m, 7, data_resp(ResponseStatus::Rs, &[]));
    let done = alarms(&mut m);
    assert_eq!(done.len(), 2);
    assert!(done.iter().all(|a| !a.acknowledged));
    let why = done[0].problem.as_deref().unwrap();
    assert!(why.contains("left Data_Exchange"), "{why}");
}

#[test]
fn without_enabled_alarms_blocks_are_not_acknowledged() {
    let mut m = master(); // DP-V0 slave, no alarms enabled
    bring_up(&mut m);
    next(&mut m, 5).unwrap();
    answer(&mut m, 5, data_resp(ResponseStatus::Dh, &[0, 0]));
    next(&mut m, 6).unwrap();
    answer(&mut m, 6, diag_resp(&TWO_ALARMS));
    assert_eq!(acyclic(&mut m, 7), None);
    assert!(alarms(&mut m).is_empty());
}
