//! Issue 30: the BK3000 as its manual describes it (catalogue, user
//! terminals, RunOnCfgFault, free placement, register access, the PLC
//! interface, K-bus and initialisation errors).

use super::*;
use crate::bk3000::catalogue::Source;
use crate::bk3000::user;

#[test]
fn catalogue_has_every_terminal_the_manual_names() {
    // p. 49-51 and the FMS list of p. 63.
    for (name, cfgs) in [
        (
            "KL3012",
            &[
                &[0x50u8, 0x50][..],
                &[0xB2, 0xB2],
                &[0xC0, 0x00, 0x82, 0xC0, 0x00, 0x82],
            ][..],
        ),
        ("KL3022", &[&[0x50, 0x50][..], &[0xB2, 0xB2]]),
        ("KL3032", &[&[0x50, 0x50][..], &[0xB2, 0xB2]]),
        ("KL3042", &[&[0x50, 0x50][..], &[0xB2, 0xB2]]),
        ("KL3052", &[&[0x50, 0x50][..], &[0xB2, 0xB2]]),
        ("KL3062", &[&[0x50, 0x50][..], &[0xB2, 0xB2]]),
        ("KL3302", &[&[0x50, 0x50][..], &[0xB2, 0xB2]]),
        // "KL3xx2, KL3351 … 0x50 (muß je Klemme zweimal verwendet werden)"
        (
            "KL3351",
            &[
                &[0x50, 0x50][..],
                &[0xB2, 0xB2],
                &[0xC0, 0x00, 0x82, 0xC0, 0x00, 0x82],
            ],
        ),
        // "KL2502, KL5302 1 Kanal: 0xB2 (zweimal) 2 Kanäle: 0xB5 (einmal)"
        ("KL5302", &[&[0xB2, 0xB2][..], &[0xB5]]),
        // "126 Byte Data-Area 0xC0,0xFF"
        ("DATA126", &[&[0xC0, 0xFF, 0xFF][..]]),
    ] {
        let t = lookup(name).unwrap_or_else(|| panic!("{name} missing"));
        assert_eq!(t.source, Source::Manual, "{name}");
        for c in cfgs {
            assert!(t.variants.iter().any(|v| v.cfg == *c), "{name}: {c:02X?}");
        }
        let s = strip(&format!("{name},KL9010"));
        for v in t.variants {
            assert!(
                check_cfg(&s, Options::default(), v.cfg).is_ok(),
                "{name} {:02X?}",
                v.cfg
            );
        }
    }
    // The data area: 2 + 126 bytes each way, read back.
    let (mut b, m) = Bench::started("DATA126,KL9010");
    assert_eq!((m.image().in_len, m.image().out_len), (128, 128));
    let mut out = vec![0u8; 128];
    out[2..4].copy_from_slice(&[0x12, 0x34]);
    out[126..128].copy_from_slice(&[0xAB, 0xCD]);
    b.dx(&out);
    let i = b.dx(&out);
    assert_eq!(&i[2..4], &[0x12, 0x34]);
    assert_eq!(&i[126..128], &[0xAB, 0xCD]);
    // "C0 FF" alone is too few CfgData (the second length byte missing).
    assert_eq!(
        check_cfg(&strip("DATA126,KL9010"), Options::default(), &[0xC0, 0xFF])
            .unwrap_err()
            .error,
        CfgError::TooFew
    );
}

