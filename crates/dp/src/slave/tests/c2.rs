//! Class 2 (MSAC_C2) and I&M in the slave core. The byte strings are
//! those of `shared/reference/dpv1-c2-im-alarms.md` (§4.4 examples, §4.6
//! sequences, the abort table), written out here, not produced by our
//! encoders.

use super::*;

/// The reference's minimal Initiate.req: Send_Timeout 100 (1 s), R/W
/// supported, no profile, type-0 addresses.
const INITIATE_1S: [u8; 20] = [
    0x57, 0x00, 0x00, 0x00, 0x00, 0x64, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x02,
    0x00, 0x00, 0x00, 0x00,
];
/// The reference's Initiate.res example (Max_Len_Data_Unit 240).
const INITIATE_RES: [u8; 16] = [
    0x57, 0xF0, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x02, 0x00, 0x00, 0x00, 0x00,
];
/// The class-2 master's SAP.
const MS2: u8 = 50;
const RM: u8 = 49;
/// A class-2 master (a tool next to the PLC `MASTER`).
const TOOL: u8 = 5;

/// Set_Prm with DPV1_Enable, no alarms, watchdog off.
fn c1_prm() -> Vec<u8> {
    [prm(0x80), vec![0x80, 0x00, 0x00]].concat()
}

/// Initiate.req with Send_Timeout `st` (units of 10 ms).
fn initiate(st: u16) -> Vec<u8> {
    let mut r = INITIATE_1S.to_vec();
    r[4..6].copy_from_slice(&st.to_be_bytes());
    r
}

/// A DP-V1 device with class 2 and I&M: record slot 1 index 2, I&M0..4.
#[derive(Debug)]
struct C2Device {
    features: Features,
    record: Vec<u8>,
    im: [[u8; 64]; 5],
    im_writes: Vec<u8>,
    outputs: Vec<u8>,
    /// Reads answer `Pending` for this many polls.
    delay: u32,
    polls: u32,
}

fn c2_features(channels: u8) -> Features {
    Features {
        dpv1: true,
        c1_read_write: true,
        c2_read_write: true,
        c2_max_count_channels: channels,
        im: true,
        ..Features::default()
    }
}

impl C2Device {
    fn new(features: Features) -> C2Device {
        let mut im0 = [b' '; 64];
        im0[10..12].copy_from_slice(&[0x01, 0x1E]);
        im0[12..21].copy_from_slice(b"DPCTL-GEN");
        C2Device {
            features,
            record: vec![0xA1, 0xA2, 0xA3],
            im: [im0, [b' '; 64], [b' '; 64], [b' '; 64], [0; 64]],
            im_writes: vec![],
            outputs: vec![],
            delay: 0,
            polls: 0,
        }
    }
}

