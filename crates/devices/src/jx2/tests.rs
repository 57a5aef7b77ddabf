//! The JX2-PROFI1 module: register rules, every error number, the
//! manual's examples, with the DP slave core in front where the bus
//! matters.

use super::script::{Command, Interpreter, Progress};
use super::*;
use profibus_dp::pdu::diag::SlaveDiag;
use profibus_dp::slave::{Device, DpSlave, OwnAddress};
use profibus_fdl::station::passive::{Reply, Responder};
use profibus_fdl::{DataTelegram, FunctionCode, RequestKind, ResponseStatus};
use serde_json::Value;

const MASTER: u8 = 1;

fn t(ms: u64) -> Instant {
    Instant::ZERO + Duration::from_millis(ms)
}

/// A PLC with the module as module 2, a script interpreter and the slave
/// core in front of a clone of the module (the clone is swapped in and
/// out: the slave owns its device).
struct Rig {
    plc: Plc,
    slave: DpSlave<Jx2>,
    now: Instant,
}

impl Rig {
    fn new() -> Rig {
        Rig {
            plc: Plc::new(2).unwrap(),
            slave: DpSlave::new(Jx2::new(), 0),
            now: t(0),
        }
    }

    /// Run script lines (as the PLC), letting time pass while they wait;
    /// returns the replies.
    fn plc(&mut self, lines: &str) -> Vec<Value> {
        let mut it = Interpreter::script(lines).unwrap();
        let mut out = vec![];
        self.sync_in();
        for _ in 0..1000 {
            match it.run(&mut self.plc, self.now) {
                Progress::Idle => break,
                Progress::Waiting(_) | Progress::Busy => {
                    self.now += Duration::from_millis(5);
                    self.plc.module.settle(self.now);
                }
            }
        }
        assert!(it.finished(), "script blocked: {lines}");
        while let Some(r) = it.take_reply() {
            out.push(serde_json::to_value(r).unwrap());
        }
        self.sync_out();
        out
    }

    fn reg(&mut self, r: u32) -> i32 {
        self.sync_in();
        let v = self.plc.read(self.now, r);
        self.sync_out();
        v
    }

    fn sync_in(&mut self) {
        self.plc.module = self.slave.device().clone();
        self.plc.module.events.clear();
    }

    fn sync_out(&mut self) {
        *self.slave.device_mut() = self.plc.module.clone();
        self.slave.handle_timeout(self.now);
    }

    fn req(&mut self, dsap: Option<u8>, data: &[u8]) -> (Reply, Vec<u8>) {
        self.now += Duration::from_millis(1);
        self.slave.handle_timeout(self.now);
        let fc = FunctionCode::request(RequestKind::SrdHigh);
        let req = DataTelegram::new(self.slave.address(), MASTER, fc, data)
            .with_saps(dsap, dsap.map(|_| 62));
        let mut out = [0u8; 246];
        let r = self.slave.on_request(self.now, &req, &mut out);
        let n = match r {
            Reply::Data { len, .. } => len,
            _ => 0,
        };
        (r, out[..n].to_vec())
    }

    fn prm(&mut self, ident: u16) {
        let id = ident.to_be_bytes();
        self.req(Some(61), &[0x80, 1, 1, 0, id[0], id[1], 0, 0x80, 0, 0]);
    }

    fn cfg(&mut self, cfg: &[u8]) {
        self.req(Some(62), cfg);
    }

    fn diag(&mut self) -> Vec<u8> {
        self.req(Some(60), &[]).1
    }

    fn exchange(&mut self, outputs: &[u8]) -> (Reply, Vec<u8>) {
        self.req(None, outputs)
    }

    /// MSAC_C1 request, then polls until an answer or `polls` polls.
    fn c1(&mut self, pdu: &[u8], polls: usize) -> Option<Vec<u8>> {
        let (r, _) = self.req(Some(51), pdu);
        assert_eq!(r, Reply::ShortAck);
        for _ in 0..polls {
            let (r, d) = self.req(Some(51), &[]);
            if let Reply::Data { .. } = r {
                return Some(d);
            }
        }
        None
    }
}

fn ok(v: &Value) -> bool {
    v["ok"] == Value::Bool(true)
}

fn error_of(v: &Value) -> Option<u64> {
    v["error"].as_u64()
}

