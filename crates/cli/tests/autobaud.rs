//! `--baud auto` of `dpctl sniff`, `dpctl monitor` and `dpctl scan` on a
//! `dpctl bus --check-rates` (a station set to another rate than the line
//! hears garbage and sends garbage, as on RS-485).

mod common;

use common::*;
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::Duration;

/// Master 2 with the generic slave at 3, on a line at 500 kbit/s.
const BUS_500K: &str = r#"[master]
address = 2
baud = "500k"

[[slave]]
address = 3
name = "echo"
gsd = "DPCTL_GEN.GSD"
modules = ["1 byte in", "2 words in/out"]
"#;

fn slave(bus: &Bus, i: usize, addr: u8, baud: &str) -> Proc {
    Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--json", "--port", &bus.link_str(i)])
            .args(["--addr", &addr.to_string(), "--baud", baud, "--gsd"])
            .arg(repo().join("crates/devices/gsd/DPCTL_GEN.GSD"))
            .args(["--module", "1 byte in", "--module", "2 words in/out"])
            .stdout(Stdio::piped())
            .stdin(Stdio::null()),
    )
}

/// The first `baud_found` JSON line of `lines`.
fn baud_found(lines: &mut Lines) -> Value {
    loop {
        let l = lines
            .next_line(Duration::from_secs(30))
            .unwrap_or_else(|| panic!("no baud_found line: {:?}", lines.1));
        if let Ok(v) = serde_json::from_str::<Value>(&l) {
            if v["event"] == "baud_found" {
                return v;
            }
        }
    }
}

#[test]
fn sniff_and_monitor_find_the_rate_of_a_running_master() {
    let line = Bus::start(4, &["--baud", "500k", "--check-rates"]);
    let dir = TempDir::new("autobaud");
    std::fs::copy(
        repo().join("crates/devices/gsd/DPCTL_GEN.GSD"),
        dir.path("DPCTL_GEN.GSD"),
    )
    .unwrap();
    let bus = dir.path("bus.toml");
    std::fs::write(&bus, BUS_500K).unwrap();
    // The monitor's bus file names another rate: --baud auto wins.
    let mon_bus = dir.path("mon.toml");
    std::fs::write(&mon_bus, BUS_500K.replace("500k", "1.5M")).unwrap();
    let mut s = slave(&line, 1, 3, "500k");
    let _s = started(&mut s, Duration::from_secs(20));
    let _master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--latency", "100", "--port"])
            .arg(line.link(0))
            .arg("--config")
            .arg(&bus)
            .stdout(Stdio::null())
            .stdin(Stdio::null()),
    );
    let mut sniff = Proc::spawn(
        "dpctl sniff",
        Command::new(dpctl())
            .args(["sniff", "--json", "--baud", "auto", "--port"])
            .arg(line.link(2))
            .stdout(Stdio::piped())
            .stdin(Stdio::null()),
    );
    let mut monitor = Proc::spawn(
        "dpctl monitor",
        Command::new(dpctl())
            .args(["monitor", "--json", "--baud", "auto", "--port"])
            .arg(line.link(3))
            .arg("--config")
            .arg(&mon_bus)
            .stdout(Stdio::piped())
            .stdin(Stdio::null()),
    );
    let mut sn = Lines::from(&mut sniff);
    let v = baud_found(&mut sn);
    assert_eq!(v["baud"], 500_000, "{v}");
    assert_eq!(v["how"], "heard", "{v}");
    // The sniffer then decodes the line at that rate.
    assert!(sn.wait_for("\"fc\"", Duration::from_secs(10)), "{:?}", sn.1);
    let mut mo = Lines::from(&mut monitor);
    let v = baud_found(&mut mo);
    assert_eq!(v["baud"], 500_000, "{v}");
    // … and follows the master's slave to Data_Exchange at it.
    assert!(
        mo.wait_for("\"data_exchange\"", Duration::from_secs(30)),
        "{:?}",
        mo.1
    );
}

#[test]
fn scan_finds_the_rate_of_a_silent_slave() {
    let line = Bus::start(2, &["--baud", "93.75k", "--check-rates"]);
    let mut s = slave(&line, 1, 5, "93.75k");
    let _s = started(&mut s, Duration::from_secs(20));
    let mut cmd = Command::new(dpctl());
    cmd.args([
        "scan",
        "--json",
        "--baud",
        "auto",
        "--port",
        &line.link_str(0),
    ]);
    let out = Proc::spawn_captured(cmd).finish(Duration::from_secs(120));
    assert!(out.status.success(), "{}{}", out.stdout, out.stderr);
    let rows: Vec<Value> = out
        .stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l}: {e}")))
        .collect();
    assert_eq!(rows[0]["event"], "baud_found", "{}", out.stdout);
    assert_eq!(rows[0]["baud"], 93_750, "{}", out.stdout);
    assert_eq!(rows[0]["how"], "answered");
    assert_eq!(rows[0]["station"], 5);
    assert!(
        rows.iter()
            .any(|r| r["address"] == 5 && r["type"] == "passive" && r["ident"] == "0x0DCE"),
        "{}",
        out.stdout
    );
}

#[test]
fn other_commands_refuse_baud_auto() {
    let mut cmd = Command::new(dpctl());
    cmd.args([
        "diag",
        "--port",
        "/nonexistent",
        "--slave",
        "3",
        "--baud",
        "auto",
    ]);
    let out = Proc::spawn_captured(cmd).finish(Duration::from_secs(20));
    assert!(!out.status.success());
    assert!(
        out.stderr
            .contains("--baud auto is only for dpctl scan, sniff and monitor"),
        "{}",
        out.stderr
    );
}