#[test]
fn common_kl_families_run_with_their_data_sheet_sizes() {
    let n = CATALOGUE
        .iter()
        .filter(|t| t.source == Source::Datasheet)
        .count();
    assert!(n >= 60, "{n} data-sheet terminals");
    assert!(CATALOGUE.len() >= 85, "{}", CATALOGUE.len());
    // Every catalogue terminal runs in a strip, every format checks.
    for t in CATALOGUE.iter().filter(|t| t.name != "KL9010") {
        let s = strip(&format!("{},KL9010", t.name));
        let img = s.default_image(Options::default());
        assert!(
            check_cfg(&s, Options::default(), &img.cfg).is_ok(),
            "{}",
            t.name
        );
        let (bi, bo) = t.digital_bits();
        assert_eq!(
            img.digital,
            ((bi as usize).div_ceil(8), (bo as usize).div_ceil(8)),
            "{}",
            t.name
        );
    }
    // A digital terminal with inputs and outputs (KL1859: 8 + 8).
    let s = strip("KL1859,KL2012,KL9010");
    let img = s.default_image(Options::default());
    assert_eq!(img.cfg, [0x10, 0x21]);
    assert_eq!(entry(&img, "2.KL2012.1").bit, Some(0));
    assert_eq!(entry(&img, "2.KL2012.1").byte, 1);
    // 1- and 4-channel analog terminals by analogy with KL3xx2.
    let s = strip("KL3404,KL4001:complete,KL9010");
    assert_eq!(
        s.default_image(Options::default()).cfg,
        [0x50, 0x50, 0x50, 0x50, 0xB2]
    );
}

const USER_TYPES: &str = r#"
[KL3408]
type = "complex"
summary = "8 analog inputs 0..10 V, described by the user"
channels = 8
bytes_in = 24
bytes_out = 24
status = true
cfg = "B2 B2 B2 B2 B2 B2 B2 B2"
compact_cfg = "0x57"
compact_bytes_in = 16
range = [0.0, 10.0]
unit = "V"
registers = { R8 = 3408, R9 = 0x3141 }

[KL1889]
type = "digital"
bits_in = 16
"#;

#[test]
fn user_terminal_types_from_toml() {
    let extra = user::parse_text(USER_TYPES).unwrap();
    let s = Strip::parse_with("KL1889,KL3408,KL3408:compact,KL9010", &extra).unwrap();
    let img = s.default_image(Options::default());
    assert_eq!(img.in_len, 24 + 16 + 2);
    assert_eq!(img.out_len, 24);
    assert_eq!(
        img.cfg,
        [0xB2, 0xB2, 0xB2, 0xB2, 0xB2, 0xB2, 0xB2, 0xB2, 0x57, 0x11]
    );
    assert_eq!(entry(&img, "2.KL3408.8.status").byte, 21);
    assert_eq!(entry(&img, "2.KL3408.8").byte, 22);
    assert_eq!(entry(&img, "3.KL3408.1").byte, 24);
    let ty = extra.iter().find(|t| t.name == "KL3408").unwrap();
    assert_eq!(ty.source, Source::User);
    assert_eq!(ty.type_number(), 3408);
    // A pinned value in the user's unit.
    let mut dev = Bk3000::new(s);
    dev.control("set 3.1 5").unwrap();
    // Bad descriptions: one line naming the terminal and the key.
    for (text, words) in [
        (
            "[X1]\ntype = \"analog\"",
            "terminal type `X1`: type `analog`: one of digital, complex, passive",
        ),
        (
            "[X1]\ntype = \"complex\"\nbytes_in = 3\nchannels = 2\ncfg = \"B2\"",
            "3 bytes do not split evenly over 2 channels",
        ),
        ("[X1]\ntype = \"complex\"\nbytes_in = 2", "needs cfg"),
        (
            "[X1]\ntype = \"complex\"\nbytes_in = 2\ncfg = \"zz\"",
            "cfg `zz` is not hex bytes",
        ),
        (
            "[KL3102]\ntype = \"passive\"",
            "the catalogue has it already",
        ),
        ("[X1]\ntype = \"digital\"", "needs bits_in or bits_out"),
        (
            "[X1]\ntype = \"digital\"\nbits_in = 2\nregisters = { R99 = 1 }",
            "registers are R0..R63",
        ),
        (
            "[X1]\ntype = \"digital\"\nbitsin = 2",
            "unknown field `bitsin`",
        ),
    ] {
        let e = user::parse_text(text).unwrap_err();
        assert!(e.contains(words), "{text}: {e}");
    }
    // Unknown names suggest the user's types too.
    let e = Strip::parse_with("KL3409,KL9010", &extra).unwrap_err();
    assert!(e.to_string().contains("KL3408"), "{e}");
}

