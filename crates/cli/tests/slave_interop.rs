//! `dpctl slave` against independent DP masters over socat pty pairs.
//!
//! pyprofibus (PyPI) parameterises and configures the generic slave from
//! `crates/devices/gsd/DPCTL_GEN.GSD`, then runs 1000 Data_Exchange cycles with changing
//! outputs and a freeze phase; the slave echoes the outputs. Both sides
//! check the values: the Python master the echo it gets back, this test
//! the outputs the slave reports (`--show-data --json`).
//!
//! Needs socat and `.venv` with pyprofibus (scripts/setup-test-env); the
//! test fails when they are missing.

mod common;

use common::*;
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::Duration;

const MODULES: [&str; 4] = [
    "2 words in/out",
    "8 bytes in consistent",
    "16 bytes out",
    "1 byte out with filter parameter",
];
/// Output bytes (master → slave) and input bytes of that selection.
const OUT_LEN: usize = 4 + 16 + 1;
const IN_LEN: usize = 4 + 8;
const CYCLES: u64 = 1000;

/// The outputs pattern number `n` of the Python master (see
/// tests/interop/pyprofibus_master.py).
fn pattern(n: u32, len: usize) -> Vec<u8> {
    let mut v = n.to_be_bytes().to_vec();
    v.extend((0..len.saturating_sub(4)).map(|k| (n as usize * 7 + k) as u8));
    v.truncate(len);
    v
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn json_lines(lines: &[String]) -> Vec<Value> {
    lines
        .iter()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .collect()
}

#[test]
fn pyprofibus_master_exchanges_1000_cycles_with_dpctl_slave() {
    let py = python();
    let dir = TempDir::new("pyprofibus");
    let (a, b) = (dir.path("master"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    assert!(gsd.exists(), "{} is missing", gsd.display());

    let mut slave_cmd = Command::new(dpctl());
    slave_cmd
        .args(["slave", "--port"])
        .arg(&b)
        .args(["--addr", "8", "--gsd"])
        .arg(&gsd)
        .args(["--inputs", "echo", "--show-data", "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    for m in MODULES {
        slave_cmd.args(["--module", m]);
    }
    let mut slave = Proc::spawn("dpctl slave", &mut slave_cmd);
    let mut slave_out = started(&mut slave, Duration::from_secs(10));

    let mut master_cmd = Command::new(py);
    master_cmd
        .arg(repo().join("tests/interop/pyprofibus_master.py"))
        .arg("--port")
        .arg(&a)
        .arg("--gsd")
        .arg(&gsd)
        .args(["--addr", "8", "--master", "2", "--baud", "1500000"])
        .args(["--out-len", &OUT_LEN.to_string()])
        .args(["--in-len", &IN_LEN.to_string()])
        .args([
            "--cycles",
            &CYCLES.to_string(),
            "--freeze",
            "--timeout",
            "150",
            // Seconds, not the default 1 s: a busy machine can stall the
            // Python master for longer, and the slave would drop out.
            "--watchdog-ms",
            "5000",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    for m in MODULES {
        master_cmd.args(["--module", m]);
    }
    let mut master = Proc::spawn("pyprofibus master", &mut master_cmd);
    let mut master_out = Lines::from(&mut master);
    let status = master.wait(Duration::from_secs(180));
    let master_lines = master_out.rest().to_vec();
    let summary = json_lines(&master_lines)
        .into_iter()
        .find(|v| v["event"] == "summary")
        .unwrap_or_else(|| panic!("no summary from the Python master: {master_lines:?}"));
    assert!(
        status.success(),
        "pyprofibus master failed: {summary}\nslave said: {:?}",
        slave_out.1
    );
    assert_eq!(summary["errors"], serde_json::json!([]));
    assert!(summary["cycles"].as_u64().unwrap() >= CYCLES);
    assert!(summary["frozen_checked"].as_u64().unwrap() >= 10);

    let st = slave.terminate(Duration::from_secs(10));
    assert!(st.success(), "dpctl slave exited with {st}");
    let events = json_lines(slave_out.rest());

    // The start-up sequence, without faults.
    let states: Vec<(&str, &str)> = events
        .iter()
        .filter(|v| v["event"] == "state")
        .map(|v| (v["from"].as_str().unwrap(), v["to"].as_str().unwrap()))
        .collect();
    assert_eq!(
        &states[..2],
        &[("Wait_Prm", "Wait_Cfg"), ("Wait_Cfg", "Data_Exch")]
    );
    for bad in ["prm_fault", "cfg_fault", "watchdog", "refused"] {
        assert!(
            !events.iter().any(|v| v["event"] == bad),
            "slave reported {bad}: {events:?}"
        );
    }
    let prm = events.iter().find(|v| v["event"] == "prm_ok").unwrap();
    assert_eq!(prm["master"], 2);
    assert!(events
        .iter()
        .any(|v| v["event"] == "global_control" && v["command"] == "Freeze"));
    assert!(events
        .iter()
        .any(|v| v["event"] == "global_control" && v["command"] == "Unfreeze"));

    // Master → slave: every outputs value the slave saw is one of the
    // master's patterns, in increasing order.
    let mut last = 0u32;
    let mut seen = 0u64;
    for v in events.iter().filter(|v| v["event"] == "data") {
        let out = unhex(v["outputs"].as_str().unwrap());
        assert_eq!(out.len(), OUT_LEN);
        if out.iter().all(|&b| b == 0) {
            continue; // configured, nothing received yet (or cleared)
        }
        let n = u32::from_be_bytes(out[..4].try_into().unwrap());
        assert_eq!(out, pattern(n, OUT_LEN), "outputs of pattern {n}");
        // The same pattern twice is one exchange repeated (the master
        // resends its outputs after a lost answer); never an older one.
        assert!(n >= last, "pattern {n} after {last}");
        last = n;
        seen += 1;
    }
    // The slave prints its outputs when they changed since its last
    // wake-up; on a busy machine several exchanges can fall into one
    // wake-up, so not every value is printed, but the last one is the
    // master's last pattern.
    assert!(
        seen > 0 && last >= CYCLES as u32,
        "the slave's last outputs were pattern {last} ({seen} values printed)"
    );
    let stopped = events.iter().find(|v| v["event"] == "stopped").unwrap();
    assert!(stopped["data_exchanges"].as_u64().unwrap() >= CYCLES);
}
