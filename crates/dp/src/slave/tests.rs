//! Behaviour of the slave core, request by request.

use super::*;
use crate::pdu::diag::{ext_blocks, ExtDiagBlock, SlaveDiag};
use profibus_fdl::station::passive::PassiveStation;
use profibus_fdl::station::Station;
use profibus_fdl::{Baud, BusParams, Telegram};

const IDENT: u16 = 0x4711;
const MASTER: u8 = 2;
const OTHER: u8 = 3;
const ADDR: u8 = 8;
/// 2 bytes out, 3 bytes in: `0x21` (2 B out), `0x12` (3 B in).
const CFG: [u8; 2] = [0x21, 0x12];

/// A device that records what the core does to it.
#[derive(Debug, Default)]
struct TestDevice {
    features: Features,
    outputs: Vec<u8>,
    writes: u32,
    clears: Vec<ClearReason>,
    input_counter: u8,
    reject_prm: bool,
    ext: Vec<u8>,
    ext_diag: bool,
    stat_diag: bool,
    new_diag: bool,
    /// DP-V1 reads answer `Pending` this many polls first.
    c1_delay: u32,
    c1_polls: u32,
    record: Vec<u8>,
    acked: Vec<(u8, u8, u8)>,
    /// The device writes and acknowledges alarms of its own.
    own_alarms: bool,
    address_refused: bool,
    persisted: Option<(u8, bool)>,
}

impl TestDevice {
    fn new() -> TestDevice {
        TestDevice::default()
    }
    fn with(features: Features) -> TestDevice {
        TestDevice {
            features,
            ..TestDevice::default()
        }
    }
}

impl Device for TestDevice {
    fn ident_number(&self) -> u16 {
        IDENT
    }
    fn real_cfg(&self) -> &[u8] {
        &CFG
    }
    fn features(&self) -> Features {
        self.features
    }
    fn check_prm(&mut self, _prm: &SetPrm<'_>) -> Result<(), Reason> {
        if self.reject_prm {
            Err("User_Prm_Data byte 0 out of range".into())
        } else {
            Ok(())
        }
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        expect_cfg(&CFG, cfg)
    }
    fn write_outputs(&mut self, _now: Instant, outputs: &[u8]) {
        self.writes += 1;
        self.outputs.clear();
        self.outputs.extend_from_slice(outputs);
    }
    fn read_inputs(&mut self, _now: Instant, inputs: &mut [u8]) {
        self.input_counter = self.input_counter.wrapping_add(1);
        inputs.fill(self.input_counter);
    }
    fn clear_outputs(&mut self, _now: Instant, why: ClearReason) {
        self.outputs.fill(0);
        self.clears.push(why);
    }
    fn diagnosis(&mut self, _now: Instant, diag: &mut DiagWriter<'_>) {
        if !self.ext.is_empty() {
            diag.device(&self.ext.clone());
        }
        if self.ext_diag {
            diag.set_ext_diag();
        }
        if self.stat_diag {
            diag.set_stat_diag();
        }
    }
    fn take_new_diag(&mut self) -> bool {
        std::mem::take(&mut self.new_diag)
    }
    fn dpv1_read(&mut self, _now: Instant, slot: u8, index: u8, out: &mut [u8]) -> Dpv1Outcome {
        if slot != 1 {
            return Dpv1Outcome::read_error(ERR_CLASS_ACCESS, ERR_INVALID_SLOT);
        }
        if index != 2 {
            return Dpv1Outcome::read_error(ERR_CLASS_ACCESS, ERR_INVALID_INDEX);
        }
        self.c1_polls = 0;
        if self.c1_delay > 0 {
            return Dpv1Outcome::Pending;
        }
        let n = out.len().min(self.record.len());
        out[..n].copy_from_slice(&self.record[..n]);
        Dpv1Outcome::Done(n)
    }
    fn dpv1_poll(&mut self, _now: Instant, out: &mut [u8]) -> Dpv1Outcome {
        self.c1_polls += 1;
        if self.c1_polls < self.c1_delay {
            return Dpv1Outcome::Pending;
        }
        let n = out.len().min(self.record.len());
        out[..n].copy_from_slice(&self.record[..n]);
        Dpv1Outcome::Done(n)
    }
    fn dpv1_write(&mut self, _now: Instant, slot: u8, index: u8, data: &[u8]) -> Dpv1Outcome {
        if (slot, index) != (1, 2) {
            return Dpv1Outcome::write_error(ERR_CLASS_ACCESS, ERR_INVALID_INDEX);
        }
        self.record = data.to_vec();
        Dpv1Outcome::Done(data.len())
    }
    fn alarm_ack(
        &mut self,
        _now: Instant,
        slot: u8,
        alarm_type: u8,
        seq: u8,
    ) -> Result<(), Dpv1Error> {
        if !self.own_alarms {
            return Err(Dpv1Error::dpv1(
                crate::pdu::dpv1::FN_ALARM_ACK,
                ERR_CLASS_ACCESS,
                ERR_STATE_CONFLICT,
            ));
        }
        self.acked.push((slot, alarm_type, seq));
        Ok(())
    }
    fn set_address(&mut self, new: u8, no_add_chg: bool, _rem: &[u8]) -> Result<(), Reason> {
        if self.address_refused {
            return Err("address store is write-protected".into());
        }
        self.persisted = Some((new, no_add_chg));
        Ok(())
    }
}

fn t(ms: u64) -> Instant {
    Instant::from_nanos(ms * 1_000_000)
}

/// What the slave answered, decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Ans {
    Silence,
    Sc,
    Data(ResponseStatus, Option<u8>, Option<u8>, Vec<u8>),
}

impl Ans {
    fn status(&self) -> Option<ResponseStatus> {
        match self {
            Ans::Data(s, ..) => Some(*s),
            _ => None,
        }
    }
    fn data(&self) -> &[u8] {
        match self {
            Ans::Data(_, _, _, d) => d,
            _ => &[],
        }
    }
}

struct Bench {
    slave: DpSlave<TestDevice>,
}

impl Bench {
    fn new(dev: TestDevice) -> Bench {
        Bench {
            slave: DpSlave::new(dev, ADDR),
        }
    }

    fn req(
        &mut self,
        now: Instant,
        from: u8,
        kind: RequestKind,
        saps: Option<(u8, u8)>,
        data: &[u8],
    ) -> Ans {
        let fc = FunctionCode::Request {
            kind,
            fcb: false,
            fcv: false,
        };
        let (dsap, ssap) = saps.unzip();
        let req = DataTelegram::new(ADDR, from, fc, data).with_saps(dsap, ssap);
        let mut out = [0u8; 246];
        match self.slave.on_request(now, &req, &mut out) {
            Reply::Silence => Ans::Silence,
            Reply::ShortAck => Ans::Sc,
            Reply::Data {
                status,
                dsap,
                ssap,
                len,
            } => Ans::Data(status, dsap, ssap, out[..len].to_vec()),
        }
    }

    fn sap(&mut self, now: Instant, from: u8, dsap: u8, data: &[u8]) -> Ans {
        let ssap = if dsap == sap::MSAC_C1 || dsap == sap::ALARM_ACK {
            sap::MSAC_C1
        } else {
            sap::MASTER
        };
        self.req(now, from, RequestKind::SrdHigh, Some((dsap, ssap)), data)
    }

    fn dx(&mut self, now: Instant, from: u8, outputs: &[u8]) -> Ans {
        self.req(now, from, RequestKind::SrdHigh, None, outputs)
    }

