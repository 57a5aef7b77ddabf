//! `dpctl gsd show` and `dpctl gsd check` as a user runs them.

mod common;

use common::{repo, run_dpctl as dpctl, TempDir};
use std::path::PathBuf;

fn gsd(name: &str) -> PathBuf {
    repo().join("crates/devices/gsd").join(name)
}

#[test]
fn show_prints_identity_bauds_modules_and_parameters() {
    let f = gsd("DPCTL_GEN.GSD");
    let o = dpctl(&["gsd", "show", f.to_str().unwrap()]);
    assert!(o.status.success(), "{}", o.stderr);
    let out = o.stdout;
    for want in [
        "Ident number:  0x0DCE",
        "  12Mbit/s         800",
        "User_Prm_Data: 6 byte(s) for the station: 80 00 00 01 FF 9C",
        "byte 4: \"Offset\" Signed16 default -100, allowed -1000..=1000",
        "\"2 words in consistent (special format)\" 40 C1",
        "2 words (consistent) in",
        "parameter at module byte 0: \"Filter\" Unsigned8 default 5",
    ] {
        assert!(out.contains(want), "missing `{want}` in\n{out}");
    }
}

#[test]
fn show_json_is_one_object() {
    let f = gsd("BNF_00D0.GSD");
    let o = dpctl(&["gsd", "show", "--json", f.to_str().unwrap()]);
    assert!(o.status.success(), "{}", o.stderr);
    let out = o.stdout;
    assert_eq!(out.lines().count(), 1);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["ident"], "0x00D0");
    assert_eq!(v["modules"].as_array().unwrap().len(), 32);
    assert_eq!(v["modules"][5]["cfg"], "C0 51 43");
    assert_eq!(v["modules"][5]["input_bytes"], 8);
    assert_eq!(v["modules"][5]["output_bytes"], 36);
    assert_eq!(v["bauds"][8]["max_tsdr"], 800);
    // Lenient by default: the quirks are warnings, on stderr and in the
    // object.
    assert!(o
        .stderr
        .contains("BNF_00D0.GSD:49:1: warning: expected `MaxTsdr_…`, found `MaxTsd_9.6`"));
    assert!(!v["warnings"].as_array().unwrap().is_empty());
}

#[test]
fn strict_show_and_check_fail_on_quirks() {
    let f = gsd("BNF_00D0.GSD");
    let o = dpctl(&["gsd", "show", "--strict", f.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let o = dpctl(&["gsd", "check", "--strict", f.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(o
        .stdout
        .contains("BNF_00D0.GSD:91:1: error: expected `Module`, found `Modules`"));
    let err = o.stderr;
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with("dpctl: ") && err.contains("73 error(s)"),
        "{err}"
    );
    // Lenient check: warnings only, exit 0.
    let o = dpctl(&["gsd", "check", f.to_str().unwrap()]);
    assert!(o.status.success());
    assert!(o.stdout.contains("ok, 32 module(s)"));
}

#[test]
fn check_reports_errors_with_positions() {
    let tmp = TempDir::new("gsd_cli");
    let dir = &tmp.0;
    let f = dir.join("broken.gsd");
    std::fs::write(
        &f,
        "#Profibus_DP\nIdent_Number=0x10\nMax_Module=x\nModule=\"m\" 0x10,300\nEndModule\n",
    )
    .unwrap();
    let o = dpctl(&["gsd", "check", f.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let out = o.stdout;
    let p = f.display();
    assert!(
        out.contains(&format!(
            "{p}:3:12: error: expected a number for `Max_Module`, found `x`"
        )),
        "{out}"
    );
    assert!(
        out.contains(&format!(
            "{p}:4:17: error: an identifier byte of the module 300 is outside 0..=255"
        )),
        "{out}"
    );
    // JSON: one object per diagnostic.
    let o = dpctl(&["gsd", "check", "--json", f.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let lines: Vec<serde_json::Value> = o
        .stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(lines
        .iter()
        .any(|v| v["line"] == 3 && v["col"] == 12 && v["severity"] == "error"));
    // A missing file: one line on stderr, exit 1.
    let o = dpctl(&["gsd", "show", dir.join("nope.gsd").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(o.stderr.contains("cannot read the file"), "{}", o.stderr);
}

#[test]
fn check_reports_selection_problems_of_modules() {
    let f = gsd("MyGSDFile.gsd");
    let o = dpctl(&["gsd", "check", f.to_str().unwrap()]);
    assert!(o.status.success());
    assert!(
        o.stdout.contains(
            "module 0 `Bedarfsdaten PKW` alone: 8 output bytes; the limit is 6 (Max_Output_Len)"
        ),
        "{}",
        o.stdout
    );
}

#[test]
fn localised_extensions_are_read_like_gsd() {
    // `.gse`, `.gsg`, … are GSD files in other languages: `gsd show`,
    // `gsd check` and `slave --gsd` take them like `.gsd`.
    let tmp = TempDir::new("gsd_cli_ext");
    let dir = &tmp.0;
    let en = gsd("corpus/siemens_dp_rs232c_link.gse");
    let mut files = vec![en.clone(), gsd("corpus/siemens_dp_rs232c_link.gsg")];
    for ext in ["gsp", "gst", "GSE"] {
        let f = dir.join(format!("SIEM8042.{ext}"));
        std::fs::copy(&en, &f).unwrap();
        files.push(f);
    }
    for f in &files {
        let f = f.to_str().unwrap();
        let o = dpctl(&["gsd", "show", f]);
        assert!(o.status.success(), "{f}: {}", o.stderr);
        assert!(o.stdout.contains("Ident number:  0x8042"), "{f}");
        let o = dpctl(&["gsd", "show", "--json", f]);
        let v: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
        assert_eq!(v["other"][0], "Periphery=\"DPS\"", "{f}");
        let o = dpctl(&["gsd", "check", f]);
        assert!(o.status.success(), "{f}: {}", o.stderr);
        assert!(
            o.stdout.contains("ok, 193 module(s), 0 warning(s)"),
            "{f}: {}",
            o.stdout
        );
        // The slave reads the file and looks the module up before it
        // opens its port.
        let o = dpctl(&[
            "slave",
            "--gsd",
            f,
            "--module",
            "no such module",
            "--port",
            "/nonexistent",
            "--addr",
            "5",
        ]);
        assert_eq!(o.status.code(), Some(1), "{f}");
        assert!(
            o.stderr.contains("no module named `no such module`"),
            "{f}: {}",
            o.stderr
        );
    }
}