#[test]
fn reset_values_and_fresh_module() {
    let mut r = Rig::new();
    for (reg, v) in [
        (12100, 1),
        (12101, 0),
        (12102, 4),
        (12103, 4),
        (12107, 0),
        (12112, 300),
        (12113, 400),
        (12114, 4),
        (12115, 4),
        (12116, 700),
        (12117, 800),
        (12118, 0),
        (12124, 0),
        (12126, 500),
        (12127, 600),
        (12128, 0),
        (12139, 0),
        (12199, 103),
        (12300, 0),
        (12304, NOT_CONFIGURED),
        (12400, NO_OUTPUT),
        (12700, 0),
    ] {
        assert_eq!(r.reg(reg), v, "register {reg}");
    }
    assert_eq!(r.slave.device().own_address(), OwnAddress::NoneYet);
    assert_eq!(r.slave.address(), profibus_dp::slave::NO_ADDRESS);
    let (reply, _) = r.req(Some(60), &[]);
    assert_eq!(reply, Reply::Silence, "not on the bus without an address");
    let st = r.plc("status");
    assert_eq!(
        st[0]["leds"],
        serde_json::json!({"dx": false, "err": "blinking"})
    );
    // The PLC's own registers are plain memory.
    assert!(ok(&r.plc("write 1000 7\nread 1000")[1]));
    assert_eq!(r.reg(1000), 7);
}

/// Example 1 of the manual (L1499): 16/16 words, station 4.
#[test]
fn basic_program() {
    let mut r = Rig::new();
    let replies = r.plc(
        "wait-bit 12100 13 clear 1s\n\
         write 12102 16\n\
         write 12103 16\n\
         write 12107 4\n\
         read 12100\n\
         wait-bit 12100 13 clear 1s\n",
    );
    assert!(replies.iter().all(ok), "{replies:?}");
    assert_eq!(
        replies[4]["value"].as_i64().unwrap() & status::BUSY as i64,
        status::BUSY as i64,
        "BUSY right after the address write"
    );
    assert_eq!(
        r.reg(12100),
        status::BUFFER_OK | status::ADDRESS_OK | status::INITIALISED
    );
    assert_eq!(r.slave.address(), 4);
    assert_eq!(r.slave.device().real_cfg(), &[0x5F, 0x6F]);
    r.prm(IDENT);
    r.cfg(&[0x5F, 0x6F]);
    assert_eq!(r.reg(12132), 2, "Data_ex");
    assert_ne!(r.reg(12100) & status::DATA_EXCHANGE, 0);
    r.plc("write 12300 0x1234\nwrite 12315 65535");
    let mut out = vec![0u8; 32];
    out[0] = 0xAB;
    out[1] = 0xCD;
    out[31] = 7;
    let (reply, inputs) = r.exchange(&out);
    assert!(matches!(
        reply,
        Reply::Data {
            status: ResponseStatus::Dl,
            ..
        }
    ));
    assert_eq!(inputs.len(), 32);
    assert_eq!(&inputs[..2], &[0x12, 0x34], "high byte first");
    assert_eq!(&inputs[30..], &[0xFF, 0xFF]);
    assert_eq!(r.reg(12400), 0xABCD);
    assert_eq!(r.reg(12415), 7);
    // Output words cannot be written; configuration is frozen.
    let w = r.plc("write 12400 1\nwrite 12102 8");
    assert_eq!(w[0]["ignored"], "output words are written by the master");
    assert!(!ok(&w[1]));
    assert_eq!(r.reg(12102), 16);
    assert_eq!(r.reg(12400), 0xABCD);
}

#[test]
fn error_1_address() {
    let mut r = Rig::new();
    let w = r.plc("write 12107 127");
    assert_eq!(error_of(&w[0]), Some(1), "out of range");
    let w = r.plc("write 12101 6\nwrite 12107 5\nwrite 12107 6");
    assert!(ok(&w[1]));
    assert_eq!(error_of(&w[2]), Some(1), "already set");
    assert_eq!(r.reg(12107), 5);
    assert_eq!(r.reg(12134), 1);
    assert_ne!(r.reg(12100) & status::ERROR, 0);
    let w = r.plc("write 12101 6\nread 12134");
    assert_eq!(w[1]["value"], 0, "command 6 clears");
    // Invalid buffer configuration.
    let w = r.plc("write 12101 5\nwait-bit 12100 13 clear\nwrite 12112 100\nwrite 12107 5");
    assert_eq!(error_of(&w[2]), Some(2));
    assert_eq!(error_of(&w[3]), Some(1));
}

