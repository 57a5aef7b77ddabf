use super::*;
use crate::pkw::Pkw;

const T0: Instant = Instant::ZERO;

fn ms(n: u64) -> Instant {
    T0 + Duration::from_millis(n)
}

fn cycle(d: &mut Omega, now: Instant, out: &[u8], inputs: usize) -> Vec<u8> {
    d.write_outputs(now, out);
    let mut i = vec![0u8; inputs];
    d.read_inputs(now, &mut i);
    i
}

/// Run one PKW job on a board configured 0x73 0x71 0x51 0x61; returns
/// the response words.
fn job(d: &mut Omega, req: Pkw) -> Pkw {
    let l = d.check_cfg(&[0x73, 0x71, 0x51, 0x61]).unwrap();
    let mut out = vec![0u8; l.outputs];
    cycle(d, ms(0), &out, l.inputs);
    req.emit(&mut out);
    let i = cycle(d, ms(1), &out, l.inputs);
    assert_eq!(Pkw::parse(&i), Some(Pkw::ZERO), "processing delay");
    let i = cycle(d, ms(10), &out, l.inputs);
    Pkw::parse(&i).unwrap()
}

/// `d` answers the PKW request `req` with `want` (as printed).
fn assert_job(d: &mut Omega, req: Pkw, want: &str) {
    assert_eq!(job(d, req).to_string(), want, "{req:?}");
}

#[test]
fn configuration_rules() {
    let ok = |c: &[u8]| check_configuration(c).unwrap();
    let l = ok(&[0x73, 0x71, 0x51, 0x65]);
    assert_eq!(
        (l.input_bytes(), l.output_bytes()),
        (16, 24),
        "§5.5: 8 AI, 12 AO"
    );
    // §6.1: A, B and C give the same layout.
    let a = ok(&[0x73, 0x75]);
    let b = ok(&[0x73, 0x71, 0x53, 0x63]);
    let c = ok(&[0xF9]);
    for l in [a, b, c] {
        assert_eq!((l.pkw, l.setpoints, l.actual_values), (true, 2, 2));
        assert_eq!((l.input_bytes(), l.output_bytes()), (20, 20));
    }
    assert!(!ok(&[0x73]).pkw, "a lone 0x73 is the 1/1 standard module");
    assert_eq!(ok(&[0x73]).input_bytes(), 8);
    let l = ok(&[0xC0, 0x51, 0x43]);
    assert_eq!(
        (l.setpoints, l.actual_values),
        (8, 1),
        "by the standard: 36 B out, 8 in"
    );
    assert_eq!((l.output_bytes(), l.input_bytes()), (36, 8));
    assert_eq!(ok(&[0xC0, 0xD5, 0xD5]).input_bytes(), 44);
    assert_eq!(ok(&[0xFB]).setpoints, 3);
    for (bad, why) in [
        (&[0x71, 0x73, 0x51, 0x61][..], "standard module"),
        (&[0x73, 0x51, 0x61], "status / control"),
        (&[0x71, 0x51], "at least one setpoint"),
        (&[0x71, 0x61], "at least one setpoint"),
        (&[0xF9, 0x51], "block-consistent"),
        (&[0x73, 0x75, 0x51], "standard module"),
        (&[0x71, 0x51, 0x53, 0x61], "more than one"),
        (&[0x71, 0x51, 0x61, 0x71], "second status"),
        (&[0x71, 0x52, 0x61], "not a module"),
        (&[], "empty"),
    ] {
        let e = check_configuration(bad).unwrap_err();
        assert!(e.to_string().contains(why), "{bad:02X?}: {e}");
    }
    // A fault against the rules sets b_MESSAGE 3 and is refused.
    let mut d = Omega::with_defaults().with_counts(2, 2).unwrap();
    assert!(d.check_cfg(&[0x73, 0x51, 0x61]).is_err());
    assert_eq!(d.b_message(), 3);
    assert!(d.check_cfg(&[0xF9]).is_ok());
    assert_eq!(d.b_message(), 0);
    assert!(Omega::with_defaults().with_counts(9, 1).is_err());
}

