use super::catalogue::{lookup, Mapping, CATALOGUE};
use super::image::{check_cfg, CfgError, Entry, Options, Strip, StripError};
use super::master::Bk3000Master;
use super::prm::{PrmError, StartupMode, UserPrm};
use super::*;
use profibus_dp::pdu::sap;
use profibus_dp::slave::{DpSlave, SlaveState};
use profibus_fdl::station::passive::{Reply, Responder};
use profibus_fdl::{DataTelegram, FunctionCode, RequestKind};
use std::time::Duration;

const T0: Instant = Instant::ZERO;
const MASTER: u8 = 2;
const ADDR: u8 = 5;

fn strip(list: &str) -> Strip {
    Strip::parse(list).unwrap()
}

fn entry<'a>(img: &'a Image, name: &str) -> &'a Entry {
    img.entries
        .iter()
        .find(|e| e.name == name)
        .unwrap_or_else(|| panic!("no {name} in {:#?}", img.entries))
}

/// The manual's appendix example (p. 38-40): POS01 is the coupler, so
/// terminal n is POS(n+1).
const APPENDIX: &str = "KL1002,KL1002,KL1002,KL1002,KL1002, KL2012,KL2012,KL2012, KL3002, \
KL4002,KL4002, KL3002, KL9100, KL1002,KL1002,KL1002, KL2012,KL2012, KL4002, KL9010";

fn pos(p: usize) -> usize {
    p - 1
}

#[test]
fn catalogue_has_the_issue_terminals_and_the_manual_identifiers() {
    for name in [
        "KL1002", "KL1104", "KL1408", "KL2012", "KL2134", "KL2408", "KL3002", "KL3102", "KL3202",
        "KL4002", "KL4032", "KL1501", "KL2502", "KL5001", "KL9100", "KL9400", "KL9010",
    ] {
        assert!(lookup(name).is_some(), "{name} missing");
    }
    let cfg = |t: &str, m: Mapping| lookup(t).unwrap().variant(m).unwrap().cfg;
    // p. 49: KL3xx2 compact 0x50 per channel, complete 0xB2 per channel,
    // 24 bit in / 8 bit out 0xC0,0x00,0x82 per channel.
    for t in ["KL3002", "KL3102", "KL3202"] {
        assert_eq!(cfg(t, Mapping::Compact), &[0x50, 0x50]);
        assert_eq!(cfg(t, Mapping::Complete), &[0xB2, 0xB2]);
        assert_eq!(
            cfg(t, Mapping::StatusControl),
            &[0xC0, 0x00, 0x82, 0xC0, 0x00, 0x82]
        );
    }
    // p. 50: KL1501 0xB4 / 0xB3 / 0xB5; KL2502 0xB2 twice or 0xB5;
    // KL5001 0x93 / 0xB4.
    assert_eq!(cfg("KL1501", Mapping::Standard), &[0xB4]);
    assert_eq!(cfg("KL1501", Mapping::Compact), &[0xB3]);
    assert_eq!(cfg("KL1501", Mapping::Complete), &[0xB5]);
    assert_eq!(cfg("KL2502", Mapping::Complete), &[0xB2, 0xB2]);
    assert_eq!(cfg("KL2502", Mapping::Standard), &[0xB5]);
    assert_eq!(cfg("KL5001", Mapping::Compact), &[0x93]);
    assert_eq!(cfg("KL5001", Mapping::Complete), &[0xB4]);
    // Every variant's identifiers carry exactly its lengths.
    for t in CATALOGUE {
        for v in t.variants {
            let tot = profibus_dp::pdu::cfg::totals(v.cfg).unwrap();
            assert_eq!(
                (tot.input_bytes, tot.output_bytes),
                (v.in_len as usize, v.out_len as usize),
                "{} {:?}",
                t.name,
                v.mapping
            );
            for f in v.inputs {
                assert!(f.offset + f.bytes <= v.in_len, "{} input field", t.name);
            }
            for f in v.outputs {
                assert!(f.offset + f.bytes <= v.out_len, "{} output field", t.name);
            }
        }
    }
}