#[test]
fn user_terminal_types_from_the_bus_file_and_device_opt() {
    use crate::profile::DeviceOptions;
    let entry = crate::PROFILES.iter().find(|p| p.name == "bk3000").unwrap();
    // Bus file: [slave.terminal_types.KL3408] is a table in the options.
    let table: toml::Table = USER_TYPES.parse().unwrap();
    let mut o = DeviceOptions::new();
    o.set("terminals", "KL1889,KL3408,KL9010");
    o.set("terminal_types", toml::Value::Table(table));
    let p = entry.configure(&o, Some(5)).unwrap();
    let ch = p
        .channels(&[0xB2; 8].iter().copied().chain([0x11]).collect::<Vec<_>>())
        .unwrap();
    assert!(ch.channels.iter().any(|c| c.name == "2.KL3408.8"), "{ch:?}");
    // --device-opt terminal-types-file=FILE
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("types.toml");
    std::fs::write(&f, USER_TYPES).unwrap();
    let mut o = DeviceOptions::new();
    o.set_text("terminals", "KL3408,KL9010");
    o.set_pair(&format!("terminal-types-file={}", f.display()))
        .unwrap();
    assert!(entry.configure(&o, Some(5)).unwrap().device(None).is_ok());
    // A faulty file names the file and the terminal.
    std::fs::write(&f, "[KL3408]\ntype = \"complex\"\n").unwrap();
    let e = entry.configure(&o, Some(5)).unwrap_err().to_string();
    assert!(
        e.contains("types.toml") && e.contains("KL3408") && e.contains("needs cfg"),
        "{e}"
    );
}

/// Write register `r` of KL3102 channel 1 (complete mapping, terminal
/// 1): control 0xC0 | r, the value in the output word.
fn reg_write(b: &mut Bench, r: u8, v: u16) -> Vec<u8> {
    let mut out = vec![0u8; 6];
    out[0] = 0xC0 | r;
    out[1..3].copy_from_slice(&v.to_be_bytes());
    b.dx(&out)
}

fn reg_read(b: &mut Bench, r: u8) -> (u8, u16) {
    let mut out = vec![0u8; 6];
    out[0] = 0x80 | r;
    let i = b.dx(&out);
    (i[0], u16::from_be_bytes([i[1], i[2]]))
}

#[test]
fn register_set_code_word_and_scaling() {
    let (mut b, _m) = Bench::started("KL3102:complete,KL9010");
    // Data sheet example 1: control 0x88 reads R8, status 0x88, 3102.
    assert_eq!(reg_read(&mut b, 8), (0x88, 3102));
    assert_eq!(reg_read(&mut b, 9), (0x89, 0x3141), "software version 1A");
    // Without the code word the user area keeps its value.
    let i = reg_write(&mut b, 34, 0x0200);
    assert_eq!(i[0], 0xA2, "write acknowledged: control without bit 6");
    assert_eq!(reg_read(&mut b, 34).1, 0x0100, "R34 write-protected");
    // Example 2: control 0xDF writes the code word 0x1235 into R31,
    // status 0x9F acknowledges.
    let i = reg_write(&mut b, 31, 0x1235);
    assert_eq!((i[0], i[1], i[2]), (0x9F, 0, 0));
    // User scaling: gain 2 (0x0200), offset 100, feature bit 0.
    reg_write(&mut b, 34, 0x0200);
    reg_write(&mut b, 33, 100);
    reg_write(&mut b, 32, 0x0003);
    assert_eq!(reg_read(&mut b, 32).1, 0x0003);
    // Manufacturer settings and ROM stay.
    reg_write(&mut b, 20, 0x0300);
    reg_write(&mut b, 8, 1234);
    assert_eq!(reg_read(&mut b, 20).1, 0x0100);
    assert_eq!(reg_read(&mut b, 8).1, 3102);
    // Process data mode: 2.5 V = raw 8192 → 100 + 2·8192 = 16484.
    b.slave.device_mut().control("set 1.1 2.5").unwrap();
    let i = b.dx(&[0; 6]);
    assert_eq!(i16::from_be_bytes([i[1], i[2]]), 100 + 2 * 8192);
    assert_eq!(i[0], 0, "in range");
    // 6 V ·2 is beyond 0x7FFF: overrange and error, value clamped; the
    // channel's diagnosis message names terminal 1, channel 1.
    b.slave.device_mut().control("set 1.1 6").unwrap();
    let i = b.dx(&[0; 6]);
    assert_eq!(i[0], 0x42, "overrange + error");
    assert_eq!(i16::from_be_bytes([i[1], i[2]]), 0x7FFF);
    let d = b.diag();
    assert_ne!(d[0] & 0x08, 0, "Ext_Diag");
    assert!(
        d[8..].chunks(8).any(|m| m == [1, 1, 0, 0, 0, 0x42, 0, 0]),
        "{d:02X?}"
    );
    // R0 holds the raw value, R6 the status byte.
    assert_eq!(reg_read(&mut b, 6).1, 0x42);
    // Restore the factory settings (R7 = 0x7000): scaling off again.
    reg_write(&mut b, 7, 0x7000);
    b.slave.device_mut().control("set 1.1 2.5").unwrap();
    let i = b.dx(&[0; 6]);
    assert_eq!(i16::from_be_bytes([i[1], i[2]]), 8192);
    assert_eq!(b.diag().len(), 6, "error gone, diagnosis empty");
}