    fn diag(&mut self, now: Instant, from: u8) -> Vec<u8> {
        let a = self.sap(now, from, sap::SLAVE_DIAG, &[]);
        assert_eq!(a.status(), Some(ResponseStatus::Dl));
        a.data().to_vec()
    }

    fn broadcast_gc(&mut self, now: Instant, from: u8, cmd: u8, group: u8) {
        let req = DataTelegram {
            da: BROADCAST,
            sa: from,
            fc: FunctionCode::request(RequestKind::SdnHigh),
            dsap: Some(sap::GLOBAL_CONTROL),
            ssap: Some(sap::MASTER),
            data: &[cmd, group],
            format: None,
        };
        let mut none = [0u8; 0];
        assert_eq!(self.slave.on_request(now, &req, &mut none), Reply::Silence);
    }

    fn events(&mut self) -> Vec<SlaveEvent> {
        std::iter::from_fn(|| self.slave.poll_event()).collect()
    }

    /// Set_Prm + Chk_Cfg from `MASTER` with `prm`.
    fn start(&mut self, now: Instant, prm: &[u8]) {
        assert_eq!(self.sap(now, MASTER, sap::SET_PRM, prm), Ans::Sc);
        assert_eq!(
            self.slave.state(),
            SlaveState::WaitCfg,
            "{:?}",
            self.events()
        );
        assert_eq!(self.sap(now, MASTER, sap::CHK_CFG, &CFG), Ans::Sc);
        assert_eq!(
            self.slave.state(),
            SlaveState::DataExch,
            "{:?}",
            self.events()
        );
    }
}

/// Set_Prm: Lock_Req, WD_On with 100 ms, min TSDR 11, IDENT, no groups.
fn prm(status: u8) -> Vec<u8> {
    vec![status, 10, 1, 11, (IDENT >> 8) as u8, IDENT as u8, 0]
}
const LOCK_WD: u8 = 0x88;

fn diag(bytes: &[u8]) -> SlaveDiag<'_> {
    SlaveDiag::parse(bytes).unwrap()
}

#[test]
fn start_up_sequence_like_a_master() {
    let mut b = Bench::new(TestDevice::new());
    let d0 = b.diag(t(0), MASTER);
    // Station_Not_Ready; Prm_Req + always-1; no master; ident.
    assert_eq!(d0, vec![0x02, 0x05, 0x00, 0xFF, 0x47, 0x11]);
    assert_eq!(
        b.dx(t(0), MASTER, &[1, 2]).status(),
        Some(ResponseStatus::Rs)
    );
    b.start(t(1), &prm(LOCK_WD));
    let d1 = b.diag(t(2), MASTER);
    let d = diag(&d1);
    assert!(d.ready_for(MASTER), "{}", d.status_words());
    assert_eq!(d1[..4], [0x00, 0x0C, 0x00, MASTER]);
    let a = b.dx(t(3), MASTER, &[0xAB, 0xCD]);
    assert_eq!(a, Ans::Data(ResponseStatus::Dl, None, None, vec![1, 1, 1]));
    assert_eq!(b.slave.device().outputs, vec![0xAB, 0xCD]);
    assert_eq!(b.slave.outputs(), &[0xAB, 0xCD]);
    assert_eq!(b.slave.inputs(), &[1, 1, 1]);
    assert_eq!(b.slave.stats().data_exchanges, 1);
    let ev = b.events();
    assert!(ev.contains(&SlaveEvent::State {
        from: SlaveState::WaitPrm,
        to: SlaveState::WaitCfg
    }));
    assert!(ev.contains(&SlaveEvent::State {
        from: SlaveState::WaitCfg,
        to: SlaveState::DataExch
    }));
    assert!(ev.iter().any(|e| matches!(
        e,
        SlaveEvent::CfgAccepted {
            inputs: 3,
            outputs: 2,
            ..
        }
    )));
    // Get_Cfg answers the real configuration.
    assert_eq!(
        b.sap(t(3), OTHER, sap::GET_CFG, &[]),
        Ans::Data(ResponseStatus::Dl, Some(62), Some(59), CFG.to_vec())
    );
}

#[test]
fn prm_faults_keep_the_slave_in_wait_prm() {
    let dpv1 = Features {
        dpv1: true,
        ..Features::default()
    };
    let cases: Vec<(Vec<u8>, Features, bool, &str, bool)> = vec![
        // (prm, features, device rejects, reason contains, not supported)
        (
            vec![0x88, 10, 1, 11, 0x12, 0x34, 0],
            Features::default(),
            false,
            "ident number 0x1234",
            false,
        ),
        (
            vec![0x88, 10, 1],
            Features::default(),
            false,
            "shorter",
            false,
        ),
        (prm(0xA8), Features::default(), false, "sync", true),
        (prm(0x98), Features::default(), false, "freeze", true),
        (
            vec![0x88, 0, 1, 11, 0x47, 0x11, 0],
            Features::default(),
            false,
            "WD_Fact_1 = 0",
            false,
        ),
        (
            prm(0x88),
            Features::default(),
            true,
            "byte 0 out of range",
            false,
        ),
        (prm(0x88), dpv1, false, "3 DPV1_Status bytes", false),
        (
            [prm(0x88), vec![0x80, 0x20, 0x00]].concat(),
            dpv1,
            false,
            "alarms enabled",
            true,
        ),
        (
            [prm(0x88), vec![0xA0, 0x00, 0x00]].concat(),
            dpv1,
            false,
            "DP-V2",
            true,
        ),
    ];
    for (p, features, reject, words, not_supp) in cases {
        let mut dev = TestDevice::with(features);
        dev.reject_prm = reject;
        let mut b = Bench::new(dev);
        assert_eq!(b.sap(t(0), MASTER, sap::SET_PRM, &p), Ans::Sc, "{words}");
        assert_eq!(b.slave.state(), SlaveState::WaitPrm, "{words}");
        let d = b.diag(t(0), MASTER);
        let d = diag(&d);
        assert!(d.status1.contains(StationStatus1::PRM_FAULT), "{words}");
        assert_eq!(
            d.status1.contains(StationStatus1::NOT_SUPPORTED),
            not_supp,
            "{words}"
        );
        assert!(d.status2.contains(StationStatus2::PRM_REQ));
        assert_eq!(d.master_address, NO_MASTER);
        let ev = b.events();
        let fault = ev
            .iter()
            .find_map(|e| match e {
                SlaveEvent::PrmFault { reason, .. } => Some(reason.to_string()),
                _ => None,
            })
            .unwrap();
        assert!(fault.contains(words), "{fault:?} lacks {words:?}");
        // A good Set_Prm clears the fault.
        let mut good = prm(0x88);
        if features.dpv1 {
            good.extend([0, 0, 0]);
        }
        b.slave.device_mut().reject_prm = false;
        assert_eq!(b.sap(t(1), MASTER, sap::SET_PRM, &good), Ans::Sc);
        let d = b.diag(t(1), MASTER);
        assert_eq!(d[0] & 0x50, 0, "Prm_Fault and Not_Supported cleared");
    }
}

