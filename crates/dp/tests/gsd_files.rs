//! The GSD files in `crates/devices/gsd/` and `crates/devices/gsd/corpus/`: every file parses (strictly
//! where it has no vendor quirks), writes back to the same model, and the
//! module tables, Chk_Cfg and User_Prm_Data of the five device files match
//! expectations checked by hand against the manuals.

use profibus_dp::config::gsd::{
    DiagKind, Gsd, ParseOptions, PrmInput, PrmValue, Problem, Quirk, SelectionError,
};
use profibus_fdl::timing::Baud;
use std::path::PathBuf;

mod common;
use common::{gsd_files, root};

fn load(name: &str) -> Gsd {
    Gsd::from_file(root().join(name), ParseOptions::LENIENT)
        .unwrap_or_else(|e| panic!("{e}"))
        .gsd
}

/// (input bytes, output bytes) of every module.
fn io_table(g: &Gsd) -> Vec<(usize, usize)> {
    g.modules
        .iter()
        .map(|m| {
            let t = m.io().unwrap();
            (t.input_bytes, t.output_bytes)
        })
        .collect()
}

/// Every problem of `want` is among `problems`.
fn assert_has(problems: &[Problem], want: &[Problem]) {
    for w in want {
        assert!(problems.contains(w), "{w:?} not in {problems:?}");
    }
}

fn sel(g: &Gsd, names: &[&str]) -> Vec<usize> {
    names
        .iter()
        .map(|n| {
            g.module_index(n)
                .unwrap_or_else(|| panic!("no module `{n}`"))
        })
        .collect()
}

#[test]
fn every_file_parses_and_round_trips() {
    // Only the files with vendor quirks need lenient mode: the two
    // manual files, and SIPOS 5 (`24V Pins = 0`, a blank for the `_`).
    let quirky = [
        "BM4OPRO1.GSD",
        "BNF_00D0.GSD",
        "siemens_sipos5_actuator.gsd",
    ];
    // Siemens' stand-in file for unknown slaves describes no module.
    let no_modules = ["siemens_dummy_slave_siem8fff.gsd"];
    for path in gsd_files() {
        let name = path.file_name().unwrap().to_str().unwrap().to_string();
        let parsed = Gsd::from_file(&path, ParseOptions::LENIENT)
            .unwrap_or_else(|e| panic!("{name}: lenient parse failed: {e}"));
        let strict = Gsd::from_file(&path, ParseOptions::STRICT);
        if quirky.contains(&name.as_str()) {
            let e = strict.expect_err(&name);
            assert!(
                e.errors
                    .iter()
                    .all(|d| matches!(d.kind, DiagKind::Quirk(_))),
                "{name}: {:?}",
                e.errors
            );
        } else {
            let s = strict.unwrap_or_else(|e| panic!("{name}: strict parse failed: {e}"));
            assert_eq!(s.gsd, parsed.gsd, "{name}");
        }
        assert_eq!(
            parsed.gsd.modules.is_empty(),
            no_modules.contains(&name.as_str()),
            "{name}: modules"
        );
        for m in &parsed.gsd.modules {
            m.io()
                .unwrap_or_else(|e| panic!("{name}: module `{}`: {e}", m.name));
        }
        // Round trip: parse → write → parse gives the same model, and the
        // written file needs no leniency.
        let text = parsed.gsd.write();
        let again = Gsd::parse(&text, ParseOptions::STRICT)
            .unwrap_or_else(|e| panic!("{name}: written file does not parse: {e}\n{text}"));
        assert_eq!(again.gsd, parsed.gsd, "{name}: round trip");
    }
}