#[test]
fn status_byte_underrange_on_a_unipolar_range_and_limits() {
    let (mut b, _m) = Bench::started("KL3022:complete,KL9010");
    // 4..20 mA: 2 mA is below the range.
    b.slave.device_mut().control("set 1.1 2").unwrap();
    let i = b.dx(&[0; 6]);
    assert_eq!(i[0], 0x41, "underrange + error");
    assert_eq!(&i[1..3], &[0, 0]);
    // Limit 1 (R35) with feature bit 9: 12 mA is above 4000.
    reg_write(&mut b, 31, 0x1235);
    reg_write(&mut b, 35, 4000);
    reg_write(&mut b, 32, 0x0202);
    b.slave.device_mut().control("set 1.1 12").unwrap();
    let i = b.dx(&[0; 6]);
    assert_eq!(i[0], 0x04, "limit 1: value above");
    // Filter R37 = 2: the value moves a quarter of the way per cycle.
    reg_write(&mut b, 37, 2);
    b.slave.device_mut().control("set 1.1 4").unwrap();
    let first = b.dx(&[0; 6]);
    let v = i16::from_be_bytes([first[1], first[2]]);
    assert!(v > 0 && v < 16384, "filtered: {v}");
}

#[test]
fn run_on_cfg_fault_runs_with_a_maximal_configuration() {
    // The master is set up for KL1104,KL2134,KL3102,KL4002 (p. 46: "in
    // einer Maximal-Konfiguration"); only KL1104,KL3102 are plugged.
    let mut b = Bench::new("KL3102,KL1104,KL9010");
    let max = [0x50, 0x50, 0x60, 0x60, 0x10, 0x20];
    let mut u = [0u8; 10];
    b.start(&u, &max);
    assert_eq!(
        b.slave.state(),
        SlaveState::WaitPrm,
        "refused without the mode"
    );
    u[1] = 0x01;
    b.start(&u, &max);
    assert_eq!(b.slave.state(), SlaveState::DataExch, "RunOnCfgFault");
    assert!(b.slave.device().user_prm().run_on_cfg_fault);
    // The master's lengths: 5 in, 5 out; the plugged terminals' data
    // where the automatic image puts them; the fault in the diagnosis.
    b.slave.device_mut().control("set 1.1 5").unwrap();
    b.slave.device_mut().control("set 2.1 1").unwrap();
    let i = b.dx(&[0; 5]);
    assert_eq!(i.len(), 5);
    assert_eq!(i16::from_be_bytes([i[0], i[1]]), 16384);
    assert_eq!(i[4] & 1, 1, "KL1104 bit after the words");
    let d = b.diag();
    assert_eq!(d[0] & 0x04, 0, "no Cfg_Fault");
    assert_eq!(d[12], 2, "CfgData error 2 in the coupler's message");
}