#[test]
fn cyclic_data_high_word_first() {
    let mut d = Omega::with_defaults().with_auto_enable();
    let l = d.check_cfg(&[0x71, 0x53, 0x61]).unwrap();
    assert_eq!((l.inputs, l.outputs), (12, 8));
    let i = cycle(&mut d, T0, &[0x04, 0x7F, 0, 1, 0x12, 0x34, 0x56, 0x78], 12);
    assert_eq!(d.control_words(), [0x047F, 0x0001]);
    assert_eq!(d.setpoint(0), Some(0x1234_5678));
    // Status word 1: Remote, setpoint reached, voltage, quick stop,
    // operation enabled, switched on, ready; AV1 follows SP1; AV2 has no
    // setpoint.
    assert_eq!(i, [0x06, 0x37, 0, 0, 0x12, 0x34, 0x56, 0x78, 0, 0, 0, 0]);
}

/// Control word 1 and setpoint 1 on a board configured 0x71 0x51 0x61:
/// status word 1 and actual value 1.
fn drive(d: &mut Omega, now: Instant, cw: u16, sp: i32) -> (u16, i32) {
    let mut out = [0u8; 8];
    out[..2].copy_from_slice(&cw.to_be_bytes());
    out[4..].copy_from_slice(&sp.to_be_bytes());
    let i = cycle(d, now, &out, 8);
    (
        u16::from_be_bytes([i[0], i[1]]),
        i32::from_be_bytes([i[4], i[5], i[6], i[7]]),
    )
}

#[test]
fn a_plcs_enable_sequence_reaches_operation_enabled_and_the_drive_follows() {
    // Chapter 9.4 (L1333-1347) status bits, DRIVECOM control bits.
    let mut d = Omega::with_defaults();
    d.check_cfg(&[0x71, 0x51, 0x61]).unwrap();
    // Power-on: switch-on disabled (bit 6) and Remote (bit 9); the
    // setpoint is not followed.
    assert_eq!(drive(&mut d, ms(0), 0x0000, 1500), (0x0240, 0));
    assert_eq!(d.drive_state(), DriveState::SwitchOnDisabled);
    // Enable operation without shutdown first: nothing happens.
    assert_eq!(drive(&mut d, ms(1), 0x000F, 1500), (0x0250, 0));
    // Shutdown: ready to switch on (bits 0, 4, 5).
    assert_eq!(drive(&mut d, ms(2), 0x0006, 1500), (0x0231, 0));
    // Switch on: switched on (bit 1).
    assert_eq!(drive(&mut d, ms(3), 0x0007, 1500), (0x0233, 0));
    // Enable operation: operation enabled (bit 2), setpoint reached
    // (bit 10), and actual value 1 follows setpoint 1.
    assert_eq!(drive(&mut d, ms(4), 0x000F, 1500), (0x0637, 1500));
    assert_eq!(drive(&mut d, ms(5), 0x000F, -700), (0x0637, -700));
    assert_eq!(d.drive_state(), DriveState::OperationEnabled);
    // Disable operation: the actual value stays where it was.
    assert_eq!(drive(&mut d, ms(6), 0x0007, 3000), (0x0233, -700));
    // Quick stop from operation enabled: bit 5 goes to 0.
    drive(&mut d, ms(7), 0x000F, 3000);
    assert_eq!(drive(&mut d, ms(8), 0x000B, 3000).0, 0x0217);
    // A fault from the control input, reset by the fault-reset bit's edge.
    assert_eq!(drive(&mut d, ms(9), 0x0000, 0).0, 0x0240, "disable voltage");
    drive(&mut d, ms(10), 0x0006, 0);
    drive(&mut d, ms(10), 0x000F, 100);
    assert!(d.control("fault 0x0003").unwrap().contains("fault 16#0003"));
    assert_eq!(drive(&mut d, ms(11), 0x000F, 200), (0x0218, 100));
    assert_eq!(drive(&mut d, ms(12), 0x008F, 200).0, 0x0240 | 0x10);
    assert_eq!(d.drive_state(), DriveState::SwitchOnDisabled);
    drive(&mut d, ms(13), 0x0006, 200);
    assert_eq!(drive(&mut d, ms(14), 0x000F, 200), (0x0637, 200));
    let states: Vec<String> = std::iter::from_fn(|| d.poll_event())
        .filter(|e| e.kind == "drive")
        .map(|e| e.text)
        .collect();
    assert!(
        states.contains(&"operation enabled".to_string())
            && states.contains(&"fault 16#0003".to_string()),
        "{states:?}"
    );
    // The master leaves: control word 0 = disable voltage.
    d.clear_outputs(ms(15), ClearReason::Watchdog);
    assert_eq!(d.drive_state(), DriveState::SwitchOnDisabled);
}

