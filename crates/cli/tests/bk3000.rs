//! The Beckhoff BK3000 profile end to end: `dpctl slave --device bk3000`
//! with a mixed terminal strip on one end of a socat pty pair, and on the
//! other `dpctl master` with a `device = "bk3000"` bus file (named
//! channels both ways, a wrong configuration, a pulled terminal) or
//! pyprofibus with `crates/devices/gsd/BK30BECF.GSD`; and the BK3000 of `dpctl demo`.
//!
//! Needs socat and `.venv` with pyprofibus (scripts/setup-test-env); the
//! tests fail when they are missing.

mod common;

use common::*;
use serde_json::Value;
use std::io::Write;
use std::path::PathBuf;
use std::process::{ChildStdin, Command, Stdio};
use std::time::Duration;

const STRIP: &str = "KL1104,KL2134,KL3102,KL4002,KL9010";
const WAIT: Duration = Duration::from_secs(30);

/// A pty pair with `dpctl slave --device bk3000 --json --control -` on
/// one end, address 15 from the rotary switches.
struct Rig {
    dir: TempDir,
    master_port: PathBuf,
    _socat: Proc,
    slave: Proc,
    stdin: ChildStdin,
    out: Lines,
}

fn rig(tag: &str) -> Rig {
    let dir = TempDir::new(tag);
    let (a, b) = (dir.path("master"), dir.path("slave"));
    let socat = pty_pair(&a, &b);
    let mut cmd = Command::new(dpctl());
    cmd.args(["slave", "--device", "bk3000", "--terminals", STRIP])
        .args(["--switch-ones", "5", "--switch-tens", "1"])
        .args(["--control", "-", "--json", "--port"])
        .arg(&b)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .stdin(Stdio::piped());
    let mut slave = Proc::spawn("dpctl slave", &mut cmd);
    let stdin = slave.child.as_mut().unwrap().stdin.take().unwrap();
    let out = started(&mut slave, WAIT);
    let start: Value = serde_json::from_str(
        out.1
            .iter()
            .find(|l| l.contains("\"event\":\"start\""))
            .unwrap(),
    )
    .unwrap();
    assert_eq!(start["address"], 15, "rotary switches 1 and 5");
    assert_eq!(start["ident"], "0xBECF");
    Rig {
        dir,
        master_port: a,
        _socat: socat,
        slave,
        stdin,
        out,
    }
}

impl Rig {
    /// Send a control command and wait for its answer.
    fn control(&mut self, line: &str, answer: &str) {
        writeln!(self.stdin, "{line}").unwrap();
        self.stdin.flush().unwrap();
        assert!(
            self.out.wait_for(answer, WAIT),
            "no `{answer}` after `{line}`: {:?}",
            self.out.1
        );
    }

