//! `dpctl master` against what the field brings (issue 26): a slave whose
//! Slave_Diag leaves the always-1 bit clear (an independent raw slave in
//! Python, tests/interop/raw_dp_slave.py), a slave configured otherwise
//! than the bus file (Cfg_Fault: back-off, one line per change, the
//! configurations side by side), and `--exchanges` with a slave nobody
//! answers for (a deadline, by default 60 s).

mod common;

use common::{
    dpctl, generic_slave, json_lines, pty_pair, repo, require, run_dpctl, slave_of, Bus, Lines,
    Proc, TempDir,
};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const WAIT: Duration = Duration::from_secs(60);

fn write_bus(dir: &TempDir, baud: &str, slaves: &[(u8, &str)]) -> std::path::PathBuf {
    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let mut t = format!("[master]\naddress = 2\nbaud = \"{baud}\"\n");
    for (a, m) in slaves {
        t.push_str(&format!(
            "[[slave]]\naddress = {a}\ngsd = \"{}\"\nmodules = [\"{m}\"]\nwatchdog_ms = 5000\n",
            gsd.display()
        ));
    }
    let p = dir.path("bus.toml");
    std::fs::write(&p, t).unwrap();
    p
}

/// The raw Python slave at address 8 of DPCTL_GEN.GSD with "2 words
/// in/out" (0x71), on `port`; returns once its port is open.
fn raw_slave(port: &Path) -> (Proc, Lines) {
    require("python3");
    let mut p = Proc::spawn(
        "raw_dp_slave.py",
        Command::new("python3")
            .arg(repo().join("tests/interop/raw_dp_slave.py"))
            .arg("--port")
            .arg(port)
            .args(["--addr", "8", "--ident", "0x0DCE", "--cfg", "71"])
            .args(["--inputs", "4"])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit()),
    );
    let mut lines = Lines::from(&mut p);
    assert!(
        lines.wait_for("ready", Duration::from_secs(20)),
        "raw_dp_slave.py did not start: {:?}",
        lines.1
    );
    (p, lines)
}

