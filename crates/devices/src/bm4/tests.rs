use super::PKW as D;
use super::*;
use crate::pkw::Pkw;
use profibus_dp::config::gsd::{Gsd, ParseOptions};

const T0: Instant = Instant::ZERO;

fn example() -> Bm4 {
    Bm4::example(6)
}

/// PKW module + all five example variables, in table order.
fn full_cfg() -> Vec<u8> {
    let mut c = vec![0x73];
    let t = VarTable::example();
    for i in 0..5 {
        c.extend_from_slice(&t.identifier(i));
    }
    c
}

/// One Data_Exchange: outputs in, inputs out.
fn cycle(d: &mut Bm4, now: Instant, out: &[u8], inputs: usize) -> Vec<u8> {
    d.write_outputs(now, out);
    let mut i = vec![0u8; inputs];
    d.read_inputs(now, &mut i);
    i
}

fn pkw_job(d: &mut Bm4, req: Pkw) -> Pkw {
    let l = d.check_cfg(&[0x73]).unwrap();
    let mut out = vec![0u8; l.outputs];
    let i = cycle(d, T0, &out, l.inputs);
    assert_eq!(Pkw::parse(&i), Some(Pkw::ZERO));
    req.emit(&mut out);
    let i = cycle(d, T0, &out, l.inputs);
    Pkw::parse(&i).unwrap()
}

/// `d` answers the PKW request `req` with `want` (as printed).
fn assert_job(d: &mut Bm4, req: Pkw, want: &str) {
    assert_eq!(pkw_job(d, req).to_string(), want, "{req:?}");
}

