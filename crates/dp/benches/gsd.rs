//! GSD parser speed (a bench binary, no framework): parsing the device
//! files and the largest corpus file, writing a model back, building
//! Chk_Cfg and User_Prm_Data, and refusing oversized input (a 100 MB file
//! by its length, a 10 MB line of text) without reading it all.
//!
//! Run: `cargo bench -p profibus-dp --bench gsd`. Prints the median of
//! several rounds per case.

use profibus_dp::config::gsd::{decode_latin1, Gsd, ParseOptions, MAX_LINE_LEN};
use std::hint::black_box;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Median time of one call of `f`, over rounds of about 50 ms.
fn measure<T>(name: &str, mut f: impl FnMut() -> T) {
    let mut calls = 1u64;
    loop {
        let t = Instant::now();
        for _ in 0..calls {
            black_box(f());
        }
        if t.elapsed() > Duration::from_millis(50) {
            break;
        }
        calls *= 2;
    }
    let mut rounds: Vec<Duration> = (0..9)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..calls {
                black_box(f());
            }
            t.elapsed() / calls as u32
        })
        .collect();
    rounds.sort();
    println!("{name:<52} {:>12.3?}", rounds[rounds.len() / 2]);
}

fn file(name: &str) -> (PathBuf, String) {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../devices/gsd")
        .join(name);
    let text = decode_latin1(&std::fs::read(&p).unwrap());
    (p, text)
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return;
    }
    for name in [
        "BNF_00D0.GSD",
        "JX2P0DC3.GSD",
        "corpus/proview_siemens_diag_repeater.gsd",
    ] {
        let (_, text) = file(name);
        measure(&format!("parse {name} ({} B)", text.len()), || {
            Gsd::parse(&text, ParseOptions::LENIENT).unwrap()
        });
    }
    let (path, text) = file("DPCTL_GEN.GSD");
    let g = Gsd::parse(&text, ParseOptions::LENIENT).unwrap().gsd;
    measure("from_file DPCTL_GEN.GSD", || {
        Gsd::from_file(&path, ParseOptions::LENIENT).unwrap()
    });
    measure("write DPCTL_GEN.GSD", || g.write());
    let sel = g
        .select(&["1 byte in", "1 byte out with filter parameter"])
        .unwrap();
    measure("user_prm_data + chk_cfg, DPCTL_GEN.GSD", || {
        (
            g.user_prm_data(&sel, &[]).unwrap(),
            g.chk_cfg(&sel).unwrap(),
        )
    });

    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().to_path_buf();
    let big = dir.join("big.gsd");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(100 << 20)
        .unwrap();
    measure("refuse a 100 MB file (from_file)", || {
        Gsd::from_file(&big, ParseOptions::LENIENT).unwrap_err()
    });
    let long_line = format!("#Profibus_DP\nInfo_Text=\"{}\"\n", "x".repeat(MAX_LINE_LEN));
    measure("refuse a 64 KiB line (parse)", || {
        Gsd::parse(&long_line, ParseOptions::LENIENT).unwrap_err()
    });
    let line10m = format!("#Profibus_DP\n{}", "y".repeat(10 << 20));
    measure("refuse a 10 MB line (parse)", || {
        Gsd::parse(&line10m, ParseOptions::LENIENT).unwrap_err()
    });
}
