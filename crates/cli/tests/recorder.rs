//! The triggered recorder of `dpctl sniff` on a `dpctl bus`: a master
//! with a wrong module list for its slave (Chk_Cfg says one byte in, the
//! slave has two words in/out) makes the slave answer its diagnosis with
//! Cfg_Fault; `--trigger cfg_fault` must write a pcapng segment that
//! holds the fault with its context (the Set_Prm and Chk_Cfg before it),
//! read back with tshark and the dissector. A second sniffer with
//! `--split` writes one file per firing. A third, on a line with flipped
//! bits, records the corrupt bytes flagged. The tests fail when tshark
//! is missing.

mod common;

use common::{dpctl, repo, require, Bus, Proc, TempDir};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const WAIT: Duration = Duration::from_secs(90);

/// `tshark` with the dissector: one row per packet, fields split by `|`.
fn tshark(capture: &Path, fields: &[&str]) -> Vec<Vec<String>> {
    require("tshark");
    let mut cmd = Command::new("tshark");
    cmd.arg("-X")
        .arg(format!(
            "lua_script:{}",
            repo().join("tools/wireshark/profibus_dl.lua").display()
        ))
        .arg("-r")
        .arg(capture)
        .args(["-T", "fields", "-E", "separator=|", "-E", "occurrence=a"]);
    for f in fields {
        cmd.args(["-e", f]);
    }
    let out = cmd.output().expect("run tshark");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "tshark failed: {err}");
    assert!(!err.contains("Lua Error"), "the dissector failed: {err}");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!text.contains("Lua Error"), "the dissector failed: {text}");
    text.lines()
        .map(|l| l.split('|').map(str::to_string).collect())
        .collect()
}

/// A slave 10 with two words in/out, and a master 2 that expects
/// `modules` of it.
fn start_pair(bus: &Bus, modules: &str) -> (Proc, Proc) {
    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let slave = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--port", &bus.link_str(1), "--addr", "10"])
            .args(["--baud", "1.5M", "--gsd"])
            .arg(&gsd)
            .args(["--module", "2 words in/out"])
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    let config = bus.dir().path("bus.toml");
    std::fs::write(
        &config,
        format!(
            "[master]\naddress = 2\nbaud = \"1.5M\"\n\
             [[slave]]\naddress = 10\ngsd = \"{}\"\nmodules = [{modules}]\n",
            gsd.display()
        ),
    )
    .unwrap();
    let master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--latency", "20", "--port", &bus.link_str(0)])
            .arg("--config")
            .arg(&config)
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    (slave, master)
}

/// Read JSON lines of `p` until `n` trigger events came and `after` more
/// lines followed the last; returns the trigger events.
fn triggers(p: &Proc, n: usize, after: usize) -> Vec<Value> {
    let end = Instant::now() + WAIT;
    let mut fired = vec![];
    let mut since = 0;
    let mut tail = vec![];
    while fired.len() < n || since < after {
        let left = end.saturating_duration_since(Instant::now());
        let Some(l) = p.stdout_line(left) else {
            panic!(
                "{} of {n} triggers fired; last lines: {tail:#?}",
                fired.len()
            );
        };
        let v: Value = serde_json::from_str(&l).unwrap_or_else(|e| panic!("{e}: {l}"));
        since += 1;
        if v["event"] == "trigger" {
            fired.push(v);
            since = 0;
        }
        tail.push(l);
        if tail.len() > 20 {
            tail.remove(0);
        }
    }
    fired
}

fn path(v: &Value) -> PathBuf {
    PathBuf::from(v["file"].as_str().expect("a file name"))
}

