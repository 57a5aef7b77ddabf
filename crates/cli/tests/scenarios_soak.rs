//! `dpctl soak`: a short fault soak holds its invariants and really sees
//! faults; a deliberately broken invariant makes the command fail.

mod common;

use common::{dpctl, Proc};
use std::process::Command;
use std::time::Duration;

/// Generous: the soak is CPU-bound and the suite runs on a loaded machine.
const DEADLINE: Duration = Duration::from_secs(900);

#[test]
fn a_short_soak_holds_its_invariants_under_faults() {
    let cycles = 10_000u64;
    let mut cmd = Command::new(dpctl());
    cmd.args([
        "soak",
        "--cycles",
        &cycles.to_string(),
        "--seed",
        "7",
        "--json",
    ]);
    let out = Proc::spawn_captured(cmd).finish(DEADLINE);
    assert!(out.status.success(), "{}\n{}", out.stdout, out.stderr);
    let r: serde_json::Value = serde_json::from_str(out.stdout.trim()).expect("one JSON object");
    assert_eq!(r["violations"].as_array().map(Vec::len), Some(0), "{r}");
    assert_eq!(r["cycles"], cycles);
    assert_eq!(r["seed"], 7);
    // Disturbances happened: every kind of fault, corrupted telegrams
    // rejected by the receivers, slaves disturbed and recovered.
    let m = &r["medium"];
    for k in ["dropped", "bits_flipped", "noise_bursts"] {
        assert!(m[k].as_u64().unwrap() > 0, "{k}: {m}");
    }
    let i = &r["integrity"];
    assert!(i["corrupted"].as_u64().unwrap() > 0, "{i}");
    assert_eq!(
        i["corrupted"].as_u64().unwrap(),
        i["rejected"].as_u64().unwrap() + i["undetected"].as_u64().unwrap()
    );
    assert!(r["receiver_errors"].as_u64().unwrap() > 0);
    // Forged tokens (SD4 has no FCS) are a part of the undetected ones;
    // the master's token ring counters are reported: its first claim at
    // least, and a claim for every token it dropped as a duplicate.
    assert!(i["forged_tokens"].as_u64().unwrap() <= i["undetected"].as_u64().unwrap());
    let ring = &r["token_ring"];
    let claims = ring["claims"].as_u64().unwrap();
    assert!(
        claims > ring["duplicate_tokens"].as_u64().unwrap(),
        "{ring}"
    );
    let disturbances = r["disturbances"].as_u64().unwrap();
    assert!(disturbances > 0);
    assert_eq!(r["recovery"]["count"], disturbances);
    assert!(r["recovery"]["max_ms"].as_f64().unwrap() <= 1000.0);
    let slaves = r["slaves"].as_array().unwrap();
    let profiles: Vec<&str> = slaves
        .iter()
        .map(|s| s["profile"].as_str().unwrap())
        .collect();
    for p in ["generic", "bm4", "omega", "jx2", "rfid", "bk3000"] {
        assert!(profiles.contains(&p), "{p} missing: {profiles:?}");
    }
    for s in slaves {
        // Most cycles exchanged data despite the faults.
        assert!(
            s["data_exchanges"].as_u64().unwrap() > cycles * 8 / 10,
            "{s}"
        );
    }
}

#[test]
fn a_broken_invariant_fails_the_command_and_says_which() {
    let mut cmd = Command::new(dpctl());
    cmd.args(["soak", "--cycles", "5000", "--unplug", "5:300"]);
    let out = Proc::spawn_captured(cmd).finish(DEADLINE);
    assert_eq!(out.status.code(), Some(1), "{}\n{}", out.stdout, out.stderr);
    let last = out.stderr.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("dpctl: soak failed: invariant broken: recovery: slave 5 (omega) not back in Data_Exchange"),
        "{}",
        out.stderr
    );
    assert!(out.stdout.contains("invariant broken"), "{}", out.stdout);
}
