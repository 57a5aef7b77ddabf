//! `dpctl doctor` on a socat pty: it says what it could not check there,
//! and fails on a port that does not exist.

mod common;

use common::*;
use std::process::Command;

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