#[test]
fn appendix_example_layout() {
    let s = strip(APPENDIX);
    let img = s.default_image(Options::default());
    // Outputs (p. 38-39): analog POS11, POS12, POS20 in bytes 0..11,
    // digital %QB12 POS07 … POS18, %QB13 POS19.
    let out = |name: &str| {
        let e = entry(&img, name);
        (e.byte, e.bit)
    };
    assert_eq!(out(&format!("{}.KL4002.1", pos(11))), (0, None));
    assert_eq!(out(&format!("{}.KL4002.2", pos(11))), (2, None));
    assert_eq!(out(&format!("{}.KL4002.1", pos(12))), (4, None));
    assert_eq!(out(&format!("{}.KL4002.2", pos(12))), (6, None));
    assert_eq!(out(&format!("{}.KL4002.1", pos(20))), (8, None));
    assert_eq!(out(&format!("{}.KL4002.2", pos(20))), (10, None));
    let qb = [
        (7, 1, 12, 0),
        (7, 2, 12, 1),
        (8, 1, 12, 2),
        (8, 2, 12, 3),
        (9, 1, 12, 4),
        (9, 2, 12, 5),
        (18, 1, 12, 6),
        (18, 2, 12, 7),
        (19, 1, 13, 0),
        (19, 2, 13, 1),
    ];
    for (p, ch, byte, bit) in qb {
        assert_eq!(
            out(&format!("{}.KL2012.{ch}", pos(p))),
            (byte, Some(bit)),
            "POS{p:02} channel {ch}"
        );
    }
    assert_eq!(img.out_len, 14, "the last byte %QB13 is padded");
    // Inputs: the analog words first (POS10, POS13: two channels of one
    // word each), then the digital bits from POS02 on. The BK3000 edition
    // prints 2 bytes per analog terminal here (%IB0..%IB3, digital from
    // %IB4), which contradicts its own "two bytes per channel" rule
    // (p. 40); the BK2000/BK4000 editions of the same example give 4.
    assert_eq!(out(&format!("{}.KL3002.1", pos(10))), (0, None));
    assert_eq!(out(&format!("{}.KL3002.2", pos(10))), (2, None));
    assert_eq!(out(&format!("{}.KL3002.1", pos(13))), (4, None));
    for (k, p) in [2, 3, 4, 5, 6, 15, 16, 17].into_iter().enumerate() {
        for ch in 1..=2u8 {
            let bit = 2 * k + ch as usize - 1;
            assert_eq!(
                out(&format!("{}.KL1002.{ch}", pos(p))),
                (8 + bit / 8, Some((bit % 8) as u8)),
                "POS{p:02} channel {ch}"
            );
        }
    }
    assert_eq!(img.in_len, 10);
    // POS14 (power feed) and POS21 (end terminal) have no data.
    assert!(img
        .entries
        .iter()
        .all(|e| e.terminal != "KL9100" && e.terminal != "KL9010"));
    assert_eq!(
        img.cfg,
        [0x50, 0x50, 0x60, 0x60, 0x60, 0x60, 0x50, 0x50, 0x60, 0x60, 0x11, 0x21]
    );
}

#[test]
fn s5_example_strip() {
    // p. 33: BK3000 at station 3 with 8 x KL1002, 4 x KL2012, … (the rest
    // of the strip is cut off in the summary): 16 input bits, 8 output bits.
    let s = strip("KL1002,KL1002,KL1002,KL1002,KL1002,KL1002,KL1002,KL1002,KL2012,KL2012,KL2012,KL2012,KL9010");
    let img = s.default_image(Options::default());
    assert_eq!((img.in_len, img.out_len), (2, 1));
    assert_eq!(img.cfg, [0x11, 0x20]);
    assert_eq!(entry(&img, "8.KL1002.2").byte, 1);
    assert_eq!(entry(&img, "8.KL1002.2").bit, Some(7));
    assert_eq!(entry(&img, "12.KL2012.2").bit, Some(7));
    // p. 48: the digital codes may be split freely.
    for ok in [
        &[0x11, 0x20][..],
        &[0x10, 0x10, 0x20],
        &[0x20, 0x11],
        &[0x30, 0x10],
    ] {
        let i = check_cfg(&s, Options::default(), ok).unwrap();
        assert_eq!((i.in_len, i.out_len), (2, 1), "{ok:02X?}");
    }
    for (bad, err) in [
        (&[0x11][..], CfgError::TooFew),
        (&[0x12, 0x20], CfgError::FaultyByte(0)),
        (&[0x11, 0x21], CfgError::FaultyByte(1)),
        (&[0x11, 0x20, 0x10], CfgError::FaultyByte(2)),
        (&[0x50, 0x11, 0x20], CfgError::FaultyByte(0)),
        (&[], CfgError::TooFew),
    ] {
        assert_eq!(
            check_cfg(&s, Options::default(), bad).unwrap_err().error,
            err,
            "{bad:02X?}"
        );
    }
}

#[test]
fn strip_rules_refused_at_start() {
    assert_eq!(
        Strip::parse("KL1104,KL2134").unwrap_err(),
        StripError::NoEndTerminal("KL2134")
    );
    assert_eq!(
        Strip::parse("KL1104,KL9010,KL2134").unwrap_err(),
        StripError::AfterEnd(3)
    );
    assert_eq!(Strip::parse("").unwrap_err(), StripError::Empty);
    let many = vec!["KL1002"; 64].join(",") + ",KL9010";
    assert_eq!(Strip::parse(&many).unwrap_err(), StripError::TooMany(65));
    let ok = vec!["KL1002"; 63].join(",") + ",KL9010";
    assert_eq!(Strip::parse(&ok).unwrap().len(), 64);
    // 41 x 6 complete bytes = 246 > 244.
    let long = vec!["KL3102:complete"; 41].join(",") + ",KL9010";
    let e = Strip::parse(&long).unwrap_err();
    assert_eq!(
        e,
        StripError::TooLong {
            inputs: 246,
            outputs: 246
        }
    );
    assert!(e.to_string().contains("at most 244"));
    let e = Strip::parse("KL1234,KL9010").unwrap_err().to_string();
    assert!(e.contains("`KL1234` is not in the catalogue"), "{e}");
    let e = Strip::parse("KL1104:complete,KL9010")
        .unwrap_err()
        .to_string();
    assert!(e.contains("no `complete` mapping"), "{e}");
    // Terminal files: one per line, comments.
    let s = Strip::parse("# strip\nKL1104   # inputs\nKL3102:complete\n\nKL9010\n").unwrap();
    assert_eq!(s.names(), ["KL1104", "KL3102:complete", "KL9010"]);
}

