//! Cross-check with an independent GSD parser: pyprofibus 1.13 (from PyPI,
//! installed in `.venv` by `scripts/setup-test-env`) reads every file in
//! `gsd/` and `gsd/corpus/` and must see the same ident number, module
//! names and identifier bytes, baud rates and limits as we do; it also
//! reads what our writer makes of each file.
//!
//! Where pyprofibus legitimately differs, the difference is asserted, not
//! skipped:
//! - It does not read the vendor quirks our lenient mode accepts: it sees
//!   no modules in `BM4OPRO1.GSD` (commented-out `#Profibus_DP`) and
//!   `BNF_00D0.GSD` (`Modules='…'`). For those two files the comparison
//!   runs on a copy with the quirks rewritten to standard syntax.
//! - It builds User_Prm_Data from the constant bytes only, without the
//!   defaults of `Ext_User_Prm_Data_Ref` parameters; files whose defaults
//!   differ from their constant bytes are listed with the bytes that
//!   differ.
//!
//! The test fails (it does not skip) when the venv is missing.

use profibus_dp::gsd::{Gsd, ParseOptions};
use profibus_fdl::timing::Baud;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

fn python() -> PathBuf {
    let py = root().join(".venv/bin/python");
    assert!(
        py.exists(),
        "{} is missing: run scripts/setup-test-env to install pyprofibus (this test does not skip)",
        py.display()
    );
    py
}

fn gsd_files() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for dir in ["gsd", "gsd/corpus"] {
        for e in std::fs::read_dir(root().join(dir)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x.eq_ignore_ascii_case("gsd")) {
                v.push(p);
            }
        }
    }
    v.sort();
    v
}

/// Run the pyprofibus reader on `files`; one JSON object per file.
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
    for r in &v {
        assert!(r.get("error").is_none(), "pyprofibus: {r}");
    }
    v
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// Compare pyprofibus's reading `py` with our model.
fn compare(name: &str, py: &Value, g: &Gsd) {
    assert_eq!(py["ident"], g.ident_number, "{name}: ident");
    assert_eq!(py["modular"], g.modular_station, "{name}: Modular_Station");
    assert_eq!(py["dpv1"], g.dpv1_slave, "{name}: DPV1_Slave");
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
    assert_eq!(theirs, ours, "{name}: module names and identifier bytes");
    for b in Baud::ALL {
        if b == Baud::B31250 {
            continue; // pyprofibus has no 31.25 kbit/s keys
        }
        let key = b.gsd_suffix();
        assert_eq!(py["supp"][key], g.supports_baud(b), "{name}: {key}_supp");
        let tsdr = g.max_tsdr(b).map_or(Value::Null, Value::from);
        assert_eq!(py["max_tsdr"][key], tsdr, "{name}: MaxTsdr_{key}");
    }
    for (key, ours) in [
        ("max_input_len", g.max_input_len),
        ("max_output_len", g.max_output_len),
        ("max_module", g.max_module),
    ] {
        assert_eq!(
            py[key],
            ours.map_or(Value::Null, Value::from),
            "{name}: {key}"
        );
    }
}

/// Files whose User_Prm_Data differs from pyprofibus's because parameter
/// defaults differ from the constant bytes: (file, byte offset, our byte,
/// pyprofibus's byte).
const PRM_DEFAULTS_BEYOND_CONST: &[(&str, usize, u8, u8)] = &[
    // "Cut-Off time" Unsigned16 default 1 at bytes 2-3.
    ("proview_abb_rpba01.gsd", 3, 0x01, 0x00),
    // "TDP_Monitoring" / "TDX_Monitoring" Bit(0)/Bit(1) default 1 at 10.
    ("proview_siemens_diag_repeater.gsd", 10, 0x03, 0x00),
];

/// The modules pyprofibus configures by default: the `Preset` modules,
/// then for a compact station every other module. (For a compact station
/// with several modules we default to the first instead, but accept all
/// of them in file order too; see `Gsd::default_selection`.)
fn pyprofibus_selection(g: &Gsd) -> Vec<usize> {
    let preset = (0..g.modules.len()).filter(|&i| g.modules[i].preset);
    let rest = (0..g.modules.len()).filter(|&i| !g.modules[i].preset && !g.modular_station);
    preset.chain(rest).collect()
}

fn compare_prm(name: &str, py: &Value, g: &Gsd) {
    let ours = g.user_prm_data(&pyprofibus_selection(g), &[]).unwrap();
    let theirs = py["user_prm_data"].as_str().unwrap();
    let diffs: Vec<_> = PRM_DEFAULTS_BEYOND_CONST
        .iter()
        .filter(|d| d.0 == name)
        .collect();
    if diffs.is_empty() {
        assert_eq!(theirs, hex(&ours), "{name}: User_Prm_Data");
    } else {
        let mut expected = ours.clone();
        for &&(_, at, our, their) in &diffs {
            assert_eq!(ours[at], our, "{name}: byte {at}");
            expected[at] = their;
        }
        assert_eq!(
            theirs,
            hex(&expected),
            "{name}: User_Prm_Data apart from the defaults"
        );
    }
}

#[test]
fn pyprofibus_reads_what_we_read() {
    let files = gsd_files();
    assert!(files.len() >= 15, "{files:?}");
    let quirky = ["BM4OPRO1.GSD", "BNF_00D0.GSD"];
    let raw = pyprofibus(&files, false);
    let fixed_files: Vec<PathBuf> = files
        .iter()
        .filter(|f| quirky.contains(&f.file_name().unwrap().to_str().unwrap()))
        .cloned()
        .collect();
    assert_eq!(fixed_files.len(), 2);
    let fixed = pyprofibus(&fixed_files, true);
    for (path, py) in files.iter().zip(&raw) {
        let name = path.file_name().unwrap().to_str().unwrap();
        let g = Gsd::from_file(path, ParseOptions::LENIENT)
            .unwrap_or_else(|e| panic!("{e}"))
            .gsd;
        let py = if quirky.contains(&name) {
            assert_eq!(
                py["modules"].as_array().unwrap().len(),
                0,
                "{name}: pyprofibus was expected to miss the quirky modules"
            );
            &fixed[fixed_files.iter().position(|f| f == path).unwrap()]
        } else {
            py
        };
        compare(name, py, &g);
        compare_prm(name, py, &g);
    }
}

#[test]
fn pyprofibus_reads_what_we_write() {
    let files = gsd_files();
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("gsd_written");
    std::fs::create_dir_all(&dir).unwrap();
    let mut written = Vec::new();
    let mut models = Vec::new();
    for path in &files {
        let g = Gsd::from_file(path, ParseOptions::LENIENT).unwrap().gsd;
        let out = dir.join(path.file_name().unwrap());
        std::fs::write(&out, g.write_latin1()).unwrap();
        written.push(out);
        models.push(g);
    }
    let py = pyprofibus(&written, false);
    for ((path, g), py) in written.iter().zip(&models).zip(&py) {
        let name = path.file_name().unwrap().to_str().unwrap();
        compare(name, py, g);
        compare_prm(name, py, g);
    }
}
