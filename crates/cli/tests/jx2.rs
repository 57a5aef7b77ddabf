//! The Jetter JX2-PROFI1 end to end: `dpctl slave --device jx2` on one end
//! of a socat pty pair, played by register scripts (`--script`), stdin
//! and the control socket; `dpctl master` and `dpctl dpv1` on the other
//! end; pyprofibus as an independent master. The manual's examples with
//! its register numbers (module 2: 12100…).
//!
//! Needs socat and `.venv` with pyprofibus (scripts/setup-test-env); the
//! tests fail when they are missing.

mod common;

use common::*;
use serde_json::Value;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

/// Extra slot time for pty latency on a busy machine.
const LATENCY: &str = "50";

struct Jx2 {
    dir: TempDir,
    master_port: PathBuf,
    _socat: Proc,
    slave: Proc,
    rx: Receiver<String>,
    /// Every stdout line so far.
    lines: Vec<String>,
    /// Lines before this index were matched already.
    cursor: usize,
}

fn gsd() -> String {
    repo()
        .join("crates/devices/gsd/JX2P0DC3.GSD")
        .display()
        .to_string()
}

/// `dpctl slave --device jx2 --json` with a script (may be empty) and a
/// control socket; stdin piped.
fn start(tag: &str, script: &str) -> Jx2 {
    let dir = TempDir::new(tag);
    let (a, b) = (dir.path("master"), dir.path("slave"));
    let socat = pty_pair(&a, &b);
    let plc = dir.path("plc.txt");
    std::fs::write(&plc, script).unwrap();
    let mut cmd = Command::new(dpctl());
    cmd.args(["slave", "--device", "jx2", "--json", "--port"])
        .arg(&b)
        .arg("--script")
        .arg(&plc)
        .arg("--control")
        .arg(dir.path("ctl"))
        .current_dir(&dir.0)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    let mut slave = Proc::spawn("dpctl slave --device jx2", &mut cmd);
    let out = slave.child.as_mut().unwrap().stdout.take().unwrap();
    let (tx, rx) = channel();
    std::thread::spawn(move || {
        for l in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(l).is_err() {
                break;
            }
        }
    });
    let mut j = Jx2 {
        dir,
        master_port: a,
        _socat: socat,
        slave,
        rx,
        lines: vec![],
        cursor: 0,
    };
    j.expect("start", |v| v["event"] == "start", 10);
    j
}

impl Jx2 {
    /// The next stdout JSON line (after the last match) for which `pred`
    /// holds, within `secs`.
    fn expect(&mut self, what: &str, pred: impl Fn(&Value) -> bool, secs: u64) -> Value {
        let end = Instant::now() + Duration::from_secs(secs);
        loop {
            while self.cursor < self.lines.len() {
                let i = self.cursor;
                self.cursor += 1;
                if let Ok(v) = serde_json::from_str::<Value>(&self.lines[i]) {
                    if pred(&v) {
                        return v;
                    }
                }
            }
            match self
                .rx
                .recv_timeout(end.saturating_duration_since(Instant::now()))
            {
                Ok(l) => self.lines.push(l),
                Err(_) => panic!("no {what} within {secs} s; stdout: {:#?}", self.lines),
            }
        }
    }

    /// Send a register command on stdin; its reply.
    fn cmd(&mut self, line: &str) -> Value {
        let stdin = self.slave.child.as_mut().unwrap().stdin.as_mut().unwrap();
        writeln!(stdin, "{line}").unwrap();
        stdin.flush().unwrap();
        self.expect(line, |v| v["src"] == "stdin", 30)
    }

    fn bus(&self, modules: &[&str], gsd_path: &str) -> PathBuf {
        let p = self.dir.path(&format!("bus{}.toml", self.cursor));
        let list: Vec<String> = modules.iter().map(|m| format!("{m:?}")).collect();
        std::fs::write(
            &p,
            format!(
                "[master]\naddress = 1\nbaud = \"1.5M\"\n[[slave]]\naddress = 3\ngsd = {gsd_path:?}\n\
                 modules = [{}]\nwatchdog_ms = 2000\n",
                list.join(", ")
            ),
        )
        .unwrap();
        p
    }