#[test]
fn generated_gsd_has_the_example_files_modules() {
    let d = example();
    let text = d.gsd_text();
    let ours = Gsd::parse(&text, ParseOptions::STRICT).unwrap().gsd;
    let theirs = Gsd::from_file(
        concat!(env!("CARGO_MANIFEST_DIR"), "/gsd/MyGSDFile.gsd"),
        ParseOptions { lenient: true },
    )
    .unwrap()
    .gsd;
    let mods = |g: &Gsd| {
        g.modules
            .iter()
            .map(|m| (m.name.clone(), m.cfg.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(mods(&ours), mods(&theirs));
    assert_eq!(ours.ident_number, 0x0008);
    assert_eq!(ours.max_input_len, Some(20), "12 + PKW 8");
    assert_eq!(ours.max_output_len, Some(14));
    assert!(ours.set_slave_add_supp && ours.auto_baud_supp);
    // No table: the default file itself.
    let def = Bm4::new(VarTable::default_table(), Addressing::fixed(6));
    assert_eq!(def.gsd_file(), DEFAULT_GSD);
}

#[test]
fn chk_cfg_takes_table_modules_only() {
    let mut d = example();
    let l = d.check_cfg(&full_cfg()).unwrap();
    assert_eq!((l.inputs, l.outputs), (8 + 12, 8 + 6));
    assert_eq!(d.real_cfg(), &full_cfg()[..]);
    // Any subset in any order, PKW optional.
    let t = VarTable::example();
    let mut c = t.identifier(4).to_vec();
    c.extend_from_slice(&t.identifier(3));
    assert_eq!(
        d.check_cfg(&c).unwrap(),
        IoLayout {
            inputs: 4,
            outputs: 2
        }
    );
    assert_eq!(d.led(), Led::ParameteriseConfigure);
    for (bad, why) in [
        (vec![0x42, 0xC1, 0x02, 0x05], "no module"),
        (vec![0x42, 0xC0, 0x02, 0x04], "no module"),
        ([t.identifier(0), t.identifier(0)].concat(), "twice"),
        (
            [t.identifier(0).to_vec(), vec![0x73]].concat(),
            "must be the first",
        ),
        (vec![], "empty"),
        (vec![0x42, 0xC1], "does not start"),
    ] {
        let e = d.check_cfg(&bad).unwrap_err();
        assert!(e.to_string().contains(why), "{bad:02X?}: {e}");
        // A master's mismatch is no "configuration error" (L2057-2059).
        assert_eq!(d.led(), Led::ParameteriseConfigure);
    }
    // Default table: the "all modules" module, alone or after PKW.
    let mut def = Bm4::new(VarTable::default_table(), Addressing::fixed(6));
    let l = def
        .check_cfg(&[0x73, 0x2F, 0x6F, 0x6F, 0x6F, 0x1F, 0x5F, 0x5F, 0x5F])
        .unwrap();
    assert_eq!((l.inputs, l.outputs), (8 + 112, 8 + 112));
    assert!(def
        .check_cfg(&[0x2F, 0x6F, 0x6F, 0x6F, 0x1F, 0x5F, 0x5F, 0x5F, 0x82, 0x0F, 0x00, 0x00])
        .is_err());
}

#[test]
fn process_data_in_motorola_order_in_cfg_order() {
    let mut d = example();
    let t = VarTable::example();
    // di_MyReadVar3, ud_MyReadVar1 in; u_MyWriteVar2 out.
    let cfg = [t.identifier(4), t.identifier(0), t.identifier(3)].concat();
    let l = d.check_cfg(&cfg).unwrap();
    assert_eq!((l.inputs, l.outputs), (8, 2));
    let i = cycle(&mut d, T0, &[0xAB, 0xCD], 8);
    assert_eq!(i, [0, 0, 0x0B, 0xB8, 0, 0, 0x03, 0xE8]);
    assert_eq!(d.value(3, 0), Some(0xABCD));
    assert_eq!(d.led(), Led::DataExchange);
    d.set_value(4, 0, -2).unwrap();
    let i = cycle(&mut d, T0, &[0, 0], 8);
    assert_eq!(&i[..4], &[0xFF, 0xFF, 0xFF, 0xFE]);
}

#[test]
fn pkw_examples_of_the_manual() {
    // Read di_MyReadVar3 (PNU 4): 1004 → 2004 0000 0000 0BB8 (L1568-1607).
    let mut d = example();
    let r = pkw_job(&mut d, Pkw::new(1, 4, 0, 0));
    assert_eq!(r.to_string(), "2004 0000 0000 0BB8");
    // Write ud_MyWriteVar1 (PNU 2): 3002 0000 1234 5678 → 2002 mirrored.
    let mut d = example();
    let r = pkw_job(&mut d, Pkw::new(3, 2, 0, 0x1234_5678));
    assert_eq!(r.to_string(), "2002 0000 1234 5678");
    assert_eq!(d.value(2, 0), Some(0x1234_5678));
    // A variable that does not exist: 7xxx, PWE2 0x000B.
    let mut d = example();
    assert_job(&mut d, Pkw::new(1, 9, 0, 0), "7009 0000 0000 000B");
}

#[test]
fn pkw_error_numbers() {
    let cases: [(Pkw, &str); 8] = [
        (Pkw::new(3, 0, 0, 1), "7000 0000 0000 0001"), // INPUT: read only
        (Pkw::new(2, 2, 0, 1), "7002 0000 0000 0005"), // word to UDINT
        (Pkw::new(3, 3, 0, 1), "7003 0000 0000 0005"), // dword to UINT
        (Pkw::new(2, 3, 0, 7), "1003 0000 0000 0007"), // word to UINT: ok
        (Pkw::new(4, 1, 0, 0), "7001 0000 0000 0016"), // PBE not supported
        (Pkw::new(9, 1, 0, 0), "7001 0000 0000 0016"), // reserved AK
        (Pkw::new(6, 1, 0, 0), "7001 0000 0000 0005"), // element of a single variable
        (Pkw::new(1, 1, 1, 0), "7001 0000 0000 0003"), // IND ≠ 0
    ];
    for (req, want) in cases {
        let mut d = example();
        assert_eq!(pkw_job(&mut d, req).to_string(), want, "{req}");
    }
    // A variable configured as cyclic data: refused (0x000B).
    let mut d = example();
    let t = VarTable::example();
    let cfg = [vec![0x73], t.identifier(4).to_vec()].concat();
    let l = d.check_cfg(&cfg).unwrap();
    let mut out = vec![0u8; l.outputs];
    cycle(&mut d, T0, &out, l.inputs);
    Pkw::new(1, 4, 0, 0).emit(&mut out);
    let i = cycle(&mut d, T0, &out, l.inputs);
    assert_eq!(Pkw::parse(&i).unwrap().to_string(), "7004 0000 0000 000B");
    assert!(D.error_text(0x0B).starts_with("variable does not exist"));
}

#[test]
fn pkw_arrays_of_the_default_table() {
    let mut d = Bm4::new(VarTable::default_table(), Addressing::fixed(6));
    // d_RefValue0..7 (PNU 2): write element 3, read it back.
    let r = pkw_job(&mut d, Pkw::new(8, 2, 3, 0xDEAD_BEEF));
    assert_eq!(r.to_string(), "5002 0003 DEAD BEEF");
    let r = pkw_job(&mut d, Pkw::new(6, 2, 3, 0));
    assert_eq!(r.to_string(), "5002 0003 DEAD BEEF");
    // b_RefValue (PNU 0, BYTE): word element write, range checked.
    assert_job(&mut d, Pkw::new(7, 0, 15, 0x7F), "4000 000F 0000 007F");
    assert_job(&mut d, Pkw::new(7, 0, 15, 0x100), "7000 000F 0000 0005");
    assert_job(&mut d, Pkw::new(6, 0, 16, 0), "7000 0010 0000 0003");
    // Actual values (PNU 4) are read only; a plain read of an array is
    // the wrong type.
    assert_job(&mut d, Pkw::new(7, 4, 0, 1), "7004 0000 0000 0001");
    assert_job(&mut d, Pkw::new(1, 4, 0, 0), "7004 0000 0000 0005");
}

#[test]
fn a_job_starts_on_any_change_of_the_request_words() {
    // The manual sets IND, PWE1, PWE2, then PKE (L1571-1581, L1611-1619)
    // and never asks for PKE = 0 between jobs: a second array job that
    // changes only IND, or a second write with a new value and the same
    // PKE, is executed.
    let mut d = Bm4::new(VarTable::default_table(), Addressing::fixed(6));
    let l = d.check_cfg(&[0x73]).unwrap();
    let mut out = vec![0u8; l.outputs];
    let mut run = |d: &mut Bm4, req: Pkw| {
        req.emit(&mut out);
        Pkw::parse(&cycle(d, T0, &out, l.inputs))
            .unwrap()
            .to_string()
    };
    // d_RefValue0..7 (PNU 2): write element 3, then element 4 (IND only
    // changes… and the value), then read 3 and 4 by IND alone.
    assert_eq!(
        run(&mut d, Pkw::new(8, 2, 3, 0x1111_1111)),
        "5002 0003 1111 1111"
    );
    assert_eq!(
        run(&mut d, Pkw::new(8, 2, 4, 0x1111_1111)),
        "5002 0004 1111 1111"
    );
    assert_eq!(run(&mut d, Pkw::new(6, 2, 3, 0)), "5002 0003 1111 1111");
    assert_eq!(
        run(&mut d, Pkw::new(8, 2, 3, 0x2222_2222)),
        "5002 0003 2222 2222"
    );
    assert_eq!(run(&mut d, Pkw::new(6, 2, 3, 0)), "5002 0003 2222 2222");
    assert_eq!(run(&mut d, Pkw::new(6, 2, 4, 0)), "5002 0004 1111 1111");
    // Example 2's write (L1609-1639), then a second value, same PKE 3002.
    let mut d = example();
    let l = d.check_cfg(&[0x73]).unwrap();
    let mut out = vec![0u8; l.outputs];
    let mut run = |d: &mut Bm4, req: Pkw| {
        req.emit(&mut out);
        Pkw::parse(&cycle(d, T0, &out, l.inputs))
            .unwrap()
            .to_string()
    };
    assert_eq!(
        run(&mut d, Pkw::new(3, 2, 0, 0x1234_5678)),
        "2002 0000 1234 5678"
    );
    assert_eq!(
        run(&mut d, Pkw::new(3, 2, 0, 0x0000_0BB8)),
        "2002 0000 0000 0BB8"
    );
    assert_eq!(run(&mut d, Pkw::new(1, 2, 0, 0)), "2002 0000 0000 0BB8");
}

#[test]
fn sdiag_example_and_status_codes() {
    use profibus_dp::slave::DpSlave;
    let mut s = DpSlave::new(example(), 6);
    let dev = s.device_mut();
    // 16#1234_5678_90AB_CDEF in a_ED_DATA[0..7] (L1989-2010).
    dev.control("sdiag EF CD AB 90 78 56 34 12").unwrap();
    assert!(!dev.sdiag_ok());
    assert!(dev.take_new_diag());
    assert_eq!(dev.sdiag(&[1, 2, 3], true, false), Err(SdiagError::Busy));
    let mut buf = [0u8; 244];
    let n = s.diagnosis(T0, &mut buf);
    assert_eq!(n, 15);
    // Byte 7 (index 6) is the header; user bytes from the 8th byte.
    assert_eq!(buf[6], 0x09);
    assert_eq!(
        &buf[7..15],
        &[0xEF, 0xCD, 0xAB, 0x90, 0x78, 0x56, 0x34, 0x12]
    );
    assert_ne!(buf[0] & 0x08, 0, "Ext_Diag");
    assert_eq!(&buf[4..6], &[0x00, 0x08]);
    let dev = s.device_mut();
    assert!(dev.sdiag_ok());
    assert_eq!(dev.poll_event().unwrap().kind, "diag");
    assert_eq!(dev.sdiag(&[1, 2], true, false), Err(SdiagError::TooShort));
    assert_eq!(SdiagError::TooShort.d_status(), 0x0101_8400);
    assert_eq!(SdiagError::TooLong.d_status(), 0x0201_8400);
    assert_eq!(SdiagError::EdFlag.d_status(), 0x0101_8200);
    assert_eq!(SdiagError::Busy.d_status(), 0x00B6_8000);
    assert_eq!(dev.sdiag(&[0; 61], true, false), Err(SdiagError::TooLong));
    assert_eq!(dev.sdiag(&[0; 3], false, false), Err(SdiagError::EdFlag));
    dev.sdiag(&[7; 60], true, true).unwrap();
    let n = s.diagnosis(T0, &mut buf);
    assert_eq!(n, 6 + 1 + 60);
    assert_ne!(buf[2] & 0x80, 0, "Ext_Diag_Overflow");
}

#[test]
fn addressing_modes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().to_path_buf();
    let a = |us, sw| Addressing::from_us_device(us, sw, Some(&dir));
    assert_eq!(a(6, None).unwrap().address, 6);
    assert!(!a(6, None).unwrap().accepts_set_slave_add());
    assert_eq!(a(128, Some(6)).unwrap().address, 6);
    assert!(a(128, Some(0)).is_err());
    assert!(a(128, None).is_err());
    assert!(a(0, None).is_err());
    assert!(a(129, None).is_err());
    assert!(Addressing::from_us_device(126, None, None).is_err());
    // 127: every start at 126, accepted, not stored.
    let every = a(127, None).unwrap();
    assert_eq!((every.address, every.mode), (126, AddressMode::EveryStart));
    let mut d = Bm4::new(VarTable::example(), every);
    assert!(d.features().set_slave_add);
    d.set_address(9, false, &[]).unwrap();
    assert!(!dir.join(STATE_FILE).exists());
    // 126 (and 128 with the switch at 0x7E..): set once, then kept.
    let once = a(128, Some(0x7E)).unwrap();
    assert_eq!((once.address, once.mode), (126, AddressMode::SetOnce));
    let store = once.store.clone().unwrap();
    let mut d = Bm4::new(VarTable::example(), once);
    d.set_address(17, false, &[]).unwrap();
    assert!(d.set_address(18, false, &[]).is_err(), "only once");
    assert!(!store.exists(), "the device itself writes no file");
    // The program running the slave keeps it (on SlaveEvent::AddressChanged).
    crate::address::StoredAddress {
        address: 17,
        no_add_chg: false,
    }
    .save(&store)
    .unwrap();
    let again = a(126, None).unwrap();
    assert_eq!(again.address, 17);
    assert!(
        !Bm4::new(VarTable::example(), again)
            .features()
            .set_slave_add
    );
}

#[test]
fn led_states_follow_the_bus() {
    let mut d = example();
    assert_eq!(d.led(), Led::ParameteriseConfigure);
    d.check_cfg(&full_cfg()).unwrap();
    cycle(&mut d, T0, &[0; 14], 20);
    assert_eq!(d.led(), Led::DataExchange);
    d.clear_outputs(T0, ClearReason::Watchdog);
    assert_eq!(d.led(), Led::BusError);
    let texts: Vec<String> = std::iter::from_fn(|| d.poll_event())
        .filter(|e| e.kind == "led")
        .map(|e| e.text)
        .collect();
    assert_eq!(
        texts,
        ["data exchange (H1 green)", "bus error / watchdog (H2 red)"]
    );
}

#[test]
fn configuration_error_software_watchdog_and_blink_codes() {
    // "Konfigurationsfehler": the b maXX PLC did not configure the module
    // (L2057-2059): H2 and H4 red, and no configuration is accepted.
    let mut d = example();
    assert!(d
        .control("plc unconfigured")
        .unwrap()
        .contains("configuration error"));
    assert_eq!(d.led(), Led::ConfigurationError);
    let e = d.check_cfg(&full_cfg()).unwrap_err().to_string();
    assert!(e.contains("did not configure the module"), "{e}");
    d.control("plc configured").unwrap();
    assert_eq!(d.led(), Led::ParameteriseConfigure);
    d.check_cfg(&full_cfg()).unwrap();
    cycle(&mut d, T0, &[0; 14], 20);
    assert_eq!(d.led(), Led::DataExchange);
    // Software watchdog (L2046, L2061-2065): all LEDs on, the module
    // leaves data exchange and refuses until switched off and on.
    assert!(d
        .control("fault software-watchdog")
        .unwrap()
        .contains("H1 H2 H3 H4"));
    assert!(d.take_restart());
    assert!(d.check_cfg(&full_cfg()).is_err());
    d.control("fault none").unwrap();
    assert_eq!(d.led(), Led::ParameteriseConfigure);
    // Blink codes 1..4 (L2071-2075).
    for n in 1..=4u8 {
        d.control(&format!("fault blink {n}")).unwrap();
        assert_eq!(d.led(), Led::Blink(n));
    }
    assert!(d.control("fault blink 5").is_err());
    let texts: Vec<String> = std::iter::from_fn(|| d.poll_event())
        .filter(|e| e.kind == "led")
        .map(|e| e.text)
        .collect();
    assert!(
        texts
            .iter()
            .any(|t| t.contains("blink 2x: no PROFIBUS slave software")),
        "{texts:?}"
    );
    assert!(
        texts.iter().any(|t| t.starts_with("software watchdog")),
        "{texts:?}"
    );
}

#[test]
fn pkw_dialect_codes() {
    use crate::pkw::{Command, Reply};
    assert_eq!(D.command(&Pkw::new(6, 9, 3, 0)), Command::ReadElement(3));
    assert_eq!(D.command(&Pkw::new(4, 9, 6, 0)), Command::Unsupported(4));
    assert_eq!(D.response(5, 2, Reply::ElementDword(7)).pke, 0x5005);
    assert_eq!(D.request(1, Command::Describe(1)), None);
    assert!(D.error_text(0x0B).starts_with("variable does not exist"));
}

/// B44: the two internal SDIAG errors with their d_STATUS bytes
/// (L1977-1978), raised once on demand; the next SDIAG works again.
#[test]
fn sdiag_internal_errors_give_the_manuals_d_status() {
    let mut d = example();
    assert_eq!(
        d.control("sdiag-fail range").unwrap(),
        "the next SDIAG fails with d_STATUS 16#00B78000"
    );
    let e = d.control("sdiag 01 02 03").unwrap_err().to_string();
    assert!(e.contains("parameter out of range"), "{e}");
    // Bytes 0..3: Function_Num 00, Error_Decode 80, codes B7 00.
    assert_eq!(
        SdiagError::OutOfRange.d_status().to_le_bytes(),
        [0x00, 0x80, 0xB7, 0x00]
    );
    d.sdiag_fail_next(SdiagError::NoMemory);
    assert_eq!(d.sdiag(&[1, 2, 3], true, false), Err(SdiagError::NoMemory));
    assert_eq!(
        SdiagError::NoMemory.d_status().to_le_bytes(),
        [0x00, 0x80, 0xC3, 0x02]
    );
    assert!(!d.take_new_diag(), "a refused SDIAG announces nothing");
    d.sdiag(&[1, 2, 3], true, false).unwrap();
    assert!(d.take_new_diag());
    assert!(d.control("sdiag-fail full").is_err());
}

/// B59: u_LOCAL_NODE_ID and u_BAUDRATE read back (L691, L1399-1411).
#[test]
fn status_reads_back_node_id_and_baudrate() {
    let mut d = example();
    assert_eq!(
        d.control("status").unwrap(),
        "parameterise / configure (H3 green); u_LOCAL_NODE_ID 6; u_BAUDRATE auto"
    );
    d.set_baud(profibus_fdl::Baud::B1500000);
    assert!(d
        .control("status")
        .unwrap()
        .ends_with("u_LOCAL_NODE_ID 6; u_BAUDRATE 1500000"));
    // Every-start address: 126 until the master sets one.
    let mut d = Bm4::new(
        VarTable::example(),
        Addressing::from_us_device(127, None, None).unwrap(),
    );
    assert_eq!(d.local_node_id(), 126);
    d.set_address(9, false, &[]).unwrap();
    assert_eq!(d.local_node_id(), 9);
    assert!(d.control("status").unwrap().contains("u_LOCAL_NODE_ID 9;"));
}
