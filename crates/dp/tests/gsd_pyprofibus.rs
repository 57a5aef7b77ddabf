//! Cross-check with an independent GSD parser: pyprofibus 1.13 (from PyPI,
//! installed in `.venv` by `scripts/setup-test-env`) reads every file in
//! `crates/devices/gsd/` and `crates/devices/gsd/corpus/` and must see the same ident number, module
//! names and identifier bytes, baud rates and limits as we do; it also
//! reads what our writer makes of each file.
//!
//! Where pyprofibus legitimately differs, the difference is asserted, not
//! skipped (every difference is listed in `KNOWN_DIFFERENCES`, every file
//! it cannot read in `UNREADABLE`):
//! - It does not read the vendor quirks our lenient mode accepts: it sees
//!   no modules in `BM4OPRO1.GSD` (commented-out `#Profibus_DP`) and
//!   `BNF_00D0.GSD` (`Modules='…'`). For those two files the comparison
//!   runs on a copy with the quirks rewritten to standard syntax.
//! - It builds User_Prm_Data from the constant bytes only, without the
//!   defaults of `Ext_User_Prm_Data_Ref` parameters; files whose defaults
//!   differ from their constant bytes are listed with the bytes that
//!   differ.
//! - It skips a module written without a blank before its identifier
//!   bytes (`Module="empty slot"0x00`), and cannot read a file with an
//!   upper-case hex prefix (`0X60`).
//! - For a compact station with several modules it configures all of
//!   them; User_Prm_Data is compared for that same selection.
//!
//! The test fails (it does not skip) when the venv is missing.

use profibus_dp::config::gsd::{Gsd, ParseOptions};
use profibus_fdl::timing::Baud;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{gsd_files, root};

fn python() -> PathBuf {
    let py = root().join(".venv/bin/python");
    assert!(
        py.exists(),
        "{} is missing: run scripts/setup-test-env to install pyprofibus (this test does not skip)",
        py.display()
    );
    py
}

/// Run the pyprofibus reader on `files`; one JSON object per file (with
/// `error` where pyprofibus could not read it).
fn pyprofibus(files: &[PathBuf], fix_quirks: bool) -> Vec<Value> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/pyprofibus_gsd.py");
    let mut cmd = Command::new(python());
    cmd.arg(script);
    if fix_quirks {
        cmd.arg("--fix-quirks");
    }
    let out = cmd.args(files).output().expect("run .venv/bin/python");
    assert!(
        out.status.success(),
        "pyprofibus reader failed (run scripts/setup-test-env): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Vec<Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(v.len(), files.len());
    v
}

fn hex(b: &[u8]) -> String {
    format!("{:#}", profibus_fdl::wire::Hex(b)).to_lowercase()
}

