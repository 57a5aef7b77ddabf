//! Unit tests of the master core driven directly through `MasterApp`.

use super::*;
use crate::diag::{StationStatus1 as S1, StationStatus2 as S2};
use profibus_fdl::timing::{Baud, BusParams};
use profibus_fdl::wire::StationType;

/// A master with one slave; no cyclic Global_Control, so that the tests
/// of the poll sequence see only the slave's requests.
pub(super) fn master() -> DpMaster {
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
fn next(m: &mut DpMaster, now: u64) -> Option<(Option<u8>, Vec<u8>)> {
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
fn data_resp(status: ResponseStatus, data: &[u8]) -> Outcome<'_> {
    Outcome::Response {
        status,
        station: StationType::Passive,
        dsap: None,
        ssap: None,
        data,
    }
}

fn diag_resp(data: &[u8]) -> Outcome<'_> {
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

const FRESH: [u8; 6] = [0x02, 0x05, 0x00, 0xFF, 0x12, 0x34];
const READY: [u8; 6] = [0x00, 0x0C, 0x00, 0x02, 0x12, 0x34];

fn bring_up(m: &mut DpMaster) {
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
    // The observed failure: 20 bytes of process data taken as Slave_Diag
    // (Master_Lock set, always-1 bit clear, ident 0). Then a 3-byte one.
    let bogus = [
        0x80, 0x00, 0x00, 0x00, 0x00, 0x00, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14,
    ];
    for (t, data) in [(6, &bogus[..]), (7, &[0x00, 0x0C, 0x00][..])] {
        assert_eq!(next(&mut m, t).unwrap().0, Some(sap::SLAVE_DIAG));
        answer(&mut m, t, diag_resp(data));
        assert_eq!(m.slave_state(8), Some(SlaveState::DataExchange));
    }
    assert_eq!(m.slave_stats(8).unwrap().invalid_diags, 2);
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
    // Master_Lock by master 5 and a foreign ident, but bit 2 of
    // Station_Status_2 clear: not a diagnosis.
    assert_eq!(next(&mut m, 1).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(&mut m, 1, diag_resp(&[0x80, 0x00, 0x00, 0x05, 0x00, 0x00]));
    assert_eq!(m.slave_state(8), Some(SlaveState::Diag));
    assert!(m.poll_event().is_none());
    assert_eq!(next(&mut m, 2).unwrap().0, Some(sap::SLAVE_DIAG));
    answer(&mut m, 2, diag_resp(&FRESH));
    assert_eq!(next(&mut m, 3).unwrap().0, Some(sap::SET_PRM));
    assert_eq!(m.slave_stats(8).unwrap().invalid_diags, 1);
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