    fn file(&self, name: &str, text: &str) -> PathBuf {
        let p = self.dir.path(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn master(&self) -> Command {
        let mut c = Command::new(dpctl());
        c.args(["master", "--port"]).arg(&self.master_port);
        c
    }

    /// Run `dpctl master --config BUS --json --interval 100 [extra]` until
    /// a JSON line satisfies `done` (at most 30 s), then stop it; its
    /// lines.
    fn master_until(
        &self,
        bus: &PathBuf,
        extra: &[&str],
        done: impl Fn(&Value) -> bool,
    ) -> Vec<Value> {
        let mut cmd = self.master();
        cmd.arg("--config")
            .arg(bus)
            .args(["--json", "--interval", "100"])
            .args(extra)
            .stdout(Stdio::piped())
            .stdin(Stdio::null());
        let mut m = Proc::spawn("dpctl master", &mut cmd);
        let mut out = Lines::from(&mut m);
        let end = std::time::Instant::now() + WAIT;
        let mut hit = false;
        while !hit && std::time::Instant::now() < end {
            out.wait_for("\n", Duration::from_millis(200));
            hit = out
                .1
                .iter()
                .filter_map(|l| serde_json::from_str::<Value>(l).ok())
                .any(|v| done(&v));
        }
        m.terminate(Duration::from_secs(10));
        let lines = json_lines(out.rest());
        assert!(
            hit,
            "dpctl master never showed what the test waits for: {lines:?}"
        );
        lines
    }

    /// The slave's events so far, as JSON.
    fn events(&self) -> Vec<Value> {
        json_lines(&self.out.1)
    }

    fn stop(mut self) -> Vec<Value> {
        drop(self.stdin);
        let st = self.slave.terminate(Duration::from_secs(10));
        assert!(st.success(), "dpctl slave exited with {st}");
        json_lines(self.out.rest())
    }
}

fn bus_file(terminals: &str) -> String {
    let list: Vec<String> = terminals.split(',').map(|t| format!("\"{t}\"")).collect();
    format!(
        "[master]\naddress = 2\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 15\ndevice = \"bk3000\"\n\
         terminals = [{}]\nwatchdog_ms = 1000\n",
        list.join(", ")
    )
}

#[test]
fn master_shows_named_channels_and_writes_outputs_by_name() {
    let mut r = rig("bk3000-master");
    // Inputs the terminals see: -2.5 V on the KL3102's channel 2, the
    // KL1104's input 2 on.
    r.control("set 3.KL3102.2 -2.5", "pinned to -2.500 V");
    r.control("set 1.KL1104.2 1", "input 1.KL1104.2 pinned to 1");
    let bus = r.file("bus.toml", &bus_file(STRIP));
    let cmds = r.file(
        "cmds.jsonl",
        "{\"slave\": 15, \"set\": {\"2.KL2134.3\": 1, \"4.KL4002.1\": 5.0}}\n",
    );
    let cmds = cmds.display().to_string();
    let in_view = |st: &Value| {
        let ch = &st["slaves"][0]["channels"];
        st["event"] == "status"
            && ch["inputs"]["3.KL3102.2"]
                .as_f64()
                .is_some_and(|v| (v + 2.5).abs() < 0.001)
            && ch["inputs"]["1.KL1104.2"] == true
            && ch["outputs"]["2.KL2134.3"] == true
            && ch["outputs"]["4.KL4002.1"]
                .as_f64()
                .is_some_and(|v| (v - 5.0).abs() < 0.001)
    };
    let lines = r.master_until(&bus, &["--input", &cmds], in_view);
    assert!(
        lines
            .iter()
            .any(|v| v["event"] == "state" && v["slave"] == 15 && v["to"] == "data_exchange"),
        "{lines:?}"
    );
    // The outputs written by name reached the emulated terminals.
    assert!(r.out.wait_for("4.KL4002.1=5.000 V", WAIT), "{:?}", r.out.1);
    let ev = r.events();
    assert!(
        ev.iter().any(|e| e["kind"] == "outputs"
            && e["text"].as_str().unwrap().contains("2.KL2134.3=1")),
        "{ev:?}"
    );
    // In words: the named values with their units.
    let mut cmd = r.master();
    cmd.arg("--config")
        .arg(&bus)
        .args(["--interval", "100"])
        .stdout(Stdio::piped())
        .stdin(Stdio::null());
    let mut m = Proc::spawn("dpctl master", &mut cmd);
    let mut text = Lines::from(&mut m);
    assert!(text.wait_for("3.KL3102.2=-2.5001 V", WAIT), "{:?}", text.1);
    m.terminate(Duration::from_secs(10));
    assert!(
        text.1.iter().any(|l| l.contains("in: ")
            && l.contains("3.KL3102.2=-2.5001 V")
            && l.contains("1.KL1104.2=1")
            && l.contains("out: 4.KL4002.1=")),
        "{:?}",
        text.1
    );
    r.stop();
}

#[test]
fn wrong_configuration_gives_cfgdata_error_and_blink_code() {
    let r = rig("bk3000-cfg");
    // The master believes the KL4002 sits before the KL3102.
    let bus = r.file("bus.toml", &bus_file("KL1104,KL2134,KL4002,KL3102,KL9010"));
    let blink = "device: CfgData error 2: CfgData byte 0 faulty; I/O-ERR blinks 6 pulses, then 1";
    let lines = r.master_until(&bus, &[], |v| {
        v["event"] == "diag"
            && v["words"]
                .as_array()
                .is_some_and(|w| w.iter().any(|w| w == blink))
    });
    let diag: Vec<&Value> = lines
        .iter()
        .filter(|v| v["event"] == "diag" && v["slave"] == 15)
        .collect();
    // Cfg_Fault + Ext_Diag; manufacturer bytes: length 10, reserved 0,
    // message 00 FF, UserPrm 00 00, CfgData error 2 at byte 0.
    assert!(
        diag.iter().any(|v| v["raw"]
            .as_str()
            .unwrap()
            .ends_with("0A 00 00 FF 00 00 02 00 00 00")),
        "{diag:?}"
    );
    assert!(
        diag.iter()
            .any(|v| v["words"].as_array().unwrap().iter().any(|w| {
                w
            == "device: CfgData error 2: CfgData byte 0 faulty; I/O-ERR blinks 6 pulses, then 1"
            })),
        "{diag:?}"
    );
    let ev = r.stop();
    assert!(
        ev.iter().any(|e| e["event"] == "cfg_fault"
            && e["reason"]
                .as_str()
                .unwrap()
                .contains("terminal 3 (KL3102)")),
        "{ev:?}"
    );
    assert!(
        ev.iter().any(|e| e["kind"] == "io-err"
            && e["text"]
                .as_str()
                .unwrap()
                .contains("I/O-ERR 6 pulses, then 1")),
        "{ev:?}"
    );
}

#[test]
fn pulled_terminal_is_reported_to_the_master() {
    let mut r = rig("bk3000-pull");
    let bus = r.file("bus.toml", &bus_file(STRIP));
    let mut cmd = r.master();
    cmd.arg("--config")
        .arg(&bus)
        .args(["--json", "--interval", "100"])
        .stdout(Stdio::piped())
        .stdin(Stdio::null());
    let mut m = Proc::spawn("dpctl master", &mut cmd);
    let mut mout = Lines::from(&mut m);
    assert!(
        mout.wait_for("\"to\":\"data_exchange\"", WAIT),
        "{:?}",
        mout.1
    );
    r.control("pull 3", "K-bus error, break behind terminal 2");
    assert!(
        mout.wait_for(
            "K-bus data error, break behind terminal 2; I/O-ERR blinks 4 pulses, then 2",
            WAIT
        ),
        "{:?}",
        mout.1
    );
    r.control("plug 3", "K-bus running again");
    m.terminate(Duration::from_secs(10));
    let diag: Vec<Value> = mout
        .rest()
        .iter()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| v["event"] == "diag")
        .collect();
    assert!(
        diag.iter().any(|v| v["words"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w == "device: K-bus error")),
        "{diag:?}"
    );
    r.stop();
}

#[test]
fn pyprofibus_exchanges_data_with_the_coupler_through_its_gsd() {
    let py = python();
    let mut r = rig("bk3000-py");
    r.control("set 1.KL1104.1 1", "input 1.KL1104.1 pinned to 1");
    // Outputs: KL4002 channel 1 = 0x4000 (5 V), channel 2 = 0,
    // KL2134 outputs 1 and 3.
    let mut cmd = Command::new(py);
    cmd.arg(repo().join("tests/interop/pyprofibus_bk3000.py"))
        .arg("--port")
        .arg(&r.master_port)
        .arg("--gsd")
        .arg(repo().join("crates/devices/gsd/BK30BECF.GSD"))
        .args(["--addr", "15", "--in-len", "5", "--out-len", "5"])
        .args(["--outputs", "4000000005", "--cycles", "30"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    for m in [
        "KL3xx2, KL3351: 2 x 16 bit in (compact)",
        "KL4xx2: 2 x 16 bit out (compact)",
        "8 digital inputs (1 byte)",
        "8 digital outputs (1 byte)",
    ] {
        cmd.args(["--module", m]);
    }
    let lines = json_lines(run_pyprofibus(&mut cmd));
    let last = lines.iter().rev().find(|v| v["event"] == "dx").unwrap();
    let inputs = last["inputs"].as_str().unwrap();
    // Byte 4: the digital inputs, KL1104 input 1 pinned on.
    let di = u8::from_str_radix(&inputs[8..10], 16).unwrap();
    assert_eq!(di & 1, 1, "{inputs}");
    assert!(r.out.wait_for("4.KL4002.1=5.000 V", WAIT), "{:?}", r.out.1);
    let ev = r.stop();
    assert!(ev
        .iter()
        .any(|e| e["event"] == "state" && e["to"] == "Data_Exch"));
    assert!(
        ev.iter().any(|e| e["kind"] == "outputs"
            && e["text"].as_str().unwrap().contains("2.KL2134.1=1")
            && e["text"].as_str().unwrap().contains("2.KL2134.3=1")),
        "{ev:?}"
    );
}

/// `dpctl slave` of a BK3000 with the terminals `strip` on no line.
fn start_strip(strip: &str) -> Output {
    let args = ["--port", "/dev/null", "--device", "bk3000", "--addr", "5"];
    run_dpctl(&[&["slave", "--terminals", strip], &args[..]].concat())
}

#[test]
fn strips_the_coupler_cannot_run_are_refused_at_start() {
    for (strip, words) in [
        ("KL1104,KL2134", "must end with the end terminal KL9010"),
        ("KL1104,KL9010,KL2134", "follows the end terminal"),
        ("KL1104,KL7777,KL9010", "`KL7777` is not in the catalogue"),
    ] {
        let o = start_strip(strip);
        assert_eq!(o.status.code(), Some(1), "{strip}: {o:?}");
        assert!(o.stderr.contains(words), "{strip}: {}", o.stderr);
    }
    let many = vec!["KL1002"; 64].join(",") + ",KL9010";
    let o = start_strip(&many);
    assert!(o.stderr.contains("at most 64"), "{}", o.stderr);
}

#[test]
fn the_demo_runs_a_bk3000_with_named_channels() {
    let o = run_dpctl(&["demo", "--fast", "--cycles", "400", "--json"]);
    assert!(o.status.success(), "{}", o.stderr);
    let lines = json_lines(o.stdout.lines());
    let st = lines.iter().rev().find(|v| v["event"] == "status").unwrap();
    let bk = st["slaves"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["address"] == 9)
        .expect("the BK3000");
    assert_eq!(bk["state"], "data_exchange", "{bk}");
    let ch = &bk["channels"];
    assert!(ch["inputs"]["3.KL3102.1"].is_f64(), "{ch}");
    assert!(ch["outputs"]["4.KL4002.1"].as_f64().unwrap() > 0.0, "{ch}");
}

/// Manual p. 24: the BK3000 runs at up to 1.5 Mbit/s (only the BK3100 and
/// BK3110 reach 12 Mbit/s), and its GSD stops at `1.5M_supp`. On a pty
/// every rate passes the bytes, so an unrestricted search would lock at
/// the first rate it tries, 12 Mbit/s; the coupler's search starts at
/// 1.5 Mbit/s and never listens faster.
#[test]
fn baud_search_keeps_to_the_rates_of_the_gsd() {
    let dir = TempDir::new("bk3000-baud");
    let (a, b) = (dir.path("master"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    let mut slave = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--device", "bk3000", "--terminals", STRIP])
            .args(["--addr", "15", "--baud", "search", "--json", "--port"])
            .arg(&b)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit()),
    );
    let mut out = started(&mut slave, WAIT);
    // FDL Status request to station 15 from the master at 2 (SD1).
    let fs = [0x10, 15, 2, 0x49, (15u8 + 2 + 0x49), 0x16];
    let mut line = std::fs::OpenOptions::new().write(true).open(&a).unwrap();
    assert!(
        wait_for_lock(&mut line, &fs, &mut out),
        "no baud_locked: {:?}",
        out.1
    );
    let locked: Value =
        serde_json::from_str(out.1.iter().find(|l| l.contains("baud_locked")).unwrap()).unwrap();
    assert_eq!(locked["baud"], 1_500_000, "the fastest rate of the GSD");
}

/// Send `telegram` until the slave reports its rate.
fn wait_for_lock(line: &mut std::fs::File, telegram: &[u8], out: &mut Lines) -> bool {
    for _ in 0..20 {
        line.write_all(telegram).unwrap();
        if out.wait_for("baud_locked", Duration::from_millis(500)) {
            return true;
        }
    }
    false
}