#[test]
fn process_data_monitoring_faults_the_drive_when_p127_says_so() {
    // P127 = 4 activates monitoring (L1080-1083): the cyclic data timeout
    // and a diagnosis read during data exchange (L1186) are error 16#0003.
    let mut d = Omega::with_defaults();
    assert_job(&mut d, Pkw::new(2, 127, 0, 4), "107F 0000 0000 0004");
    drive(&mut d, ms(20), 0x0006, 0);
    drive(&mut d, ms(21), 0x000F, 0);
    d.handle_timeout(ms(1021));
    assert_eq!(d.drive_state(), DriveState::Fault(3));
    let mut d = Omega::with_defaults();
    d.check_cfg(&[0x71, 0x51, 0x61]).unwrap();
    drive(&mut d, ms(0), 0x0006, 0);
    d.handle_timeout(ms(1000));
    assert_eq!(d.drive_state(), DriveState::ReadyToSwitchOn, "P127 = 0");
}

#[test]
fn pkw_examples_of_the_manual() {
    // Read P218 (double word): 10DA → 20DA, value in PWE1/PWE2 (L1028-1047);
    // it follows setpoint 1, here 0.
    let mut d = Omega::with_defaults();
    assert_job(&mut d, Pkw::new(1, 218, 0, 0), "20DA 0000 0000 0000");
    // P127 := 4: 207F 0000 0000 0004 → 107F 0000 0000 0004 (L1080-1097).
    let mut d = Omega::with_defaults();
    assert_job(&mut d, Pkw::new(2, 127, 0, 4), "107F 0000 0000 0004");
    assert_eq!(d.parameter(127), Some(4));
    // Maximum of P126: 407E 0006 → 307E 0006 0000 000F (L1161-1178).
    let mut d = Omega::with_defaults();
    assert_job(&mut d, Pkw::new(4, 126, 6, 0), "307E 0006 0000 000F");
    // P003 = 0x0064 (L1901-1906).
    let mut d = Omega::with_defaults();
    assert_job(&mut d, Pkw::new(1, 3, 0, 0), "1003 0000 0000 0064");
    // PNU 1000 := 0x12345678, read back (L1859-1870).
    let mut d = Omega::with_defaults();
    assert_job(
        &mut d,
        Pkw::new(3, 1000, 0, 0x1234_5678),
        "23E8 0000 1234 5678",
    );
    assert_job(&mut d, Pkw::new(1, 1000, 0, 0), "23E8 0000 1234 5678");
    assert_eq!(d.omega_value(1000), Some(0x1234_5678));
}

#[test]
fn pkw_error_table() {
    let cases: [(Pkw, &str); 12] = [
        (Pkw::new(1, 999, 0, 0), "73E7 0000 0000 0008"),
        (Pkw::new(2, 218, 0, 1), "70DA 0000 0000 0005"),
        (Pkw::new(3, 127, 0, 1), "707F 0000 0000 0005"),
        (Pkw::new(2, 1, 0, 1), "7001 0000 0000 0001"),
        (Pkw::new(2, 126, 0, 0x10), "707E 0000 0000 0002"),
        (Pkw::new(1, 126, 1, 0), "707E 0000 0000 0003"),
        (Pkw::new(4, 126, 3, 0), "707E 0003 0000 0104"),
        (Pkw::new(4, 218, 6, 0), "70DA 0006 0000 0103"),
        (Pkw::new(4, 1000, 1, 0), "73E8 0001 0000 0102"),
        (Pkw::new(2, 1000, 0, 1), "73E8 0000 0000 0005"),
        (Pkw::new(5, 3, 0, 0), "7003 0000 0000 0080"),
        (Pkw::new(4, 127, 1, 0), "307F 0001 0000 0005"),
    ];
    for (req, want) in cases {
        let mut d = Omega::with_defaults();
        assert_eq!(job(&mut d, req).to_string(), want, "{req}");
    }
    let mut d = Omega::with_defaults();
    assert_eq!(
        job(&mut d, Pkw::new(4, 127, 2, 0)).pwe2,
        0x0008,
        "info: STORE"
    );
    assert_eq!(
        job(&mut d, Pkw::new(4, 218, 2, 0)).pwe2,
        0x0001,
        "info: protected"
    );
}