#[test]
fn cfg_fault_returns_to_wait_prm() {
    let mut b = Bench::new(TestDevice::new());
    assert_eq!(b.sap(t(0), MASTER, sap::SET_PRM, &prm(LOCK_WD)), Ans::Sc);
    assert_eq!(b.sap(t(0), MASTER, sap::CHK_CFG, &[0x21, 0x13]), Ans::Sc);
    assert_eq!(b.slave.state(), SlaveState::WaitPrm);
    let d = b.diag(t(0), MASTER);
    let d = diag(&d);
    assert!(d.status1.contains(StationStatus1::CFG_FAULT));
    assert!(d.status2.contains(StationStatus2::PRM_REQ));
    let reason = b
        .events()
        .into_iter()
        .find_map(|e| match e {
            SlaveEvent::CfgFault { reason, .. } => Some(reason),
            _ => None,
        })
        .unwrap();
    assert!(reason.to_string().contains("byte 1 is 0x13, expected 0x12"));
    // Chk_Cfg in Wait_Prm is not accepted.
    assert_eq!(b.sap(t(0), MASTER, sap::CHK_CFG, &CFG), Ans::Sc);
    assert_eq!(b.slave.state(), SlaveState::WaitPrm);
    // Set_Prm, then the right Chk_Cfg clears Cfg_Fault.
    b.start(t(1), &prm(LOCK_WD));
    let d = b.diag(t(1), MASTER);
    assert!(diag(&d).ready_for(MASTER));
}

#[test]
fn watchdog_expiry_clears_outputs_and_returns_to_wait_prm() {
    let mut b = Bench::new(TestDevice::new());
    b.start(t(0), &prm(LOCK_WD)); // 10 × 1 × 10 ms = 100 ms
    assert_eq!(b.slave.watchdog(), Some(Duration::from_millis(100)));
    assert_eq!(b.slave.poll_timeout(), Some(t(100)));
    b.dx(t(50), MASTER, &[7, 7]);
    // Retriggered by the Data_Exchange; a request from another master
    // does not retrigger.
    b.sap(t(120), OTHER, sap::SLAVE_DIAG, &[]);
    assert_eq!(b.slave.poll_timeout(), Some(t(150)));
    b.slave.handle_timeout(t(149));
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    assert_eq!(b.slave.device().outputs, vec![7, 7]);
    b.slave.handle_timeout(t(150));
    assert_eq!(b.slave.state(), SlaveState::WaitPrm);
    assert_eq!(b.slave.device().outputs, vec![0, 0]);
    assert_eq!(b.slave.device().clears, vec![ClearReason::Watchdog]);
    assert_eq!(b.slave.master(), None);
    assert_eq!(b.slave.poll_timeout(), None);
    let ev = b.events();
    assert!(ev
        .iter()
        .any(|e| matches!(e, SlaveEvent::WatchdogExpired { master: MASTER, .. })));
    let d = b.diag(t(151), MASTER);
    assert_eq!(d[..4], [0x02, 0x05, 0x00, 0xFF]);
    assert_eq!(b.slave.stats().watchdog_expiries, 1);
}

#[test]
fn watchdog_base_1ms_only_for_dpv1_slaves() {
    let p = [prm(LOCK_WD), vec![0x04, 0, 0]].concat();
    let mut v1 = Bench::new(TestDevice::with(Features {
        dpv1: true,
        ..Features::default()
    }));
    v1.start(t(0), &p);
    assert_eq!(v1.slave.watchdog(), Some(Duration::from_millis(10)));
    let mut v0 = Bench::new(TestDevice::new());
    v0.start(t(0), &p);
    assert_eq!(v0.slave.watchdog(), Some(Duration::from_millis(100)));
}

#[test]
fn data_exchange_refusals() {
    let mut b = Bench::new(TestDevice::new());
    b.start(t(0), &prm(LOCK_WD));
    // Another master: RS, outputs untouched.
    assert_eq!(
        b.dx(t(1), OTHER, &[9, 9]).status(),
        Some(ResponseStatus::Rs)
    );
    assert_eq!(b.slave.device().writes, 0);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    // Wrong length: RS, Wait_Prm, outputs cleared.
    b.dx(t(2), MASTER, &[1, 2]);
    assert_eq!(
        b.dx(t(3), MASTER, &[1, 2, 3]).status(),
        Some(ResponseStatus::Rs)
    );
    assert_eq!(b.slave.state(), SlaveState::WaitPrm);
    assert_eq!(b.slave.device().outputs, vec![0, 0]);
    assert_eq!(b.slave.device().clears, vec![ClearReason::LeftDataExchange]);
}

#[test]
fn fail_safe_master_sends_no_outputs() {
    let f = Features {
        dpv1: true,
        fail_safe: true,
        ..Features::default()
    };
    let mut b = Bench::new(TestDevice::with(f));
    b.start(t(0), &[prm(LOCK_WD), vec![0x40, 0, 0]].concat());
    b.dx(t(1), MASTER, &[5, 6]);
    assert_eq!(b.slave.device().outputs, vec![5, 6]);
    let a = b.dx(t(2), MASTER, &[]);
    assert_eq!(a.status(), Some(ResponseStatus::Dl));
    assert_eq!(a.data().len(), 3);
    assert_eq!(b.slave.device().outputs, vec![0, 0]);
    b.dx(t(3), MASTER, &[]);
    assert_eq!(b.slave.device().clears, vec![ClearReason::FailSafe]);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
}

#[test]
fn lock_belongs_to_the_parameterising_master() {
    let mut b = Bench::new(TestDevice::new());
    b.start(t(0), &prm(LOCK_WD));
    b.events();
    // Another master's Set_Prm and Chk_Cfg are acknowledged and ignored.
    assert_eq!(b.sap(t(1), OTHER, sap::SET_PRM, &prm(0x80)), Ans::Sc);
    assert_eq!(b.sap(t(1), OTHER, sap::CHK_CFG, &CFG), Ans::Sc);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    assert_eq!(b.slave.master(), Some(MASTER));
    let refusals = b
        .events()
        .into_iter()
        .filter(|e| matches!(e, SlaveEvent::Refused { master: OTHER, .. }))
        .count();
    assert_eq!(refusals, 2);
    // It gets diagnosis (naming the owner) and the inputs.
    let d = b.diag(t(2), OTHER);
    assert_eq!(diag(&d).master_address, MASTER);
    let a = b.sap(t(2), OTHER, sap::RD_INP, &[]);
    assert_eq!(a.data().len(), 3);
    b.dx(t(2), MASTER, &[0x11, 0x22]);
    assert_eq!(b.sap(t(2), OTHER, sap::RD_OUTP, &[]).data(), &[0x11, 0x22]);
    // The owner unlocks: the slave is free for the other master.
    assert_eq!(b.sap(t(3), MASTER, sap::SET_PRM, &prm(0x40)), Ans::Sc);
    assert_eq!(b.slave.state(), SlaveState::WaitPrm);
    assert_eq!(b.slave.master(), None);
    assert_eq!(b.slave.device().outputs, vec![0, 0]);
    assert_eq!(b.sap(t(4), OTHER, sap::SET_PRM, &prm(0x80)), Ans::Sc);
    assert_eq!(b.slave.master(), Some(OTHER));
    assert_eq!(b.slave.watchdog(), None);
}

#[test]
fn prm_without_lock_only_updates_min_tsdr() {
    let mut b = Bench::new(TestDevice::new());
    b.start(t(0), &prm(LOCK_WD));
    assert_eq!(b.slave.min_tsdr(), 11);
    let mut p = prm(0x00);
    p[3] = 40;
    assert_eq!(b.sap(t(1), MASTER, sap::SET_PRM, &p), Ans::Sc);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    assert_eq!(b.slave.min_tsdr(), 40);
    // min TSDR 0 keeps the value.
    let mut p = prm(LOCK_WD);
    p[3] = 0;
    b.start(t(2), &p);
    assert_eq!(b.slave.min_tsdr(), 40);
}

