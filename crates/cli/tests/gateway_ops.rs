//! `dpctl gateway` in operation against a real mosquitto: JSON logs,
//! the health topic and `--health-file`, the `[mqtt]` reload on SIGHUP
//! (the bus stays in Data_Exchange), the stop on SIGTERM. Fails (never
//! skips) when mosquitto is missing: run `scripts/setup-test-env`.

mod common;

use common::mqtt::{self, broker, echo_bus_text, free_port, write_bus};
use common::{dpctl, Lines, Proc, TempDir};
use std::process::Command;
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
        mqtt::sim_gateway(&["--log-format", "json"], &bus, port)
            .arg("--health-file")
            .arg(&health),
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

/// The `ts` (publish time, wall ms) of the messages on `topic` published
/// at or after `since`, waiting (within [`T`]) until there are `n`.
fn published_since(lines: &mut Lines, topic: &str, since: u64, n: usize) -> Vec<u64> {
    let ts = |lines: &Lines| -> Vec<u64> {
        (lines.1.iter())
            .filter_map(|l| l.split_once(' ').filter(|(t, _)| *t == topic))
            .filter_map(|(_, p)| serde_json::from_str::<serde_json::Value>(p).ok()?["ts"].as_u64())
            .filter(|ts| *ts >= since)
            .collect()
    };
    let end = Instant::now() + T;
    while ts(lines).len() < n {
        if lines
            .next_line(end.saturating_duration_since(Instant::now()))
            .is_none()
        {
            panic!("only {} messages on {topic} since {since}", ts(lines).len());
        }
    }
    ts(lines)[..n].to_vec()
}

fn wall_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_millis() as u64
}

/// SIGHUP takes the report-by-exception keys without a restart: a
/// BK3000's noisy analog inputs (the simulation's sine waves change in
/// every cycle) come at most every 250 ms on the defaults; after
/// `deadband = 0` and `min_interval_ms = 0` every change is published
/// (50 messages in well under the 12 s the defaults would take); after
/// `[[mqtt.slave]] min_interval_ms = 1000` at most one a second.
#[test]
fn sighup_retunes_the_traffic_of_a_noisy_slave() {
    let dir = TempDir::new("gateway-retune");
    let port = free_port();
    let _mosq = broker(&dir, port);
    let bus_text = |mqtt: &str| {
        format!(
            "[master]\naddress = 1\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 40\ndevice = \"bk3000\"\n\
             terminals = [\"KL3102\", \"KL3102\", \"KL9010\"]\n\n[mqtt]\nbus = \"line\"\n{mqtt}"
        )
    };
    let bus = write_bus(&dir, &bus_text(""));
    let (_sub, mut lines) = mqtt::subscribe(
        port,
        &["-v", "-t", "profibus/line/#"],
        &[],
        "profibus/line/probe",
    );
    let mut gw = Proc::spawn(
        "dpctl gateway",
        &mut mqtt::sim_gateway(&["--log-format", "json"], &bus, port),
    );
    let mut log = Lines::from(&mut gw);
    let topic = "profibus/line/40/inputs";
    let ts = published_since(&mut lines, topic, 0, 5);
    let gaps: Vec<u64> = ts.windows(2).skip(1).map(|w| w[1] - w[0]).collect();
    assert!(gaps.iter().all(|g| *g >= 250), "defaults: {gaps:?}");

    // Every change.
    std::fs::write(&bus, bus_text("deadband = 0\nmin_interval_ms = 0\n")).unwrap();
    gw.signal(1);
    let l = logged(&mut log, "reloaded [mqtt]");
    let m = l["message"].as_str().unwrap();
    assert!(
        m.contains("deadband: (none) → 0") && m.contains("min_interval_ms: (none) → 0"),
        "{l}"
    );
    let since = wall_ms();
    let ts = published_since(&mut lines, topic, since, 50);
    let took = ts[49] - ts[0];
    assert!(took < 5000, "50 messages took {took} ms");

    // One a second for this slave.
    std::fs::write(
        &bus,
        bus_text("deadband = 0\nmin_interval_ms = 0\n[[mqtt.slave]]\naddress = 40\nmin_interval_ms = 1000\n"),
    )
    .unwrap();
    gw.signal(1);
    assert!(
        log.wait_for("slave: (none) → ", T),
        "no reload of `slave`:\n{}",
        log.1.join("\n")
    );
    let since = wall_ms();
    let ts = published_since(&mut lines, topic, since, 3);
    let gaps: Vec<u64> = ts.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(
        gaps.iter().all(|g| (1000..4000).contains(g)),
        "[[mqtt.slave]] min_interval_ms = 1000: {gaps:?}"
    );
    assert!(
        !log.1
            .iter()
            .any(|l| l.contains("only change with a restart")),
        "{}",
        log.1.join("\n")
    );
}

/// A bad `[mqtt]` or `[opcua]` setting is one line with the file, the
/// line and the column of the key, then the message as before.
#[test]
fn bad_gateway_settings_name_their_line_and_column() {
    let dir = TempDir::new("gateway-bad-at");
    // echo_bus_text: `[mqtt]` on line 10, its keys from line 11.
    for (mqtt, want) in [
        (
            "bus = \"line\"\nqos = 3\n",
            "bus.toml:12:1: [mqtt]: `qos` must be 0, 1 or 2",
        ),
        (
            "retain = true\n",
            "bus.toml:11:1: [mqtt]: unknown key `retain`",
        ),
        (
            "[[mqtt.slave]]\naddress = 3\n[[mqtt.slave]]\naddress = 3\n",
            "bus.toml:13:1: [mqtt]: `slave` lists slave 3 twice",
        ),
        (
            "[[mqtt.slave]]\naddress = 3\nchannels = { nope = 1 }\n",
            "bus.toml:13:14: [mqtt]: `slave` slave 3 has no channel `nope`",
        ),
        (
            "[[mqtt.slave]]\naddress = 9\n",
            "bus.toml:12:1: [mqtt]: `slave` names slave 9, which the bus file does not have",
        ),
        (
            "bus = \"line\"\n\n[opcua]\nanonymous = true\nsecurity = [\"none\"]\n",
            "bus.toml:15:1: [opcua]: `security` `none` is only taken from the command line",
        ),
    ] {
        let bus = write_bus(&dir, &echo_bus_text(mqtt));
        let mut cmd = Command::new(dpctl());
        cmd.args(["gateway", "--sim", "--config"])
            .arg(&bus)
            .args(["--mqtt", "mqtt://127.0.0.1:1"]);
        let out = Proc::spawn_captured(cmd).finish(T);
        assert!(!out.status.success(), "{mqtt}");
        let lines: Vec<&str> = out.stderr.lines().collect();
        assert_eq!(lines.len(), 1, "{mqtt}: {}", out.stderr);
        assert!(
            lines[0].starts_with("dpctl: ") && lines[0].contains(want),
            "{mqtt}: want {want}\n{}",
            out.stderr
        );
    }
}
