//! `dpctl gateway` in operation against a real mosquitto: JSON logs,
//! the health topic and `--health-file`, the `[mqtt]` reload on SIGHUP
//! (the bus stays in Data_Exchange), the stop on SIGTERM. Fails (never
//! skips) when mosquitto is missing: run `scripts/setup-test-env`.

mod common;

use common::mqtt::{self, broker, echo_bus_text, free_port, write_bus};
use common::{dpctl, Lines, Proc, TempDir};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const T: Duration = Duration::from_secs(30);

/// The first message on `topic` whose payload contains every needle
/// (seen before or within [`T`]).
fn expect(lines: &mut Lines, topic: &str, needles: &[&str]) -> serde_json::Value {
    let hit = |l: &str| {
        l.split_once(' ')
            .is_some_and(|(t, p)| t == topic && needles.iter().all(|n| p.contains(n)))
    };
    let json = |l: &str| serde_json::from_str(l.split_once(' ').unwrap().1).unwrap();
    if let Some(l) = lines.1.iter().find(|l| hit(l)) {
        return json(l);
    }
    let end = Instant::now() + T;
    while let Some(l) = lines.next_line(end.saturating_duration_since(Instant::now())) {
        if hit(&l) {
            return json(&l);
        }
    }
    panic!(
        "no message on {topic} with {needles:?}; got:\n{}",
        lines.1.join("\n")
    );
}

fn publish(port: u16, topic: &str, payload: &str) {
    common::require("mosquitto_pub");
    let ok = Command::new("mosquitto_pub")
        .args(["-h", "127.0.0.1", "-p", &port.to_string(), "-q", "1"])
        .args(["-t", topic, "-m", payload])
        .status()
        .expect("mosquitto_pub")
        .success();
    assert!(ok, "mosquitto_pub to {topic} failed");
}

/// Waits for a log line (a JSON object) containing `needle`; returns it.
fn logged(log: &mut Lines, needle: &str) -> serde_json::Value {
    assert!(
        log.wait_for(needle, T),
        "no `{needle}` in the log:\n{}",
        log.1.join("\n")
    );
    let l = log.1.iter().rev().find(|l| l.contains(needle)).unwrap();
    serde_json::from_str(l).unwrap_or_else(|e| panic!("not a JSON log line ({e}): {l}"))
}