#[test]
fn a_slave_whose_diagnosis_lacks_the_always_one_bit_reaches_data_exchange() {
    let dir = TempDir::new("always-one");
    let (a, b) = (dir.path("master"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    let (_slave, mut slave_out) = raw_slave(&b);
    let cfg = write_bus(&dir, "19.2k", &[(8, "2 words in/out")]);
    let o = run_dpctl(&[
        "master",
        "--port",
        a.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
        "--exchanges",
        "20",
        "--json",
        // Python on a loaded machine: allow for its scheduling.
        "--latency",
        "200",
    ]);
    assert!(o.status.success(), "dpctl master failed: {}", o.stderr);
    assert!(slave_out.wait_for("data_exchange", Duration::from_secs(5)));
    let lines = json_lines(o.stdout.lines());
    let status = lines
        .iter()
        .rev()
        .find(|v| v["event"] == "status")
        .expect("a status line");
    let s = slave_of(status, 8);
    assert_eq!(s["state"], "data_exchange", "{s}");
    assert!(s["data_exchanges"].as_u64().unwrap() >= 20, "{s}");
    assert!(s["always_one_clear"].as_u64().unwrap() >= 2, "{s}");
    assert_eq!(s["invalid_diags"], 0, "{s}");
    // The diagnosis in words says what is missing.
    let diag = lines
        .iter()
        .find(|v| v["event"] == "diag")
        .expect("a diag line");
    assert!(
        diag["words"][0]
            .as_str()
            .unwrap()
            .contains("always-1 bit (Station_Status_2 bit 2) clear"),
        "{diag}"
    );
}

#[test]
fn cfg_fault_backs_off_reports_once_and_shows_both_configurations() {
    let dir = TempDir::new("cfg-mismatch");
    let bus = Bus::start(2, &[]);
    let _slave = Proc::spawn(
        "dpctl slave 10",
        generic_slave(bus.link(1), 10, "1.5M", &["4 words out consistent"]).stderr(Stdio::null()),
    );
    let cfg = write_bus(&dir, "1.5M", &[(10, "2 words in/out")]);
    let mut m = Proc::spawn(
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
    let mut out = Lines::from(&mut m);
    assert!(
        out.wait_for(r#""event":"cfg_mismatch""#, WAIT),
        "no cfg_mismatch: {:#?}",
        out.1
    );
    // Wait until the start-up has failed a few times more (status lines
    // count them), then count the lines about slave 10.
    let end = Instant::now() + WAIT;
    loop {
        let failed = json_lines(&out.1)
            .iter()
            .filter(|v| v["event"] == "status")
            .filter_map(|v| slave_of(v, 10)["failed_startups"].as_u64())
            .max()
            .unwrap_or(0);
        if failed >= 6 {
            break;
        }
        assert!(Instant::now() < end, "start-up retried {failed} times");
        out.next_line(Duration::from_secs(1));
    }
    m.terminate(Duration::from_secs(5));
    let events = json_lines(&out.1);
    let about = |kind: &str| {
        events
            .iter()
            .filter(|v| v["event"] == kind && v["slave"] == 10)
            .cloned()
            .collect::<Vec<Value>>()
    };
    assert_eq!(about("fault").len(), 1, "{:#?}", about("fault"));
    assert!(about("state").len() <= 4, "{:#?}", about("state"));
    let mismatch = about("cfg_mismatch");
    assert_eq!(mismatch.len(), 1, "{mismatch:#?}");
    let v = &mismatch[0];
    assert_eq!(v["configured"][0]["bytes"], "71", "{v}");
    assert_eq!(v["configured"][0]["meaning"], "2 words in+out", "{v}");
    assert_eq!(v["configured"][0]["module"], "2 words in/out", "{v}");
    assert_eq!(v["actual"][0]["bytes"], "E3", "{v}");
    assert_eq!(v["actual"][0]["meaning"], "4 words (consistent) out", "{v}");
    assert_eq!(v["actual"][0]["module"], "4 words out consistent", "{v}");
    assert_eq!(v["configured"].as_array().unwrap().len(), 1, "{v}");
    assert_eq!(v["actual"].as_array().unwrap().len(), 1, "{v}");
    drop(bus);
}

/// `s` without ANSI escape sequences (log lines may be coloured).
fn plain(s: &str) -> String {
    let mut out = String::new();
    let mut esc = false;
    for c in s.chars() {
        match (esc, c) {
            (false, '\u{1b}') => esc = true,
            (true, c) if c.is_ascii_alphabetic() => esc = false,
            (true, _) => {}
            (false, c) => out.push(c),
        }
    }
    out
}

#[test]
fn exchanges_without_timeout_wait_at_most_the_default() {
    // Slave 9 never answers. Without --timeout the deadline is the
    // default, which the master logs at start (the 60 s themselves are
    // not waited for here).
    let dir = TempDir::new("exchanges-default");
    let bus = Bus::start(2, &[]); // station 1: nobody
    let cfg = write_bus(&dir, "1.5M", &[(9, "2 words in/out")]);
    let mut cmd = Command::new(dpctl());
    cmd.args(["master", "--json", "--exchanges", "5", "--port"])
        .arg(bus.link(0))
        .arg("--config")
        .arg(&cfg)
        .env("DPCTL_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    let mut m = Proc::spawn_captured(cmd);
    let end = Instant::now() + WAIT;
    let line = loop {
        let l = m
            .stderr_line(end.saturating_duration_since(Instant::now()))
            .expect("a log line naming the deadline");
        let l = plain(&l);
        if l.contains("waiting for Data_Exchange at most") {
            break l;
        }
    };
    assert!(line.contains("timeout_s=60"), "{line}");
    m.terminate(Duration::from_secs(5));
}

#[test]
fn exchanges_with_a_silent_slave_time_out_naming_it() {
    let dir = TempDir::new("exchanges-timeout");
    let bus = Bus::start(2, &[]); // station 1: nobody
    let cfg = write_bus(&dir, "1.5M", &[(9, "2 words in/out")]);
    let started = Instant::now();
    let o = run_dpctl(&[
        "master",
        "--port",
        &bus.link_str(0),
        "--config",
        cfg.to_str().unwrap(),
        "--exchanges",
        "5",
        "--timeout",
        "2",
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", o.stderr);
    assert!(started.elapsed() < WAIT);
    let err = o.stderr.trim_end();
    assert!(
        err.contains("not every slave reached 5 Data_Exchange cycles")
            && err.contains("slave 9 (offline, 0 exchanges)"),
        "{err}"
    );
}