#[test]
fn omega_bnf_00d0() {
    let g = load("crates/devices/gsd/BNF_00D0.GSD");
    assert_eq!(g.ident_number, 0x00D0);
    assert_eq!(g.vendor_name.as_deref(), Some("BAUMÜLLER"));
    assert_eq!(g.user_prm_data_len, Some(5));
    assert!(g.freeze_mode_supp && g.sync_mode_supp && g.auto_baud_supp);
    assert!(!g.set_slave_add_supp);
    assert_eq!(
        (
            g.max_module,
            g.max_input_len,
            g.max_output_len,
            g.max_data_len
        ),
        (Some(4), Some(44), Some(44), Some(88))
    );
    // MaxTsd_ read as MaxTsdr_.
    let tsdr: Vec<_> = g
        .supported_bauds()
        .iter()
        .map(|&b| g.max_tsdr(b).unwrap())
        .collect();
    assert_eq!(tsdr, [60, 60, 60, 60, 100, 150, 250, 450, 800]);
    assert!(!g.supports_baud(Baud::B45450));
    let mut expected = vec![
        (8, 8),   // Service data module 0x73
        (4, 4),   // Status / control module 0x71
        (8, 8),   // 1 AV, 1 SP 0x73
        (12, 12), // 0x75
        (20, 20), // 0x79
        (8, 36),  // 0xC0,81,67: 18 words out, 4 words in (outputs first)
        (36, 36), // 0xC0,81,81
        (16, 16), // 0xF7
        (20, 20), // 0xF9
        (24, 24), // 0xFB
        (28, 28), // 0xFD
        (32, 32), // 0xFF
        (36, 36), // 0xC0,209,209
        (40, 40), // 0xC0,211,211
        (16, 44), // 0xC0,213,199: 22 words out, 8 words in
        (44, 44), // 0xC0,213,213
    ];
    expected.extend((1..=8).map(|n| (4 * n, 0)));
    expected.extend((1..=8).map(|n| (0, 4 * n)));
    assert_eq!(io_table(&g), expected);
    assert_eq!(g.modules[12].cfg, [0xC0, 0xD1, 0xD1]);
    assert_eq!(g.modules[16].name, "1 cycl. actual value ( 2 AI)");
    // The reference's example A: 0x73,0x71,0x5F,0x6F ⇒ 44 in / 44 out.
    let s = g
        .select(&[
            "Service data module",
            "Status / control module",
            "8 cycl. actual values (16 AI)",
            "8 cycl. setpoints (16 AO)",
        ])
        .unwrap();
    assert_eq!(g.chk_cfg(&s).unwrap(), [0x73, 0x71, 0x5F, 0x6F]);
    assert_eq!(g.check_selection(&s), vec![]);
    assert_eq!(g.user_prm_data(&s, &[]).unwrap(), [0; 5]);
    // One more module breaks Max_Module and the lengths.
    let mut five = s.clone();
    five.push(g.module_index("1 cycl. setpoint ( 2 AO)").unwrap());
    let too_long = Problem::OutputTooLong {
        bytes: 48,
        max: 44,
        limit: "Max_Output_Len",
    };
    let too_many = Problem::TooManyModules { count: 5, max: 4 };
    assert_has(&g.check_selection(&five), &[too_many, too_long]);
}

#[test]
fn bm4_default_file() {
    let g = load("crates/devices/gsd/BM4OPRO1.GSD");
    assert_eq!(g.ident_number, 0x0008);
    assert_eq!(g.implementation_type.as_deref(), Some("DPC31"));
    assert!(g.set_slave_add_supp && g.auto_baud_supp && !g.freeze_mode_supp);
    assert_eq!(g.slave_family.as_ref().map(|f| f.main), Some(10));
    assert_eq!(
        io_table(&g),
        [
            (112, 112),
            (8, 8),
            (0, 16),
            (0, 32),
            (0, 32),
            (0, 32),
            (16, 0),
            (32, 0),
            (32, 0),
            (32, 0)
        ]
    );
    let all = sel(&g, &["all modules"]);
    assert_eq!(
        g.chk_cfg(&all).unwrap(),
        [0x2F, 0x6F, 0x6F, 0x6F, 0x1F, 0x5F, 0x5F, 0x5F]
    );
    assert_eq!(g.check_selection(&all), vec![]);
    assert_eq!(g.user_prm_data(&all, &[]).unwrap(), [0, 0, 0]);
    // The 4th identifier byte of the variable modules is the PKW number.
    let m = g.find_module("8 DWord d_ActValues8..15").unwrap();
    let id = m.identifiers().next().unwrap().unwrap();
    assert_eq!(id.manufacturer, [0x02, 0x07]);
    // The commented-out header is a quirk: a warning when lenient.
    let w = Gsd::from_file(
        root().join("crates/devices/gsd/BM4OPRO1.GSD"),
        ParseOptions::LENIENT,
    )
    .unwrap()
    .warnings;
    assert_eq!(w.len(), 1);
    assert_eq!(w[0].kind, DiagKind::Quirk(Quirk::CommentedSectionHeader));
    assert_eq!((w[0].pos.line, w[0].pos.col), (18, 1));
}