    /// `dpctl dpv1 … --json ARGS`: success and the JSON line.
    fn dpv1(&self, bus: &Path, args: &[&str]) -> (bool, Value, String) {
        let out = Command::new(dpctl())
            .args(["dpv1", "--port"])
            .arg(&self.master_port)
            .arg("--config")
            .arg(bus)
            .args(["--slave", "3", "--latency", LATENCY, "--json"])
            .args(args)
            .output()
            .unwrap();
        let v = String::from_utf8_lossy(&out.stdout)
            .lines()
            .find_map(|l| serde_json::from_str(l).ok())
            .unwrap_or(Value::Null);
        (
            out.status.success(),
            v,
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    }

    /// `dpctl master --json` in the background, with commands from a file
    /// (or from its stdin with `Some("-")`).
    fn master(&self, bus: &Path, input: Option<&str>) -> (Proc, Receiver<String>) {
        let mut cmd = Command::new(dpctl());
        cmd.args([
            "master",
            "--json",
            "--interval",
            "100",
            "--latency",
            LATENCY,
        ])
        .arg("--port")
        .arg(&self.master_port)
        .arg("--config")
        .arg(bus)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
        if input == Some("-") {
            cmd.args(["--input", "-"]).stdin(Stdio::piped());
        } else if let Some(text) = input {
            let f = self.dir.path("master-input.jsonl");
            std::fs::write(&f, text).unwrap();
            cmd.arg("--input").arg(f);
        }
        let mut p = Proc::spawn("dpctl master", &mut cmd);
        let out = p.child.as_mut().unwrap().stdout.take().unwrap();
        let (tx, rx) = channel();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(l).is_err() {
                    break;
                }
            }
        });
        (p, rx)
    }
}

/// The first master line for which `pred` holds, within `secs`.
fn master_line(rx: &Receiver<String>, secs: u64, pred: impl Fn(&Value) -> bool) -> Value {
    let end = Instant::now() + Duration::from_secs(secs);
    let mut seen = vec![];
    while let Ok(l) = rx.recv_timeout(end.saturating_duration_since(Instant::now())) {
        if let Ok(v) = serde_json::from_str::<Value>(&l) {
            if pred(&v) {
                return v;
            }
        }
        seen.push(l);
    }
    panic!("master did not print the line within {secs} s: {seen:#?}");
}

/// Example 2's configuration (L1580-1600) and its data-record task
/// (tAzyklDienste, L1761-1848) as register lines.
const EXAMPLE_2: &str = "\
; tInit
wait-bit 12100 13 clear 5s
write 12101 5
wait-bit 12100 13 clear 5s
write 12101 6
write 12112 300
write 12113 400
write 12102 4
write 12103 4
write 12116 600
write 12117 800
write 12114 120
write 12115 120
write 12107 3
wait-bit 12100 13 clear 5s
write 12300 0x0102 0x0304 0x0506 0x0708
write 600 0x1122 0x3344 0x5566
; tAzyklDienste
label ds
wait-bit 12100 4,5 set 60s
if-bit 12100 4 set goto read
if-bit 12100 5 set goto write
goto ds
label read
calc 100 r12118 + 1
calc 100 r100 / 2
copy r100 600 12600
write 12101 11
goto ds
label write
if r12123 != 5 goto refuse
calc 100 r12119 + 1
calc 100 r100 / 2
copy r100 12800 800
write 12101 13
goto ds
label refuse
write 12101 14
goto ds
";

/// `dpctl dpv1 --config` takes a bus file whose slave is a device
/// profile (`device = "jx2"`, its default 4/4 words), as `master`, `pkw`
/// and `rfid` do; it used to refuse it ("need a loader with the device
/// registry").
#[test]
fn dpv1_takes_a_bus_file_with_a_device_profile() {
    let mut j = start("jx2-device-bus", EXAMPLE_2);
    j.expect(
        "the address write",
        |v| v["src"] == "script" && v["reg"] == 12107 && v["ok"] == true,
        20,
    );
    let bus = j.dir.path("device.toml");
    std::fs::write(
        &bus,
        "[master]\naddress = 1\nbaud = \"1.5M\"\n[[slave]]\naddress = 3\ndevice = \"jx2\"\n\
         watchdog_ms = 2000\n",
    )
    .unwrap();
    let (ok, v, err) = j.dpv1(
        &bus,
        &["--slot", "1", "--index", "2", "read", "--length", "5"],
    );
    assert!(ok, "{err} {v}");
    assert_eq!(v["data"], "11 22 33 44 55");
}

