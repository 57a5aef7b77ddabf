//! The worked examples of the BM4-O-PRO-01 and Omega Drive-Line II
//! manuals, end to end through real processes: `dpctl slave --device
//! bm4|omega` on one end of a socat pty pair, `dpctl pkw` / `dpctl
//! master` on the other; and pyprofibus (PyPI) as the master of both
//! profiles.
//!
//! Needs socat and `.venv` with pyprofibus (scripts/setup-test-env); the
//! tests fail when they are missing.

mod common;

use common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

struct Rig {
    dir: TempDir,
    master_port: PathBuf,
    _socat: Proc,
    slave: Proc,
    out: Lines,
}

/// A pty pair with `dpctl slave --json <args>` on one end.
/// Milliseconds added to the masters' slot time and timeouts: a reply
/// through a pty pair on a busy machine can take that long, and a late
/// reply must not count as a lost one.
const LATENCY: &str = "100";

fn rig(tag: &str, args: &[impl AsRef<std::ffi::OsStr>], stdin: bool) -> Rig {
    let dir = TempDir::new(tag);
    let (a, b) = (dir.path("master"), dir.path("slave"));
    let socat = pty_pair(&a, &b);
    let mut cmd = Command::new(dpctl());
    cmd.args(["slave", "--port"])
        .arg(&b)
        .arg("--json")
        .args(args)
        .current_dir(&dir.0)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .stdin(if stdin { Stdio::piped() } else { Stdio::null() });
    let mut slave = Proc::spawn("dpctl slave", &mut cmd);
    let out = started(&mut slave, Duration::from_secs(10));
    Rig {
        dir,
        master_port: a,
        _socat: socat,
        slave,
        out,
    }
}