#[test]
fn bm4_example_file() {
    let g = load("crates/devices/gsd/MyGSDFile.gsd");
    assert_eq!(
        io_table(&g),
        [(8, 8), (4, 0), (4, 0), (0, 4), (0, 2), (4, 0)]
    );
    let m = g.module("di_MyReadVar3").unwrap();
    assert_eq!(m.cfg, [0x42, 0xC1, 0x02, 0x04]);
    let id = m.identifiers().next().unwrap().unwrap();
    let input = id.input.unwrap();
    assert_eq!(
        (input.units, input.words, input.consistent),
        (2, true, true)
    );
    assert_eq!(id.output, None);
    assert_eq!(id.manufacturer, [0x02, 0x04]);
    // The variables alone fit Max_Input_Len=12 / Max_Output_Len=6 …
    let vars = sel(
        &g,
        &[
            "ud_MyReadVar1",
            "ud_MyReadVar2",
            "ud_MyWriteVar1",
            "u_MyWriteVar2",
            "di_MyReadVar3",
        ],
    );
    assert_eq!(g.check_selection(&vars), vec![]);
    // … the PKW module on top does not (the manual's own inconsistency).
    let mut with_pkw = vec![g.module_index("Bedarfsdaten PKW").unwrap()];
    with_pkw.extend(&vars);
    let inputs = Problem::InputTooLong {
        bytes: 20,
        max: 12,
        limit: "Max_Input_Len",
    };
    let outputs = Problem::OutputTooLong {
        bytes: 14,
        max: 6,
        limit: "Max_Output_Len",
    };
    assert_has(&g.check_selection(&with_pkw), &[inputs, outputs]);
}

#[test]
fn beckhoff_bk3000() {
    let g = load("crates/devices/gsd/BK30BECF.GSD");
    assert_eq!(g.ident_number, 0xBECF);
    assert!(g.fms_supp && g.freeze_mode_supp && g.sync_mode_supp && !g.dpv1_slave);
    assert_eq!(g.supported_bauds().last(), Some(&Baud::B1500000));
    assert!(!g.supports_baud(Baud::B12000000));
    let s = sel(
        &g,
        &[
            "16 digital inputs (2 bytes)",
            "KL3xx2, KL3351: 2 x 24 bit in, 8 bit out",
            "KL5001: 32 bit in (compact)",
        ],
    );
    assert_eq!(
        g.chk_cfg(&s).unwrap(),
        [0x11, 0xC0, 0x00, 0x82, 0xC0, 0x00, 0x82, 0x93]
    );
    let io: Vec<_> = s.iter().map(|&i| io_table(&g)[i]).collect();
    assert_eq!(io, [(2, 0), (6, 2), (4, 0)]);
    assert_eq!(g.user_prm_data(&s, &[]).unwrap(), [0; 10]);
    let v: Vec<PrmValue> = [
        "2-byte PLC interface=used",
        "Configuration=programmed configuration",
    ]
    .iter()
    .map(|s| s.parse().unwrap())
    .collect();
    let prm = g.user_prm_data(&s, &v).unwrap();
    assert_eq!((prm[5], prm[9]), (0x01, 0x02));
}

#[test]
fn jetter_jx2_profi1() {
    let g = load("crates/devices/gsd/JX2P0DC3.GSD");
    assert!(g.dpv1_slave && g.c1_read_write_supp);
    assert_eq!(g.c1_max_data_len, Some(240));
    assert_eq!(g.max_diag_data_len, Some(32));
    assert!(g.supports_baud(Baud::B45450) && g.auto_baud_supp && !g.set_slave_add_supp);
    // The manual's example: 16 input words with words 8-11 consistent,
    // 12 output words with words 4-11 consistent.
    let s = g
        .select(&[
            "INPUT : 8 words",
            "INPUT (consistent) : 4 words",
            "INPUT : 4 words",
            "OUTPUT : 4 words",
            "OUTPUT (consistent) : 8 words",
        ])
        .unwrap();
    assert_eq!(g.chk_cfg(&s).unwrap(), [0x57, 0xD3, 0x53, 0x63, 0xE7]);
    let t = profibus_dp::pdu::cfg::totals(&g.chk_cfg(&s).unwrap()).unwrap();
    assert_eq!((t.input_bytes, t.output_bytes), (32, 24));
    assert_eq!(g.check_selection(&s), vec![]);
    assert_eq!(g.user_prm_data(&s, &[]).unwrap(), [0x80, 0x00, 0x00]);
    let big = g.find_module("INPUT (consistent) : 64 words").unwrap();
    assert_eq!(big.io().unwrap().input_bytes, 128);
    // Names match exactly: the consistent and plain modules apart.
    assert_eq!(
        g.find_module("INPUT (consistent) : 2 words").unwrap().cfg,
        [0xD1]
    );
    assert_eq!(g.find_module("INPUT : 2 words").unwrap().cfg, [0x51]);
    assert!(g.find_module("INPUT: 2 words").is_err());
}