#[test]
fn error_2_cyclic_areas() {
    for (script, why) in [
        ("write 12102 123", "more than 122 words"),
        (
            "write 12102 101",
            "inputs 300..400 reach the outputs at 400",
        ),
        ("write 12113 302", "outputs inside the inputs"),
        ("write 12112 998", "inputs beyond 999"),
        ("write 12112 299", "below 300"),
        (
            "write 12113 500\nwrite 12116 900\nwrite 12117 950\nwrite 12102 100\nwrite 12103 109",
            "IN + OUT > 208",
        ),
    ] {
        let mut r = Rig::new();
        let w = r.plc(script);
        assert_eq!(error_of(w.last().unwrap()), Some(2), "{why}: {w:?}");
        assert_eq!(r.reg(12100) & status::BUFFER_OK, 0, "{why}");
        assert_eq!(
            r.reg(12300),
            NOT_CONFIGURED,
            "{why}: invalid layout reads -1"
        );
    }
}

#[test]
fn error_3_record_areas() {
    for (script, why) in [
        ("write 12114 0", "read area of 0 registers"),
        ("write 12115 121", "write area over 120"),
        ("write 12116 302", "read area inside the inputs"),
        ("write 12117 702", "write area inside the read area"),
        ("write 12116 998", "read area beyond 999"),
    ] {
        let mut r = Rig::new();
        let w = r.plc(script);
        assert_eq!(error_of(w.last().unwrap()), Some(3), "{why}: {w:?}");
    }
    // The read and write areas may share their start (L1232).
    let mut r = Rig::new();
    let w = r.plc("write 12117 700");
    assert!(ok(&w[0]), "{w:?}");
}

#[test]
fn error_6_init_error_49_memory() {
    let mut r = Rig::new();
    // 104·3 + 104·3 + 12 = 636 > 632, while IN + OUT = 208 is allowed.
    let w = r.plc(
        "write 12112 300\nwrite 12113 500\nwrite 12116 700\nwrite 12117 800\n\
         write 12102 104\nwrite 12103 104\nwrite 12114 12\nwrite 12107 3",
    );
    assert!(w[..7].iter().all(ok), "{w:?}");
    assert_eq!(error_of(&w[7]), Some(6));
    assert_eq!(r.reg(12136), INIT_ERROR_MEMORY);
    assert_eq!(r.reg(12100) & status::ADDRESS_OK, 0, "not initialised");
    // 8 registers fit: 624 + 8 = 632.
    let w = r.plc("write 12101 6\nwrite 12114 8\nwrite 12107 3");
    assert!(w.iter().all(ok), "{w:?}");
    assert_eq!(r.reg(12136), 0);
}

/// A module at station 3 with `in`/`out` words, Set_Prm accepted.
fn online(r: &mut Rig, setup: &str) {
    let w = r.plc(&format!("{setup}\nwrite 12107 3\nwait-bit 12100 2 set 1s"));
    assert!(w.iter().all(ok), "{w:?}");
    assert_eq!(r.slave.address(), 3);
}

#[test]
fn error_7_prm_and_error_8_cfg() {
    let mut r = Rig::new();
    online(&mut r, "");
    r.prm(0x1234);
    assert_eq!(r.reg(12134), 7, "wrong ident number");
    let d = r.diag();
    let sd = SlaveDiag::parse(&d).unwrap();
    assert!(sd
        .status1
        .contains(profibus_dp::pdu::diag::StationStatus1::PRM_FAULT));
    r.plc("write 12101 6");
    r.prm(IDENT);
    assert_eq!(r.reg(12132), 1, "Wait_Cfg");
    assert_eq!(r.reg(12160), 10);
    assert_eq!(r.reg(12161), 0x0180, "bytes 0x80 0x01, low byte first");
    assert_eq!(r.reg(12236), 0x0D);
    r.cfg(&[0x53, 0x65]);
    assert_eq!(r.reg(12134), 8, "6 output words, 4 configured");
    let sd_bytes = r.diag();
    let sd = SlaveDiag::parse(&sd_bytes).unwrap();
    assert!(sd
        .status1
        .contains(profibus_dp::pdu::diag::StationStatus1::CFG_FAULT));
    r.prm(IDENT);
    r.cfg(&[0xD3, 0x63]);
    assert_eq!(
        r.reg(12132),
        2,
        "consistent inputs without a window: more consistency, accepted (L950)"
    );
    r.prm(IDENT);
    r.cfg(&[0x53, 0x63]);
    assert_eq!(r.reg(12132), 2);
    assert_eq!(r.reg(12180), 2);
    assert_eq!(r.reg(12181), 0x6353);
    assert_eq!(r.reg(12265), 0x63);
}