impl Rig {
    fn bus(&self, name: &str, text: &str) -> PathBuf {
        let p = self.dir.path(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    /// `dpctl pkw … --json OP…`: exit success and the JSON line.
    fn pkw(&self, bus: &Path, slave: u8, op: &[&str]) -> (bool, Value, String) {
        let out = Command::new(dpctl())
            .args(["pkw", "--port"])
            .arg(&self.master_port)
            .arg("--config")
            .arg(bus)
            .args(["--slave", &slave.to_string(), "--json"])
            .args(["--latency", LATENCY])
            .args(op)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).to_string();
        let stderr = String::from_utf8_lossy(&out.stderr).to_string();
        let v = stdout
            .lines()
            .find_map(|l| serde_json::from_str(l).ok())
            .unwrap_or(Value::Null);
        (out.status.success(), v, stderr)
    }

    /// `dpctl master --cycles N --json`: the JSON lines.
    /// Run `dpctl master` on the bus file until it stops by itself
    /// (`until`: `--exchanges N --timeout S`, or `--cycles N`).
    fn master(&self, bus: &Path, until: &[&str]) -> Vec<Value> {
        let out = Command::new(dpctl())
            .args(["master", "--port"])
            .arg(&self.master_port)
            .arg("--config")
            .arg(bus)
            .args(until)
            .args(["--latency", LATENCY, "--json"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "dpctl master: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        json_lines(String::from_utf8_lossy(&out.stdout).lines())
    }

    fn stop(mut self) -> Vec<Value> {
        let st = self.slave.terminate(Duration::from_secs(10));
        assert!(st.success(), "dpctl slave exited with {st}");
        json_lines(self.out.rest())
    }
}

/// `dpctl slave` arguments of a BM4 with the manual's example variables,
/// then `extra`.
fn bm4(extra: &[&str]) -> Vec<String> {
    let vars = repo().join("crates/devices/data/bm4_example_vars.toml");
    let vars = vars.display().to_string();
    let args = ["--device", "bm4", "--vars", &vars]
        .into_iter()
        .chain(extra.iter().copied());
    args.map(String::from).collect()
}

const BM4_BUS: &str = r#"
[master]
address = 2
baud = "1.5M"
[[slave]]
address = 6
gsd = "my.gsd"
modules = ["Bedarfsdaten PKW", "ud_MyReadVar1", "u_MyWriteVar2"]
watchdog_ms = 1000
"#;

#[test]
fn bm4_pkw_examples_of_the_manual() {
    let r = rig(
        "bm4-pkw",
        &bm4(&["--addr", "6", "--write-gsd", "my.gsd"]),
        false,
    );
    // The generated GSD has the modules of the manual's MyGSDFile.gsd.
    let ours = std::fs::read_to_string(r.dir.path("my.gsd")).unwrap();
    for line in [
        "\"Bedarfsdaten PKW\" 0x73",
        "\"ud_MyReadVar1\" 0x42,0xC1,0x02,0x00",
        "\"u_MyWriteVar2\" 0x82,0xC0,0x01,0x03",
        "\"di_MyReadVar3\" 0x42,0xC1,0x02,0x04",
    ] {
        assert!(ours.contains(line), "generated GSD lacks {line}:\n{ours}");
    }
    let bus = r.bus("bus.toml", BM4_BUS);

    // Read di_MyReadVar3: 1004 → 2004, 3000 (PWE1 0000, PWE2 0BB8).
    let (ok, v, err) = r.pkw(&bus, 6, &["read", "di_MyReadVar3"]);
    assert!(ok, "{err}");
    assert_eq!(v["request"], "1004 0000 0000 0000");
    assert_eq!(v["response"], "2004 0000 0000 0BB8");
    assert_eq!(v["value"], 3000);

    // Write ud_MyWriteVar1 := 16#12345678 with 3002 → 2002, mirrored.
    let (ok, v, err) = r.pkw(&bus, 6, &["write", "ud_MyWriteVar1=0x12345678", "--dword"]);
    assert!(ok, "{err}");
    assert_eq!(v["request"], "3002 0000 1234 5678");
    assert_eq!(v["response"], "2002 0000 1234 5678");
    // The word format is found by reading first.
    let (ok, v, err) = r.pkw(&bus, 6, &["write", "ud_MyWriteVar1=7"]);
    assert!(ok, "{err}");
    assert_eq!(v["response"], "2002 0000 0000 0007");

    // A variable that does not exist: 7xxx with 0x000B, exit 1.
    let (ok, v, err) = r.pkw(&bus, 6, &["read", "9"]);
    assert!(!ok);
    assert_eq!(v["code"], 0x000B);
    assert!(err.contains("error 0x000B"), "{err}");
    // Cyclic variables are not for PKW; INPUT variables are read only.
    let (ok, v, _) = r.pkw(&bus, 6, &["read", "ud_MyReadVar1"]);
    assert!(!ok && v["code"] == 0x000B, "{v}");
    let (ok, v, _) = r.pkw(&bus, 6, &["write", "di_MyReadVar3=1", "--dword"]);
    assert!(!ok && v["code"] == 0x0001, "{v}");

    let events = r.stop();
    let jobs: Vec<&str> = events
        .iter()
        .filter(|e| e["kind"] == "pkw")
        .filter_map(|e| e["text"].as_str())
        .collect();
    assert!(
        jobs.iter()
            .any(|t| t.contains("3002 0000 1234 5678 -> 2002 0000 1234 5678")),
        "{jobs:?}"
    );
}

/// The PKW example of docs/devices/bm4.md as written: its `BUS.toml` block
/// and its `dpctl slave --device bm4` line, then `dpctl pkw
/// … --slave 6 read di_MyReadVar3` gives the manual's 3000.
#[test]
fn bm4_page_pkw_example_works_as_written() {
    let readme = std::fs::read_to_string(repo().join("docs/devices/bm4.md")).unwrap();
    let after = readme
        .split("`BUS.toml` for these two slaves")
        .nth(1)
        .expect("docs/devices/bm4.md shows BUS.toml for the PKW examples");
    let block = after.split("```toml\n").nth(1).unwrap();
    let bus_text = block.split("```").next().unwrap();
    let line = readme
        .lines()
        .find(|l| l.starts_with("dpctl slave --port PTY --device bm4 --addr 6 "))
        .expect("docs/devices/bm4.md's bm4 slave line");
    // The page's arguments after the port, without `--write-gsd`, its
    // paths relative to the repository (where the page runs them).
    let mut args: Vec<String> = line
        .split_whitespace()
        .skip(4)
        .map(|a| match a.starts_with("crates/") {
            true => repo().join(a).display().to_string(),
            false => a.to_string(),
        })
        .collect();
    if let Some(i) = args.iter().position(|a| a == "--write-gsd") {
        args.drain(i..i + 2);
    }
    let r = rig("bm4-readme", &args, false);
    std::os::unix::fs::symlink(repo().join("crates"), r.dir.path("crates")).unwrap();
    let bus = r.bus("BUS.toml", bus_text);
    let (ok, v, err) = r.pkw(&bus, 6, &["read", "di_MyReadVar3"]);
    assert!(ok, "{err} {v}\n{bus_text}");
    assert_eq!(v["value"], 3000, "{v}");
    r.stop();
}

#[test]
fn bm4_user_diagnosis_example_reaches_the_master() {
    let args = bm4(&["--addr", "6", "--write-gsd", "my.gsd", "--control", "-"]);
    let mut r = rig("bm4-diag", &args, true);
    let bus = r.bus("bus.toml", BM4_BUS);
    {
        use std::io::Write;
        let stdin = r.slave.child.as_mut().unwrap().stdin.as_mut().unwrap();
        // 16#1234_5678_90AB_CDEF in a_ED_DATA[0..7] (manual L1989-2010).
        writeln!(stdin, "sdiag EF CD AB 90 78 56 34 12").unwrap();
        stdin.flush().unwrap();
    }
    assert!(
        r.out.wait_for("SDIAG: 8 bytes", Duration::from_secs(5)),
        "{:?}",
        r.out.1
    );
    let lines = r.master(&bus, &["--exchanges", "100", "--timeout", "120"]);
    let diag = lines
        .iter()
        .filter(|v| v["event"] == "diag")
        .find(|v| {
            v["raw"]
                .as_str()
                .unwrap()
                .ends_with("00 08 09 EF CD AB 90 78 56 34 12")
        })
        .unwrap_or_else(|| panic!("no diagnosis with the user bytes: {lines:?}"));
    assert!(diag["raw"].as_str().unwrap().len() == 15 * 3 - 1);
    let events = r.stop();
    assert!(
        events
            .iter()
            .any(|e| e["kind"] == "diag" && e["text"].as_str().unwrap().contains("x_OK")),
        "{events:?}"
    );
}

#[test]
fn bm4_set_once_address_survives_a_restart() {
    let state = TempDir::new("bm4-state");
    let sd = state.0.display().to_string();
    let args = bm4(&[
        "--us-device",
        "126",
        "--state-dir",
        &sd,
        "--write-gsd",
        "my.gsd",
    ]);
    let r = rig("bm4-addr", &args, false);
    assert!(r.out.1.iter().any(|l| l.contains("\"address\":126")));
    let bus = r.bus("bus.toml", &BM4_BUS.replace("address = 6", "address = 7"));
    let cmds = r.bus(
        "cmds.jsonl",
        "{\"set_slave_add\": 126, \"new_address\": 7, \"ident\": \"0x0008\"}\n",
    );
    let out = Command::new(dpctl())
        .args(["master", "--port"])
        .arg(&r.master_port)
        .arg("--config")
        .arg(&bus)
        .arg("--input")
        .arg(&cmds)
        .args(["--cycles", "50", "--latency", LATENCY, "--json"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let events = r.stop();
    assert!(
        events
            .iter()
            .any(|e| e["event"] == "address" && e["new"] == 7),
        "{events:?}"
    );
    // Power cycle: the stored address is used.
    let r = rig("bm4-addr2", &args, false);
    assert!(
        r.out.1.iter().any(|l| l.contains("\"address\":7")),
        "{:?}",
        r.out.1
    );
    r.stop();
}

/// BNF_00D0.GSD with its vendor quirks written out in standard syntax by
/// our GSD writer (pyprofibus reads no modules from the original).
fn omega_gsd(dir: &TempDir) -> PathBuf {
    let g = profibus::dp::config::gsd::Gsd::from_file(
        repo().join("crates/devices/gsd/BNF_00D0.GSD"),
        profibus::dp::config::gsd::ParseOptions { lenient: true },
    )
    .unwrap()
    .gsd;
    let p = dir.path("BNF_00D0.GSD");
    std::fs::write(&p, g.write_latin1()).unwrap();
    p
}

fn omega_bus(gsd: &Path, modules: &[&str]) -> String {
    format!(
        "[master]\naddress = 2\nbaud = \"1.5M\"\n[[slave]]\naddress = 25\ngsd = \"{}\"\nmodules = [{}]\nwatchdog_ms = 1000\n",
        gsd.display(),
        modules
            .iter()
            .map(|m| format!("\"{m}\""))
            .collect::<Vec<_>>()
            .join(", ")
    )
}

#[test]
fn omega_pkw_examples_of_the_manual() {
    // Address 25 from the rotary switches S40 = 1, S41 = 9 (L506-511).
    let r = rig(
        "omega-pkw",
        &["--device", "omega", "--switch", "0x19"],
        false,
    );
    assert!(r.out.1.iter().any(|l| l.contains("\"address\":25")));
    let gsd = omega_gsd(&r.dir);
    let bus = r.bus(
        "bus.toml",
        &omega_bus(
            &gsd,
            &[
                "Service data module",
                "Status / control module",
                "1 cycl. actual value ( 2 AI)",
                "1 cycl. setpoint ( 2 AO)",
            ],
        ),
    );
    // Read P218: 10DA → 20DA (double word).
    let (ok, v, err) = r.pkw(&bus, 25, &["read", "218"]);
    assert!(ok, "{err}");
    assert_eq!(v["request"], "10DA 0000 0000 0000");
    assert!(v["response"].as_str().unwrap().starts_with("20DA 0000"));
    // P127 := 4: 207F 0000 0000 0004 → 107F 0000 0000 0004.
    let (ok, v, err) = r.pkw(&bus, 25, &["write", "P127=4"]);
    assert!(ok, "{err}");
    assert_eq!(v["request"], "207F 0000 0000 0004");
    assert_eq!(v["response"], "107F 0000 0000 0004");
    // Maximum of P126: 407E 0006 → 307E 0006 0000 000F.
    let (ok, v, err) = r.pkw(&bus, 25, &["describe", "126", "max"]);
    assert!(ok, "{err}");
    assert_eq!(v["request"], "407E 0006 0000 0000");
    assert_eq!(v["response"], "307E 0006 0000 000F");
    let (ok, v, err) = r.pkw(&bus, 25, &["describe", "127", "attribute"]);
    assert!(ok, "{err}");
    assert!(
        v["words"].as_str().unwrap().contains("2 bytes, UNSIGNED"),
        "{v}"
    );
    // P003 = 0x0064.
    let (ok, v, _) = r.pkw(&bus, 25, &["read", "P3"]);
    assert!(ok && v["response"] == "1003 0000 0000 0064", "{v}");
    // The Omega's array: PNU 1000 := 16#12345678, read back.
    let (ok, v, err) = r.pkw(&bus, 25, &["write", "1000=0x12345678"]);
    assert!(ok, "{err}");
    assert_eq!(v["request"], "33E8 0000 1234 5678");
    assert_eq!(v["response"], "23E8 0000 1234 5678");
    let (ok, v, _) = r.pkw(&bus, 25, &["read", "1000"]);
    assert!(ok && v["response"] == "23E8 0000 1234 5678", "{v}");
    // By name from the V-controller table, and P[i] in the Omega's array
    // (P1000[i] = PNU 1000 + i); `list` names the parameters.
    let (ok, v, err) = r.pkw(&bus, 25, &["write", "M_communication_monitoring=0"]);
    assert!(ok, "{err}");
    assert_eq!(v["request"], "207F 0000 0000 0000");
    let (ok, v, _) = r.pkw(&bus, 25, &["read", "P1000[0]"]);
    assert!(ok && v["response"] == "23E8 0000 1234 5678", "{v}");
    let (ok, v, err) = r.pkw(&bus, 25, &["list"]);
    assert!(
        ok && v["pnu"].is_u64() && v["name"].is_string(),
        "{v} {err}"
    );
    // Errors are decoded: impermissible parameter number.
    let (ok, v, err) = r.pkw(&bus, 25, &["read", "999"]);
    assert!(!ok && v["code"] == 8, "{v}");
    assert!(err.contains("impermissible parameter number"), "{err}");
    r.stop();
}

#[test]
fn omega_configurations_a_b_c_give_the_same_layout() {
    let r = rig("omega-abc", &["--device", "omega", "--addr", "25"], false);
    let gsd = omega_gsd(&r.dir);
    let configs: [&[&str]; 3] = [
        &["Service data module", "2 actual values, 2 setpoints"],
        &[
            "Service data module",
            "Status / control module",
            "2 cycl. actual values ( 4 AI)",
            "2 cycl. setpoints ( 4 AO)",
        ],
        &["Data block 2 actual values / setpoints"],
    ];
    for (i, mods) in configs.iter().enumerate() {
        let bus = r.bus(&format!("bus{i}.toml"), &omega_bus(&gsd, mods));
        let lines = r.master(&bus, &["--exchanges", "30", "--timeout", "120"]);
        assert!(
            lines
                .iter()
                .any(|v| v["event"] == "state" && v["to"] == "data_exchange"),
            "config {i}: {lines:?}"
        );
        let st = lines.iter().rev().find(|v| v["event"] == "status").unwrap();
        let s = &st["slaves"][0];
        // 10 words each way: PKW, status/control, 2 values.
        assert_eq!(s["inputs"].as_str().unwrap().split(' ').count(), 20);
        assert_eq!(s["outputs"].as_str().unwrap().split(' ').count(), 20);
    }
    let events = r.stop();
    let cfgs: Vec<(u64, u64)> = events
        .iter()
        .filter(|e| e["event"] == "cfg_ok")
        .map(|e| {
            (
                e["inputs"].as_u64().unwrap(),
                e["outputs"].as_u64().unwrap(),
            )
        })
        .collect();
    assert!(
        cfgs.len() >= 3 && cfgs.iter().all(|c| *c == (20, 20)),
        "{cfgs:?}"
    );
    // A configuration against the rules is refused with b_MESSAGE 3.
    let r = rig("omega-bad", &["--device", "omega", "--addr", "25"], false);
    let gsd = omega_gsd(&r.dir);
    let bus = r.bus(
        "bad.toml",
        &omega_bus(
            &gsd,
            &["Status / control module", "2 cycl. actual values ( 4 AI)"],
        ),
    );
    // Start-up takes 4 poll cycles; retries on a busy machine add some,
    // and a slave that answered late is probed again only every 100 ms
    // (a cycle without a slave in data exchange takes about 1.5 ms).
    let lines = r.master(&bus, &["--cycles", "1000"]);
    assert!(lines.iter().any(|v| v["event"] == "fault"), "{lines:?}");
    let events = r.stop();
    assert!(events.iter().any(
        |e| e["event"] == "cfg_fault" && e["reason"].as_str().unwrap().contains("b_MESSAGE 3")
    ));
    assert!(events
        .iter()
        .any(|e| e["kind"] == "status" && e["text"].as_str().unwrap().contains("b_MESSAGE 3")));
}

/// pyprofibus drives the profile with `modules` from `gsd` and runs one
/// PKW job by hand.
#[allow(clippy::too_many_arguments)]
fn pyprofibus_pkw(
    r: &Rig,
    py: &Path,
    gsd: &Path,
    addr: u8,
    modules: &[&str],
    lens: (usize, usize),
    request: &str,
    expect: &str,
) {
    let mut cmd = Command::new(py);
    cmd.arg(repo().join("tests/interop/pyprofibus_pkw.py"))
        .arg("--port")
        .arg(&r.master_port)
        .arg("--gsd")
        .arg(gsd)
        .args(["--addr", &addr.to_string()])
        .args([
            "--in-len",
            &lens.0.to_string(),
            "--out-len",
            &lens.1.to_string(),
        ])
        .args(["--request", request, "--expect", expect])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    for m in modules {
        cmd.args(["--module", m]);
    }
    let lines = run_pyprofibus(&mut cmd);
    let summary: Value = serde_json::from_str(lines.last().unwrap()).unwrap();
    assert_eq!(summary["phase"], "done");
    assert_eq!(summary["response"], expect);
}

#[test]
fn pyprofibus_runs_both_profiles_into_data_exchange_with_pkw() {
    let py = python();
    // BM4 with the manual's MyGSDFile.gsd from crates/devices/gsd/.
    let r = rig("py-bm4", &bm4(&["--addr", "6"]), false);
    pyprofibus_pkw(
        &r,
        &py,
        &repo().join("crates/devices/gsd/MyGSDFile.gsd"),
        6,
        &["Bedarfsdaten PKW", "ud_MyReadVar1", "u_MyWriteVar2"],
        (12, 10),
        "1004000000000000",
        "2004000000000BB8",
    );
    let ev = r.stop();
    assert!(ev
        .iter()
        .any(|e| e["event"] == "state" && e["to"] == "Data_Exch"));
    // Omega with BNF_00D0.GSD.
    let r = rig("py-omega", &["--device", "omega", "--addr", "25"], false);
    let gsd = omega_gsd(&r.dir);
    pyprofibus_pkw(
        &r,
        &py,
        &gsd,
        25,
        &[
            "Service data module",
            "Status / control module",
            "1 cycl. actual value ( 2 AI)",
            "1 cycl. setpoint ( 2 AO)",
        ],
        (16, 16),
        "207F000000000004",
        "107F000000000004",
    );
    let ev = r.stop();
    assert!(ev
        .iter()
        .any(|e| e["event"] == "state" && e["to"] == "Data_Exch"));
}