#[test]
fn example_2_data_records_and_diagnosis_kinds() {
    let mut j = start("jx2-ex2", EXAMPLE_2);
    j.expect(
        "the address write",
        |v| v["src"] == "script" && v["reg"] == 12107 && v["ok"] == true,
        20,
    );
    let bus = j.bus(&["INPUT : 4 words", "OUTPUT : 4 words"], &gsd());

    // DS-read: the PLC copies (12118 + 1) / 2 words from R600.
    let (ok, v, err) = j.dpv1(
        &bus,
        &["--slot", "1", "--index", "2", "read", "--length", "5"],
    );
    assert!(ok, "{err} {v}");
    assert_eq!(v["data"], "11 22 33 44 55");
    let r = j.cmd("read 12120 3");
    assert_eq!(r["values"], serde_json::json!([1, 0, 2]), "slot and index");
    // DS-write to index 5: accepted, lands in R800.
    let (ok, v, err) = j.dpv1(&bus, &["--index", "5", "write", "AA BB CC"]);
    assert!(ok, "{err} {v}");
    let r = j.cmd("read 800 2");
    assert_eq!(r["values"], serde_json::json!([0xAABB, 0xCC00]));
    // Index 6: command 14, the master decodes the negative answer.
    let (ok, v, err) = j.dpv1(&bus, &["--index", "6", "write", "01 02"]);
    assert!(!ok);
    assert_eq!(v["error_code_1"], "0xA1", "{v}");
    assert!(err.contains("application: write error"), "{err}");
    // Longer than the 240-byte area? The area holds 240: 241 bytes cannot
    // be asked for; a write of 4 bytes to a 4-register area is fine.

    // Diagnosis kinds while a master runs.
    let (mut master, rx) = j.master(&bus, Some("-"));
    master_line(&rx, 20, |v| {
        v["event"] == "state" && v["to"] == "data_exchange"
    });
    // The master's command input: a record job, its refusal in words.
    {
        let stdin = master.child.as_mut().unwrap().stdin.as_mut().unwrap();
        writeln!(
            stdin,
            r#"{{"dpv1_write": 3, "slot": 0, "index": 7, "data": "01 02"}}"#
        )
        .unwrap();
        stdin.flush().unwrap();
    }
    let job = master_line(&rx, 20, |v| v["event"] == "job");
    assert!(
        job["result"]
            .as_str()
            .is_some_and(|r| r.contains("application: write error")),
        "{job}"
    );
    let r = j.cmd("if r12139 != 0 write 12101 10");
    assert!(r["ok"] == true, "{r}");
    for l in ["write 12140 14", "write 12146 1", "write 12147 65535"] {
        assert_eq!(j.cmd(l)["ok"], true, "{l}");
    }
    assert_eq!(j.cmd("write 12101 8")["ok"], true);
    let d = master_line(&rx, 20, |v| {
        v["event"] == "diag"
            && v["raw"]
                .as_str()
                .is_some_and(|r| r.ends_with("08 81 00 00 01 00 FF FF"))
    });
    assert!(
        d["raw"].as_str().unwrap().starts_with("08 "),
        "Ext_Diag: {d}"
    );
    assert_eq!(j.cmd("wait r12139 == 0 10s")["ok"], true, "fetched");
    // Static diagnosis: bytes FF 00, Stat_Diag; then back with a status
    // diagnosis.
    for l in ["write 12140 12", "write 12146 255", "write 12101 9"] {
        assert_eq!(j.cmd(l)["ok"], true, "{l}");
    }
    master_line(&rx, 20, |v| {
        v["event"] == "diag"
            && v["raw"]
                .as_str()
                .is_some_and(|r| r.ends_with("06 81 00 00 FF 00"))
            && v["words"].to_string().contains("Stat_Diag")
    });
    assert_eq!(j.cmd("wait r12139 == 0 10s")["ok"], true);
    for l in ["write 12140 10", "write 12101 7"] {
        assert_eq!(j.cmd(l)["ok"], true, "{l}");
    }
    master_line(&rx, 20, |v| {
        v["event"] == "diag"
            && v["raw"]
                .as_str()
                .is_some_and(|r| r.ends_with("04 81 00 00"))
            && !v["words"].to_string().contains("Stat_Diag")
    });
    // The inputs the PLC wrote reach the master.
    master_line(&rx, 20, |v| {
        v["event"] == "status" && v["slaves"][0]["inputs"] == "01 02 03 04 05 06 07 08"
    });
    master.signal(15);
    master.wait(Duration::from_secs(10));

    // The control socket takes the same commands.
    let mut s = std::os::unix::net::UnixStream::connect(j.dir.path("ctl")).unwrap();
    writeln!(s, "read 12199").unwrap();
    let mut reply = String::new();
    BufReader::new(&s).read_line(&mut reply).unwrap();
    let v: Value = serde_json::from_str(&reply).unwrap();
    assert_eq!(v["value"], 103, "{reply}");
    drop(s);
    let st = j.slave.terminate(Duration::from_secs(10));
    assert!(st.success(), "{st}");
    assert!(!j.dir.path("ctl").exists(), "the control socket is removed");
}