impl Device for C2Device {
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
        Ok(())
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        expect_cfg(&CFG, cfg)
    }
    fn write_outputs(&mut self, _now: Instant, outputs: &[u8]) {
        self.outputs = outputs.to_vec();
    }
    fn read_inputs(&mut self, _now: Instant, inputs: &mut [u8]) {
        inputs.fill(0x33);
    }
    fn dpv1_read(&mut self, _now: Instant, slot: u8, index: u8, out: &mut [u8]) -> Dpv1Outcome {
        if (slot, index) != (1, 2) {
            return Dpv1Outcome::read_error(ERR_CLASS_ACCESS, ERR_INVALID_INDEX);
        }
        self.polls = 0;
        if self.delay > 0 {
            return Dpv1Outcome::Pending;
        }
        let n = out.len().min(self.record.len());
        out[..n].copy_from_slice(&self.record[..n]);
        Dpv1Outcome::Done(n)
    }
    fn dpv1_poll(&mut self, _now: Instant, out: &mut [u8]) -> Dpv1Outcome {
        self.polls += 1;
        if self.polls < self.delay {
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
    fn im_read(&mut self, number: u8, out: &mut [u8; 64]) -> bool {
        match self.im.get(number as usize) {
            Some(r) => {
                *out = *r;
                true
            }
            None => false,
        }
    }
    fn im_write(&mut self, _now: Instant, number: u8, record: &[u8; 64]) -> Result<(), Dpv1Error> {
        self.im[number as usize] = *record;
        self.im_writes.push(number);
        Ok(())
    }
}

struct C2Bench {
    slave: DpSlave<C2Device>,
}

impl C2Bench {
    fn new(features: Features) -> C2Bench {
        C2Bench {
            slave: DpSlave::new(C2Device::new(features), ADDR),
        }
    }

    fn req(
        &mut self,
        now: Instant,
        from: u8,
        dsap: Option<u8>,
        ssap: Option<u8>,
        data: &[u8],
    ) -> Ans {
        let fc = FunctionCode::Request {
            kind: RequestKind::SrdHigh,
            fcb: false,
            fcv: false,
        };
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

    /// A class-2 request from `TOOL` (SSAP 50) to `dsap`.
    fn c2(&mut self, now: Instant, dsap: u8, data: &[u8]) -> Ans {
        self.req(now, TOOL, Some(dsap), Some(MS2), data)
    }

    /// Request, then poll once: the response's data unit.
    fn c2_ask(&mut self, now: Instant, dsap: u8, data: &[u8]) -> Vec<u8> {
        assert_eq!(self.c2(now, dsap, data), Ans::Sc, "request {data:02X?}");
        let a = self.c2(now, dsap, &[]);
        assert_eq!(
            a.status(),
            Some(ResponseStatus::Dl),
            "poll after {data:02X?}"
        );
        a.data().to_vec()
    }

    /// Open a connection (Initiate, RM reply, poll for Initiate.res);
    /// returns the SAP.
    fn open(&mut self, now: Instant, st: u16) -> u8 {
        let rm = self.c2(now, RM, &initiate(st));
        let d = rm.data();
        assert_eq!(d.len(), 4, "RM reply {rm:?}");
        assert_eq!(d[0], 0x56, "RM reply {rm:?}");
        let sap = d[1];
        let res = self.c2(now, sap, &[]);
        assert_eq!(res.data()[0], 0x57, "Initiate.res {res:?}");
        sap
    }

    fn events(&mut self) -> Vec<SlaveEvent> {
        std::iter::from_fn(|| self.slave.poll_event()).collect()
    }

    fn tick(&mut self, now: Instant) {
        if self.slave.poll_timeout().is_some_and(|t| t <= now) {
            self.slave.handle_timeout(now);
        }
    }
}

#[test]
fn initiate_rm_reply_poll_and_initiate_res() {
    let mut b = C2Bench::new(c2_features(1));
    // Before any Set_Prm: class 2 does not depend on the DP state.
    assert_eq!(b.slave.state(), SlaveState::WaitPrm);
    assert_eq!(
        b.c2(t(0), RM, &INITIATE_1S),
        Ans::Data(
            ResponseStatus::Dl,
            Some(MS2),
            Some(RM),
            vec![0x56, 0x30, 0x03, 0xE8]
        ),
        "RM reply: SAP 48 (highest first), Poll_Timeout 1000 ms"
    );
    assert_eq!(
        b.c2(t(1), 48, &[]),
        Ans::Data(
            ResponseStatus::Dl,
            Some(MS2),
            Some(48),
            INITIATE_RES.to_vec()
        )
    );
    assert_eq!(b.c2(t(2), 48, &[]), Ans::Sc, "nothing outstanding");
    assert_eq!(b.c2(t(3), 48, &[0x48, 0x00]).data(), &[0x48, 0x00], "Idle");
    assert!(b.events().contains(&SlaveEvent::C2Opened {
        master: TOOL,
        sap: 48,
        send_timeout: Duration::from_secs(1),
    }));
    assert_eq!(
        b.slave.c2_connections().collect::<Vec<_>>(),
        vec![(48, TOOL)]
    );
    // Read and Write on the connection, with the class-1 poll pattern.
    assert_eq!(
        b.c2_ask(t(4), 48, &[0x5E, 1, 2, 8]),
        [0x5E, 1, 2, 3, 0xA1, 0xA2, 0xA3]
    );
    assert_eq!(b.c2_ask(t(5), 48, &[0x5F, 1, 2, 2, 7, 8]), [0x5F, 1, 2, 2]);
    assert_eq!(b.slave.device().record, vec![7, 8]);
    assert_eq!(
        b.c2_ask(t(6), 48, &[0x5E, 9, 9, 8]),
        [0xDE, 0x80, 0xB0, 0x00],
        "negative response: invalid index"
    );
    // Data_Transport: the device's default hook says "feature not supported".
    assert_eq!(
        b.c2_ask(t(7), 48, &[0x51, 1, 2, 1, 9]),
        [0xD1, 0x80, 0xA9, 0x00]
    );
    // Idle while a reply is ready: the reply.
    assert_eq!(b.c2(t(8), 48, &[0x5E, 1, 2, 8]), Ans::Sc);
    assert_eq!(b.c2(t(9), 48, &[0x48, 0x00]).data()[0], 0x5E);
    // The master aborts (user instance, reason 0): SC, closed, SAP free.
    assert_eq!(b.c2(t(10), 48, &[0x58, 0x00, 0x20, 0x00]), Ans::Sc);
    assert!(b.events().iter().any(|e| matches!(
        e,
        SlaveEvent::C2Closed {
            sap: 48,
            by_master: true,
            ..
        }
    )));
    assert_eq!(b.c2(t(11), 48, &[]).status(), Some(ResponseStatus::Rs));
    assert_eq!(b.slave.state(), SlaveState::WaitPrm);
}

#[test]
fn im0_over_class2_and_class1() {
    let mut b = C2Bench::new(c2_features(1));
    let sap = b.open(t(0), 100);
    let select = [0x5F, 0x00, 0xFF, 0x04, 0x08, 0x00, 0xFD, 0xE8];
    assert_eq!(b.c2_ask(t(1), sap, &select), [0x5F, 0x00, 0xFF, 0x04]);
    let res = b.c2_ask(t(2), sap, &[0x5E, 0x00, 0xFF, 0x44]);
    assert_eq!(res[..8], [0x5E, 0x00, 0xFF, 0x44, 0x08, 0x00, 0xFD, 0xE8]);
    assert_eq!(res[8..], b.slave.device().im[0]);
    assert_eq!(&res[8 + 12..8 + 21], b"DPCTL-GEN");
    // Class 1, from the master holding the slave in Data_Exch.
    b.req(t(3), MASTER, Some(sap::SET_PRM), Some(62), &c1_prm());
    b.req(t(3), MASTER, Some(sap::CHK_CFG), Some(62), &CFG);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    let c1_ask = |b: &mut C2Bench, now, data: &[u8]| {
        assert_eq!(b.req(now, MASTER, Some(51), Some(51), data), Ans::Sc);
        b.req(now, MASTER, Some(51), Some(51), &[]).data().to_vec()
    };
    // A read without a selection: state conflict (the class-2 selection
    // belongs to the connection).
    assert_eq!(
        c1_ask(&mut b, t(4), &[0x5E, 0x00, 0xFF, 0x44]),
        [0xDE, 0x80, 0xB5, 0x00]
    );
    assert_eq!(c1_ask(&mut b, t(5), &select), [0x5F, 0x00, 0xFF, 0x04]);
    let res = c1_ask(&mut b, t(6), &[0x5E, 0x00, 0xFF, 0x44]);
    assert_eq!(res[..8], [0x5E, 0x00, 0xFF, 0x44, 0x08, 0x00, 0xFD, 0xE8]);
    assert_eq!(res.len(), 4 + 68);
    // A short read gets the first bytes.
    let res = c1_ask(&mut b, t(7), &[0x5E, 0x00, 0xFF, 0x06]);
    assert_eq!(
        res,
        [0x5E, 0x00, 0xFF, 0x06, 0x08, 0x00, 0xFD, 0xE8, b' ', b' ']
    );
}

#[test]
fn write_im1_and_read_it_back() {
    let mut b = C2Bench::new(c2_features(1));
    let sap = b.open(t(0), 100);
    // I&M1: 10-byte header, TAG_FUNCTION 32, TAG_LOCATION 22.
    let mut im1 = [b' '; 64];
    im1[10..16].copy_from_slice(b"PUMP 3");
    im1[42..48].copy_from_slice(b"HALL B");
    let write = [&[0x5F, 0x00, 0xFF, 0x44, 0x08, 0x00, 0xFD, 0xE9][..], &im1].concat();
    assert_eq!(b.c2_ask(t(1), sap, &write), [0x5F, 0x00, 0xFF, 0x44]);
    assert_eq!(b.slave.device().im_writes, vec![1]);
    assert_eq!(b.slave.device().im[1], im1);
    let res = b.c2_ask(t(2), sap, &[0x5E, 0x00, 0xFF, 0x44]);
    assert_eq!(res[4..8], [0x08, 0x00, 0xFD, 0xE9]);
    assert_eq!(res[8..], im1);
    // I&M0 is read-only; unknown records, non-calls and odd lengths.
    let im0_write = [&[0x5F, 0x00, 0xFF, 0x44, 0x08, 0x00, 0xFD, 0xE8][..], &im1].concat();
    assert_eq!(b.c2_ask(t(3), sap, &im0_write), [0xDF, 0x80, 0xB6, 0x00]);
    assert_eq!(
        b.c2_ask(t(4), sap, &[0x5F, 0x00, 0xFF, 0x04, 0x08, 0x00, 0xFD, 0xED]),
        [0xDF, 0x80, 0xB0, 0x00],
        "I&M5 (65005)"
    );
    assert_eq!(
        b.c2_ask(t(5), sap, &[0x5F, 0x00, 0xFF, 0x04, 0x09, 0x00, 0xFD, 0xE8]),
        [0xDF, 0x80, 0xB8, 0x00],
        "not a call"
    );
    assert_eq!(
        b.c2_ask(
            t(6),
            sap,
            &[0x5F, 0x00, 0xFF, 0x05, 0x08, 0x00, 0xFD, 0xE9, 0x20]
        ),
        [0xDF, 0x80, 0xB1, 0x00],
        "5 bytes"
    );
    assert_eq!(b.slave.device().im_writes, vec![1], "nothing else written");
}

#[test]
fn a_device_without_im_gets_index_255_itself() {
    let mut b = C2Bench::new(Features {
        im: false,
        ..c2_features(1)
    });
    let sap = b.open(t(0), 100);
    assert_eq!(
        b.c2_ask(t(1), sap, &[0x5F, 0x00, 0xFF, 0x04, 0x08, 0x00, 0xFD, 0xE8]),
        [0xDF, 0x80, 0xB0, 0x00],
        "the device's own answer (invalid index)"
    );
}

#[test]
fn send_timeout_expiry_aborts_with_to() {
    let mut b = C2Bench::new(c2_features(1));
    let sap = b.open(t(0), 100);
    // Requests keep it open: one every 900 ms for 3 s.
    for i in 1..=4 {
        b.tick(t(900 * i));
        assert_eq!(b.c2(t(900 * i), sap, &[0x48, 0x00]).data(), &[0x48, 0x00]);
    }
    assert_eq!(b.slave.poll_timeout(), Some(t(3600 + 1000)));
    drop(b.events());
    // Silence for Send_Timeout: closed with TO.
    b.tick(t(4599));
    assert_eq!(b.slave.c2_connections().count(), 1);
    b.tick(t(4600));
    assert_eq!(b.slave.c2_connections().count(), 0);
    let ev = b.events();
    let closed = ev
        .iter()
        .find(|e| matches!(e, SlaveEvent::C2Closed { .. }))
        .expect("closed");
    assert_eq!(
        closed.to_string(),
        "class-2 connection of master 5 on SAP 48 closed by the slave: \
         aborted by MSAC_C2: connection timeout (TO)"
    );
    // The master hears of it with its next request, once.
    assert_eq!(
        b.c2(t(5000), sap, &[0x48, 0x00]),
        Ans::Data(
            ResponseStatus::Dl,
            Some(MS2),
            Some(sap),
            vec![0x58, 0x00, 0x13, 0x00]
        )
    );
    assert_eq!(
        b.c2(t(5001), sap, &[0x48, 0x00]).status(),
        Some(ResponseStatus::Rs)
    );
    // Also when the master never polls for Initiate.res.
    b.c2(t(6000), RM, &INITIATE_1S);
    b.tick(t(7000));
    assert_eq!(b.slave.c2_connections().count(), 0);
}

#[test]
fn send_timeout_below_the_minimum_is_sto() {
    let mut b = C2Bench::new(c2_features(1));
    // Rate not told yet: 1 s minimum (as at 1.5 Mbit/s and above).
    assert_eq!(
        b.c2(t(0), RM, &initiate(99)).data(),
        &[0x58, 0x00, 0x16, 0x00]
    );
    assert_eq!(b.slave.c2_connections().count(), 0);
    // A passive station tells the slave its rate: 187.5 kbit/s needs 4 s.
    let st = PassiveStation::new(b.slave, BusParams::defaults(Baud::B187500));
    b.slave = st.into_app();
    assert_eq!(
        b.c2(t(1), RM, &initiate(399)).data(),
        &[0x58, 0x00, 0x16, 0x00]
    );
    assert_eq!(b.c2(t(2), RM, &initiate(400)).data()[0], 0x56);
    Responder::set_baud(&mut b.slave, Baud::B500000);
    assert_eq!(min_send_timeout(Some(Baud::B500000)), 200);
    assert_eq!(min_send_timeout(Some(Baud::B12000000)), 100);
    assert_eq!(min_send_timeout(Some(Baud::B9600)), 400);
    let ev = b.events();
    assert!(ev.iter().any(|e| e.to_string().contains(
        "MSAC_C2_Initiate from master 5 refused: Initiate refused, aborted by MSAC_C2: Send_Timeout too small (STO)"
    )), "{ev:?}");
}

#[test]
fn too_many_connections_get_abort_res() {
    let mut b = C2Bench::new(c2_features(2));
    assert_eq!(b.open(t(0), 100), 48);
    assert_eq!(b.open(t(1), 100), 47, "highest free SAP next");
    assert_eq!(
        b.c2(t(2), RM, &INITIATE_1S),
        Ans::Data(
            ResponseStatus::Dl,
            Some(MS2),
            Some(RM),
            vec![0x58, 0x00, 0x1F, 0x00]
        )
    );
    // Closing one frees its SAP for the next Initiate.
    assert_eq!(b.c2(t(3), 48, &[0x58, 0x00, 0x20, 0x00]), Ans::Sc);
    assert_eq!(b.open(t(4), 100), 48);
}

#[test]
fn invalid_initiates_and_connection_errors() {
    let mut b = C2Bench::new(c2_features(2));
    // 19 bytes: FE.
    assert_eq!(
        b.c2(t(0), RM, &INITIATE_1S[..19]).data(),
        &[0x58, 0x00, 0x12, 0x00]
    );
    // S_Type 1 (network/MAC address) without Max_Initiate_PDU_Length: IA.
    let mut ext = INITIATE_1S[..16].to_vec();
    ext[12..14].copy_from_slice(&[0x01, 0x08]);
    ext.extend([0, 0, 1, 2, 3, 4, 5, 6, 0, 0]);
    assert_eq!(b.c2(t(1), RM, &ext).data(), &[0x58, 0x00, 0x17, 0x00]);
    // Type 0 with length 3: IA.
    let mut bad = INITIATE_1S.to_vec();
    bad[13] = 3;
    bad.push(0);
    assert_eq!(b.c2(t(2), RM, &bad).data(), &[0x58, 0x00, 0x17, 0x00]);
    // A new request while one is outstanding: sequence error, closed.
    b.slave.device_mut().delay = 5;
    let sap = b.open(t(3), 100);
    assert_eq!(b.c2(t(4), sap, &[0x5E, 1, 2, 8]), Ans::Sc);
    assert_eq!(b.c2(t(5), sap, &[]), Ans::Sc, "pending in the device");
    assert_eq!(
        b.c2(t(6), sap, &[0x5E, 1, 2, 8]),
        Ans::Sc,
        "a repeat is a poll"
    );
    assert_eq!(
        b.c2(t(7), sap, &[0x48, 0x00]).data(),
        &[0x48, 0x00],
        "Idle: wait"
    );
    assert_eq!(
        b.c2(t(8), sap, &[0x5F, 1, 2, 1, 9]).data(),
        &[0x58, 0x00, 0x11, 0x00]
    );
    assert_eq!(b.slave.c2_connections().count(), 0);
    // A PDU that does not decode: FE, closed.
    let sap = b.open(t(9), 100);
    assert_eq!(
        b.c2(t(10), sap, &[0x77, 1]).data(),
        &[0x58, 0x00, 0x12, 0x00]
    );
    assert_eq!(b.slave.c2_connections().count(), 0);
    // Another master on the connection's SAP: RS.
    let sap = b.open(t(11), 100);
    assert_eq!(
        b.req(t(12), OTHER, Some(sap), Some(MS2), &[0x48, 0x00])
            .status(),
        Some(ResponseStatus::Rs)
    );
    // Lengths against C2_Max_Data_Len.
    assert_eq!(
        b.c2_ask(t(13), sap, &[0x5E, 1, 2, 0]),
        [0xDE, 0x80, 0xB7, 0x00]
    );
    assert_eq!(
        b.c2_ask(t(14), sap, &[0x5E, 1, 2, 241]),
        [0xDE, 0x80, 0xB7, 0x00]
    );
}

#[test]
fn class2_is_refused_when_not_offered() {
    // DP-V0 slave: SAP 49 and the connection SAPs are not activated.
    let mut b = C2Bench::new(Features::default());
    assert_eq!(
        b.c2(t(0), RM, &INITIATE_1S),
        Ans::Data(ResponseStatus::Rs, None, None, vec![])
    );
    assert_eq!(b.c2(t(1), 48, &[]).status(), Some(ResponseStatus::Rs));
    // DP-V1 with class 1 only: the same.
    let mut b = C2Bench::new(Features {
        c2_read_write: false,
        ..c2_features(1)
    });
    assert_eq!(
        b.c2(t(0), RM, &INITIATE_1S).status(),
        Some(ResponseStatus::Rs)
    );
    let ev = b.events();
    assert!(ev.iter().any(|e| e.to_string()
        == "MSAC_C2_Initiate from master 5 refused: the slave offers no class-2 connections (C2_Read_Write_supp)"),
        "{ev:?}");
}

#[test]
fn class2_read_while_a_class1_master_exchanges_data() {
    let mut b = C2Bench::new(c2_features(1));
    b.req(t(0), MASTER, Some(sap::SET_PRM), Some(62), &c1_prm());
    b.req(t(0), MASTER, Some(sap::CHK_CFG), Some(62), &CFG);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    let dx = |b: &mut C2Bench, now, out: u8| {
        let a = b.req(now, MASTER, None, None, &[out, out]);
        assert_eq!(a.data(), &[0x33; 3], "Data_Exchange answered");
    };
    dx(&mut b, t(1), 1);
    let sap = b.open(t(2), 100);
    dx(&mut b, t(3), 2);
    assert_eq!(b.c2(t(4), sap, &[0x5E, 1, 2, 8]), Ans::Sc);
    dx(&mut b, t(5), 3);
    // Class 1 on the same record meanwhile.
    assert_eq!(
        b.req(t(6), MASTER, Some(51), Some(51), &[0x5E, 1, 2, 1]),
        Ans::Sc
    );
    dx(&mut b, t(7), 4);
    assert_eq!(
        b.c2(t(8), sap, &[]).data(),
        &[0x5E, 1, 2, 3, 0xA1, 0xA2, 0xA3]
    );
    assert_eq!(
        b.req(t(9), MASTER, Some(51), Some(51), &[]).data(),
        &[0x5E, 1, 2, 1, 0xA1]
    );
    dx(&mut b, t(10), 5);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    assert_eq!(b.slave.device().outputs, vec![5, 5]);
    assert_eq!(
        b.slave.master(),
        Some(MASTER),
        "the class-2 tool owns nothing"
    );
}

#[test]
fn one_pending_request_in_the_device_at_a_time() {
    let mut b = C2Bench::new(c2_features(2));
    b.req(t(0), MASTER, Some(sap::SET_PRM), Some(62), &c1_prm());
    b.req(t(0), MASTER, Some(sap::CHK_CFG), Some(62), &CFG);
    b.slave.device_mut().delay = 2;
    let sap = b.open(t(1), 100);
    // Class 1 first: pending in the device.
    assert_eq!(
        b.req(t(2), MASTER, Some(51), Some(51), &[0x5E, 1, 2, 2]),
        Ans::Sc
    );
    // The class-2 read waits (it is not handed to the device yet).
    assert_eq!(b.c2(t(3), sap, &[0x5E, 1, 2, 3]), Ans::Sc);
    assert_eq!(b.c2(t(4), sap, &[]), Ans::Sc);
    // Class 1 finishes (second poll), then class 2 runs.
    assert_eq!(b.req(t(5), MASTER, Some(51), Some(51), &[]), Ans::Sc);
    assert_eq!(
        b.req(t(6), MASTER, Some(51), Some(51), &[]).data(),
        &[0x5E, 1, 2, 2, 0xA1, 0xA2]
    );
    assert_eq!(b.c2(t(7), sap, &[]), Ans::Sc, "now pending in the device");
    // A class-1 request meanwhile waits in its turn.
    assert_eq!(
        b.req(t(8), MASTER, Some(51), Some(51), &[0x5E, 1, 2, 1]),
        Ans::Sc
    );
    assert_eq!(b.req(t(8), MASTER, Some(51), Some(51), &[]), Ans::Sc);
    assert_eq!(b.c2(t(9), sap, &[]), Ans::Sc);
    assert_eq!(
        b.c2(t(10), sap, &[]).data(),
        &[0x5E, 1, 2, 3, 0xA1, 0xA2, 0xA3]
    );
    assert_eq!(
        b.req(t(11), MASTER, Some(51), Some(51), &[]),
        Ans::Sc,
        "now started"
    );
    assert_eq!(
        b.req(t(12), MASTER, Some(51), Some(51), &[]).data(),
        &[0x5E, 1, 2, 1, 0xA1]
    );
}

#[test]
fn on_the_wire_initiate_gets_the_rm_reply() {
    // Through the passive station: SD2 Initiate.req to DSAP 49 from SSAP
    // 50 (DA, SA with the SAP bit 0x80), answered with an SD2 DL reply.
    let slave = DpSlave::new(C2Device::new(c2_features(1)), ADDR);
    let mut st = PassiveStation::new(slave, BusParams::defaults(Baud::B1500000));
    let req = wire_request(ADDR, TOOL, 0x6D, Some((RM, MS2)), &INITIATE_1S);
    let reply = wire(&mut st, t(0), &req);
    let (tg, _) = Telegram::parse(&reply).unwrap();
    let d = tg.as_data().unwrap();
    assert_eq!((d.dsap, d.ssap), (Some(MS2), Some(RM)));
    assert_eq!(d.data, &[0x56, 0x30, 0x03, 0xE8]);
}