/// SIGHUP takes a changed `[mqtt]` (here `writable`) while the slave
/// stays in Data_Exchange; a broken file or a key that needs a restart
/// is refused with the cause (file:line:col) and the running settings
/// stay; health on the topic and in the file; SIGTERM stops within a
/// bound with status 0, offline health and a final log line. Logs are
/// JSON lines (`--log-format json`).
#[test]
fn gateway_reloads_on_sighup_reports_health_and_stops_on_sigterm() {
    let dir = TempDir::new("gateway-ops");
    let port = free_port();
    let _mosq = broker(&dir, port);
    let bus = write_bus(&dir, &echo_bus_text("bus = \"line\"\n"));
    let health = dir.path("line.health");
    let (_sub, mut lines) = mqtt::subscribe(
        port,
        &["-v", "-t", "profibus/line/#"],
        &[],
        "profibus/line/probe",
    );
    let mut gw = Proc::spawn(
        "dpctl gateway",
        Command::new("sh")
            .args(["-c", "exec \"$0\" \"$@\" 2>&1"])
            .arg(dpctl())
            .args(["--log-format", "json", "gateway", "--config"])
            .arg(&bus)
            .arg("--sim")
            .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")])
            .arg("--health-file")
            .arg(&health)
            .env_remove("DPCTL_LOG")
            .stdout(Stdio::piped()),
    );
    let mut log = Lines::from(&mut gw);
    let start = logged(&mut log, "starting: bus file");
    assert_eq!(start["level"], "INFO", "{start}");
    assert_eq!(start["target"], "dpctl::ops", "{start}");
    assert!(
        start["message"].as_str().unwrap().contains("simulated bus"),
        "{start}"
    );
    logged(&mut log, "slave 3 in Data_Exchange");
    expect(&mut lines, "profibus/line/3/state", &["data_exchange"]);
    let h = expect(&mut lines, "profibus/line/health", &["\"ok\""]);
    assert_eq!(h["data_exchange"], 1, "{h}");
    assert_eq!(h["broker_connected"], true, "{h}");
    // The file, rewritten every second.
    common::wait_for("the health file", T, || {
        std::fs::read_to_string(&health).is_ok_and(|t| t.contains("\"ok\""))
    });
    let f: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&health).unwrap()).unwrap();
    assert_eq!(f["healthy"], true, "{f}");
    assert!(f["last_cycle_age_ms"].as_u64().unwrap() < 2000, "{f}");

    // Not writable yet.
    publish(
        port,
        "profibus/line/3/outputs/set",
        r#"{"hex": "11223344", "id": "w1"}"#,
    );
    let r = expect(&mut lines, "profibus/line/3/outputs/response", &["\"w1\""]);
    assert_eq!(r["ok"], false, "{r}");

    // Writable after a reload.
    std::fs::write(&bus, echo_bus_text("bus = \"line\"\nwritable = [3]\n")).unwrap();
    gw.signal(1);
    let l = logged(&mut log, "reloaded [mqtt]");
    assert!(
        l["message"]
            .as_str()
            .unwrap()
            .contains("writable: (none) → [3]"),
        "{l}"
    );
    publish(
        port,
        "profibus/line/3/outputs/set",
        r#"{"hex": "11223344", "id": "w2"}"#,
    );
    let r = expect(&mut lines, "profibus/line/3/outputs/response", &["\"w2\""]);
    assert_eq!(r["ok"], true, "{r}");
    expect(&mut lines, "profibus/line/3/inputs", &["\"11223344\""]);

    // A broken file: refused with its line and column, the bus and the
    // running settings stay (writes still go through).
    std::fs::write(&bus, echo_bus_text("bus = \"line\"\nwritable = [3\n")).unwrap();
    gw.signal(1);
    let l = logged(&mut log, "not reloaded");
    assert_eq!(l["level"], "ERROR", "{l}");
    let m = l["message"].as_str().unwrap();
    assert!(m.contains("bus.toml:1"), "no file:line:col in {l}");
    // A key of the connection: needs a restart, refused.
    std::fs::write(&bus, echo_bus_text("bus = \"other\"\nwritable = [3]\n")).unwrap();
    gw.signal(1);
    let l = logged(&mut log, "only change with a restart");
    assert!(
        l["message"]
            .as_str()
            .unwrap()
            .contains("bus: \"line\" → \"other\""),
        "{l}"
    );
    publish(
        port,
        "profibus/line/3/outputs/set",
        r#"{"hex": "55667788", "id": "w3"}"#,
    );
    let r = expect(&mut lines, "profibus/line/3/outputs/response", &["\"w3\""]);
    assert_eq!(r["ok"], true, "{r}");
    expect(&mut lines, "profibus/line/3/inputs", &["\"55667788\""]);

    // The slave never left Data_Exchange.
    let states: Vec<&String> = lines
        .1
        .iter()
        .filter(|l| l.starts_with("profibus/line/3/state "))
        .collect();
    assert!(
        states
            .iter()
            .skip_while(|l| !l.contains("data_exchange"))
            .all(|l| l.contains("data_exchange")),
        "{states:#?}"
    );
    assert!(
        !log.1.iter().any(|l| l.contains("left Data_Exchange")),
        "{}",
        log.1.join("\n")
    );

    // SIGTERM: a prompt, clean stop.
    let asked = Instant::now();
    gw.signal(15);
    let status = gw.wait(Duration::from_secs(5));
    let took = asked.elapsed();
    assert!(status.success(), "{status}:\n{}", log.1.join("\n"));
    assert!(took < Duration::from_secs(3), "took {took:?}");
    expect(&mut lines, "profibus/line/health", &["\"offline\""]);
    expect(&mut lines, "profibus/line/status", &["offline"]);
    let rest = log.rest().to_vec();
    let last: serde_json::Value = serde_json::from_str(rest.last().unwrap()).unwrap();
    assert_eq!(last["message"], "dpctl gateway stopped", "{last}");
    let f: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&health).unwrap()).unwrap();
    assert_eq!(f["state"], "offline", "{f}");
    // Every line a JSON object with the five keys.
    for l in &rest {
        let v: serde_json::Value = serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}"));
        for k in ["time", "level", "target", "message", "fields"] {
            assert!(v.get(k).is_some(), "no `{k}` in {l}");
        }
    }
}