#[test]
fn pkw_error_examples_of_the_manual() {
    // L1045-1047: reading P218 when the actual value cannot be read →
    // 70DA 0000 0000 0082 (here: P218 is parameterised as a cyclic actual
    // value, L1020).
    let mut d = Omega::with_defaults().with_cyclic_parameters(vec![218]);
    assert_job(&mut d, Pkw::new(1, 218, 0, 0), "70DA 0000 0000 0082");
    // L1096-1097: writing P127 := 4 when the setpoint cannot be written →
    // 707F 0000 0000 0083 (P127 parameterised cyclically, L1067).
    let mut d = Omega::with_defaults();
    d.control("cyclic P127").unwrap();
    assert_job(&mut d, Pkw::new(2, 127, 0, 4), "707F 0000 0000 0083");
    assert_eq!(d.parameter(127), Some(0), "not written");
    // 0x0081: the PLC's function blocks do not run (x_EN, L1023); the
    // remote bit is 0 then (L1366).
    let mut d = Omega::with_defaults();
    d.control("plc off").unwrap();
    assert_job(&mut d, Pkw::new(1, 3, 0, 0), "7003 0000 0000 0081");
    assert_eq!(d.status_word() & STATUS_REMOTE, 0);
    // 0x0084 / 0x0085: the master configured other counts than
    // si_NR_RD_VALUE / si_NR_WR_VALUE: accepted on the bus, b_MESSAGE 3,
    // no setpoint / actual value transmission (L378, L920-921, L1197,
    // L1298-1299).
    let mut d = Omega::with_defaults().with_counts(1, 2).unwrap();
    assert_job(&mut d, Pkw::new(1, 3, 0, 0), "7003 0000 0000 0084");
    assert_eq!(d.b_message(), 3);
    let mut d = Omega::with_defaults().with_counts(2, 1).unwrap();
    assert_job(&mut d, Pkw::new(1, 3, 0, 0), "7003 0000 0000 0085");
}

#[test]
fn service_data_timeout_t_timeout_sd_data() {
    // A controller slower than t_TIMEOUT_SD_DATA (L456, L1667-1673): the
    // job fails at the timeout with 0x0082 / 0x0083 and b_ERR bit 4 (V
    // controller) or bit 3 (the Omega's array, on the board) is set.
    let mut d = Omega::with_defaults()
        .with_pkw_delay(Duration::from_millis(200))
        .with_sd_timeout(Duration::from_millis(50));
    let l = d.check_cfg(&[0x73, 0x71, 0x51, 0x61]).unwrap();
    let mut out = vec![0u8; l.outputs];
    Pkw::new(1, 3, 0, 0).emit(&mut out);
    cycle(&mut d, ms(0), &out, l.inputs);
    assert_eq!(d.poll_timeout(), Some(ms(50)));
    let i = cycle(&mut d, ms(49), &out, l.inputs);
    assert_eq!(Pkw::parse(&i), Some(Pkw::ZERO));
    d.handle_timeout(ms(50));
    assert_eq!(d.b_err(), B_ERR_SD_CONTROLLER_TIMEOUT);
    let i = cycle(&mut d, ms(50), &out, l.inputs);
    assert_eq!(Pkw::parse(&i).unwrap().to_string(), "7003 0000 0000 0082");
    assert!(d.status_text().contains("V controller timeout"));
    // Reset, then a write to the Omega's array: bit 3, 0x0083.
    cycle(&mut d, ms(60), &vec![0u8; l.outputs], l.inputs);
    Pkw::new(3, 1000, 0, 7).emit(&mut out);
    cycle(&mut d, ms(70), &out, l.inputs);
    d.handle_timeout(ms(120));
    assert_eq!(d.b_err() & B_ERR_SD_BOARD_TIMEOUT, B_ERR_SD_BOARD_TIMEOUT);
    let i = cycle(&mut d, ms(120), &out, l.inputs);
    assert_eq!(Pkw::parse(&i).unwrap().to_string(), "73E8 0000 0000 0083");
    // O46: the FB goes on with cyclic data, so a service data timeout
    // is b_MESSAGE −3 (timeout warning) until x_QUIT.
    assert_eq!(d.b_message(), -3);
    assert!(d
        .status_text()
        .starts_with("b_MESSAGE -3 (timeout warning)"));
    d.quit();
    assert_eq!(d.b_message(), 0);
    // Within the timeout the job runs (default 5 ms vs 5000 ms).
    let mut d = Omega::with_defaults();
    assert_job(&mut d, Pkw::new(1, 3, 0, 0), "1003 0000 0000 0064");
}

#[test]
fn a_new_command_needs_pke_zero_first() {
    let mut d = Omega::with_defaults();
    let l = d.check_cfg(&[0x73, 0x71, 0x51, 0x61]).unwrap();
    let mut out = vec![0u8; l.outputs];
    Pkw::new(1, 3, 0, 0).emit(&mut out);
    cycle(&mut d, ms(0), &out, l.inputs);
    Pkw::new(2, 127, 0, 4).emit(&mut out);
    cycle(&mut d, ms(10), &out, l.inputs);
    let i = cycle(&mut d, ms(20), &out, l.inputs);
    assert_eq!(Pkw::parse(&i).unwrap().to_string(), "707F 0000 0000 0101");
    assert_eq!(d.parameter(127), Some(0), "not executed");
}