#[test]
fn errors_9_10_diagnosis_and_example_2_kinds() {
    let mut r = Rig::new();
    online(&mut r, "");
    r.prm(IDENT);
    r.cfg(&[0x53, 0x63]);
    let w = r.plc("write 12140 9\nwrite 12140 33");
    assert_eq!(error_of(&w[0]), Some(9));
    assert_eq!(error_of(&w[1]), Some(9));
    let w = r.plc("write 12101 6\nwrite 12140 10\nwrite 12101 8");
    assert_eq!(
        error_of(&w[2]),
        Some(9),
        "extended diagnosis needs > 10 bytes"
    );
    // Diag1: status diagnosis without user data.
    let w = r.plc(
        "write 12101 6\nif r12139 != 0 write 12101 10\nwrite 12140 10\nwrite 12101 7\nread 12139",
    );
    assert_eq!(w[4]["value"], 1, "{w:?}");
    let (reply, _) = r.exchange(&[0; 8]);
    assert!(
        matches!(
            reply,
            Reply::Data {
                status: ResponseStatus::Dh,
                ..
            }
        ),
        "DH announces it"
    );
    let d = r.diag();
    assert_eq!(
        &d[6..],
        &[0x04, 0x81, 0x00, 0x00],
        "the DP-V1 status header only"
    );
    let sd = SlaveDiag::parse(&d).unwrap();
    assert!(!sd
        .status1
        .contains(profibus_dp::pdu::diag::StationStatus1::EXT_DIAG));
    assert_eq!(r.reg(12139), 0, "fetched");
    // Diag2: extended, 4 user bytes 01 00 FF FF.
    let w = r.plc("write 12140 14\nwrite 12146 1\nwrite 12147 65535\nwrite 12101 8\nwrite 12101 7");
    assert_eq!(
        error_of(&w[4]),
        Some(10),
        "the extended one is not fetched yet"
    );
    let d = r.diag();
    assert_eq!(d.len(), 14);
    assert_eq!(&d[6..], &[0x08, 0x81, 0, 0, 0x01, 0x00, 0xFF, 0xFF]);
    assert_eq!(r.reg(12210), 1);
    assert_eq!(r.reg(12213), 0xFF);
    let sd = SlaveDiag::parse(&d).unwrap();
    assert!(sd
        .status1
        .contains(profibus_dp::pdu::diag::StationStatus1::EXT_DIAG));
    // Diag3: static, 2 user bytes FF 00: the master stops exchanging.
    r.plc("write 12101 6\nwrite 12140 12\nwrite 12146 255\nwrite 12101 9");
    let d = r.diag();
    assert_eq!(&d[6..], &[0x06, 0x81, 0, 0, 0xFF, 0x00]);
    let sd = SlaveDiag::parse(&d).unwrap();
    assert!(sd
        .status2
        .contains(profibus_dp::pdu::diag::StationStatus2::STAT_DIAG));
    r.plc("write 12140 10\nwrite 12101 7");
    let sd_bytes = r.diag();
    let sd = SlaveDiag::parse(&sd_bytes).unwrap();
    assert!(!sd
        .status2
        .contains(profibus_dp::pdu::diag::StationStatus2::STAT_DIAG));
    // Command 10 aborts a pending diagnosis: the old one stays.
    let w = r.plc("write 12140 14\nwrite 12101 8\nread 12139\nwrite 12101 10\nread 12139");
    assert_eq!(
        (w[2]["value"].as_i64(), w[4]["value"].as_i64()),
        (Some(2), Some(0))
    );
    assert_eq!(r.diag().len(), 10);
    // System bytes are protected.
    let w = r.plc("write 12141 0xFFFF\nwrite 12201 1");
    assert!(!ok(&w[0]) && !ok(&w[1]));
}