#[test]
fn a_cfg_fault_trigger_records_the_fault_with_its_context() {
    let dir = TempDir::new("trigger");
    let one = dir.path("fault.pcapng");
    let split = dir.path("chk.pcapng");
    let bus = Bus::start(5, &[]);
    let all = {
        let mut cmd = Command::new(dpctl());
        cmd.args(["sniff", "--json", "--port", &bus.link_str(2)])
            .args([
                "--trigger",
                "cfg_fault",
                "--pre",
                "12",
                "--post",
                "3",
                "--pcap",
            ])
            .arg(&one);
        Proc::spawn_captured(cmd)
    };
    let each = {
        let mut cmd = Command::new(dpctl());
        cmd.args(["sniff", "--json", "--port", &bus.link_str(3)])
            .args(["--trigger", "service == CHK_CFG and request"])
            .args(["--pre", "0", "--post", "1", "--split", "--pcap"])
            .arg(&split);
        Proc::spawn_captured(cmd)
    };
    let plain = {
        let mut cmd = Command::new(dpctl());
        cmd.args(["sniff", "--plain", "--port", &bus.link_str(4)]);
        Proc::spawn_captured(cmd)
    };
    bus.wait_connected(3);
    let (mut slave, mut master) = start_pair(&bus, r#""1 byte in""#);
    // Plain lines carry the DP layer in words after ` | `.
    let mut want: Vec<(&str, &str)> = vec![
        ("| Set_Prm request: ", "; watchdog "),
        (
            "| Chk_Cfg request: 1 byte in (10)",
            "; 1 byte in, 0 bytes out",
        ),
        ("| Slave_Diag response: ", "Cfg_Fault"),
    ];
    let end = Instant::now() + WAIT;
    while !want.is_empty() {
        let left = end.saturating_duration_since(Instant::now());
        let l = plain
            .stdout_line(left)
            .unwrap_or_else(|| panic!("dpctl sniff --plain never printed {want:?}"));
        want.retain(|(a, b)| !(l.contains(a) && l.contains(b)));
    }
    drop(plain);
    let fired = triggers(&all, 1, 10);
    let split_fired = triggers(&each, 2, 3);
    master.terminate(Duration::from_secs(10));
    slave.terminate(Duration::from_secs(10));
    let mut all = all;
    all.terminate(Duration::from_secs(10));
    let mut each = each;
    each.terminate(Duration::from_secs(10));

    // The JSON event names the trigger, its segment and file.
    let f = &fired[0];
    assert_eq!(f["trigger"], "cfg_fault", "{f}");
    assert_eq!(f["segment"], 1, "{f}");
    assert_eq!(path(f), one);
    assert!(f["t_us"].is_u64(), "{f}");

    let rows = tshark(
        &one,
        &[
            "frame.comment",
            "pbdp.service",
            "pbdl.fc.request",
            "pbdp.cfg.id",
            "pbdp.diag.cfg_fault",
        ],
    );
    assert!(rows[0][0].contains("segment 1"), "{rows:#?}");
    let fault = (rows.iter())
        .position(|r| r[0].contains("trigger: cfg_fault"))
        .unwrap_or_else(|| panic!("no trigger comment: {rows:#?}"));
    // The firing record is the diagnosis with Cfg_Fault …
    assert_eq!(rows[fault][1], "Slave_Diag", "{rows:#?}");
    assert!(
        ["1", "True"].contains(&rows[fault][4].as_str()),
        "{rows:#?}"
    );
    // … after the Chk_Cfg with the master's wrong identifier (0x10,
    // one byte in) and its Set_Prm.
    let chk = (rows[..fault].iter())
        .rposition(|r| r[1] == "Chk_Cfg" && r[3].contains("0x10"))
        .unwrap_or_else(|| panic!("no Chk_Cfg before the fault: {rows:#?}"));
    assert!(
        rows[..chk].iter().any(|r| r[1] == "Set_Prm"),
        "no Set_Prm before the Chk_Cfg: {rows:#?}"
    );
    // Three records after the firing (the segment may have grown when
    // the fault came again within them).
    assert!(rows.len() >= fault + 4, "{rows:#?}");

    // `--split`: one file per firing, FILE-1.pcapng, FILE-2.pcapng, …
    // each the Chk_Cfg request and the record after it.
    for (i, f) in split_fired.iter().enumerate().take(2) {
        let file = dir.path(&format!("chk-{}.pcapng", i + 1));
        assert_eq!(path(f), file, "{f}");
        let rows = tshark(&file, &["frame.comment", "pbdp.service", "pbdl.fc.request"]);
        assert_eq!(rows.len(), 2, "{}: {rows:#?}", file.display());
        assert_eq!(rows[0][1], "Chk_Cfg", "{rows:#?}");
        assert!(
            rows[0][0].contains(&format!("segment {}", i + 1))
                && rows[0][0].contains("trigger: service == chk_cfg and request"),
            "{rows:#?}"
        );
    }
    let out = bus.stop();
    assert!(out.status.success(), "dpctl bus: {}", out.stderr);
}

#[test]
fn flipped_bits_are_recorded_and_flagged() {
    let dir = TempDir::new("corrupt");
    let file = dir.path("corrupt.pcapng");
    let bus = Bus::start(3, &["--flip", "0.002"]);
    let sniffer = {
        let mut cmd = Command::new(dpctl());
        cmd.args(["sniff", "--json", "--port", &bus.link_str(2)])
            .args([
                "--trigger",
                "corrupt",
                "--pre",
                "2",
                "--post",
                "2",
                "--pcap",
            ])
            .arg(&file);
        Proc::spawn_captured(cmd)
    };
    bus.wait_connected(1);
    let (mut slave, mut master) = start_pair(&bus, r#""2 words in/out""#);
    let fired = triggers(&sniffer, 3, 5);
    master.terminate(Duration::from_secs(10));
    slave.terminate(Duration::from_secs(10));
    let mut sniffer = sniffer;
    sniffer.terminate(Duration::from_secs(10));
    assert_eq!(fired[0]["trigger"], "corrupt");
    let rows = tshark(
        &file,
        &[
            "frame.comment",
            "frame.packet_flags_crc_error",
            "pbdl.fcs.good",
        ],
    );
    let flagged: Vec<&Vec<String>> = rows
        .iter()
        .filter(|r| r[0].contains("trigger: corrupt"))
        .collect();
    assert!(flagged.len() >= 3, "{rows:#?}");
    for r in flagged {
        // pcapng marks the record, and the dissector says so.
        assert!(["1", "True"].contains(&r[1].as_str()), "{rows:#?}");
        assert!(["0", "False"].contains(&r[2].as_str()), "{rows:#?}");
    }
    let out = bus.stop();
    assert!(out.status.success(), "dpctl bus: {}", out.stderr);
}