#[test]
fn mixed_strip_cfg_and_master_choices() {
    let s = strip("KL1104,KL2134,KL3102,KL4002,KL1501,KL2502,KL5001,KL9010");
    let img = s.default_image(Options::default());
    assert_eq!(
        img.cfg,
        [0x50, 0x50, 0x60, 0x60, 0xB4, 0xB2, 0xB2, 0x93, 0x10, 0x20]
    );
    assert_eq!(
        (img.in_len, img.out_len),
        (4 + 5 + 6 + 4 + 1, 4 + 5 + 6 + 1)
    );
    // The master may choose complete mapping for the KL3102 and the
    // alternative formats.
    let cfg = [0xB2, 0xB2, 0x61, 0xB5, 0xB5, 0xC0, 0x00, 0x84, 0x30];
    let i = check_cfg(&s, Options::default(), &cfg).unwrap();
    assert_eq!(i.in_len, 6 + 6 + 6 + 5 + 1);
    assert_eq!(i.out_len, 6 + 4 + 6 + 6 + 1 + 1);
    assert_eq!(entry(&i, "3.KL3102.1.status").byte, 0);
    assert_eq!(entry(&i, "3.KL3102.2").byte, 4);
    // A wrong identifier at the KL4002: the first byte no format has.
    let e = check_cfg(&s, Options::default(), &[0x50, 0x50, 0x50, 0x60]).unwrap_err();
    assert_eq!(e.error, CfgError::FaultyByte(2));
    assert!(e.reason.contains("terminal 4 (KL4002)"), "{}", e.reason);
    assert_eq!(e.error.blink(), (6, 3));
    let e = check_cfg(&s, Options::default(), &[0x50, 0x50, 0x60]).unwrap_err();
    assert_eq!(e.error, CfgError::TooFew);
    assert_eq!(e.error.blink(), (6, 0));
    // PLC interface first, cycle counter next, both before the terminals.
    let opts = Options {
        plc_interface: true,
        cycle_counter: true,
    };
    let img = s.default_image(opts);
    assert_eq!(&img.cfg[..3], &[0xB1, 0x10, 0x50]);
    assert_eq!(entry(&img, "plc.status").byte, 0);
    assert_eq!(entry(&img, "kbus.counter").byte, 2);
    assert_eq!(entry(&img, "3.KL3102.1").byte, 3);
    assert!(check_cfg(&s, opts, &img.cfg).is_ok());
    let e = check_cfg(&s, opts, &img.cfg[1..]).unwrap_err();
    assert_eq!(e.error, CfgError::FaultyByte(0));
}

#[test]
fn user_prm_data_validation() {
    let ok = UserPrm::parse(&[0; 10], false).unwrap();
    assert_eq!(ok, UserPrm::default());
    assert_eq!(UserPrm::parse(&[0; 9], false), Err(PrmError::TooFew(9)));
    assert_eq!(UserPrm::parse(&[], false).unwrap_err().code(), 2);
    let faulty = |i: usize, v: u8| {
        let mut d = [0u8; 10];
        d[i] = v;
        UserPrm::parse(&d, false).unwrap_err()
    };
    for (i, v) in [(0, 0x80), (2, 0x08), (3, 0x03), (5, 0x02), (9, 0x02)] {
        let e = faulty(i, v);
        assert_eq!(
            (e.code(), e.byte()),
            (3, i as u8),
            "byte {i} = 0x{v:02X}: {e}"
        );
    }
    let mut d = [0u8; 12];
    d[3] = 0x0A;
    d[5] = 0x01;
    d[9] = 0x02;
    let p = UserPrm::parse(&d, true).unwrap();
    assert_eq!(p.startup, StartupMode::ParameterStatDiag);
    assert!(p.cycle_counter && p.plc_interface && p.programmed);
    assert_eq!(UserPrm::parse(&p.emit(), true), Ok(p));
}

fn set_prm(user: &[u8]) -> Vec<u8> {
    let mut v = vec![0x88, 1, 100, 11, (IDENT >> 8) as u8, IDENT as u8, 0];
    v.extend_from_slice(user);
    v
}

struct Bench {
    slave: DpSlave<Bk3000>,
    /// The time of the next request.
    now: Instant,
}

impl Bench {
    fn new(list: &str) -> Bench {
        Bench {
            slave: DpSlave::new(Bk3000::new(strip(list)), ADDR),
            now: T0,
        }
    }

    /// A coupler with the terminals `list` in data exchange with a master
    /// configured for the same strip.
    fn started(list: &str) -> (Bench, Bk3000Master) {
        let mut b = Bench::new(list);
        let m = Bk3000Master::from_names(&list.split(',').collect::<Vec<_>>()).unwrap();
        b.start(&m.user_prm_data(), m.chk_cfg());
        (b, m)
    }

    fn req(&mut self, dsap: Option<u8>, data: &[u8]) -> (Reply, Vec<u8>) {
        let fc = FunctionCode::request(RequestKind::SrdHigh);
        let req =
            DataTelegram::new(ADDR, MASTER, fc, data).with_saps(dsap, dsap.map(|_| sap::MASTER));
        let mut out = [0u8; 246];
        let r = self.slave.on_request(self.now, &req, &mut out);
        let len = match r {
            Reply::Data { len, .. } => len,
            _ => 0,
        };
        (r, out[..len].to_vec())
    }

