//! `dpctl doctor` on a socat pty: it says what it could not check there,
//! and fails on a port that does not exist.

mod common;

use common::*;
use std::process::Command;

/// The check `what` of a JSON report.
fn check<'a>(report: &'a serde_json::Value, what: &str) -> &'a serde_json::Value {
    let checks = report["checks"].as_array().unwrap();
    (checks.iter().find(|c| c["what"] == what))
        .unwrap_or_else(|| panic!("{what} missing: {report}"))
}

/// The RTS control check of a JSON report failed, saying `why`.
fn rts_check_fails(report: &serde_json::Value, why: &str) {
    let rts = check(report, "RTS control");
    assert_eq!(rts["verdict"], "fail");
    let detail = rts["detail"].as_str().unwrap();
    assert!(detail.contains(why), "{rts}");
}

#[test]
fn doctor_on_a_pty_names_what_it_could_not_check() {
    let dir = TempDir::new("doctor");
    let (a, b) = (dir.path("a"), dir.path("b"));
    let _socat = pty_pair(&a, &b);
    let bus = dir.path("bus.toml");
    std::fs::write(&bus, "[master]\naddress = 2\nbaud = \"1.5M\"\n").unwrap();
    let out = Command::new(dpctl())
        .args(["doctor", "--port"])
        .arg(&a)
        .arg("--config")
        .arg(&bus)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("/dev/pts/"), "{text}");
    assert!(text.contains("ok          open: "), "{text}");
    assert!(text.contains("is a pseudo terminal"), "{text}");
    for what in ["8E1", "baud rates", "RS-485 mode", "latency", "slot time"] {
        assert!(
            text.lines()
                .any(|l| l.trim_start().starts_with(&format!("not checked {what}: "))),
            "{what}: {text}"
        );
    }
    // The slot time check names the bus file's numbers.
    assert!(text.contains("TSL 300 bit = 200 µs at 1.5Mbit/s"), "{text}");
    assert!(text.contains("5 check(s) could not be made"), "{text}");

    // Without a bus file there is no timing check.
    let out = Command::new(dpctl())
        .args(["doctor", "--port"])
        .arg(&b)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(!text.contains("slot time"), "{text}");
}

#[test]
fn doctor_fails_on_a_missing_port() {
    let out = Command::new(dpctl())
        .args(["doctor", "--port", "/nonexistent/ttyUSB9"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("FAIL        open: "), "{text}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("not fit for PROFIBUS"), "{err}");
}

#[test]
fn doctor_json_is_one_object_with_every_check() {
    let dir = TempDir::new("doctor-json");
    let (a, b) = (dir.path("a"), dir.path("b"));
    let _socat = pty_pair(&a, &b);
    let run = |rts: &str| {
        Command::new(dpctl())
            .args(["doctor", "--json", "--rts", rts, "--port"])
            .arg(&a)
            .output()
            .unwrap()
    };
    let out = run("off");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert_eq!(text.lines().count(), 1, "one JSON object: {text}");
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["path"], a.to_string_lossy().as_ref());
    assert!(
        v["device"].as_str().unwrap().starts_with("/dev/pts/"),
        "{v}"
    );
    assert_eq!(v["kind"]["type"], "pty");
    assert_eq!(v["rts"], "off");
    assert_eq!(v["failed"], false);
    assert_eq!(v["unchecked"], 4);
    let verdict = |what: &str| check(&v, what)["verdict"].clone();
    assert_eq!(verdict("open"), "ok");
    assert_eq!(verdict("8E1"), "unchecked");
    assert_eq!(verdict("RTS control"), "ok");

    // RTS direction control cannot work on a pty: the check fails, the
    // exit status says so, stdout is still the JSON report.
    let out = run("on-send");
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["rts"].as_str(), v["failed"].as_bool()),
        (Some("on-send"), Some(true))
    );
    rts_check_fails(&v, "a pty has no RTS line");
}

#[test]
fn rts_on_send_on_a_pty_is_a_clear_one_line_error() {
    let dir = TempDir::new("rts");
    let (a, b) = (dir.path("a"), dir.path("b"));
    let _socat = pty_pair(&a, &b);
    let bus = dir.path("bus.toml");
    std::fs::write(&bus, "[master]\naddress = 2\nbaud = \"1.5M\"\n").unwrap();
    let slave = ["slave", "--addr", "8", "--device", "omega"];
    let master = ["master", "--config", bus.to_str().unwrap()];
    let scan = ["scan"];
    for args in [&slave[..], &master, &scan] {
        let out = Command::new(dpctl())
            .args(args)
            .args(["--rts", "on-send", "--port"])
            .arg(&a)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(
            err.contains("--rts on-send needs an RTS line") && err.contains("leave --rts off"),
            "{args:?}: {err}"
        );
    }
    // A bad value is a usage error that lists the values.
    let out = Command::new(dpctl())
        .args(["scan", "--rts", "always", "--port"])
        .arg(&a)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("off") && err.contains("on-send"), "{err}");
}

#[test]
fn rts_on_send_through_a_serial_device_server_is_refused_clearly() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = format!("tcp://{}", listener.local_addr().unwrap());
    let out = Command::new(dpctl())
        .args(["doctor", "--json", "--rts", "on-send", "--port", &port])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["kind"]["type"], "tcp");
    rts_check_fails(&v, "drives its transceiver itself");
    let out = Command::new(dpctl())
        .args(["scan", "--rts", "on-send", "--port", &port])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("--rts on-send needs an RTS line"), "{err}");
}