#[test]
fn aeg_id_reader() {
    let g = load("crates/devices/gsd/AEGI0DC4.GSD");
    assert!(!g.modular_station);
    let s = g.default_selection();
    assert_eq!(s, [0]);
    assert_eq!(g.chk_cfg(&s).unwrap(), [0x3F]);
    assert_eq!(io_table(&g), [(16, 16)]);
    assert_eq!(g.user_prm_data(&s, &[]).unwrap(), Vec::<u8>::new());
    assert_eq!(g.check_selection(&s), vec![]);
    // A compact station takes only its fixed configuration.
    assert!(matches!(
        g.check_selection(&[]).as_slice(),
        [Problem::FixedConfiguration { .. }]
    ));
}

#[test]
fn dpctl_generic_slave() {
    let g = load("crates/devices/gsd/DPCTL_GEN.GSD");
    assert_eq!(g.ident_number, 0x0DCE);
    assert!(g.dpv1_slave && g.c1_read_write_supp && g.freeze_mode_supp && g.sync_mode_supp);
    assert!(g.set_slave_add_supp);
    assert_eq!(
        g.user_prm_data(&[], &[]).unwrap(),
        [0x80, 0, 0, 0x01, 0xFF, 0x9C]
    );
    let v = |s: &[&str]| -> Vec<PrmValue> { s.iter().map(|x| x.parse().unwrap()).collect() };
    assert_eq!(
        g.user_prm_data(&[], &v(&["Mode=fast", "offset=-1000"]))
            .unwrap(),
        [0x80, 0, 0, 0x02, 0xFC, 0x18]
    );
    let s = g
        .select(&["1 byte in", "1 byte out with filter parameter"])
        .unwrap();
    assert_eq!(g.chk_cfg(&s).unwrap(), [0x10, 0x20]);
    assert_eq!(
        g.user_prm_data(&s, &[]).unwrap(),
        [0x80, 0, 0, 1, 0xFF, 0x9C, 0x05]
    );
    assert_eq!(
        g.user_prm_data(&s, &v(&["1:Filter=7", "Mode=3"])).unwrap(),
        [0x80, 0, 0, 3, 0xFF, 0x9C, 0x07]
    );
    // Errors say what is wrong.
    let e = g.user_prm_data(&s, &v(&["Offset=2000"])).unwrap_err();
    assert_eq!(
        e.to_string(),
        "parameter `Offset`: 2000 is not allowed; allowed: -1000..=1000"
    );
    let e = g.user_prm_data(&s, &v(&["Mode=turbo"])).unwrap_err();
    assert!(matches!(e, SelectionError::UnknownText { .. }), "{e}");
    let e = g.user_prm_data(&s, &v(&["Moed=1"])).unwrap_err();
    assert_eq!(
        e,
        SelectionError::UnknownParameter {
            name: "Moed".into(),
            position: None,
            suggestions: profibus_dp::config::names::DidYouMean(vec!["Mode".into()])
        }
    );
    let e = g.user_prm_data(&s, &v(&["0:Filter=1"])).unwrap_err();
    assert!(
        matches!(
            e,
            SelectionError::UnknownParameter {
                position: Some(0),
                ..
            }
        ),
        "{e}"
    );
    let _ = PrmInput::Int(0);
    let all: Vec<usize> = (0..g.modules.len()).collect();
    assert!(g
        .check_selection(&all)
        .contains(&Problem::TooManyModules { count: 9, max: 8 }));
    assert_eq!(g.unit_diag_bit_text(1), Some("Test diagnosis bit 1"));
    assert_eq!(
        g.unit_diag_not_bit_text(7),
        Some("Test diagnosis bit 7 clear")
    );
}