    fn diag(&mut self) -> Vec<u8> {
        self.req(Some(sap::SLAVE_DIAG), &[]).1
    }

    fn start(&mut self, user: &[u8], cfg: &[u8]) {
        self.req(Some(sap::SET_PRM), &set_prm(user));
        self.req(Some(sap::CHK_CFG), cfg);
    }

    fn dx(&mut self, out: &[u8]) -> Vec<u8> {
        self.req(None, out).1
    }
}

/// K51: the modelled K-bus cycle time against the reaction-time table
/// of p. 23 ("Laufzeit auf dem K-Bus", measured values; digital OUT, IN,
/// analog terminals → T_Zyklus in µs): every row within 15 µs.
#[test]
fn kbus_cycle_time_follows_the_reaction_time_table() {
    let table: [(usize, usize, usize, u16); 26] = [
        (4, 0, 0, 150),
        (8, 0, 0, 170),
        (12, 0, 0, 170),
        (16, 0, 0, 200),
        (20, 0, 0, 200),
        (24, 0, 0, 220),
        (28, 0, 0, 220),
        (32, 0, 0, 245),
        (0, 4, 0, 150),
        (0, 8, 0, 180),
        (0, 12, 0, 180),
        (0, 16, 0, 200),
        (0, 20, 0, 200),
        (0, 24, 0, 230),
        (0, 28, 0, 230),
        (0, 32, 0, 250),
        (4, 4, 0, 170),
        (8, 8, 0, 195),
        (12, 12, 0, 220),
        (16, 16, 0, 250),
        (20, 20, 0, 275),
        (24, 24, 0, 300),
        (28, 28, 0, 325),
        (32, 32, 0, 350),
        (4, 4, 1, 630),
        (4, 4, 2, 700),
    ];
    for (dout, din, analog, want) in table {
        let mut names = vec!["KL2134"; dout / 4];
        names.extend(vec!["KL1104"; din / 4]);
        names.extend(vec!["KL3202"; analog]);
        names.push("KL9010");
        let d = Bk3000::new(strip(&names.join(",")));
        let got = d.kbus_cycle_us();
        assert!(
            got.abs_diff(want) <= 15,
            "{dout} DO, {din} DI, {analog} KL3202: {got} µs, the table {want} µs"
        );
    }
}

/// K51: with `kbus_timing` the outputs reach the terminals one K-bus
/// cycle after the Data_Exchange, and a new input value reaches the
/// master one cycle after it changed.
#[test]
fn process_data_are_delayed_by_the_kbus_cycle() {
    let list = "KL1104,KL2134,KL9010";
    let mut b = Bench {
        slave: DpSlave::new(Bk3000::new(strip(list)).with_kbus_timing(true), ADDR),
        now: T0,
    };
    let m = Bk3000Master::from_names(&list.split(',').collect::<Vec<_>>()).unwrap();
    b.start(&m.user_prm_data(), m.chk_cfg());
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    let cycle = Duration::from_micros(166); // 140 + 8 bits × 3.3 µs
    assert_eq!(b.slave.device().kbus_cycle_us(), 166);
    let t1 = T0 + Duration::from_millis(1);
    b.now = t1;
    let mut out = vec![0u8; m.image().out_len];
    m.encode("2.KL2134.3", 1.0, &mut out).unwrap();
    b.dx(&out);
    let dev = b.slave.device_mut();
    assert_eq!(
        dev.output_value("2.KL2134.3"),
        Some(0),
        "still on the K-bus"
    );
    assert_eq!(dev.poll_timeout(), Some(t1 + cycle));
    dev.handle_timeout(t1 + (cycle - Duration::from_micros(1)));
    assert_eq!(dev.output_value("2.KL2134.3"), Some(0));
    dev.handle_timeout(t1 + cycle);
    assert_eq!(
        dev.output_value("2.KL2134.3"),
        Some(1),
        "one K-bus cycle later"
    );
    // An input set at t2 shows from t2 + T on.
    let t2 = T0 + Duration::from_millis(2);
    b.now = t2;
    b.dx(&out);
    b.slave.device_mut().control("set 1.KL1104.2 1").unwrap();
    let bit = |b: &mut Bench, at: Instant| {
        b.now = at;
        let i = b.dx(&out);
        let view = m.decode(Dir::In, &i);
        view.iter().find(|c| c.name == "1.KL1104.2").unwrap().raw
    };
    assert_eq!(bit(&mut b, t2 + (cycle - Duration::from_micros(1))), 0);
    assert_eq!(bit(&mut b, t2 + cycle), 1);
    assert_eq!(bit(&mut b, t2 + cycle * 2), 1);
}

