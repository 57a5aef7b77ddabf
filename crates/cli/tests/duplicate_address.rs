//! Two `dpctl slave` processes at one address on a `dpctl bus`: every
//! request to that address gets two answers (garbled into one on a paced
//! line, or one after the other). `dpctl master` names the address as a
//! possible duplicate, once.

mod common;

use common::{dpctl, generic_slave, repo, Bus, Lines, Proc};
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn slave(bus: &Bus, link: usize) -> Proc {
    Proc::spawn(
        "dpctl slave",
        generic_slave(bus.link(link), 5, "1.5M", &["1 byte in"]).stderr(Stdio::null()),
    )
}

/// The `duplicate_address` events among the JSON lines so far.
fn duplicates(lines: &[String]) -> Vec<Value> {
    common::json_lines(lines)
        .into_iter()
        .filter(|v| v["event"] == "duplicate_address")
        .collect()
}

fn master_names_two_slaves_at_one_address(extra: &[&str]) {
    let bus = Bus::start(3, extra);
    let _a = slave(&bus, 1);
    let _b = slave(&bus, 2);
    // Both slaves listen before the master starts.
    bus.wait_connected(2);
    let config = bus.dir().path("bus.toml");
    std::fs::write(
        &config,
        format!(
            "[master]\naddress = 2\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 5\ngsd = \"{}\"\n\
             modules = [\"1 byte in\"]\n",
            repo().join("crates/devices/gsd/DPCTL_GEN.GSD").display()
        ),
    )
    .unwrap();
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--latency", "50"])
            .arg("--port")
            .arg(bus.link(0))
            .arg("--config")
            .arg(&config)
            .stdout(Stdio::piped())
            .stdin(Stdio::null()),
    );
    let mut lines = Lines::from(&mut master);
    assert!(
        lines.wait_for("\"event\":\"duplicate_address\"", Duration::from_secs(60)),
        "no duplicate_address event: {:#?}",
        &lines.1[lines.1.len().saturating_sub(20)..]
    );
    let found = duplicates(&lines.1);
    assert_eq!(found[0]["slave"], 5, "{}", found[0]);
    // Reported once: 20 more status lines (2 s of polling) bring no second.
    let mut statuses = 0;
    let end = Instant::now() + Duration::from_secs(60);
    while statuses < 20 {
        let left = end.saturating_duration_since(Instant::now());
        let l = lines.next_line(left).expect("status lines");
        statuses += l.contains("\"event\":\"status\"") as usize;
    }
    assert_eq!(duplicates(&lines.1).len(), 1, "{:?}", duplicates(&lines.1));
    master.terminate(Duration::from_secs(10));
}

/// An unpaced hub hands on both answers whole, one after the other.
#[test]
fn master_names_a_duplicate_address_answered_twice() {
    master_names_two_slaves_at_one_address(&[]);
}

/// A paced hub garbles the two answers into one (counted as collisions).
#[test]
fn master_names_a_duplicate_address_with_garbled_answers() {
    master_names_two_slaves_at_one_address(&["--baud", "1.5M"]);
}