#[test]
fn corpus_user_prm_data() {
    // ABB RPBA-01: 24 bytes; "Cut-Off time" (Unsigned16, default 1) at 2.
    let g = load("crates/devices/gsd/corpus/proview_abb_rpba01.gsd");
    let mut want = vec![0u8; 24];
    want[3] = 1;
    assert_eq!(g.user_prm_data(&[], &[]).unwrap(), want);
    let v: Vec<PrmValue> = [
        "Fail Safe mode=Use fail-safe values",
        "Operation mode=1",
        "Failsafe PZD10=0x1234",
    ]
    .iter()
    .map(|s| s.parse().unwrap())
    .collect();
    let d = g.user_prm_data(&[], &v).unwrap();
    assert_eq!(d[1], 0b01_0010); // BitArea(0-1)=2, BitArea(4-5)=1
    assert_eq!(&d[22..24], &[0x12, 0x34]);
    // SEW: the Bit(0) default 1 is already in the constant bytes.
    let g = load("crates/devices/gsd/corpus/proview_sew_movidrive_dfp21.gsd");
    assert_eq!(
        g.user_prm_data(&[], &[]).unwrap(),
        [0x00, 0x00, 0x00, 0x06, 0x81, 0x00, 0x00, 0x01, 0x01]
    );
    // Siemens diagnostic repeater: BitArea(0-7) default 0x54 at 7, two
    // Bit defaults of 1 at 10.
    let g = load("crates/devices/gsd/corpus/proview_siemens_diag_repeater.gsd");
    assert_eq!(
        g.user_prm_data(&[], &[]).unwrap(),
        [0x80, 0x00, 0x08, 0x08, 0x81, 0x00, 0x00, 0x54, 0x00, 0x00, 0x03]
    );
    assert_eq!(g.slots.len(), 1);
    assert_eq!(g.unit_diag_areas.len(), 3);
    assert_eq!(g.unit_diag_areas[0].values.len(), 202);
    assert!(g
        .other
        .iter()
        .any(|l| l.starts_with("Version_Firmware_Download")));
    // pyprofibus's compact dummy means all its modules together; a
    // compact station's modules are otherwise alternatives, and the
    // default is the first.
    let g = load("crates/devices/gsd/corpus/pyprofibus_dummy_compact.gsd");
    assert_eq!(g.default_selection(), [0]);
    let all = [0, 1, 2];
    assert_eq!(g.check_selection(&all), vec![]);
    assert_eq!(g.chk_cfg(&all).unwrap(), [0x00, 0x10, 0x20]);
    assert_eq!(g.user_prm_data(&all, &[]).unwrap(), [0, 0, 0, 0x42]);
    assert!(matches!(
        g.check_selection(&[1, 2]).as_slice(),
        [Problem::FixedConfiguration { .. }]
    ));
}

/// The files of `crates/devices/gsd/corpus/` (every GSD extension), sorted.
fn corpus_files() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("crates/devices/gsd/corpus"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| profibus_dp::config::gsd::is_gsd_file_name(p))
        .collect();
    v.sort();
    v
}

#[test]
fn vendor_corpus_parses_leniently() {
    let files = corpus_files();
    assert!(files.len() >= 28, "{files:?}");
    let mut exts = std::collections::BTreeSet::new();
    for path in &files {
        let name = path.file_name().unwrap().to_str().unwrap();
        exts.insert(path.extension().unwrap().to_str().unwrap().to_string());
        let p =
            Gsd::from_file(path, ParseOptions::LENIENT).unwrap_or_else(|e| panic!("{name}: {e}"));
        // No syntax trouble hidden in the warnings either.
        for w in &p.warnings {
            assert!(
                !matches!(w.kind, DiagKind::Syntax | DiagKind::TooLarge | DiagKind::Io),
                "{name}: {w}"
            );
        }
        for m in &p.gsd.modules {
            m.io()
                .unwrap_or_else(|e| panic!("{name}: `{}`: {e}", m.name));
        }
    }
    assert_eq!(
        exts.into_iter().collect::<Vec<_>>(),
        ["gsd", "gse", "gsf", "gsg", "gsi", "gss"]
    );
}