#[test]
fn new_set_prm_in_data_exch_goes_to_wait_cfg() {
    let mut b = Bench::new(TestDevice::new());
    b.start(t(0), &prm(LOCK_WD));
    b.dx(t(1), MASTER, &[3, 4]);
    assert_eq!(b.sap(t(2), MASTER, sap::SET_PRM, &prm(LOCK_WD)), Ans::Sc);
    assert_eq!(b.slave.state(), SlaveState::WaitCfg);
    assert_eq!(b.slave.device().outputs, vec![0, 0]);
    assert_eq!(
        b.dx(t(3), MASTER, &[3, 4]).status(),
        Some(ResponseStatus::Rs)
    );
}

fn sync_freeze() -> TestDevice {
    TestDevice::with(Features {
        sync: true,
        freeze: true,
        ..Features::default()
    })
}

#[test]
fn sync_holds_outputs_until_the_next_sync() {
    let mut b = Bench::new(sync_freeze());
    b.start(t(0), &prm(LOCK_WD | 0x20));
    b.dx(t(1), MASTER, &[1, 1]);
    assert_eq!(b.slave.device().outputs, vec![1, 1]);
    b.broadcast_gc(t(2), MASTER, 0x20, 0); // Sync
    assert!(b.slave.sync_mode());
    let d = b.diag(t(2), MASTER);
    assert!(diag(&d).status2.contains(StationStatus2::SYNC_MODE));
    b.dx(t(3), MASTER, &[2, 2]);
    b.dx(t(4), MASTER, &[3, 3]);
    assert_eq!(b.slave.device().outputs, vec![1, 1], "held in sync mode");
    b.broadcast_gc(t(5), MASTER, 0x20, 0);
    assert_eq!(
        b.slave.device().outputs,
        vec![3, 3],
        "latest applied at Sync"
    );
    b.dx(t(6), MASTER, &[4, 4]);
    assert_eq!(b.slave.device().outputs, vec![3, 3]);
    // Sync + Unsync: Unsync wins; outputs flow again from the next DX.
    b.broadcast_gc(t(7), MASTER, 0x30, 0);
    assert!(!b.slave.sync_mode());
    b.dx(t(8), MASTER, &[5, 5]);
    assert_eq!(b.slave.device().outputs, vec![5, 5]);
    // A Global_Control from another master, or to another group, is ignored.
    b.broadcast_gc(t(9), OTHER, 0x20, 0);
    assert!(!b.slave.sync_mode());
    b.broadcast_gc(t(9), MASTER, 0x20, 0x04);
    assert!(!b.slave.sync_mode());
}

#[test]
fn freeze_latches_inputs() {
    let mut b = Bench::new(sync_freeze());
    let mut p = prm(LOCK_WD | 0x10);
    p[6] = 0x02; // group 2
    b.start(t(0), &p);
    let a1 = b.dx(t(1), MASTER, &[0, 0]);
    assert_eq!(a1.data(), &[1, 1, 1]);
    b.broadcast_gc(t(2), MASTER, 0x08, 0x02); // Freeze, group 2
    assert!(b.slave.freeze_mode());
    let frozen = b.dx(t(3), MASTER, &[0, 0]).data().to_vec();
    assert_eq!(frozen, vec![2, 2, 2], "latched at the Freeze command");
    assert_eq!(b.dx(t(4), MASTER, &[0, 0]).data(), &frozen[..]);
    assert_eq!(b.sap(t(4), OTHER, sap::RD_INP, &[]).data(), &frozen[..]);
    b.broadcast_gc(t(5), MASTER, 0x08, 0); // Freeze again: re-latch
    assert_eq!(b.dx(t(6), MASTER, &[0, 0]).data(), &[3, 3, 3]);
    b.broadcast_gc(t(7), MASTER, 0x0C, 0); // Freeze + Unfreeze: Unfreeze
    assert!(!b.slave.freeze_mode());
    assert_eq!(b.dx(t(8), MASTER, &[0, 0]).data(), &[4, 4, 4]);
}

#[test]
fn unsupported_sync_is_ignored_and_clear_data_clears() {
    let mut b = Bench::new(TestDevice::new());
    b.start(t(0), &prm(LOCK_WD));
    b.dx(t(1), MASTER, &[8, 8]);
    b.broadcast_gc(t(2), MASTER, 0x20, 0);
    assert!(!b.slave.sync_mode());
    b.dx(t(3), MASTER, &[9, 9]);
    assert_eq!(b.slave.device().outputs, vec![9, 9]);
    b.events();
    b.broadcast_gc(t(4), MASTER, 0x02, 0); // Clear_Data
    assert_eq!(b.slave.device().outputs, vec![0, 0]);
    b.dx(t(5), MASTER, &[6, 6]);
    assert_eq!(b.slave.device().outputs, vec![0, 0], "held clear");
    b.broadcast_gc(t(6), MASTER, 0x02, 0); // repeated: no new event
    b.broadcast_gc(t(7), MASTER, 0x00, 0); // Operate
    b.dx(t(8), MASTER, &[6, 6]);
    assert_eq!(b.slave.device().outputs, vec![6, 6]);
    let gcs: Vec<_> = b
        .events()
        .into_iter()
        .filter(|e| matches!(e, SlaveEvent::GlobalControl { .. }))
        .collect();
    assert_eq!(gcs.len(), 2, "{gcs:?}");
    assert_eq!(b.slave.device().clears, vec![ClearReason::ClearData]);
}

#[test]
fn new_diagnosis_is_announced_with_data_high() {
    let mut dev = TestDevice::new();
    dev.ext = vec![0xEF, 0xCD];
    let mut b = Bench::new(dev);
    b.start(t(0), &prm(LOCK_WD));
    assert_eq!(
        b.dx(t(1), MASTER, &[0, 0]).status(),
        Some(ResponseStatus::Dl)
    );
    b.slave.device_mut().new_diag = true;
    b.slave.device_mut().ext_diag = true;
    assert_eq!(
        b.dx(t(2), MASTER, &[0, 0]).status(),
        Some(ResponseStatus::Dh)
    );
    assert_eq!(
        b.dx(t(3), MASTER, &[0, 0]).status(),
        Some(ResponseStatus::Dh)
    );
    // Another master's diagnosis read does not count.
    b.diag(t(4), OTHER);
    assert_eq!(
        b.dx(t(4), MASTER, &[0, 0]).status(),
        Some(ResponseStatus::Dh)
    );
    let d = b.diag(t(5), MASTER);
    let sd = diag(&d);
    assert!(sd.status1.contains(StationStatus1::EXT_DIAG));
    assert_eq!(
        ext_blocks(sd.ext_diag).collect::<Vec<_>>(),
        vec![ExtDiagBlock::Device {
            data: &[0xEF, 0xCD]
        }]
    );
    assert_eq!(
        b.dx(t(6), MASTER, &[0, 0]).status(),
        Some(ResponseStatus::Dl)
    );
    // Static diagnosis keeps DH until it clears.
    b.slave.device_mut().stat_diag = true;
    b.slave.device_mut().new_diag = true;
    b.dx(t(7), MASTER, &[0, 0]);
    let d = b.diag(t(8), MASTER);
    assert!(diag(&d).status2.contains(StationStatus2::STAT_DIAG));
    assert_eq!(
        b.dx(t(9), MASTER, &[0, 0]).status(),
        Some(ResponseStatus::Dh)
    );
    b.slave.device_mut().stat_diag = false;
    b.diag(t(10), MASTER);
    assert_eq!(
        b.dx(t(11), MASTER, &[0, 0]).status(),
        Some(ResponseStatus::Dl)
    );
}