#[test]
fn monitoring_b_message_and_b_err() {
    let mut d = Omega::with_defaults();
    d.check_cfg(&[0x71, 0x51, 0x61]).unwrap();
    assert_eq!(
        d.poll_timeout(),
        None,
        "nothing to watch before data exchange"
    );
    cycle(&mut d, ms(0), &[0; 8], 8);
    assert_eq!(d.poll_timeout(), Some(ms(1000)));
    d.handle_timeout(ms(1000));
    assert_eq!(d.b_message(), 2);
    assert_eq!(d.b_err(), B_ERR_CYCLIC_TIMEOUT);
    assert!(d.status_text().contains("field bus error"));
    cycle(&mut d, ms(1100), &[0; 8], 8);
    assert_eq!(d.b_message(), 0, "data flow again");
    assert_eq!(d.b_err(), B_ERR_CYCLIC_TIMEOUT, "kept until x_QUIT");
    assert_eq!(
        d.control("quit").unwrap(),
        "b_MESSAGE 0 (no warning, no error), b_ERR 16#00, drive switch-on disabled, status word 1 16#0240"
    );
    let mut w = [0u8; 16];
    d.diagnosis(ms(1101), &mut DiagWriter::new(&mut w));
    assert_eq!(d.b_message(), 4, "diagnosis read during data exchange");
    let kinds: Vec<&str> = std::iter::from_fn(|| d.poll_event())
        .map(|e| e.kind)
        .collect();
    assert!(
        kinds.iter().all(|k| *k == "status") && kinds.len() >= 4,
        "{kinds:?}"
    );
}

#[test]
fn pkw_dialect_codes() {
    use crate::pkw::{Command, Pkw, Reply};
    assert_eq!(PKW.command(&Pkw::new(4, 9, 6, 0)), Command::Describe(6));
    assert_eq!(PKW.command(&Pkw::new(6, 9, 3, 0)), Command::Unsupported(6));
    assert_eq!(PKW.response(0x7E, 6, Reply::Element(0xF)).pke, 0x307E);
    assert_eq!(
        PKW.decode_response(&Pkw::new(7, 5, 0, 0x82)),
        Some(Err(0x82))
    );
    assert_eq!(PKW.error_text(0x82), "error reading actual value");
}

/// O46: b_MESSAGE 1 (general error) with b_ERR bit 1 and the warnings
/// −1, −2 (L1769-1779, L1914); errors win over warnings, 4 over both.
#[test]
fn b_message_general_error_and_warnings() {
    let mut d = Omega::with_defaults();
    d.check_cfg(&[0x71, 0x51, 0x61]).unwrap();
    cycle(&mut d, ms(0), &[0; 8], 8);
    assert!(d
        .control("warn wire-break")
        .unwrap()
        .starts_with("b_MESSAGE -2 (wire breakage warning), b_ERR 16#00"));
    d.control("warn general").unwrap();
    assert_eq!(d.b_message(), -1);
    assert!(d
        .control("board off")
        .unwrap()
        .starts_with("b_MESSAGE 1 (general error), b_ERR 16#02 (no access to option board)"));
    d.quit();
    assert_eq!(
        (d.b_message(), d.b_err()),
        (1, B_ERR_BOARD_ACCESS),
        "cause still there"
    );
    d.control("board on").unwrap();
    assert_eq!(d.b_err(), B_ERR_BOARD_ACCESS, "kept until x_QUIT");
    d.quit();
    assert_eq!((d.b_message(), d.b_err()), (-1, 0), "the warning again");
    let mut w = [0u8; 16];
    d.diagnosis(ms(1), &mut DiagWriter::new(&mut w));
    assert_eq!(d.b_message(), 4, "diagnosis read wins over a warning");
    cycle(&mut d, ms(2), &[0; 8], 8);
    assert_eq!(d.b_message(), -1);
    d.control("warn none").unwrap();
    assert_eq!(d.b_message(), 0);
    assert!(d.control("warn loud").is_err());
    let kinds: Vec<&str> = std::iter::from_fn(|| d.poll_event())
        .map(|e| e.kind)
        .collect();
    assert!(kinds.contains(&"status"), "changes are status events");
}