#[test]
fn kbus_faults_raise_their_codes_and_init_bits() {
    let (mut b, m) = Bench::started("KL1104,KL2134,KL3102,KL9010");
    let out = vec![0u8; m.image().out_len];
    b.dx(&out);
    // A terminal that does not answer: K-bus command error, 3 pulses, 0.
    let t = b.slave.device_mut().control("mute 3").unwrap();
    assert!(t.contains("3 pulses, then 0"), "{t}");
    let d = b.diag();
    assert_ne!(d[1] & 0x02, 0, "Stat_Diag");
    assert_eq!(&d[16..24], &[0, 254, 0, 0x22, 3, 0, 0, 0]);
    assert!(Bk3000Master::describe_diag(&d[6..])
        .iter()
        .any(|l| l.contains("does not answer")));
    assert!(b.dx(&out).iter().all(|&x| x == 0), "inputs 0");
    b.slave.device_mut().control("unmute 3").unwrap();
    assert_eq!(b.diag().len(), 6);
    // A changed strip: init error bit 3, 14 pulses then the terminal.
    let t = b.slave.device_mut().control("swap 2 KL2408").unwrap();
    assert!(t.contains("14 pulses, then 2"), "{t}");
    let d = b.diag();
    assert_eq!(&d[16..24], &[0, 254, 0x08, 0x20, 14, 2, 0, 0]);
    let words = Bk3000Master::describe_diag(&d[6..]);
    assert!(
        words
            .iter()
            .any(|l| l.contains("error reading the terminal types")),
        "{words:?}"
    );
    b.slave.device_mut().control("swap 2 KL2134").unwrap();
    assert_eq!(b.diag().len(), 6);
    // A pulled terminal still wins over the others (code 4).
    b.slave.device_mut().control("mute 3").unwrap();
    b.slave.device_mut().control("pull 2").unwrap();
    assert_eq!(&b.diag()[16..24], &[0, 254, 0, 0x24, 4, 1, 0, 0]);
}

/// One PLC interface step: function `f` with `data`, the toggle flipped.
fn plc(b: &mut Bench, toggle: &mut u8, f: u8, data: u8, out_len: usize) -> (u8, u8) {
    *toggle ^= 0x80;
    let mut out = vec![0u8; out_len];
    out[0] = *toggle | f;
    out[1] = data;
    let i = b.dx(&out);
    (i[0], i[1])
}

fn plc_read(b: &mut Bench, t: &mut u8, term: u8, table: u8, reg: u8, n: usize) -> u16 {
    plc(b, t, 1, term, n);
    plc(b, t, 2, table, n);
    plc(b, t, 3, reg, n);
    let (st, hi) = plc(b, t, 6, 0, n);
    assert_eq!(st & 0x7F, 6, "read acknowledged without error");
    let (_, lo) = plc(b, t, 7, 0, n);
    u16::from_be_bytes([hi, lo])
}

fn plc_write(b: &mut Bench, t: &mut u8, term: u8, table: u8, reg: u8, v: u16, n: usize) -> u8 {
    plc(b, t, 1, term, n);
    plc(b, t, 2, table, n);
    plc(b, t, 3, reg, n);
    plc(b, t, 4, (v >> 8) as u8, n);
    plc(b, t, 5, v as u8, n);
    plc(b, t, 8, 0, n).0
}