#[test]
fn diagnosis_overflow_respects_max_diag_len() {
    let mut dev = TestDevice::with(Features {
        max_diag_len: 10,
        ..Features::default()
    });
    dev.ext = vec![1, 2, 3, 4, 5];
    let mut b = Bench::new(dev);
    let d = b.diag(t(0), MASTER);
    assert_eq!(d.len(), 6, "the 6-byte block does not fit into 4");
    assert!(diag(&d).status3.contains(StationStatus3::EXT_DIAG_OVERFLOW));
    b.slave.device_mut().ext = vec![1, 2, 3];
    let d = b.diag(t(0), MASTER);
    assert_eq!(d.len(), 10);
    assert_eq!(d[2], 0);
}

#[test]
fn no_inputs_answers_short_ack_or_dh() {
    struct OutOnly;
    impl Device for OutOnly {
        fn ident_number(&self) -> u16 {
            IDENT
        }
        fn real_cfg(&self) -> &[u8] {
            &[0x20]
        }
        fn check_prm(&mut self, _: &SetPrm<'_>) -> Result<(), Reason> {
            Ok(())
        }
        fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
            expect_cfg(&[0x20], cfg)
        }
        fn write_outputs(&mut self, _: Instant, _: &[u8]) {}
        fn read_inputs(&mut self, _: Instant, _: &mut [u8]) {}
        fn take_new_diag(&mut self) -> bool {
            true
        }
    }
    let mut s = DpSlave::new(OutOnly, ADDR);
    let mut out = [0u8; 246];
    let mk = |dsap: Option<u8>, data: &'static [u8]| {
        let fc = FunctionCode::request(RequestKind::SrdHigh);
        DataTelegram::new(ADDR, MASTER, fc, data).with_saps(dsap, dsap.map(|_| 62))
    };
    s.on_request(
        t(0),
        &mk(Some(61), &[0x80, 1, 1, 0, 0x47, 0x11, 0]),
        &mut out,
    );
    s.on_request(t(0), &mk(Some(62), &[0x20]), &mut out);
    assert_eq!(s.state(), SlaveState::DataExch);
    let r = s.on_request(t(0), &mk(None, &[1]), &mut out);
    assert!(matches!(
        r,
        Reply::Data {
            status: ResponseStatus::Dh,
            len: 0,
            ..
        }
    ));
}

fn dpv1_device() -> TestDevice {
    let mut d = TestDevice::with(Features {
        dpv1: true,
        c1_read_write: true,
        alarms: true,
        ..Features::default()
    });
    d.record = vec![0xA1, 0xA2, 0xA3];
    d
}

fn dpv1_prm() -> Vec<u8> {
    [prm(LOCK_WD), vec![0x80, 0x20, 0x00]].concat()
}

#[test]
fn dpv1_read_polls_until_the_device_is_ready() {
    let mut dev = dpv1_device();
    dev.c1_delay = 2;
    let mut b = Bench::new(dev);
    b.start(t(0), &dpv1_prm());
    // Request: SC. Polls: SC while pending, then the data.
    assert_eq!(b.sap(t(1), MASTER, 51, &[0x5E, 1, 2, 8]), Ans::Sc);
    assert_eq!(b.sap(t(2), MASTER, 51, &[]), Ans::Sc);
    assert_eq!(
        b.sap(t(3), MASTER, 51, &[]),
        Ans::Data(
            ResponseStatus::Dl,
            Some(51),
            Some(51),
            vec![0x5E, 1, 2, 3, 0xA1, 0xA2, 0xA3]
        )
    );
    assert_eq!(b.sap(t(4), MASTER, 51, &[]), Ans::Sc, "nothing pending");
    // Immediate answer: still SC first, data on the first poll.
    b.slave.device_mut().c1_delay = 0;
    assert_eq!(b.sap(t(5), MASTER, 51, &[0x5E, 1, 2, 2]), Ans::Sc);
    assert_eq!(
        b.sap(t(6), MASTER, 51, &[]).data(),
        &[0x5E, 1, 2, 2, 0xA1, 0xA2]
    );
    // Errors come back as error PDUs.
    b.sap(t(7), MASTER, 51, &[0x5E, 9, 2, 2]);
    assert_eq!(b.sap(t(8), MASTER, 51, &[]).data(), &[0xDE, 0x80, 0xB2, 0]);
    b.sap(t(9), MASTER, 51, &[0x5F, 1, 2, 3, 1, 2]); // length byte 3, 2 bytes
    assert_eq!(b.sap(t(10), MASTER, 51, &[]).data(), &[0xDF, 0x80, 0xB1, 0]);
    b.sap(t(11), MASTER, 51, &[0x17]);
    assert_eq!(b.sap(t(12), MASTER, 51, &[]).data(), &[0x97, 0x80, 0xA9, 0]);
}

#[test]
fn dpv1_write_and_gating() {
    let mut b = Bench::new(dpv1_device());
    // Not in Data_Exch: RS.
    assert_eq!(
        b.sap(t(0), MASTER, 51, &[0x5E, 1, 2, 8]).status(),
        Some(ResponseStatus::Rs)
    );
    b.start(t(0), &dpv1_prm());
    assert_eq!(b.sap(t(1), MASTER, 51, &[0x5F, 1, 2, 2, 7, 8]), Ans::Sc);
    assert_eq!(
        b.sap(t(2), MASTER, 51, &[]).data(),
        &[0x5F, 1, 2, 2],
        "write response"
    );
    assert_eq!(b.slave.device().record, vec![7, 8]);
    // Another master: RS.
    assert_eq!(
        b.sap(t(3), OTHER, 51, &[0x5E, 1, 2, 8]).status(),
        Some(ResponseStatus::Rs)
    );
    // Without DPV1_Enable: RS.
    let mut b = Bench::new(dpv1_device());
    b.start(t(0), &[prm(LOCK_WD), vec![0x00, 0x00, 0x00]].concat());
    assert_eq!(
        b.sap(t(1), MASTER, 51, &[0x5E, 1, 2, 8]).status(),
        Some(ResponseStatus::Rs)
    );
}

#[test]
fn alarm_ack_reaches_the_device() {
    let mut dev = dpv1_device();
    dev.own_alarms = true;
    let mut b = Bench::new(dev);
    b.start(t(0), &dpv1_prm());
    let a = b.sap(t(1), MASTER, sap::ALARM_ACK, &[0x5C, 3, 1, 0x2D]);
    assert_eq!(
        a,
        Ans::Data(
            ResponseStatus::Dl,
            Some(51),
            Some(50),
            vec![0x5C, 3, 1, 0x2D]
        )
    );
    assert_eq!(b.slave.device().acked, vec![(3, 1, 5)]);
    let a = b.sap(t(1), MASTER, sap::ALARM_ACK, &[0x5C, 3]);
    assert_eq!(a.data()[0], 0xDC);
}