/// Where pyprofibus's reading `py` differs from our model, in words.
fn differences(py: &Value, g: &Gsd) -> Vec<String> {
    let mut d = Vec::new();
    let mut same = |what: &str, theirs: &Value, ours: Value| {
        if *theirs != ours {
            d.push(format!("{what}: ours {ours}, pyprofibus {theirs}"));
        }
    };
    same("ident", &py["ident"], g.ident_number.into());
    same("Modular_Station", &py["modular"], g.modular_station.into());
    same("DPV1_Slave", &py["dpv1"], g.dpv1_slave.into());
    for b in Baud::ALL {
        if b == Baud::B31250 {
            continue; // pyprofibus has no 31.25 kbit/s keys
        }
        let key = b.gsd_suffix();
        same(
            &format!("{key}_supp"),
            &py["supp"][key],
            g.supports_baud(b).into(),
        );
        let tsdr = g.max_tsdr(b).map_or(Value::Null, Value::from);
        same(&format!("MaxTsdr_{key}"), &py["max_tsdr"][key], tsdr);
    }
    for (key, ours) in [
        ("max_input_len", g.max_input_len),
        ("max_output_len", g.max_output_len),
        ("max_module", g.max_module),
    ] {
        same(key, &py[key], ours.map_or(Value::Null, Value::from));
    }
    // Module names and configuration (identifier) bytes, in file order.
    let theirs: Vec<(String, String)> = py["modules"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            (
                m["name"].as_str().unwrap().to_string(),
                m["cfg"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    let ours: Vec<(String, String)> = g
        .modules
        .iter()
        .map(|m| (m.name.clone(), hex(&m.cfg)))
        .collect();
    // Walk both lists; a module of ours that pyprofibus lacks is named
    // as missing, and the comparison goes on with the next one.
    let mut j = 0;
    for (i, o) in ours.iter().enumerate() {
        match theirs.get(j) {
            Some(t) if t == o => j += 1,
            Some(t) if t.0 == o.0 => {
                d.push(format!("module {i}: ours {o:?}, pyprofibus {t:?}"));
                j += 1;
            }
            _ => d.push(format!("module {i} `{}`: pyprofibus does not have it", o.0)),
        }
    }
    for t in &theirs[j.min(theirs.len())..] {
        d.push(format!("pyprofibus has a module we do not: {t:?}"));
    }
    // User_Prm_Data of the modules pyprofibus configures by default.
    let prm = g.user_prm_data(&pyprofibus_selection(g), &[]).unwrap();
    let theirs = py["user_prm_data"].as_str().unwrap();
    if theirs.len() != 2 * prm.len() {
        d.push(format!(
            "User_Prm_Data: ours {}, pyprofibus {theirs}",
            hex(&prm)
        ));
    } else {
        for (i, b) in prm.iter().enumerate() {
            let t = &theirs[2 * i..2 * i + 2];
            if *t != format!("{b:02x}") {
                d.push(format!(
                    "User_Prm_Data byte {i}: ours {b:02x}, pyprofibus {t}"
                ));
            }
        }
    }
    d
}

/// The modules pyprofibus configures by default: the `Preset` modules,
/// then for a compact station every other module. (For a compact station
/// with several modules we default to the first instead, but accept all
/// of them in file order too; see `Gsd::default_selection`.)
fn pyprofibus_selection(g: &Gsd) -> Vec<usize> {
    let preset = (0..g.modules.len()).filter(|&i| g.modules[i].preset);
    let rest = (0..g.modules.len()).filter(|&i| !g.modules[i].preset && !g.modular_station);
    preset.chain(rest).collect()
}

/// Files pyprofibus 1.13 does not read, and the start of its reason.
const UNREADABLE: &[(&str, &str)] = &[
    // `0X60`: an upper-case hex prefix.
    ("schtiot_dpv10008.gsd", "GsdError: GSD parsing failed"),
];

/// Where pyprofibus legitimately reads a file differently from us:
/// (file, difference as [`differences`] words it).
const KNOWN_DIFFERENCES: &[(&str, &str)] = &[
    // pyprofibus builds User_Prm_Data from the constant bytes only; we
    // also write the defaults of the `Ext_User_Prm_Data_Ref` parameters.
    // "Cut-Off time" Unsigned16 default 1 at bytes 2-3.
    (
        "proview_abb_rpba01.gsd",
        "User_Prm_Data byte 3: ours 01, pyprofibus 00",
    ),
    // "TDP_Monitoring" / "TDX_Monitoring" Bit(0)/Bit(1) default 1 at 10.
    (
        "proview_siemens_diag_repeater.gsd",
        "User_Prm_Data byte 10: ours 03, pyprofibus 00",
    ),
    // "DP Mode" Bit(7) default 0 over the constant 0x80; "Length of User
    // Data" default 26 over 0x18; "Failsafe Timeout" default 30.
    (
        "abb_fpba01_acs880.gsd",
        "User_Prm_Data byte 0: ours 00, pyprofibus 80",
    ),
    (
        "abb_fpba01_acs880.gsd",
        "User_Prm_Data byte 3: ours 1a, pyprofibus 18",
    ),
    (
        "abb_fpba01_acs880.gsd",
        "User_Prm_Data byte 9: ours 1e, pyprofibus 00",
    ),
    // "Diagnose" Bit(7) default 0 over the constant 0x80.
    (
        "siemens_dp_dp_coupler.gsd",
        "User_Prm_Data byte 3: ours 00, pyprofibus 80",
    ),
    // "Delay between char. x 10ms" default 20, in all four languages.
    (
        "siemens_dp_rs232c_link.gse",
        "User_Prm_Data byte 4: ours 14, pyprofibus 00",
    ),
    (
        "siemens_dp_rs232c_link.gsf",
        "User_Prm_Data byte 4: ours 14, pyprofibus 00",
    ),
    (
        "siemens_dp_rs232c_link.gsg",
        "User_Prm_Data byte 4: ours 14, pyprofibus 00",
    ),
    (
        "siemens_dp_rs232c_link.gss",
        "User_Prm_Data byte 4: ours 14, pyprofibus 00",
    ),
];

/// Differences in reading the vendor's text that our written file no
/// longer has.
const KNOWN_READING_DIFFERENCES: &[(&str, &str)] = &[
    // `Module="empty slot"0x00` (no blank before the identifier byte):
    // pyprofibus skips that module; the other 192 agree.
    (
        "siemens_dp_rs232c_link.gse",
        "module 0 `empty slot`: pyprofibus does not have it",
    ),
    (
        "siemens_dp_rs232c_link.gsf",
        "module 0 `empty slot`: pyprofibus does not have it",
    ),
    (
        "siemens_dp_rs232c_link.gsg",
        "module 0 `Leermodul`: pyprofibus does not have it",
    ),
    (
        "siemens_dp_rs232c_link.gss",
        "module 0 `empty slot`: pyprofibus does not have it",
    ),
];

/// Compare pyprofibus's readings with ours for every file: the readable
/// ones must differ exactly as [`KNOWN_DIFFERENCES`] and `also_known`
/// say, the others fail as `unreadable` says.
fn check_all(
    files: &[PathBuf],
    models: &[Gsd],
    readings: &[Value],
    unreadable: &[(&str, &str)],
    also_known: &[(&str, &str)],
) {
    let mut unexpected = Vec::new();
    for ((path, g), py) in files.iter().zip(models).zip(readings) {
        let name = path.file_name().unwrap().to_str().unwrap();
        match (unreadable.iter().find(|u| u.0 == name), py.get("error")) {
            (Some((_, why)), Some(e)) => {
                assert!(e.as_str().unwrap().contains(why), "{name}: {e}");
                continue;
            }
            (Some(_), None) => unexpected.push(format!("{name}: pyprofibus now reads it")),
            (None, Some(e)) => {
                unexpected.push(format!("{name}: pyprofibus cannot read it: {e}"));
                continue;
            }
            (None, None) => {}
        }
        let found = differences(py, g);
        let known: Vec<&str> = KNOWN_DIFFERENCES
            .iter()
            .chain(also_known)
            .filter(|k| k.0 == name)
            .map(|k| k.1)
            .collect();
        for f in &found {
            if !known.contains(&f.as_str()) {
                unexpected.push(format!("{name}: {f}"));
            }
        }
        for k in known {
            if !found.iter().any(|f| f == k) {
                unexpected.push(format!("{name}: no longer differs: {k}"));
            }
        }
    }
    assert!(unexpected.is_empty(), "{}", unexpected.join("\n"));
}

#[test]
fn pyprofibus_reads_what_we_read() {
    let files = gsd_files();
    assert!(files.len() >= 35, "{files:?}");
    let quirky = ["BM4OPRO1.GSD", "BNF_00D0.GSD"];
    let mut readings = pyprofibus(&files, false);
    let fixed_files: Vec<PathBuf> = files
        .iter()
        .filter(|f| quirky.contains(&f.file_name().unwrap().to_str().unwrap()))
        .cloned()
        .collect();
    assert_eq!(fixed_files.len(), 2);
    let fixed = pyprofibus(&fixed_files, true);
    let models: Vec<Gsd> = files
        .iter()
        .map(|path| {
            Gsd::from_file(path, ParseOptions::LENIENT)
                .unwrap_or_else(|e| panic!("{e}"))
                .gsd
        })
        .collect();
    for (path, py) in files.iter().zip(readings.iter_mut()) {
        let name = path.file_name().unwrap().to_str().unwrap();
        if quirky.contains(&name) {
            assert_eq!(
                py["modules"].as_array().unwrap().len(),
                0,
                "{name}: pyprofibus was expected to miss the quirky modules"
            );
            *py = fixed[fixed_files.iter().position(|f| f == path).unwrap()].clone();
        }
    }
    check_all(
        &files,
        &models,
        &readings,
        UNREADABLE,
        KNOWN_READING_DIFFERENCES,
    );
}

#[test]
fn pyprofibus_reads_what_we_write() {
    // Our writer emits the standard's syntax: pyprofibus reads every file
    // we write, with the same differences as in the originals.
    let files = gsd_files();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let mut written = Vec::new();
    let mut models = Vec::new();
    for path in &files {
        let g = Gsd::from_file(path, ParseOptions::LENIENT).unwrap().gsd;
        let out = dir.join(path.file_name().unwrap());
        std::fs::write(&out, g.write_latin1()).unwrap();
        written.push(out);
        models.push(g);
    }
    let readings = pyprofibus(&written, false);
    check_all(&written, &models, &readings, &[], &[]);
}