/// The consistent-input example (L1271: 16 words, 4 consistent at word 8)
/// and the consistent-output example (L1327: 12 words, 8 consistent at
/// word 4) on one module, with the GSD modules that configure them.
#[test]
fn consistent_windows_of_the_manual() {
    let mut j = start(
        "jx2-consistent",
        "write 12102 16\nwrite 12112 300\nwrite 12126 500\nwrite 12124 4\nwrite 12128 8\n\
         write 12103 12\nwrite 12113 400\nwrite 12127 600\nwrite 12125 8\nwrite 12129 4\n\
         write 12107 3\nwait-bit 12100 3 set 60s\n\
         write 1000 0x1111 0x2222 0x3333 0x4444\n\
         copy 4 1000 12500\nwrite 12101 15\nwait-bit 12100 8 set 30s\n\
         write 12101 16\nwait-bit 12100 9 set 30s\ncopy 8 12600 1100\nread 1100 8\n",
    );
    let bus = j.bus(
        &[
            "INPUT : 8 words",
            "INPUT (consistent) : 4 words",
            "INPUT : 4 words",
            "OUTPUT : 4 words",
            "OUTPUT (consistent) : 8 words",
        ],
        &gsd(),
    );
    let outputs: Vec<String> = (0..24).map(|b| format!("{b:02X}")).collect();
    let (mut master, rx) = j.master(
        &bus,
        Some(&format!(
            "{{\"slave\": 3, \"outputs\": \"{}\"}}\n",
            outputs.join(" ")
        )),
    );
    let read = j.expect(
        "the consistent outputs",
        |v| v["src"] == "script" && v["cmd"] == "read",
        60,
    );
    let words: Vec<i64> = (4..12).map(|i| (2 * i) << 8 | (2 * i + 1)).collect();
    assert_eq!(read["values"], serde_json::json!(words));
    master_line(&rx, 20, |v| {
        v["event"] == "status"
            && v["slaves"][0]["inputs"]
                .as_str()
                .is_some_and(|s| s.get(16 * 3..24 * 3 - 1) == Some("11 11 22 22 33 33 44 44"))
    });
    master.signal(15);
    master.wait(Duration::from_secs(10));
}