#[test]
fn set_slave_add_rules() {
    let f = Features {
        set_slave_add: true,
        ..Features::default()
    };
    let mut b = Bench::new(TestDevice::with(f));
    // Wrong ident, address too high: RS.
    assert_eq!(
        b.sap(t(0), MASTER, sap::SET_SLAVE_ADD, &[5, 0x12, 0x34, 0])
            .status(),
        Some(ResponseStatus::Rs)
    );
    assert_eq!(
        b.sap(t(0), MASTER, sap::SET_SLAVE_ADD, &[126, 0x47, 0x11, 0])
            .status(),
        Some(ResponseStatus::Rs)
    );
    assert_eq!(
        b.sap(t(0), MASTER, sap::SET_SLAVE_ADD, &[5, 0x47, 0x11, 0]),
        Ans::Sc
    );
    assert_eq!(b.slave.address(), 5);
    assert_eq!(b.slave.device().persisted, Some((5, false)));
    // No_Add_Chg: accepted once, then no more changes.
    assert_eq!(
        b.sap(t(0), MASTER, sap::SET_SLAVE_ADD, &[6, 0x47, 0x11, 1]),
        Ans::Sc
    );
    assert_eq!(
        b.sap(t(0), MASTER, sap::SET_SLAVE_ADD, &[7, 0x47, 0x11, 0])
            .status(),
        Some(ResponseStatus::Rs)
    );
    assert_eq!(b.slave.address(), 6);
    assert!(b.events().iter().any(|e| matches!(
        e,
        SlaveEvent::AddressChanged {
            old: 5,
            new: 6,
            no_add_chg: true
        }
    )));
    // Not supported / not in Wait_Prm / refused by the device.
    let mut b = Bench::new(TestDevice::new());
    assert_eq!(
        b.sap(t(0), MASTER, sap::SET_SLAVE_ADD, &[5, 0x47, 0x11, 0])
            .status(),
        Some(ResponseStatus::Rs)
    );
    let mut b = Bench::new(TestDevice::with(f));
    b.start(t(0), &prm(LOCK_WD));
    assert_eq!(
        b.sap(t(0), MASTER, sap::SET_SLAVE_ADD, &[5, 0x47, 0x11, 0])
            .status(),
        Some(ResponseStatus::Rs)
    );
    let mut dev = TestDevice::with(f);
    dev.address_refused = true;
    let mut b = Bench::new(dev);
    assert_eq!(
        b.sap(t(0), MASTER, sap::SET_SLAVE_ADD, &[5, 0x47, 0x11, 0])
            .status(),
        Some(ResponseStatus::Rs)
    );
    assert_eq!(b.slave.address(), ADDR);
}

#[test]
fn unknown_saps_and_odd_requests() {
    let mut b = Bench::new(TestDevice::new());
    for dsap in [0u8, 20, 48, 49, 52, 63, 0x40 | 60] {
        assert_eq!(
            b.sap(t(0), MASTER, dsap, &[1, 2]),
            Ans::Data(ResponseStatus::Rs, None, None, vec![]),
            "SAP {dsap}"
        );
    }
    // Only one SAP byte.
    let a = b.req(t(0), MASTER, RequestKind::SrdHigh, None, &[]);
    assert_eq!(a.status(), Some(ResponseStatus::Rs));
    // SDA to a DP SAP: SAP not activated for that service.
    let a = b.req(
        t(0),
        MASTER,
        RequestKind::SdaHigh,
        Some((sap::SLAVE_DIAG, 62)),
        &[],
    );
    assert_eq!(a, Ans::Data(ResponseStatus::Rs, None, None, vec![]));
    // SDN to the slave is never answered.
    let a = b.req(
        t(0),
        MASTER,
        RequestKind::SdnHigh,
        Some((sap::SLAVE_DIAG, 62)),
        &[],
    );
    assert_eq!(a, Ans::Silence);
}

fn wire_request(da: u8, sa: u8, fc: u8, saps: Option<(u8, u8)>, data: &[u8]) -> Vec<u8> {
    let t = DataTelegram::new(da, sa, FunctionCode::from_byte(fc), data)
        .with_saps(saps.map(|s| s.0), saps.map(|s| s.1));
    Telegram::Data(t).to_vec().unwrap()
}

/// The passive station plus the slave, at the byte level.
fn wire<R: Responder>(st: &mut PassiveStation<R>, now: Instant, bytes: &[u8]) -> Vec<u8> {
    st.handle_rx(now, bytes);
    let mut at = now;
    for _ in 0..4 {
        if let Some(b) = st.poll_transmit(at) {
            return b.to_vec();
        }
        match st.poll_timeout() {
            Some(d) if d <= now + Duration::from_millis(1) => {
                at = d;
                st.handle_timeout(at);
            }
            _ => break,
        }
    }
    vec![]
}

#[test]
fn on_the_wire_with_the_passive_station() {
    let mut st = PassiveStation::new(
        DpSlave::new(TestDevice::new(), ADDR),
        BusParams::defaults(Baud::B1500000),
    );
    // Data_Exchange before parameterisation: RS as in the trace of pyprofibus issue #19.
    let r = wire(
        &mut st,
        t(0),
        &wire_request(ADDR, MASTER, 0x7D, None, &[1, 2]),
    );
    assert_eq!(r, vec![0x10, 0x02, 0x08, 0x03, 0x0D, 0x16]);
    // Slave_Diag (SRD low, as profirust sends it).
    let r = wire(
        &mut st,
        t(1),
        &wire_request(ADDR, MASTER, 0x6C, Some((60, 62)), &[]),
    );
    let (tg, _) = Telegram::parse(&r).unwrap();
    let d = tg.as_data().unwrap();
    assert_eq!((d.dsap, d.ssap), (Some(62), Some(60)));
    assert_eq!(d.data, &[0x02, 0x05, 0x00, 0xFF, 0x47, 0x11]);
    // Set_Prm with min TSDR 60, Chk_Cfg.
    let mut p = prm(LOCK_WD);
    p[3] = 60;
    let r = wire(
        &mut st,
        t(2),
        &wire_request(ADDR, MASTER, 0x5D, Some((61, 62)), &p),
    );
    assert_eq!(r, vec![0xE5]);
    // From now on responses wait 60 bit times.
    st.handle_rx(
        t(3),
        &wire_request(ADDR, MASTER, 0x7D, Some((62, 62)), &CFG),
    );
    let due = st.poll_timeout().unwrap();
    assert_eq!(due, t(3) + BusParams::defaults(Baud::B1500000).bits(60));
    assert!(st
        .poll_transmit(Instant::from_nanos(due.as_nanos() - 1))
        .is_none());
    assert_eq!(st.poll_transmit(due), Some(&[0xE5u8][..]));
    // Data_Exchange: SD2 with the inputs.
    let r = wire(
        &mut st,
        t(4),
        &wire_request(ADDR, MASTER, 0x5D, None, &[1, 2]),
    );
    assert_eq!(
        r,
        vec![0x68, 0x06, 0x06, 0x68, 0x02, 0x08, 0x08, 1, 1, 1, 0x15, 0x16]
    );
    // Global_Control broadcast (SDN low, as profirust sends it): no answer.
    let r = wire(
        &mut st,
        t(5),
        &wire_request(127, MASTER, 0x44, Some((58, 62)), &[0x00, 0x00]),
    );
    assert!(r.is_empty());
    assert_eq!(st.app().state(), SlaveState::DataExch);
}

