//! `dpctl report` end to end: a capture of a `dpctl bus` segment (master
//! 2, the echo slave at 3, an Omega drive at 25 killed and started
//! again) made by `dpctl sniff --pcap`, turned into a report, and the
//! page opened in headless Chromium: it renders, its plots carry data,
//! the restart is on the timeline. The screenshot and the page are kept
//! in `target/test-artifacts/report/` (`report.png`, `report.html`,
//! `capture.pcapng`).

mod common;

use common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BUS: &str = include_str!("data/monitor_bus.toml");

fn omega(line: &Bus) -> Proc {
    Proc::spawn(
        "dpctl slave (omega)",
        Command::new(dpctl())
            .args(["slave", "--device", "omega", "--addr", "25"])
            .args(["--device-opt", "drive-enable=auto"])
            .args(["--baud", "1.5M", "--port"])
            .arg(line.link(2))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .stdin(Stdio::null()),
    )
}

/// Read the sniffer's JSON lines until one satisfies `ok`.
fn wait_sniffed(sniff: &Proc, what: &str, ok: impl Fn(&Value) -> bool) {
    let end = Instant::now() + Duration::from_secs(60);
    loop {
        let left = end.saturating_duration_since(Instant::now());
        let l = sniff
            .stdout_line(left)
            .unwrap_or_else(|| panic!("dpctl sniff never showed {what}"));
        if serde_json::from_str::<Value>(&l).is_ok_and(|v| ok(&v)) {
            return;
        }
    }
}

fn dp(v: &Value, service: &str, direction: &str, station: (&str, u8)) -> bool {
    v["dp"]["service"] == service && v["dp"]["direction"] == direction && v[station.0] == station.1
}

/// Where the test keeps what a person may want to look at.
fn artifacts() -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .expect("target dir")
        .join("test-artifacts/report");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Headless Chromium from Debian's `chromium` package.
fn chromium() -> PathBuf {
    for c in ["chromium", "chromium-browser"] {
        let found = std::env::var_os("PATH").and_then(|p| {
            std::env::split_paths(&p)
                .map(|d| d.join(c))
                .find(|p| p.is_file())
        });
        if let Some(p) = found {
            return p;
        }
    }
    need("`chromium` (the headless browser of the report test)")
}