/// Example 2's data records: DS-read answered with 11, DS-write accepted
/// only for index 5 (13), refused otherwise (14).
#[test]
fn example_2_data_records() {
    let mut r = Rig::new();
    online(
        &mut r,
        "write 12112 300\nwrite 12113 400\nwrite 12102 4\nwrite 12103 4\n\
         write 12116 600\nwrite 12117 800\nwrite 12114 120\nwrite 12115 120",
    );
    r.prm(IDENT);
    r.cfg(&[0x53, 0x63]);
    // DS-read of 5 bytes from slot 1 index 2.
    assert_eq!(
        r.c1(&[0x5E, 1, 2, 5], 3),
        None,
        "no answer before command 11"
    );
    assert_eq!(r.reg(12100) & status::DS_READ, status::DS_READ);
    assert_eq!((r.reg(12118), r.reg(12120), r.reg(12122)), (5, 1, 2));
    let w = r.plc(
        "write 1100 0x0102 0x0304 0x0506\n\
         calc 100 r12118 + 1\ncalc 100 r100 / 2\ncopy r100 1100 12600\nwrite 12101 11\nread 12600",
    );
    assert!(w.iter().all(ok), "{w:?}");
    assert_eq!(r.reg(12100) & status::DS_READ, 0);
    assert_ne!(
        r.reg(12100) & status::ACYCLIC_BUSY,
        0,
        "locked until fetched"
    );
    assert_eq!(r.reg(12600), NOT_CONFIGURED);
    assert_ne!(
        r.reg(12100) & status::ACYCLIC_ERROR,
        0,
        "access while locked"
    );
    let (_, d) = r.req(Some(51), &[]);
    assert_eq!(d, vec![0x5E, 1, 2, 5, 1, 2, 3, 4, 5]);
    assert_eq!(r.reg(12100) & status::ACYCLIC_BUSY, 0);
    // DS-write to index 5: accepted.
    let answer = "wait-bit 12100 5 set 1s\n\
                  if r12123 == 5 write 12101 13\n\
                  if r12123 != 5 write 12101 14\n";
    r.c1(&[0x5F, 0, 5, 3, 0xAA, 0xBB, 0xCC], 1);
    assert_eq!((r.reg(12119), r.reg(12121), r.reg(12123)), (3, 0, 5));
    assert_eq!((r.reg(12800), r.reg(12801)), (0xAABB, 0xCC00));
    r.plc(answer);
    let (_, d) = r.req(Some(51), &[]);
    assert_eq!(d, vec![0x5F, 0, 5, 3]);
    // Index 6: refused with "application: write error".
    r.c1(&[0x5F, 0, 6, 2, 1, 2], 1);
    r.plc(answer);
    let (_, d) = r.req(Some(51), &[]);
    assert_eq!(d, vec![0xDF, 0x80, 0xA1, 0]);
    // DS-read refused (command 12): "application: read error".
    r.c1(&[0x5E, 0, 1, 2], 0);
    r.plc("write 12101 12");
    let (_, d) = r.req(Some(51), &[]);
    assert_eq!(d, vec![0xDE, 0x80, 0xA0, 0]);
}

#[test]
fn over_long_record_write_is_refused_at_once() {
    let mut r = Rig::new();
    online(&mut r, "");
    r.prm(IDENT);
    r.cfg(&[0x53, 0x63]);
    // 4 registers = 8 bytes.
    let d = r
        .c1(&[0x5F, 0, 5, 9, 1, 2, 3, 4, 5, 6, 7, 8, 9], 1)
        .unwrap();
    assert_eq!(d, vec![0xDF, 0x80, 0xB1, 0], "access: write length error");
    assert_eq!(r.reg(12100) & status::DS_WRITE, 0, "bit 5 not set");
    // A read longer than the area is truncated to it.
    r.c1(&[0x5E, 0, 1, 20], 0);
    assert_eq!(r.reg(12118), 8);
}

#[test]
fn error_11_memory_test_and_reset() {
    let mut r = Rig::new();
    online(&mut r, "write 12102 2");
    r.prm(IDENT);
    r.cfg(&[0x51, 0x63]);
    assert_eq!(r.slave.state(), profibus_dp::slave::SlaveState::DataExch);
    let w = r
        .plc("fail-memory-test\nwrite 12101 5\nread 12100\nwait-bit 12100 13 clear 1s\nread 12102");
    assert_eq!(error_of(&w[1]), Some(11));
    assert_eq!(
        w[2]["value"].as_i64().unwrap() & 0x2001,
        0x2001,
        "BUSY and buffer OK"
    );
    assert_eq!(w[4]["value"], 4, "reset values");
    assert_eq!(r.reg(12134), 11, "the reset keeps the error");
    r.now += Duration::from_millis(1);
    let (reply, _) = r.req(None, &[0; 8]);
    assert_eq!(reply, Reply::Silence, "off the bus after the reset");
    assert_eq!(r.slave.state(), profibus_dp::slave::SlaveState::WaitPrm);
}