#[test]
fn dp_saps_serve_srd_only() {
    let rs = Ans::Data(ResponseStatus::Rs, None, None, vec![]);
    let mut b = Bench::new(TestDevice::new());
    let prm = prm(LOCK_WD);
    for kind in [RequestKind::SdaHigh, RequestKind::SdaLow, RequestKind::Msrd] {
        // Set_Prm, Chk_Cfg and Slave_Diag sent with another FDL service:
        // "SAP not activated", and nothing is executed.
        let set_prm = b.req(t(0), MASTER, kind, Some((sap::SET_PRM, sap::MASTER)), &prm);
        assert_eq!(set_prm, rs, "{kind:?}");
        assert_eq!(b.slave.state(), SlaveState::WaitPrm, "{kind:?}");
        let diag = b.req(
            t(0),
            MASTER,
            kind,
            Some((sap::SLAVE_DIAG, sap::MASTER)),
            &[],
        );
        assert_eq!(diag, rs, "{kind:?}");
    }
    b.start(t(1), &prm);
    let refused = b.slave.stats().refused;
    let chk = b.req(
        t(2),
        MASTER,
        RequestKind::SdaHigh,
        Some((sap::CHK_CFG, sap::MASTER)),
        &[0x11],
    );
    assert_eq!(chk, rs);
    let dx = b.req(t(2), MASTER, RequestKind::SdaHigh, None, &[9, 9]);
    assert_eq!(dx, rs);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    assert_eq!(
        b.slave.device().writes,
        0,
        "the SDA's outputs were not taken"
    );
    assert_eq!(b.slave.stats().refused, refused + 2);
    assert!(b.events().iter().any(|e| matches!(
        e,
        SlaveEvent::Refused {
            service: Service::Sap(Sap::ChkCfg),
            ..
        }
    )));
}

/// A device whose PLC sets the station address at run time and restarts
/// the bus interface (the JX2-PROFI1's register 1x107 and command 5).
#[derive(Debug, Default)]
struct PlcModule {
    address: Option<u8>,
    restart: bool,
    states: Vec<SlaveState>,
    prm_refusals: u32,
}

impl Device for PlcModule {
    fn ident_number(&self) -> u16 {
        IDENT
    }
    fn real_cfg(&self) -> &[u8] {
        &CFG
    }
    fn check_prm(&mut self, _prm: &SetPrm<'_>) -> Result<(), Reason> {
        Ok(())
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        expect_cfg(&CFG, cfg)
    }
    fn write_outputs(&mut self, _now: Instant, _outputs: &[u8]) {}
    fn read_inputs(&mut self, _now: Instant, _inputs: &mut [u8]) {}
    fn own_address(&self) -> OwnAddress {
        self.address.map_or(OwnAddress::NoneYet, OwnAddress::Set)
    }
    fn take_restart(&mut self) -> bool {
        std::mem::take(&mut self.restart)
    }
    fn state_changed(&mut self, _now: Instant, state: SlaveState) {
        self.states.push(state);
    }
    fn prm_refused(&mut self, _now: Instant, _reason: &Reason) {
        self.prm_refusals += 1;
    }
}

#[test]
fn a_device_sets_its_address_and_restarts_the_slave() {
    let mut s = DpSlave::new(PlcModule::default(), ADDR);
    assert_eq!(s.address(), NO_ADDRESS, "no address yet: off the bus");
    let mut out = [0u8; 246];
    let req = |da: u8, dsap: Option<u8>, data: &'static [u8]| {
        let fc = FunctionCode::request(RequestKind::SrdHigh);
        DataTelegram::new(da, MASTER, fc, data).with_saps(dsap, dsap.map(|_| sap::MASTER))
    };
    assert_eq!(
        s.on_request(t(0), &req(ADDR, Some(sap::SLAVE_DIAG), &[]), &mut out),
        Reply::Silence
    );
    s.device_mut().address = Some(9);
    assert_eq!(s.address(), 9);
    let p: &'static [u8] = &[0x80, 1, 1, 0, 0x47, 0x11, 0];
    assert_eq!(
        s.on_request(t(1), &req(9, Some(sap::SET_PRM), p), &mut out),
        Reply::ShortAck
    );
    let c: &'static [u8] = &CFG;
    s.on_request(t(2), &req(9, Some(sap::CHK_CFG), c), &mut out);
    assert_eq!(s.state(), SlaveState::DataExch);
    assert_eq!(
        s.device().states,
        [SlaveState::WaitCfg, SlaveState::DataExch]
    );
    // A wrong ident number: the device hears of the refusal.
    let bad: &'static [u8] = &[0x80, 1, 1, 0, 0x12, 0x34, 0];
    s.on_request(t(3), &req(9, Some(sap::SET_PRM), bad), &mut out);
    assert_eq!(s.device().prm_refusals, 1);
    s.on_request(t(4), &req(9, Some(sap::SET_PRM), p), &mut out);
    s.on_request(t(5), &req(9, Some(sap::CHK_CFG), c), &mut out);
    assert_eq!(s.state(), SlaveState::DataExch);
    // The device restarts: back to Wait_Prm without a master, faults
    // forgotten.
    s.device_mut().restart = true;
    s.handle_timeout(t(6));
    assert_eq!(s.state(), SlaveState::WaitPrm);
    assert_eq!(s.master(), None);
    s.on_request(t(7), &req(9, Some(sap::SET_PRM), bad), &mut out);
    let a = s.on_request(t(8), &req(9, Some(sap::SLAVE_DIAG), &[]), &mut out);
    assert!(matches!(a, Reply::Data { .. }));
    assert_ne!(out[0] & 0x40, 0, "Prm_Fault");
    s.device_mut().restart = true;
    let a = s.on_request(t(9), &req(9, Some(sap::SLAVE_DIAG), &[]), &mut out);
    assert!(matches!(a, Reply::Data { .. }));
    assert_eq!(out[0] & 0x40, 0, "no Prm_Fault after the restart");
    // Without an address again: silent.
    s.device_mut().address = None;
    assert_eq!(
        s.on_request(t(10), &req(9, Some(sap::SLAVE_DIAG), &[]), &mut out),
        Reply::Silence
    );
}

#[test]
fn dpv1_lengths_are_checked_against_c1_max_data_len() {
    // C1_Max_Data_Len = 32, as in the DP-V1 GSD of the observation.
    let mut dev = dpv1_device();
    dev.features.c1_max_data_len = 32;
    let mut b = Bench::new(dev);
    b.start(t(0), &dpv1_prm());
    let ask = |b: &mut Bench, req: Vec<u8>| -> Vec<u8> {
        assert_eq!(b.sap(t(1), MASTER, 51, &req), Ans::Sc, "{req:02X?}");
        b.sap(t(2), MASTER, 51, &[]).data().to_vec()
    };
    // Writes of 33 and 200 bytes: write length error, nothing stored.
    for n in [33usize, 200] {
        let req = [vec![0x5F, 1, 2, n as u8], vec![0xEE; n]].concat();
        assert_eq!(ask(&mut b, req), [0xDF, 0x80, 0xB1, 0], "write of {n}");
    }
    // A write of no data at all.
    assert_eq!(ask(&mut b, vec![0x5F, 1, 2, 0]), [0xDF, 0x80, 0xB1, 0]);
    assert_eq!(b.slave.device().record, vec![0xA1, 0xA2, 0xA3]);
    // Reads of 0, 33 and 241 bytes: invalid range.
    for n in [0u8, 33, 241] {
        assert_eq!(
            ask(&mut b, vec![0x5E, 1, 2, n]),
            [0xDE, 0x80, 0xB7, 0],
            "read of {n}"
        );
    }
    // Within the limit both work.
    // A length byte of 32 with 1 byte of data is malformed: write length.
    assert_eq!(
        ask(&mut b, vec![0x5F, 1, 2, 32, 0x11]),
        [0xDF, 0x80, 0xB1, 0]
    );
    let req = [vec![0x5F, 1, 2, 32], vec![0x55; 32]].concat();
    assert_eq!(ask(&mut b, req), [0x5F, 1, 2, 32]);
    assert_eq!(ask(&mut b, vec![0x5E, 1, 2, 32])[..4], [0x5E, 1, 2, 32]);
}

