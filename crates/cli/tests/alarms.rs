//! DP-V1 alarms end to end on `dpctl bus`: a `dpctl slave` generic device
//! whose GSD declares alarms raises one on a control command, `dpctl
//! master --json` acknowledges it (Alarm_Ack) and reports it, the slave's
//! alarm block leaves its diagnosis, and `dpctl monitor` on a third
//! station sees the alarm and its acknowledgement on the wire.

mod common;

use common::{all_dx, dpctl, repo, send, Bus, Lines, Proc, TempDir};
use serde_json::Value;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const WAIT: Duration = Duration::from_secs(40);

fn alarm_gsd() -> PathBuf {
    repo().join("crates/cli/tests/data/DPCTL_ALM.GSD")
}

fn bus_file(dir: &TempDir, alarms: &str) -> PathBuf {
    let t = format!(
        "[master]\naddress = 2\nbaud = \"1.5M\"\n[options]\nreprobe_ms = 50\n\
         [[slave]]\naddress = 9\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\n\
         watchdog_ms = 5000\n{alarms}\n",
        alarm_gsd().display()
    );
    let p = dir.path("bus.toml");
    std::fs::write(&p, t).unwrap();
    p
}

/// JSON lines of `lines` until one satisfies `ok`; returns it.
fn wait_json(lines: &mut Lines, what: &str, ok: impl Fn(&Value) -> bool) -> Value {
    let end = Instant::now() + WAIT;
    let mut pos = 0;
    loop {
        while pos < lines.1.len() {
            let l = &lines.1[pos];
            pos += 1;
            if let Ok(v) = serde_json::from_str::<Value>(l) {
                if ok(&v) {
                    return v;
                }
            }
        }
        assert!(
            Instant::now() < end,
            "timed out waiting for {what}; last lines: {:#?}",
            &lines.1[lines.1.len().saturating_sub(8)..]
        );
        lines.wait_for("\u{0}never", Duration::from_millis(100));
    }
}