#[test]
fn error_12_consistent_areas() {
    for (script, why) in [
        (
            "write 12102 16\nwrite 12124 4\nwrite 12128 13",
            "window beyond the inputs",
        ),
        ("write 12125 5", "more consistent outputs than outputs"),
        ("write 12124 2\nwrite 12126 300", "inside the inputs"),
        ("write 12124 2\nwrite 12126 999", "beyond 999"),
        (
            "write 12124 1\nwrite 12125 1\nwrite 12127 500",
            "consistent areas overlap",
        ),
    ] {
        let mut r = Rig::new();
        let w = r.plc(script);
        assert_eq!(error_of(w.last().unwrap()), Some(12), "{why}: {w:?}");
    }
}

/// The consistent-input example (L1271): 16 words, 4 consistent at 8.
#[test]
fn consistent_inputs_example() {
    let mut r = Rig::new();
    online(
        &mut r,
        "write 12102 16\nwrite 12112 300\nwrite 12126 500\nwrite 12124 4\nwrite 12128 8",
    );
    assert_eq!(r.slave.device().real_cfg(), &[0x57, 0xD3, 0x53, 0x63]);
    r.prm(IDENT);
    r.cfg(&[0x57, 0xD3, 0x53, 0x63]);
    assert_eq!(r.slave.state(), profibus_dp::slave::SlaveState::DataExch);
    let w = r.plc("write 1000 11 12 13 14\ncopy 4 1000 12500\nwrite 12101 15\nread 12100");
    assert!(w.iter().all(ok), "{w:?}");
    assert_eq!(w[3]["value"].as_i64().unwrap() & status::CIN_SENT as i64, 0);
    assert_eq!(r.reg(12308), 11);
    assert_eq!(r.reg(12311), 14);
    let (_, inputs) = r.exchange(&[0; 8]);
    assert_eq!(&inputs[16..24], &[0, 11, 0, 12, 0, 13, 0, 14]);
    let w = r.plc("wait-bit 12100 8 set 1s");
    assert!(ok(&w[0]));
}

/// "The consistent data area must lie inside **one** consistent module"
/// (L950, L969): the manual's 16 input words with 4 consistent at word
/// 8, configured as one consistent 16-word module, or 8 plain and one
/// consistent 8-word module, are accepted; a window split over two
/// consistent modules, or outside any, is error 8.
#[test]
fn consistent_window_inside_one_consistent_module() {
    let setup = "write 12102 16\nwrite 12112 300\nwrite 12126 500\nwrite 12124 4\nwrite 12128 8";
    for (cfg, ok) in [
        (&[0xDF, 0x63][..], true),
        (&[0x57, 0xD7, 0x63], true),
        (&[0xD7, 0xD7, 0x63], true),
        (&[0x57, 0xD3, 0x53, 0x63], true),
        (&[0x59, 0xD1, 0xD3, 0x63], false),
        (&[0x5F, 0x63], false),
        (&[0xD3, 0x5B, 0x63], false),
    ] {
        let mut r = Rig::new();
        online(&mut r, setup);
        r.prm(IDENT);
        r.cfg(cfg);
        let exchanging = r.slave.state() == profibus_dp::slave::SlaveState::DataExch;
        assert_eq!(exchanging, ok, "{cfg:02X?}");
        assert_eq!(r.reg(12134), if ok { 0 } else { 8 }, "{cfg:02X?}");
    }
}

