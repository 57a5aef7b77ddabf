//! `dpctl demo` and `dpctl decode` as a user runs them.

use serde_json::Value;
use std::process::Command;

fn dpctl(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dpctl"))
        .args(args)
        .output()
        .expect("run dpctl")
}

#[test]
fn demo_brings_every_slave_to_data_exchange_and_data_moves() {
    let o = dpctl(&["demo", "--fast", "--cycles", "500", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let lines: Vec<Value> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect();
    let status = lines
        .iter()
        .rev()
        .find(|v| v["event"] == "status")
        .expect("a status line");
    assert!(status["cycles"].as_u64().unwrap() >= 500);
    for s in status["slaves"].as_array().unwrap() {
        assert_eq!(s["state"], "data_exchange", "{s}");
        assert_eq!(s["errors"], 0);
    }
    // The echo slave returns the master's outputs.
    let echo = &status["slaves"][0];
    let out = echo["outputs"].as_str().unwrap();
    assert!(echo["inputs"].as_str().unwrap().starts_with(out));
    assert_ne!(out, "00 00 00 00", "the demo application writes outputs");
    // The counter slave counts.
    let counter = &status["slaves"][1];
    assert_ne!(counter["inputs"], "00 00 00 00");
    let summary = lines.last().unwrap();
    assert_eq!(summary["event"], "summary");
    assert!(summary["telegrams"].as_u64().unwrap() > 1000);
}

#[test]
fn decode_reports_malformed_telegrams_with_exit_1() {
    let o = dpctl(&["decode", "10", "02", "08", "00", "0B", "16"]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(err.contains("FCS mismatch"), "{err}");
    let o = dpctl(&["decode", "--json", "10 02 08 00 0A 16", "E5"]);
    assert!(o.status.success());
    let out = String::from_utf8(o.stdout).unwrap();
    let v: Vec<Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(v[0]["status"], "OK");
    assert_eq!(v[0]["sa"], 8);
    assert_eq!(v[1]["type"], "short_ack");
    let o = dpctl(&["decode"]);
    assert_eq!(o.status.code(), Some(2), "usage error");
}