#[test]
fn prm_fault_gives_userprm_error_bytes() {
    let mut b = Bench::new("KL1104,KL2134,KL9010");
    b.start(&[0; 5], &[0x10, 0x20]);
    let d = b.diag();
    assert_ne!(d[0] & 0x40, 0, "Prm_Fault");
    assert_ne!(d[0] & 0x08, 0, "Ext_Diag");
    assert_eq!(u16::from_be_bytes([d[4], d[5]]), IDENT);
    // Length byte, reserved, first coupler message.
    assert_eq!(&d[6..16], &[10, 0, 0, 255, 2, 0, 0, 0, 0, 0]);
    let mut u = [0u8; 10];
    u[5] = 0x02;
    b.start(&u, &[0x10, 0x20]);
    let d = b.diag();
    assert_eq!(&d[10..12], &[3, 5], "faulty byte 5");
    assert_eq!(b.slave.state(), SlaveState::WaitPrm);
    // A good Set_Prm clears it.
    b.start(&[0; 10], &[0x10, 0x20]);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    let d = b.diag();
    assert_eq!(d.len(), 6, "no manufacturer diagnosis: {d:02X?}");
}

#[test]
fn cfg_fault_gives_cfgdata_bytes_and_blink_code() {
    let mut b = Bench::new("KL1104,KL2134,KL3102,KL4002,KL9010");
    b.start(&[0; 10], &[0x50, 0x50, 0x60, 0x60, 0x10]);
    assert_eq!(b.slave.state(), SlaveState::WaitPrm);
    let d = b.diag();
    assert_ne!(d[0] & 0x04, 0, "Cfg_Fault");
    assert_eq!(&d[8..16], &[0, 255, 0, 0, 1, 0, 0, 0], "too few CfgData");
    let ev: Vec<_> = std::iter::from_fn(|| b.slave.device_mut().poll_event()).collect();
    assert!(
        ev.iter()
            .any(|e| e.kind == "io-err" && e.text.contains("6 pulses, then 0")),
        "{ev:?}"
    );
    b.start(&[0; 10], &[0x50, 0x50, 0x50, 0x60, 0x10, 0x20]);
    let d = b.diag();
    assert_eq!(&d[12..14], &[2, 2], "byte 2 faulty");
    let text = Bk3000Master::describe_diag(&d[6..]);
    assert!(
        text.iter()
            .any(|l| l.contains("CfgData byte 2 faulty") && l.contains("6 pulses, then 3")),
        "{text:?}"
    );
}

#[test]
fn data_exchange_outputs_named_and_inputs_simulated() {
    let (mut b, m) = Bench::started("KL1104,KL2134,KL3102,KL4002,KL9010");
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    let mut out = vec![0u8; m.image().out_len];
    m.encode("2.KL2134.3", 1.0, &mut out).unwrap();
    m.encode("4.2", 5.0, &mut out).unwrap();
    let inputs = b.dx(&out);
    assert_eq!(inputs.len(), m.image().in_len);
    let dev = b.slave.device_mut();
    assert_eq!(dev.output_value("2.KL2134.3"), Some(1));
    assert_eq!(dev.output_value("2.KL2134.1"), Some(0));
    assert_eq!(dev.output_value("4.KL4002.2"), Some(16384));
    let ev: Vec<_> = std::iter::from_fn(|| dev.poll_event()).collect();
    assert!(
        ev.iter().any(|e| e.kind == "outputs"
            && e.text.contains("2.KL2134.3=1")
            && e.text.contains("4.KL4002.2=5.000 V")),
        "{ev:?}"
    );
    // A pinned input shows in the master's named view.
    dev.control("set 3.KL3102.2 -2.5").unwrap();
    dev.control("set 1.4 1").unwrap();
    let inputs = b.dx(&out);
    let view = m.decode(Dir::In, &inputs);
    let ch = view.iter().find(|c| c.name == "3.KL3102.2").unwrap();
    assert!((ch.value + 2.5).abs() < 0.001, "{ch}");
    assert_eq!(ch.unit, Some("V"));
    let d = view.iter().find(|c| c.name == "1.KL1104.4").unwrap();
    assert_eq!(d.raw, 1);
    assert_eq!(d.position, Some(1));
    // Inputs not pinned are simulated: the walking bit moves.
    let dev = b.slave.device_mut();
    dev.control("release all").unwrap();
    let mut seen = std::collections::BTreeSet::new();
    for k in 0..8u64 {
        let mut i = vec![0u8; m.image().in_len];
        dev.read_inputs(T0 + Duration::from_millis(500 * k), &mut i);
        seen.insert(i[4] & 0x0F);
    }
    assert_eq!(seen.len(), 4, "each KL1104 input in turn: {seen:?}");
    // Outputs go to 0 when the slave leaves data exchange.
    dev.clear_outputs(T0, ClearReason::Watchdog);
    assert_eq!(dev.output_value("2.KL2134.3"), Some(0));
}

#[test]
fn pulled_terminal_is_a_kbus_error() {
    let (mut b, m) = Bench::started("KL1104,KL2134,KL3102,KL4002,KL9010");
    b.dx(&vec![0; m.image().out_len]);
    let text = b.slave.device_mut().pull(3).unwrap();
    assert!(text.contains("4 pulses, then 2"), "{text}");
    // DH tells the master to fetch the diagnosis.
    let (r, _) = b.req(None, &vec![0; m.image().out_len]);
    assert!(
        matches!(
            r,
            Reply::Data {
                status: profibus_fdl::ResponseStatus::Dh,
                ..
            }
        ),
        "{r:?}"
    );
    let d = b.diag();
    assert_ne!(d[1] & 0x02, 0, "Stat_Diag");
    assert_eq!(&d[16..24], &[0, 254, 0, 0x24, 4, 2, 0, 0]);
    let text = Bk3000Master::describe_diag(&d[6..]);
    assert!(
        text.iter().any(|l| l.contains("break behind terminal 2")),
        "{text:?}"
    );
    // Inputs are 0 while the K-bus is broken.
    b.slave.device_mut().control("set 1.1 1").unwrap();
    assert!(b.dx(&vec![0; m.image().out_len]).iter().all(|&x| x == 0));
    b.slave.device_mut().plug(3).unwrap();
    let i = b.dx(&vec![0; m.image().out_len]);
    assert_eq!(i[4] & 1, 1);
    assert_eq!(b.diag().len(), 6);
}