/// The consistent-output example (L1327): 12 words, 8 consistent at 4.
#[test]
fn consistent_outputs_example() {
    let mut r = Rig::new();
    online(
        &mut r,
        "write 12103 12\nwrite 12113 400\nwrite 12127 600\nwrite 12125 8\nwrite 12129 4",
    );
    assert_eq!(r.slave.device().real_cfg(), &[0x53, 0x63, 0xE7]);
    r.prm(IDENT);
    r.cfg(&[0x53, 0x63, 0xE7]);
    assert_eq!(r.slave.state(), profibus_dp::slave::SlaveState::DataExch);
    r.plc("write 12101 16");
    assert_eq!(r.reg(12100) & status::COUT_RECEIVED, 0);
    let out: Vec<u8> = (0..24).collect();
    r.exchange(&out);
    let w = r.plc("wait-bit 12100 9 set 1s\ncopy 8 12600 1100\nread 1100 8");
    assert!(w.iter().all(ok), "{w:?}");
    let words: Vec<i64> = (4..12).map(|i| (2 * i) << 8 | (2 * i + 1)).collect();
    assert_eq!(w[2]["values"], serde_json::json!(words));
    // The next outputs do not touch the consistent copy.
    r.exchange(&[0xFF; 24]);
    assert_eq!(r.reg(12600), words[0] as i32);
    assert_eq!(r.reg(12404), 0xFFFF);
}

#[test]
fn outputs_read_minus_65536_outside_data_exchange() {
    let mut r = Rig::new();
    online(&mut r, "");
    r.prm(IDENT);
    r.cfg(&[0x53, 0x63]);
    r.exchange(&[0, 1, 0, 2, 0, 3, 0, 4]);
    assert_eq!(r.reg(12401), 2);
    r.prm(IDENT);
    assert_eq!(r.reg(12401), NO_OUTPUT);
}

#[test]
fn script_parsing() {
    assert_eq!(
        Command::parse("copy 4 1000 12500 ; consistent data").unwrap(),
        Some(Command::Copy {
            count: script::Operand::Lit(4),
            from: 1000,
            to: 12500
        })
    );
    assert_eq!(Command::parse("  # nothing").unwrap(), None);
    assert!(Command::parse("wait-bit 12100 3 sometimes").is_err());
    assert!(Command::parse("frobnicate").is_err());
    let e = Interpreter::script("label a\ngoto b").unwrap_err();
    assert_eq!(e.line, 2);
    // Timeout.
    let mut plc = Plc::new(2).unwrap();
    let mut it = Interpreter::new();
    it.push("wait-bit 12100 3 set 50ms");
    assert_eq!(it.run(&mut plc, t(0)), Progress::Waiting(t(50)));
    assert_eq!(it.run(&mut plc, t(50)), Progress::Idle);
    let r = it.take_reply().unwrap();
    assert_eq!((r.ok, r.timeout), (false, Some(true)));
    it.push("bogus");
    assert!(!it.take_reply().unwrap().ok);
    assert!(Plc::new(10).is_err());
    // Several bits: any of them; if-bit.
    let mut it = Interpreter::script(
        "wait-bit 1000 4,5 set 1s\nif-bit 1000 5 set write 1001 7\nif-bit 1000 4 set write 1002 7",
    )
    .unwrap();
    assert_eq!(it.run(&mut plc, t(0)), Progress::Waiting(t(1000)));
    plc.write(t(1), 1000, 32);
    assert_eq!(it.run(&mut plc, t(2)), Progress::Idle);
    assert_eq!(it.take_reply().unwrap().hit, Some(vec![5]));
    assert_eq!((plc.read(t(3), 1001), plc.read(t(3), 1002)), (7, 0));
    assert_eq!(plc.module_register(100), 12100);
}

/// The registry's device: the PLC program runs inside it, inbox lines
/// are register commands answered as device events.
#[test]
fn scripted_device_runs_its_program_and_inbox() {
    let inbox = crate::ControlInbox::new();
    let program = Interpreter::script(
        "write 12102 2\nwrite 12107 9\nlabel l\nwait-bit 12100 3 set 10s\ncalc 12300 r12300 + 1\ndelay 10ms\ngoto l",
    )
    .unwrap();
    let d = ScriptedJx2::new(Plc::new(2).unwrap(), program, Some(inbox.clone()));
    let mut slave = DpSlave::new(d, 0);
    slave.handle_timeout(t(0));
    assert_eq!(slave.address(), profibus_dp::slave::NO_ADDRESS, "BUSY");
    slave.handle_timeout(t(25));
    assert_eq!(slave.address(), 9);
    inbox.push("read 12199");
    slave.handle_timeout(t(50));
    let e = std::iter::from_fn(|| slave.poll_event())
        .find_map(|e| match e {
            profibus_dp::slave::SlaveEvent::Device(d) if d.text.contains("12199") => Some(d),
            _ => None,
        })
        .expect("the inbox reply");
    assert!(e.text.contains("\"value\":103"), "{}", e.text);
    assert_eq!(slave.device().plc().module.station_address(), Some(9));
}