#[test]
fn plc_interface_reaches_the_coupler_tables_and_terminals_in_parameter_mode() {
    // p. 45: parameter mode signals ready for data exchange, "nötig, wenn
    // die Parametrierung über das 2-Byte-SPS-Interface erfolgen soll".
    let list = "KL1104,KL9100,KL2134,KL3102:complete,KL9010";
    let mut b = Bench::new(list);
    let prm = UserPrm {
        startup: StartupMode::Parameter,
        plc_interface: true,
        ..Default::default()
    };
    b.start(&prm.emit(), &[0xB1, 0xB2, 0xB2, 0x10, 0x20]);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    let n = 2 + 6 + 1;
    let mut t = 0u8;
    // Table 9: the coupler, then the terminals with process data.
    assert_eq!(plc_read(&mut b, &mut t, 0, 9, 0, n), 3000);
    assert_eq!(
        plc_read(&mut b, &mut t, 0, 9, 1, n),
        0x8401,
        "KL1104: digital, 4 bits in"
    );
    assert_eq!(
        plc_read(&mut b, &mut t, 0, 9, 2, n),
        0x8402,
        "KL2134: 4 bits out"
    );
    assert_eq!(plc_read(&mut b, &mut t, 0, 9, 3, n), 3102);
    // Terminal 3 (KL3102), table 1 (channel 2), R8.
    assert_eq!(plc_read(&mut b, &mut t, 3, 1, 8, n), 3102);
    // Code word and user gain through the interface.
    assert_eq!(plc_write(&mut b, &mut t, 3, 0, 31, 0x1235, n) & 0x40, 0);
    plc_write(&mut b, &mut t, 3, 0, 34, 0x0080, n);
    assert_eq!(b.slave.device().register(4, 1, 34), Some(0x0080));
    // A protected register: error bit 6.
    assert_ne!(plc_write(&mut b, &mut t, 3, 1, 34, 1, n) & 0x40, 0);
    // Table 0 (settings), table 98 (cycle time), no table 5.
    plc_write(&mut b, &mut t, 0, 0, 16, 2, n);
    assert_eq!(plc_read(&mut b, &mut t, 0, 0, 16, n), 2);
    assert!(plc_read(&mut b, &mut t, 0, 98, 0, n) > 200);
    plc(&mut b, &mut t, 2, 5, n);
    assert_ne!(plc(&mut b, &mut t, 6, 0, n).0 & 0x40, 0);
    // Table 70: a programmed configuration written register by register.
    plc_write(&mut b, &mut t, 0, 70, 1, 0xB1, n);
    plc_write(&mut b, &mut t, 0, 70, 2, 0x51, n);
    plc_write(&mut b, &mut t, 0, 70, 3, 0x30, n);
    assert_eq!(plc_read(&mut b, &mut t, 0, 70, 0, n), 3);
    // The K-bus is still held; function 9 starts it.
    b.slave.device_mut().control("set 1.1 1").unwrap();
    let i = b.dx(&[t, 0, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(i[8], 0, "held");
    plc(&mut b, &mut t, 9, 0, n);
    let i = b.dx(&[t | 9, 0, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(i[8] & 1, 1, "K-bus running");
    assert!(b.slave.device().status_text().contains("K-bus running"));
}

#[test]
fn programmed_configuration_places_terminals_freely() {
    // p. 51: "Mit dem Konfigurator können die Klemmen beliebig in das
    // lokale Prozeßabbild gelegt werden": the KL1104 first, the KL3102
    // words after it, in a table 70 that is no automatic layout.
    let s = strip("KL1104,KL2134,KL3102,KL9010");
    let table = vec![0x10, 0x51, 0x20];
    assert!(
        Bk3000::new(s.clone())
            .with_programmed_cfg(table.clone())
            .is_err(),
        "not the automatic layout"
    );
    let places = image::Placement::parse_list("1@0.0/-, 3@1/-").unwrap();
    let dev = Bk3000::new(s.clone())
        .with_placement(table.clone(), places)
        .unwrap();
    let mut b = Bench {
        slave: DpSlave::new(dev, ADDR),
        now: T0,
    };
    let mut u = [0u8; 10];
    u[9] = 0x02;
    b.start(&u, &table);
    assert_eq!(b.slave.state(), SlaveState::DataExch);
    b.slave.device_mut().control("set 1.4 1").unwrap();
    b.slave.device_mut().control("set 3.2 5").unwrap();
    let i = b.dx(&[0x02]);
    assert_eq!(i.len(), 5);
    assert_eq!(i[0] & 0x08, 0x08, "KL1104 channel 4 in byte 0 bit 3");
    assert_eq!(
        i16::from_be_bytes([i[3], i[4]]),
        16384,
        "KL3102 channel 2 in bytes 3-4"
    );
    assert_eq!(b.slave.device().output_value("2.KL2134.2"), Some(1));
    // Overlaps, data beyond the table and bits of byte terminals refused.
    for (text, words) in [
        ("1@1.0/-", "overlaps"),
        ("3@2/-", "beyond"),
        ("3@1.4/-", "byte-oriented"),
        ("2@0/-", "has no input data"),
        ("9@0/-", "not on the strip"),
    ] {
        let p = image::Placement::parse_list(text).unwrap();
        let e = Bk3000::new(s.clone())
            .with_placement(table.clone(), p)
            .unwrap_err();
        assert!(e.contains(words), "{text}: {e}");
    }
    assert!(image::Placement::parse_list("3:0")
        .unwrap_err()
        .contains("POS@IN/OUT"));
    // The registry option.
    let entry = crate::PROFILES.iter().find(|p| p.name == "bk3000").unwrap();
    let mut o = crate::profile::DeviceOptions::new();
    o.set_text("terminals", "KL1104,KL2134,KL3102,KL9010");
    o.set_text("programmed-cfg", "10 51 20");
    o.set_text("placement", "1@0.0/-, 3@1/-");
    assert!(entry.configure(&o, Some(5)).unwrap().device(None).is_ok());
    o.set_text("placement", "1@1.0/-");
    let e = entry.configure(&o, Some(5)).unwrap_err().to_string();
    assert!(
        e.contains("option `placement`") && e.contains("overlaps"),
        "{e}"
    );
}

#[test]
fn self_test_and_leds_follow_the_start_up() {
    let mut b = Bench::new("KL1104,KL2134,KL9010");
    let ev: Vec<_> = std::iter::from_fn(|| b.slave.device_mut().poll_event()).collect();
    assert!(
        ev.iter()
            .any(|e| e.kind == "self-test" && e.text.contains("found 3 terminals")),
        "{ev:?}"
    );
    let leds = b.slave.device().leds();
    assert_eq!(
        (leds.io_run, leds.io_err, leds.bf),
        (2, None, true),
        "not configured yet"
    );
    // Too few configuration data: I/O ERR blinks 6 then 0, BF stays on.
    b.start(&[0; 10], &[0x20]);
    assert_eq!(b.slave.device().leds().io_err, Some((6, 0)));
    assert!(b.slave.device().leds().bf);
    // Data exchange: I/O RUN on, I/O ERR off (p. 18), BF off.
    b.start(&[0; 10], &[0x10, 0x20]);
    let leds = b.slave.device().leds();
    assert_eq!((leds.io_run, leds.io_err, leds.bf), (1, None, false));
    let ev: Vec<_> = std::iter::from_fn(|| b.slave.device_mut().poll_event()).collect();
    assert!(
        ev.iter()
            .any(|e| e.kind == "led" && e.text == "I/O RUN on, I/O ERR off, BF off"),
        "{ev:?}"
    );
    b.slave.device_mut().control("pull 2").unwrap();
    assert_eq!(b.slave.device().leds().io_err, Some((4, 1)));
    assert!(b
        .slave
        .device_mut()
        .control("status")
        .unwrap()
        .contains("LEDs: I/O RUN off, I/O ERR 4 pulses then 1, BF off"));
}

#[test]
fn ident_can_be_overridden_and_the_gsd_keeps_to_its_rates() {
    // p. 28: the PNO ident is in the type files (value not printed).
    let entry = crate::PROFILES.iter().find(|p| p.name == "bk3000").unwrap();
    let mut o = crate::profile::DeviceOptions::new();
    o.set_text("ident", "0x1234");
    let p = entry.configure(&o, Some(5)).unwrap();
    assert_eq!(p.gsd().ident_number, 0x1234);
    // p. 24: up to 1.5 Mbit/s; the search keeps to these rates.
    let g = crate::gsd_files::parse(crate::gsd_files::BK30BECF).unwrap();
    let rates: profibus_fdl::station::autobaud::BaudSet = g.supported_bauds().into_iter().collect();
    assert_eq!(rates.fastest(), profibus_fdl::timing::Baud::B1500000);
    assert!(!rates.contains(profibus_fdl::timing::Baud::B3000000));
}
