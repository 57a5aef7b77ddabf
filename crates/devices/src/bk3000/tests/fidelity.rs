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