// ----- DP-V1 alarm queue ------------------------------------------------

fn alarm(t: crate::pdu::alarm::AlarmType, slot: u8, change: u8, data: &[u8]) -> Alarm {
    Alarm {
        alarm_type: t,
        slot,
        change: crate::pdu::alarm::AlarmChange::from_bits(change),
        add_ack: false,
        data: data.to_vec(),
    }
}

/// DPV1_Enable, diagnostic and process alarms (0x20 | 0x40), `mode`.
fn alarm_prm(mode: u8) -> Vec<u8> {
    [prm(LOCK_WD), vec![0x80, 0x60, mode]].concat()
}

fn ack(b: &mut Bench, now: Instant, bytes: &[u8]) -> Vec<u8> {
    b.sap(now, MASTER, sap::ALARM_ACK, bytes).data().to_vec()
}

#[test]
fn alarms_wait_in_slave_diag_until_acknowledged_in_sequence() {
    use crate::pdu::alarm::AlarmType::{Diagnostic, Process};
    let mut b = Bench::new(dpv1_device());
    b.start(t(0), &alarm_prm(1)); // sequence mode, 2 outstanding
    b.events();
    b.slave
        .raise_alarm(alarm(Diagnostic, 2, 1, &[0xAA]))
        .unwrap();
    b.slave.raise_alarm(alarm(Process, 3, 1, &[])).unwrap();
    b.slave.raise_alarm(alarm(Diagnostic, 2, 2, &[])).unwrap();
    assert_eq!(
        b.dx(t(1), MASTER, &[0, 0]).status(),
        Some(ResponseStatus::Dh)
    );
    // Two outstanding blocks (dpv1-c2-im-alarms.md §4.5: length, type,
    // slot, seq << 3 | appears, data); the third waits. Ext_Diag set.
    let d = b.diag(t(2), MASTER);
    assert_eq!(d[0] & 0x08, 0x08, "Ext_Diag");
    assert_eq!(
        &d[6..],
        &[0x05, 0x01, 0x02, 0x01, 0xAA, 0x04, 0x02, 0x03, 0x09]
    );
    // Seq 1 before seq 0: refused, both stay.
    assert_eq!(
        ack(&mut b, t(3), &[0x5C, 3, 2, 0x09]),
        [0xDC, 0x80, 0xB5, 0x00]
    );
    assert!(b.events().iter().any(|e| matches!(
        e,
        SlaveEvent::Refused {
            reason: Reason::AlarmAck(AckError::OutOfOrder {
                seq: 1,
                expected: 0
            }),
            ..
        }
    )));
    assert_eq!(b.diag(t(4), MASTER), d);
    // Seq 0: echoed; the third alarm (seq 2, disappears) comes in.
    assert_eq!(ack(&mut b, t(5), &[0x5C, 2, 1, 0x01]), [0x5C, 2, 1, 0x01]);
    assert_eq!(
        b.dx(t(6), MASTER, &[0, 0]).status(),
        Some(ResponseStatus::Dh)
    );
    let d = b.diag(t(7), MASTER);
    assert_eq!(&d[6..], &[0x04, 0x02, 0x03, 0x09, 0x04, 0x01, 0x02, 0x12]);
    // An alarm that is not outstanding (seq 0 again): negative.
    assert_eq!(ack(&mut b, t(8), &[0x5C, 2, 1, 0x01])[0], 0xDC);
    assert_eq!(ack(&mut b, t(9), &[0x5C, 3, 2, 0x09]), [0x5C, 3, 2, 0x09]);
    assert_eq!(ack(&mut b, t(10), &[0x5C, 2, 1, 0x12]), [0x5C, 2, 1, 0x12]);
    let d = b.diag(t(11), MASTER);
    assert_eq!(d.len(), 6, "all acknowledged: no blocks");
    assert_eq!(d[0] & 0x08, 0, "no Ext_Diag");
    let acked = b
        .events()
        .into_iter()
        .filter(|e| matches!(e, SlaveEvent::Alarm(a) if a.action == AlarmAction::Acknowledged))
        .count();
    assert_eq!(acked, 3);
}

#[test]
fn type_mode_keeps_one_alarm_per_type_outstanding() {
    use crate::pdu::alarm::AlarmType::{Diagnostic, Process};
    let mut b = Bench::new(dpv1_device());
    b.start(t(0), &alarm_prm(0));
    b.slave.raise_alarm(alarm(Diagnostic, 1, 1, &[])).unwrap();
    b.slave.raise_alarm(alarm(Diagnostic, 1, 2, &[])).unwrap();
    b.slave.raise_alarm(alarm(Process, 4, 1, &[])).unwrap();
    let d = b.diag(t(1), MASTER);
    // Diagnostic seq 0 and process seq 2; diagnostic seq 1 waits.
    assert_eq!(&d[6..], &[0x04, 0x01, 0x01, 0x01, 0x04, 0x02, 0x04, 0x11]);
    // Type mode: any outstanding alarm may be acknowledged first.
    assert_eq!(ack(&mut b, t(2), &[0x5C, 4, 2, 0x11]), [0x5C, 4, 2, 0x11]);
    assert_eq!(ack(&mut b, t(3), &[0x5C, 1, 1, 0x01]), [0x5C, 1, 1, 0x01]);
    assert_eq!(&b.diag(t(4), MASTER)[6..], &[0x04, 0x01, 0x01, 0x0A]);
}

#[test]
fn alarms_need_enables_fit_the_diagnosis_and_end_with_data_exchange() {
    use crate::pdu::alarm::AlarmType::{Diagnostic, Update};
    let mut dev = dpv1_device();
    dev.features.max_diag_len = 6 + 6; // room for one 6-byte block
    let mut b = Bench::new(dev);
    assert_eq!(
        b.slave.raise_alarm(alarm(Diagnostic, 1, 1, &[])),
        Err(RaiseError::Inactive)
    );
    b.start(t(0), &alarm_prm(7));
    assert_eq!(
        b.slave.raise_alarm(alarm(Update, 1, 1, &[])),
        Err(RaiseError::NotEnabled(Update))
    );
    assert_eq!(
        b.slave.raise_alarm(alarm(Diagnostic, 1, 1, &[0; 60])),
        Err(RaiseError::TooLong(60))
    );
    b.slave
        .raise_alarm(alarm(Diagnostic, 1, 1, &[1, 2]))
        .unwrap();
    b.slave
        .raise_alarm(alarm(Diagnostic, 2, 1, &[3, 4]))
        .unwrap();
    let d = b.diag(t(1), MASTER);
    assert_eq!(
        &d[6..],
        &[0x06, 0x01, 0x01, 0x01, 1, 2],
        "Max_Diag_Data_Len"
    );
    assert_eq!(d[2] & 0x80, 0, "no overflow: the second one waits");
    // A new Set_Prm (leaving Data_Exch) empties the queue.
    b.start(t(2), &alarm_prm(7));
    assert_eq!(b.diag(t(3), MASTER).len(), 6);
    assert_eq!(b.slave.alarms().queued().count(), 0);
}

mod c2;
