//! `dpctl gateway --alert` / `[mqtt] alerts` against a real MQTT broker
//! (mosquitto on a free localhost port, `mosquitto_sub` as the client):
//! the master's per-slave counters checked by the alert rules of `dpctl
//! sniff`, the alerts published on `<prefix>/<bus>/alert`. Fails (never
//! skips) when mosquitto is missing: run `scripts/setup-test-env`.

mod common;

use common::mqtt::{self, broker, echo_bus_text, echo_slave, free_port, write_bus};
use common::{dpctl, Lines, Proc, TempDir};
use std::process::Command;
use std::time::Duration;

const T: Duration = Duration::from_secs(30);

/// Wait for a message on `topic`, among the lines from index `from` on,
/// whose payload has every needle; the payload as JSON.
fn expect_from(lines: &mut Lines, from: usize, topic: &str, needles: &[&str]) -> serde_json::Value {
    let hit = |l: &str| {
        l.split_once(' ')
            .is_some_and(|(t, p)| t == topic && needles.iter().all(|n| p.contains(n)))
    };
    let payload = |l: &str| serde_json::from_str(l.split_once(' ').unwrap().1).unwrap();
    if let Some(l) = lines.1.iter().skip(from).find(|l| hit(l)) {
        return payload(l);
    }
    let end = std::time::Instant::now() + T;
    while let Some(l) = lines.next_line(end.saturating_duration_since(std::time::Instant::now())) {
        if hit(&l) {
            return payload(&l);
        }
    }
    panic!(
        "no message on {topic} with {needles:?}; got:\n{}",
        lines.1[from.min(lines.1.len())..].join("\n")
    );
}

#[test]
fn a_slave_killed_under_the_gateway_raises_alerts_on_mqtt() {
    let dir = TempDir::new("gateway-alerts");
    let port = free_port();
    let _mosq = broker(&dir, port);
    let line = common::Bus::start(2, &[]);
    let mut slave = echo_slave(&line.link(1));
    let bus = write_bus(
        &dir,
        &echo_bus_text(
            "bus = \"line\"\nalerts = [\"no_answer>0\", \"restart\"]\nalert_interval_ms = 500\n",
        ),
    );
    let (_sub, mut lines) = mqtt::subscribe(
        port,
        &["-v", "-t", "profibus/line/#"],
        &[],
        "profibus/line/probe",
    );
    let gw = Proc::spawn_captured({
        let mut c = Command::new(dpctl());
        c.arg("gateway")
            .arg("--config")
            .arg(&bus)
            .arg("--port")
            .arg(line.link(0))
            .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")])
            .args(["--alert", "3:health<50"]);
        c
    });
    expect_from(&mut lines, 0, "profibus/line/3/state", &["data_exchange"]);
    // The slave dies: its requests go unanswered, its health drops.
    let killed = lines.1.len();
    slave.signal(9);
    slave.wait(T);
    let a = expect_from(
        &mut lines,
        killed,
        "profibus/line/alert",
        &["\"no_answer\""],
    );
    assert_eq!(
        (&a["event"], &a["station"], &a["rule"]),
        (&"alert".into(), &3.into(), &"no_answer>0".into()),
        "{a}"
    );
    assert!(a["value"].as_f64().unwrap() >= 1.0, "{a}");
    assert!(a["interval_s"].as_f64().unwrap() > 0.3, "{a}");
    let a = expect_from(&mut lines, killed, "profibus/line/alert", &["\"health\""]);
    assert_eq!(
        (&a["station"], &a["rule"]),
        (&3.into(), &"3:health<50".into()),
        "{a}"
    );
    // It comes back and goes through the start-up again: a restart.
    let back = lines.1.len();
    let _slave = echo_slave(&line.link(1));
    expect_from(
        &mut lines,
        back,
        "profibus/line/3/state",
        &["data_exchange"],
    );
    let a = expect_from(&mut lines, back, "profibus/line/alert", &["\"restarts\""]);
    assert_eq!(
        (&a["station"], &a["rule"]),
        (&3.into(), &"restart".into()),
        "{a}"
    );
    assert!(a["value"].as_f64().unwrap() >= 1.0, "{a}");
    gw.signal(15);
    let out = gw.finish(T);
    assert!(out.status.success(), "gateway failed: {}", out.stderr);
}

#[test]
fn a_bad_alert_rule_in_the_bus_file_names_the_closest_statistic() {
    let dir = TempDir::new("gateway-alerts-bad");
    let bus = write_bus(&dir, &echo_bus_text("alerts = [\"retrys>1%\"]\n"));
    let out = common::run_dpctl(&[
        "gateway",
        "--config",
        bus.to_str().unwrap(),
        "--sim",
        "--mqtt",
        "mqtt://127.0.0.1:1",
    ]);
    assert!(!out.status.success());
    assert!(
        out.stderr.contains("`alerts` alert rule `retrys>1%`, column 1: unknown statistic `retrys` (did you mean `retries`?)"),
        "{}",
        out.stderr
    );
}