#[test]
fn vendor_corpus_details() {
    // ABB FPBA-01 (CR LF, a byte list continued over four lines, 22
    // alternative PPO modules of a modular station with Max_Module 1).
    let g = load("crates/devices/gsd/corpus/abb_fpba01_acs880.gsd");
    assert_eq!(g.ident_number, 0x0959);
    assert_eq!(g.modules.len(), 22);
    assert_eq!(g.modules[8].cfg, [0xF3, 0xF1, 0xF1, 0xF1]);
    let prm = g.user_prm_data(&[0], &[]).unwrap();
    assert_eq!(prm.len(), 30);
    // "DP Mode" (Bit(7) of byte 0, default 0 = DP-V0) clears the 0x80 of
    // the constant bytes; "Failsafe Timeout" 30 at 8, "PZD1 Failsafe
    // value" 1150 at 10.
    assert_eq!(
        &prm[..12],
        [0x00, 0, 0x08, 0x1A, 0x81, 0, 0, 0, 0, 0x1E, 0x04, 0x7E]
    );
    for i in 0..22 {
        assert_eq!(g.check_selection(&[i]), vec![], "module {i}");
    }
    // Siemens direct key module: a module line continued with `\`,
    // Latin-1 comments, `Freeze_Mode_supp=1;ja`.
    let g = load("crates/devices/gsd/corpus/siemens_direct_key_module_siem8007.gsd");
    assert_eq!(g.modules[0].cfg, [0x21, 0x15]);
    assert!(g.freeze_mode_supp && g.sync_mode_supp && g.set_slave_add_supp);
    assert_eq!(g.user_prm_data(&[0], &[]).unwrap(), [0; 5]);
    // SIMODRIVE sensor (Italian .gsi, encoder profile): module
    // parameters with Latin-1 names.
    let g = load("crates/devices/gsd/corpus/siemens_simodrive_sensor_encoder.gsi");
    assert_eq!(g.slave_family.as_ref().unwrap().main, 7);
    assert_eq!(g.modules.len(), 11);
    assert_eq!(g.prm_definition(2).unwrap().name, "Funzionalità classe 2");
    let i = g.module_index("Class 2 Multiturn").unwrap();
    let prm = g.user_prm_data(&[i], &[]).unwrap();
    assert_eq!(prm.len(), 18);
    assert_eq!(prm[1], 0x0A);
    // schtiot DP-V1 slave: keywords of DP-V1, I&M and a UnitDiagType
    // block, all known.
    let p = Gsd::from_file(
        root().join("crates/devices/gsd/corpus/schtiot_dpv10008.gsd"),
        ParseOptions::STRICT,
    )
    .unwrap();
    assert!(p.warnings.is_empty(), "{:?}", p.warnings);
    assert_eq!(p.gsd.other_flag("Ident_Maintenance_supp"), Some(true));
    assert_eq!(p.gsd.other_flag("Publisher_supp"), Some(true));
}

#[test]
fn localised_files_of_one_device_read_alike() {
    // The DP/RS 232C link in English, French, German and Spanish: the
    // same device, the German file with German texts.
    let read = |ext: &str| {
        load(&format!(
            "crates/devices/gsd/corpus/siemens_dp_rs232c_link.{ext}"
        ))
    };
    let en = read("gse");
    for ext in ["gsf", "gsg", "gss"] {
        let g = read(ext);
        assert_eq!(g.ident_number, en.ident_number, "{ext}");
        let cfg = |g: &Gsd| g.modules.iter().map(|m| m.cfg.clone()).collect::<Vec<_>>();
        assert_eq!(cfg(&g), cfg(&en), "{ext}");
        assert_eq!(
            g.user_prm_data(&[1], &[]).unwrap(),
            en.user_prm_data(&[1], &[]).unwrap(),
            "{ext}"
        );
    }
    assert_eq!(read("gsg").modules[1].name, "1 Byte DE/Konsistenz 1 Byte");
    assert_eq!(en.modules[1].name, "1 Byte DI/consistency 1 Byte");
}

#[test]
fn bus_files_take_localised_gsd_files() {
    let text = r#"
[master]
address = 1
baud = "1.5M"

[[slave]]
address = 5
gsd = "siemens_dp_rs232c_link.gsg"
modules = ["2 Byte DE/Konsistenz 1 Byte", "2 Byte DA/Konsistenz 1 Byte"]

[[slave]]
address = 6
gsd = "siemens_simodrive_sensor_encoder.gsi"
modules = ["Class 1 Multiturn"]
"#;
    let bus = profibus_dp::config::busfile::BusFile::parse(
        &root().join("crates/devices/gsd/corpus/bus.toml"),
        text,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let s = &bus.master.slaves;
    assert_eq!(s[0].ident_number, 0x8042);
    assert_eq!(s[0].io_lengths().unwrap(), (2, 2));
    assert_eq!(s[1].ident_number, 0x0024);
    assert_eq!(s[1].io_lengths().unwrap(), (4, 0));
}