#[test]
fn startup_parameter_mode_and_cycle_counter() {
    let mut b = Bench::new("KL1104,KL2134,KL9010");
    let prm = UserPrm {
        startup: StartupMode::ParameterStatDiag,
        cycle_counter: true,
        plc_interface: true,
        programmed: false,
        ..Default::default()
    };
    b.start(&prm.emit(), &[0xB1, 0x10, 0x10, 0x20]);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    let d = b.diag();
    assert_ne!(d[1] & 0x02, 0, "Stat_Diag in parameter mode 2");
    b.slave.device_mut().control("set 1.1 1").unwrap();
    let i = b.dx(&[0x81, 0, 0x0F]);
    // K-bus held; the PLC interface (the coupler's own) answers.
    assert_eq!(i, [0x81, 0, 0, 0], "K-bus held");
    assert_eq!(b.slave.device().output_value("2.1"), Some(0));
    b.slave.device_mut().control("run").unwrap();
    let i1 = b.dx(&[0x81, 0, 0x0F]);
    let i2 = b.dx(&[0x81, 0, 0x0F]);
    assert_eq!(i1[0], 0x81, "PLC interface status acknowledges control");
    assert_eq!(i2[2], i1[2].wrapping_add(1).max(1), "cycle counter");
    assert_ne!(i1[2], 0);
    assert_eq!(i1[3] & 1, 1);
    assert_eq!(b.slave.device().output_value("2.KL2134.4"), Some(1));
    assert_eq!(b.diag()[1] & 0x02, 0);
}

#[test]
fn programmed_configuration_is_compared_byte_for_byte() {
    let s = strip("KL1104,KL2134,KL3102,KL9010");
    let dev = Bk3000::new(s.clone());
    assert!(dev.with_programmed_cfg(vec![0x50, 0x10]).is_err());
    let dev = Bk3000::new(s)
        .with_programmed_cfg(vec![0x51, 0x30])
        .unwrap();
    let mut b = Bench {
        slave: DpSlave::new(dev, ADDR),
        now: T0,
    };
    let mut u = [0u8; 10];
    u[9] = 0x02;
    b.start(&u, &[0x50, 0x50, 0x10, 0x20]);
    assert_eq!(b.slave.state(), SlaveState::WaitPrm, "auto form refused");
    assert_eq!(&b.diag()[12..14], &[2, 0]);
    b.start(&u, &[0x51, 0x30]);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    // Without programmed configuration in User_Prm_Data the auto rules
    // apply again.
    b.start(&[0; 10], &[0x50, 0x50, 0x10, 0x20]);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
}

#[test]
fn register_read_of_the_terminal_type() {
    let list = "KL3102:complete,KL9010";
    let mut b = Bench::new(list);
    let m = Bk3000Master::from_names(&list.split(',').collect::<Vec<_>>()).unwrap();
    assert_eq!(m.chk_cfg(), &[0xB2, 0xB2]);
    b.start(&m.user_prm_data(), m.chk_cfg());
    let mut out = vec![0u8; 6];
    m.encode("1.KL3102.1.control", 0x88 as f64, &mut out)
        .unwrap();
    let i = b.dx(&out);
    let v = m.decode(Dir::In, &i);
    assert_eq!(v[0].raw, 0x88, "status acknowledges");
    assert_eq!(v[1].raw, 3102, "R8 = terminal type");
}

#[test]
fn encode_refuses_inputs_unknown_names_and_out_of_range() {
    let m = Bk3000Master::from_names(&["KL1104", "KL4002", "KL9010"]).unwrap();
    let mut out = vec![0u8; m.image().out_len];
    assert!(matches!(
        m.encode("1.KL1104.1", 1.0, &mut out),
        Err(master::ChannelError::NotOutput(_))
    ));
    assert!(matches!(
        m.encode("9.1", 1.0, &mut out),
        Err(master::ChannelError::Unknown(_))
    ));
    assert!(matches!(
        m.encode("2.1", 11.0, &mut out),
        Err(master::ChannelError::Range { .. })
    ));
    let v = m.encode("2.KL4002.1", 10.0, &mut out).unwrap();
    assert_eq!(v.raw, 0x7FFF);
    assert_eq!(v.to_string(), "2.KL4002.1 = 10.000 V");
}