fn browser(profile: &Path, args: &[&str], page: &Path) -> String {
    let out = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
        ])
        .args(["--disable-dev-shm-usage", "--hide-scrollbars"])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .arg(format!("file://{}", page.display()))
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "chromium failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn report_of_a_capture_with_a_restart_opens_in_a_browser() {
    // Fail early, before the bus runs, when the browser is missing.
    chromium();
    let line = Bus::start(4, &[]);
    let dir = TempDir::new("report");
    std::fs::copy(
        repo().join("crates/devices/gsd/DPCTL_GEN.GSD"),
        dir.path("DPCTL_GEN.GSD"),
    )
    .unwrap();
    let bus = dir.path("bus.toml");
    std::fs::write(&bus, BUS).unwrap();
    let capture = dir.path("soak.pcapng");
    let mut cmd = Command::new(dpctl());
    cmd.args(["sniff", "--json", "--port", &line.link_str(3), "--pcap"])
        .arg(&capture);
    let sniff = Proc::spawn_captured(cmd);
    line.wait_connected(1);
    let _echo = Proc::spawn(
        "dpctl slave (generic)",
        generic_slave(line.link(1), 3, "1.5M", &["1 byte in", "2 words in/out"])
            .stderr(Stdio::null()),
    );
    let mut drive = omega(&line);
    let _master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--latency", "100", "--port"])
            .arg(line.link(0))
            .arg("--config")
            .arg(&bus)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .stdin(Stdio::null()),
    );
    let dx = |v: &Value| dp(v, "Data_Exchange", "response", ("sa", 25));
    wait_sniffed(&sniff, "a Data_Exchange answer of slave 25", dx);
    // Kill the drive: the master takes it back to Slave_Diag polling.
    drive.terminate(Duration::from_secs(10));
    wait_sniffed(&sniff, "Slave_Diag to the dead slave 25", |v| {
        dp(v, "Slave_Diag", "request", ("da", 25))
    });
    let _drive = omega(&line);
    wait_sniffed(&sniff, "Set_Prm to slave 25 again", |v| {
        dp(v, "Set_Prm", "request", ("da", 25))
    });
    wait_sniffed(&sniff, "slave 25 back in Data_Exchange", dx);
    // A hundred telegrams more, so that the capture has more than 100
    // however slowly a loaded machine ran the restart.
    for n in 0..100 {
        wait_sniffed(&sniff, &format!("telegram {n} after the restart"), |v| {
            v["t_us"].is_u64() && v["event"].is_null()
        });
    }
    let out = sniff.stop();
    assert!(out.status.success(), "{out:?}");

    // The JSON report.
    let out = run_ok(
        Command::new(dpctl())
            .arg("report")
            .arg(&capture)
            .arg("--config")
            .arg(&bus)
            .arg("--json"),
    );
    let r: Value = serde_json::from_slice(&out.stdout).unwrap();
    let seg = &r["segment"];
    assert_eq!(seg["masters"], serde_json::json!([2]), "{seg}");
    assert_eq!(seg["baud"], 1_500_000, "{seg}");
    assert!(seg["telegrams"].as_u64().unwrap() > 100, "{seg}");
    assert!(seg["restarts"].as_u64().unwrap() >= 1, "{seg}");
    let st = |a: u8| {
        r["stations"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["address"] == a)
            .unwrap_or_else(|| panic!("station {a} missing: {}", r["stations"]))
            .clone()
    };
    let drive = st(25);
    assert_eq!(drive["role"], "slave");
    assert_eq!(drive["state"], "data_exchange", "{drive}");
    assert!(drive["restarts"].as_u64().unwrap() >= 1, "{drive}");
    assert!(drive["no_answer"].as_u64().unwrap() >= 1, "{drive}");
    assert!(drive["health"].as_u64().unwrap() < 100, "{drive}");
    assert!(
        drive["response_us"]["count"].as_u64().unwrap() > 0,
        "{drive}"
    );
    assert_eq!(st(3)["restarts"], 0);
    assert_eq!(st(2)["role"], "master");
    let restart = r["timeline"]
        .as_array()
        .unwrap()
        .iter()
        .any(|m| m["kind"] == "restart" && m["address"] == 25);
    assert!(restart, "no restart on the timeline: {}", r["timeline"]);
    assert!(r["cycle_histogram"]["samples"].as_u64().unwrap() > 10);
    assert!(r["response_histogram"]["samples"].as_u64().unwrap() > 10);
    assert!(!r["rotation"][0]["points"].as_array().unwrap().is_empty());
    let diag = r["diagnoses"].as_array().unwrap();
    assert!(
        diag.iter().any(|d| d["address"] == 25
            && d["lines"][0]
                .as_str()
                .unwrap()
                .starts_with("station status")),
        "{diag:?}"
    );

    // The page, in a real browser.
    let keep = artifacts();
    std::fs::copy(&capture, keep.join("capture.pcapng")).unwrap();
    let page = keep.join("report.html");
    let out = run_ok(
        Command::new(dpctl())
            .arg("report")
            .arg(&capture)
            .arg("--config")
            .arg(&bus)
            .arg("-o")
            .arg(&page),
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("report.html"));
    let profile = dir.path("chromium");
    let dom = browser(&profile, &["--dump-dom"], &page);
    assert!(dom.contains("PROFIBUS report"), "{dom}");
    for plot in ["cycle-time", "response-time", "timeline", "token-rotation"] {
        let at = dom
            .find(&format!("data-plot=\"{plot}\""))
            .unwrap_or_else(|| panic!("plot {plot} missing"));
        let points: u64 = dom[at..]
            .split("data-points=\"")
            .nth(1)
            .and_then(|s| s.split('"').next())
            .and_then(|n| n.parse().ok())
            .unwrap();
        assert!(points > 0, "plot {plot} has no data");
    }
    assert!(dom.contains("class=\"mark restart\""), "no restart mark");
    assert!(dom.contains("slave 25 restarts"));
    let shot = keep.join("report.png");
    let _ = std::fs::remove_file(&shot);
    browser(
        &profile,
        &[
            &format!("--screenshot={}", shot.display()),
            "--window-size=1200,2400",
        ],
        &page,
    );
    let png = std::fs::read(&shot).unwrap_or_else(|e| panic!("no screenshot: {e}"));
    assert!(
        png.starts_with(b"\x89PNG") && png.len() > 20_000,
        "{} bytes",
        png.len()
    );
}

#[test]
fn report_refuses_what_is_no_capture() {
    let dir = TempDir::new("report-bad");
    let f = dir.path("x.pcapng");
    std::fs::write(&f, b"hello, this is no capture file").unwrap();
    let out = Command::new(dpctl())
        .arg("report")
        .arg(&f)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("x.pcapng") && err.contains("magic"), "{err}");
    assert!(!dir.path("x.html").exists());
}