/// Every error number through the register interface (1, 2, 3, 6, 9, 10,
/// 11, 12) or the bus (7: wrong ident number, 8: wrong modules).
#[test]
fn error_numbers_through_registers_and_bus() {
    let mut j = start("jx2-errors", "");
    let err = |v: &Value| v["error"].as_u64();
    let reset = |j: &mut Jx2| {
        j.cmd("write 12101 5");
        j.cmd("wait-bit 12100 13 clear 5s");
        j.cmd("write 12101 6");
    };
    assert_eq!(
        j.cmd("read 12133")["value"],
        8,
        "19.2 kbit/s, nominal on a pty"
    );
    assert_eq!(err(&j.cmd("write 12107 127")), Some(1));
    reset(&mut j);
    assert_eq!(err(&j.cmd("write 12102 123")), Some(2));
    reset(&mut j);
    assert_eq!(err(&j.cmd("write 12116 302")), Some(3));
    reset(&mut j);
    for l in [
        "write 12113 500",
        "write 12116 700",
        "write 12117 800",
        "write 12102 104",
        "write 12103 104",
        "write 12114 12",
    ] {
        assert_eq!(j.cmd(l)["ok"], true, "{l}");
    }
    assert_eq!(err(&j.cmd("write 12107 3")), Some(6));
    assert_eq!(j.cmd("read 12136")["value"], 49);
    reset(&mut j);
    assert_eq!(err(&j.cmd("write 12140 40")), Some(9));
    reset(&mut j);
    assert_eq!(err(&j.cmd("write 12124 5")), Some(12));
    reset(&mut j);
    assert_eq!(j.cmd("fail-memory-test")["ok"], true);
    assert_eq!(err(&j.cmd("write 12101 5")), Some(11));
    j.cmd("wait-bit 12100 13 clear 5s");
    j.cmd("write 12101 6");
    // On the bus: station 3, 4/4 words.
    assert_eq!(j.cmd("write 12107 3")["ok"], true);
    assert_eq!(j.cmd("wait-bit 12100 2 set 5s")["ok"], true);
    assert_eq!(err(&j.cmd("write 12107 4")), Some(1), "already set");
    j.cmd("write 12101 6");
    assert_eq!(j.cmd("write 12101 7")["ok"], true);
    assert_eq!(
        err(&j.cmd("write 12101 7")),
        Some(10),
        "not fetched: no master"
    );
    j.cmd("write 12101 10");
    j.cmd("write 12101 6");
    // Error 8: the master configures 8 input words.
    let bus = j.bus(&["INPUT : 8 words", "OUTPUT : 4 words"], &gsd());
    let (mut m, rx) = j.master(&bus, None);
    master_line(&rx, 20, |v| {
        v["event"] == "diag" && v["words"].to_string().contains("Cfg_Fault")
    });
    m.signal(15);
    m.wait(Duration::from_secs(10));
    assert_eq!(j.cmd("read 12134")["value"], 8);
    j.cmd("write 12101 6");
    // Error 7: a GSD with another ident number.
    let other = j.dir.path("OTHER.GSD");
    let text = std::fs::read(gsd()).unwrap();
    let text = String::from_utf8_lossy(&text).replace("Ident_Number=0x0DC3", "Ident_Number=0x0DC4");
    std::fs::write(&other, text).unwrap();
    let bus = j.bus(
        &["INPUT : 4 words", "OUTPUT : 4 words"],
        &other.display().to_string(),
    );
    let (mut m, rx) = j.master(&bus, None);
    master_line(&rx, 20, |v| {
        v["event"] == "diag" && v["words"].to_string().contains("Prm_Fault")
    });
    m.signal(15);
    m.wait(Duration::from_secs(10));
    assert_eq!(j.cmd("read 12134")["value"], 7);
}

#[test]
fn pyprofibus_reaches_data_exchange_with_the_basic_program() {
    let py = python();
    // Example 1 (L1499), 4 input and 4 output words so that the modules
    // fit pyprofibus's defaults; the PLC echoes output word 0 into input
    // word 1.
    let mut j = start(
        "jx2-py",
        "wait-bit 12100 13 clear 5s\nwrite 12102 4\nwrite 12103 4\nwrite 12107 4\n\
         wait-bit 12100 13 clear 5s\nwrite 12300 0x4A58\n\
         wait-bit 12100 3 set 60s\nwait r12400 == 0x0102 60s\ncopy 1 12400 12301\n",
    );
    let mut cmd = Command::new(py);
    cmd.arg(repo().join("tests/interop/pyprofibus_jx2.py"))
        .arg("--port")
        .arg(&j.master_port)
        .arg("--gsd")
        .arg(gsd())
        .args(["--addr", "4"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    let mut p = Proc::spawn("pyprofibus", &mut cmd);
    let st = p.wait(Duration::from_secs(120));
    assert!(st.success(), "pyprofibus: {st}");
    let copy = j.expect(
        "the PLC's copy",
        |v| v["src"] == "script" && v["cmd"] == "copy",
        10,
    );
    assert_eq!(copy["ok"], true);
    let r = j.cmd("read 12400");
    assert_eq!(r["value"], 0x0102);
}