#[test]
fn profile_options_modules_and_channels() {
    use crate::{profile as registry, DeviceOptions};
    let entry = registry("bk3000").unwrap();
    let mut o = DeviceOptions::new();
    o.set_text("terminals", "KL1104,KL2134,KL3102,KL4002,KL1501,KL9010");
    o.set_text("switch-ones", "7");
    o.set_text("switch-tens", "2");
    let p = entry.configure(&o, Some(9)).unwrap();
    assert_eq!(p.address(), Some(27));
    // K51's option exists under its name and takes a boolean.
    let mut k = o.clone();
    k.set_pair("kbus-timing=true").unwrap();
    entry.configure(&k, None).unwrap().device(None).unwrap();
    k.set_pair("kbus-timing=3").unwrap();
    assert!(entry.configure(&k, None).is_err());
    assert_eq!(
        p.chk_cfg().unwrap(),
        [0x50, 0x50, 0x60, 0x60, 0xB4, 0x10, 0x20]
    );
    assert_eq!(p.user_prm_data().unwrap(), prm::DEFAULT_USER_PRM);
    let m = p.channels(&p.chk_cfg().unwrap()).unwrap();
    let c = m
        .find(crate::channels::Direction::Input, "1.KL1104.3")
        .unwrap();
    assert_eq!(
        (c.offset, c.ty),
        (9, crate::channels::ChannelType::Bool { bit: 2 })
    );
    assert!(m
        .find(crate::channels::Direction::Output, "4.KL4002.2")
        .is_some());
    // The PLC interface is recognised in the configuration.
    let m = p
        .channels(&[0xB1, 0x50, 0x50, 0x60, 0x60, 0xB4, 0x10, 0x20])
        .unwrap();
    assert_eq!(
        m.find(crate::channels::Direction::Input, "3.KL3102.1")
            .unwrap()
            .offset,
        2
    );
    assert!(p.channels(&[0x10]).is_err());
    // Analog channels are in volts both ways.
    let m = p.channels(&p.chk_cfg().unwrap()).unwrap();
    let mut out = vec![0u8; 5];
    m.write_output("4.KL4002.1", crate::channels::Value::Float(2.5), &mut out)
        .unwrap();
    assert_eq!(i16::from_be_bytes([out[0], out[1]]), 8192);
    let c = m
        .find(crate::channels::Direction::Output, "4.KL4002.1")
        .unwrap();
    assert_eq!(c.read(&out), Some(crate::channels::Value::Float(2.5001)));
    assert_eq!(c.scale.as_ref().unwrap().unit, "V");
    assert!(m
        .write_output("4.KL4002.1", crate::channels::Value::Float(11.0), &mut out)
        .is_err());
    // A bus file's list.
    let mut o = DeviceOptions::new();
    o.set(
        "terminals",
        toml::Value::Array(vec!["KL1104".into(), "KL9010".into()]),
    );
    assert_eq!(
        entry.configure(&o, None).unwrap().chk_cfg().unwrap(),
        [0x10]
    );
    // Mappings chosen in the list select the matching GSD modules.
    o.set(
        "terminals",
        toml::Value::Array(vec![
            "KL1104".into(),
            "KL3102:complete".into(),
            "KL4032:status".into(),
            "KL5001:complete".into(),
            "KL2502".into(),
            "KL9010".into(),
        ]),
    );
    let p = entry.configure(&o, None).unwrap();
    let cfg = p.chk_cfg().unwrap();
    assert_eq!(
        cfg,
        [0xB2, 0xB2, 0xC0, 0x82, 0x00, 0xC0, 0x82, 0x00, 0xB4, 0xB2, 0xB2, 0x10]
    );
    assert!(p
        .channels(&cfg)
        .unwrap()
        .find(crate::channels::Direction::Input, "2.KL3102.1.status")
        .is_some());
    // Refusals a user understands.
    // Without a strip: the manual's appendix example.
    let p = entry.configure(&DeviceOptions::new(), None).unwrap();
    assert_eq!(p.modules(), profile::gsd_modules(p.gsd(), &strip(APPENDIX)));
    // A terminal name matches exactly or not at all, with the closest.
    let mut o = DeviceOptions::new();
    o.set_text("terminals", "KL1104,KL2135,KL9010");
    let e = entry.configure(&o, None).unwrap_err().to_string();
    assert_eq!(
        e,
        "option `terminals`: terminal 2: `KL2135` is not in the catalogue; did you mean `KL2134`?"
    );
    let mut o = DeviceOptions::new();
    o.set_text("terminals", "KL1104,KL2134");
    let e = entry.configure(&o, None).unwrap_err();
    assert!(e.to_string().contains("end terminal"), "{e}");
    o.set_text("terminals", "KL1104,KL9010");
    o.set_text("switch-tens", "12");
    assert!(entry.configure(&o, None).is_err());
    let mut o = DeviceOptions::new();
    o.set_text("terminals", "KL1104,KL2134,KL9010");
    o.set_text("programmed-cfg", "10 20");
    assert!(entry.configure(&o, None).unwrap().device(None).is_ok());
    o.set_text("programmed-cfg", "10");
    assert!(entry.configure(&o, None).is_err());
}