#[test]
fn a_raised_alarm_is_acknowledged_reported_and_leaves_the_diagnosis() {
    let dir = TempDir::new("alarms-e2e");
    let bus = Bus::start(3, &[]);
    let mut slave = Proc::spawn(
        "dpctl slave 9",
        Command::new(dpctl())
            .args(["slave", "--json", "--port"])
            .arg(bus.link(1))
            .args(["--addr", "9", "--baud", "1.5M", "--gsd"])
            .arg(alarm_gsd())
            .args(["--module", "2 words in/out", "--control", "-"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut slave_lines = Lines::from(&mut slave);
    let cfg = bus_file(&dir, "");
    let mut monitor = Proc::spawn(
        "dpctl monitor",
        Command::new(dpctl())
            .args(["monitor", "--json", "--port"])
            .arg(bus.link(2))
            .arg("--config")
            .arg(&cfg)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut monitor_lines = Lines::from(&mut monitor);
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--latency", "100"])
            .arg("--port")
            .arg(bus.link(0))
            .arg("--config")
            .arg(&cfg)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut lines = Lines::from(&mut master);
    wait_json(&mut lines, "data exchange", |v| {
        v["event"] == "status" && all_dx(v)
    });
    // The master enabled the GSD's alarms: DPV1_Status_2 0xE0 (pull/plug,
    // process, diagnostic), sequence mode 3 (8 outstanding).
    wait_json(&mut slave_lines, "prm accepted", |v| v["event"] == "prm_ok");

    send(&mut slave, "alarm diagnostic 1 appears 02 00");
    let alarm = wait_json(&mut lines, "the alarm event", |v| v["event"] == "alarm");
    assert_eq!(alarm["slave"], 9, "{alarm}");
    assert_eq!(alarm["type"], "diagnostic", "{alarm}");
    assert_eq!(alarm["slot"], 1, "{alarm}");
    assert_eq!(alarm["specifier"], "appears", "{alarm}");
    assert_eq!(alarm["seq"], 0, "{alarm}");
    assert_eq!(alarm["data"], "02 00", "{alarm}");
    assert_eq!(alarm["acknowledged"], true, "{alarm}");
    // Bit 25 (bit 1 of the first data byte) has a GSD text.
    let text = alarm["text"].as_str().unwrap();
    assert!(text.contains("Wire break"), "{text}");
    let keys: Vec<&str> = alarm
        .as_object()
        .unwrap()
        .keys()
        .map(|k| k.as_str())
        .collect();
    let mut want = vec![
        "event",
        "slave",
        "type",
        "slot",
        "specifier",
        "seq",
        "data",
        "text",
        "acknowledged",
    ];
    want.sort();
    let mut got = keys.clone();
    got.sort();
    assert_eq!(got, want);

    // The slave reports the acknowledgement; its next diagnosis has no
    // alarm block (the master reads it on "data high").
    wait_json(&mut slave_lines, "the slave's acknowledgement", |v| {
        v["event"] == "alarm" && v["action"] == "acknowledged" && v["seq"] == 0
    });
    wait_json(&mut lines, "a diagnosis without the alarm", |v| {
        v["event"] == "diag" && v["slave"] == 9 && v["raw"].as_str().is_some_and(|r| r.len() == 17)
    });

    // The monitor saw the alarm in the diagnosis and the master's
    // Alarm_Ack on the wire.
    let seen = wait_json(
        &mut monitor_lines,
        "the monitor's acknowledged alarm",
        |v| v["event"] == "alarm" && v["acknowledged"] == true,
    );
    assert_eq!(
        (seen["slave"].clone(), seen["type"].clone()),
        (9.into(), "diagnostic".into())
    );
    assert_eq!(seen["seq"], 0);

    master.terminate(Duration::from_secs(5));
    monitor.terminate(Duration::from_secs(5));
    slave.terminate(Duration::from_secs(5));
}

#[test]
fn bad_alarm_names_in_a_bus_file_are_refused_with_position_and_closest_name() {
    let dir = TempDir::new("alarms-busfile");
    for (line, want) in [
        (
            "alarms = [\"diagnostik\"]",
            ":11:11: slave 9: unknown alarm type `diagnostik`; did you mean `diagnostic`?",
        ),
        (
            "alarms = [\"process\", \"update\"]",
            ":11:22: slave 9: the GSD of dpctl alarm slave does not declare update alarms \
             (no Update_Alarm_supp = 1)",
        ),
    ] {
        let cfg = bus_file(&dir, line);
        let out = Command::new(dpctl())
            .args(["master", "--port", "/nonexistent", "--config"])
            .arg(&cfg)
            .output()
            .unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(want), "{line}: {err}");
    }
}

#[test]
fn the_gateway_publishes_each_alarm_on_its_alarm_topic_not_retained() {
    use common::mqtt;
    let dir = TempDir::new("alarms-gateway");
    let port = mqtt::free_port();
    let _mosq = mqtt::broker(&dir, port);
    let line = Bus::start(2, &[]);
    let mut slave = Proc::spawn(
        "dpctl slave 9",
        Command::new(dpctl())
            .args(["slave", "--port"])
            .arg(line.link(1))
            .args(["--addr", "9", "--baud", "1.5M", "--gsd"])
            .arg(alarm_gsd())
            .args(["--module", "2 words in/out", "--control", "-"])
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    let cfg = bus_file(&dir, "[mqtt]\nprefix = \"profibus\"\nbus = \"line\"");
    let sub = ["-v", "-t", "profibus/line/#", "-t", "client/probe"];
    let (_sub, mut lines) = mqtt::subscribe(port, &sub, &[], "client/probe");
    let gw = Proc::spawn_captured({
        let mut c = Command::new(dpctl());
        c.arg("gateway")
            .arg("--config")
            .arg(&cfg)
            .arg("--port")
            .arg(line.link(0))
            .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")]);
        c
    });
    // The payload of the first message on `topic` that contains `needle`.
    let on = |lines: &mut Lines, topic: &str, needle: &str| -> Value {
        let want = format!("{topic} ");
        let hit = |l: &String| l.starts_with(&want) && l.contains(needle);
        let end = Instant::now() + WAIT;
        loop {
            if let Some(l) = lines.1.iter().find(|l| hit(l)) {
                return serde_json::from_str(&l[want.len()..]).unwrap();
            }
            let left = end.saturating_duration_since(Instant::now());
            assert!(
                lines.next_line(left).is_some(),
                "no {topic} with {needle}: {:#?}",
                lines.1
            );
        }
    };
    on(&mut lines, "profibus/line/9/state", "data_exchange");
    send(&mut slave, "alarm process 2 appears 7f");
    let a = on(&mut lines, "profibus/line/9/alarm", "\"acknowledged\"");
    assert_eq!(a["slave"], 9, "{a}");
    assert_eq!(a["type"], "process", "{a}");
    assert_eq!(a["slot"], 2, "{a}");
    assert_eq!(a["specifier"], "appears", "{a}");
    assert_eq!(a["seq"], 0, "{a}");
    assert_eq!(a["data"], "7F", "{a}");
    assert_eq!(a["acknowledged"], true, "{a}");
    assert!(a["ts"].as_u64().is_some(), "{a}");
    // A client that subscribes now gets the retained topics (the state)
    // at once, before its probe comes back, but no alarm.
    let late = ["-F", "%r %t", "-t", "profibus/line/#", "-t", "client/late"];
    let (_late, late_lines) = mqtt::subscribe(port, &late, &[], "client/late");
    assert!(
        late_lines.1.iter().any(|l| l == "1 profibus/line/9/state"),
        "{:#?}",
        late_lines.1
    );
    assert!(
        !late_lines.1.iter().any(|l| l.contains("/alarm")),
        "the alarm is not retained: {:#?}",
        late_lines.1
    );
    gw.signal(15);
    let out = gw.finish(WAIT);
    assert!(out.status.success(), "gateway failed: {}", out.stderr);
    slave.terminate(Duration::from_secs(5));
}