#[test]
fn gsd_file_agrees_with_the_emulation() {
    let g = crate::gsd_files::parse(crate::gsd_files::BK30BECF).unwrap();
    assert_eq!(g.ident_number, IDENT);
    assert!(g.sync_mode_supp && g.freeze_mode_supp && !g.dpv1_slave);
    assert_eq!(g.max_diag_data_len, Some(MAX_DIAG_LEN));
    // Every format of every complex terminal is a module.
    for t in CATALOGUE {
        for v in t.variants {
            assert!(
                g.modules.iter().any(|m| m.cfg == v.cfg),
                "{} {:?} {:02X?} has no GSD module",
                t.name,
                v.mapping,
                v.cfg
            );
        }
    }
    for b in [
        image::CFG_PLC_INTERFACE,
        image::CFG_CYCLE_COUNTER,
        0x10,
        0x20,
        0x30,
    ] {
        assert!(g.modules.iter().any(|m| m.cfg == [b]), "0x{b:02X}");
    }
    // The GSD's parameters produce User_Prm_Data the coupler decodes the
    // same way.
    let v: Vec<profibus_dp::config::gsd::PrmValue> = [
        "2-byte PLC interface=used",
        "Start-up mode=parameter mode with Stat_Diag",
        "K-bus cycle counter=on",
    ]
    .iter()
    .map(|s| s.parse().unwrap())
    .collect();
    let sel = g
        .select(&["2-byte PLC interface", "K-bus cycle counter"])
        .unwrap();
    let data = g.user_prm_data(&sel, &v).unwrap();
    let p = UserPrm::parse(&data, false).unwrap();
    assert_eq!(
        p,
        UserPrm {
            startup: StartupMode::ParameterStatDiag,
            cycle_counter: true,
            plc_interface: true,
            programmed: false,
            run_on_cfg_fault: false,
        }
    );
    assert_eq!(g.user_prm_data(&sel, &[]).unwrap(), prm::DEFAULT_USER_PRM);
    // A mixed strip selected by module names gives the emulation's Chk_Cfg.
    let s = strip("KL1104,KL2134,KL3102,KL4002,KL9010");
    let sel = g
        .select(&[
            "KL3xx2, KL3351: 2 x 16 bit in (compact)",
            "KL4xx2: 2 x 16 bit out (compact)",
            "8 digital inputs (1 byte)",
            "8 digital outputs (1 byte)",
        ])
        .unwrap();
    assert_eq!(
        g.chk_cfg(&sel).unwrap(),
        s.default_image(Options::default()).cfg
    );
}

#[test]
fn gsd_names_the_coupler_diagnosis() {
    let g = crate::gsd_files::parse(crate::gsd_files::BK30BECF).unwrap();
    let words = |d: &[u8]| profibus_dp::pdu::diag::describe(d, Some(&g), false);
    let mut b = Bench::new("KL1104,KL2134,KL3102,KL4002,KL9010");
    b.start(&[0; 10], &[0x50, 0x50, 0x50, 0x60, 0x10, 0x20]);
    let w = words(&b.diag());
    assert!(
        w.iter().any(|l| l
            == "device: CfgData error 2: CfgData byte 2 faulty; I/O-ERR blinks 6 pulses, then 3"),
        "{w:?}"
    );
    let mut u = [0u8; 10];
    u[3] = 3;
    b.start(&u, &[]);
    let w = words(&b.diag());
    assert!(
        w.iter()
            .any(|l| l == "device: UserPrmData error 3: User_Prm_Data byte 3 faulty"),
        "{w:?}"
    );
    b.start(&[0; 10], &[0x50, 0x50, 0x60, 0x60, 0x10, 0x20]);
    b.slave.device_mut().pull(4).unwrap();
    let w = words(&b.diag());
    for t in [
        "device: K-bus error",
        "device: K-bus data error, break behind terminal 3; I/O-ERR blinks 4 pulses, then 3",
    ] {
        assert!(w.iter().any(|l| l == t), "{t}: {w:?}");
    }
}

#[test]
fn sync_and_freeze_accepted_dpv1_refused_like_a_dp_v0_slave() {
    let mut b = Bench::new("KL1104,KL2134,KL9010");
    // Set_Prm with Lock_Req, Sync_Req, Freeze_Req and WD_On.
    let mut prm = set_prm(&[0; 10]);
    prm[0] = 0x88 | 0x20 | 0x10;
    b.req(Some(sap::SET_PRM), &prm);
    b.req(Some(sap::CHK_CFG), &[0x10, 0x20]);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    assert!(b.diag()[0] & 0x10 == 0, "not Not_Supported");
    // An MSAC_C1 read (slot 0, index 1) finds the SAP deactivated.
    let (r, _) = b.req(Some(sap::MSAC_C1), &[0x5E, 0, 1, 4]);
    assert!(
        matches!(
            r,
            Reply::Data {
                status: profibus_fdl::ResponseStatus::Rs,
                ..
            }
        ),
        "{r:?}"
    );
    assert_eq!(b.slave.state(), SlaveState::DataExch);
}

#[test]
fn terminals_file_option() {
    use crate::{profile as registry, DeviceOptions};
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().to_path_buf();
    let f = dir.join("strip.txt");
    std::fs::write(
        &f,
        "# my strip\nKL1408\nKL3202:complete  # PT100\nKL9100\nKL9010\n",
    )
    .unwrap();
    let mut o = DeviceOptions::new();
    o.set("terminals_file", f.display().to_string());
    let p = registry("bk3000").unwrap().configure(&o, None).unwrap();
    assert_eq!(p.chk_cfg().unwrap(), [0xB2, 0xB2, 0x10]);
    std::fs::write(&f, "KL1408\n").unwrap();
    let e = registry("bk3000")
        .unwrap()
        .configure(&o, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("strip.txt") && e.contains("end terminal"), "{e}");
}

mod fidelity;
