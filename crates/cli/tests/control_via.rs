//! One process owns the line: `dpctl master --control PATH` on `dpctl
//! bus` with a BM4 (PKW), an RFID reader and a generic DP-V1 slave;
//! `pkw`, `rfid`, `dpv1`, `im`, `diag` and `get-cfg` run through it with
//! `--via PATH` while the master keeps every slave in Data_Exchange (its
//! own status lines say so: no slave leaves it, no restart); writes to a
//! slave the bus file's `[mqtt] writable` does not list are refused; a
//! command opening the master's port is told who holds it and to use
//! `--via`. `dpctl gateway --control --control-readonly` serves a job and
//! refuses a write.

mod common;

use common::mqtt::{broker, free_port};
use common::{all_dx, dpctl, repo, run_dpctl, slave_of, Bus, Lines, Proc, TempDir};
use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

const WAIT: Duration = Duration::from_secs(60);
const BM4: u8 = 6;
const GEN: u8 = 10;
const READER: u8 = 12;

fn generic_gsd() -> PathBuf {
    repo().join("crates/devices/gsd/DPCTL_GEN.GSD")
}

/// The emulated slaves: BM4 at 6 on link 1, the generic DP-V1 slave at
/// 10 on link 2, the RFID reader at 12 on link 3.
fn slaves(bus: &Bus) -> Vec<Proc> {
    let quiet = |cmd: &mut Command| {
        cmd.stdout(Stdio::null()).stderr(Stdio::null());
    };
    let mut bm4 = Command::new(dpctl());
    bm4.args(["slave", "--device", "bm4", "--addr", "6"]).args([
        "--device-opt",
        "example=true",
        "--port",
        &bus.link_str(1),
    ]);
    quiet(&mut bm4);
    let mut gen = Command::new(dpctl());
    gen.args(["slave", "--addr", "10", "--baud", "1.5M", "--gsd"])
        .arg(generic_gsd())
        .args(["--module", "2 words in/out", "--port", &bus.link_str(2)]);
    quiet(&mut gen);
    let mut reader = Command::new(dpctl());
    reader
        .args(["slave", "--device", "rfid", "--addr", "12"])
        .args(["--latency", "20", "--port", &bus.link_str(3)]);
    quiet(&mut reader);
    vec![
        Proc::spawn("dpctl slave bm4", &mut bm4),
        Proc::spawn("dpctl slave generic", &mut gen),
        Proc::spawn("dpctl slave rfid", &mut reader),
    ]
}

/// The bus file: master 1 at 1.5 Mbit/s, the three slaves, `mqtt` as
/// the `[mqtt]` table's lines.
fn bus_file(dir: &TempDir, mqtt: &str) -> PathBuf {
    let text = format!(
        "[master]\naddress = 1\nbaud = \"1.5M\"\n[bus]\nhsa = 4\n[options]\nreprobe_ms = 50\n\
         [mqtt]\n{mqtt}\n\
         [[slave]]\naddress = 6\ndevice = \"bm4\"\nexample = true\n\
         variables = [\"ud_MyReadVar1\", \"u_MyWriteVar2\"]\nwatchdog_ms = 5000\n\
         [[slave]]\naddress = 10\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\nwatchdog_ms = 5000\n\
         [[slave]]\naddress = 12\ndevice = \"rfid\"\nwatchdog_ms = 5000\n",
        generic_gsd().display()
    );
    let p = dir.path("bus.toml");
    std::fs::write(&p, text).unwrap();
    p
}

/// The next status line of `lines` from `*seen` on that satisfies `ok`;
/// `check` sees every status line passed.
fn status(
    lines: &mut Lines,
    seen: &mut usize,
    what: &str,
    mut check: impl FnMut(&Value),
    ok: impl Fn(&Value) -> bool,
) -> Value {
    lines.json_from(seen, what, |v| {
        v["event"] == "status" && {
            check(v);
            ok(v)
        }
    })
}

/// `dpctl ARGS` (a one-shot command) through the control socket.
fn via(sock: &Path, args: &[&str]) -> common::Output {
    let (cmd, rest) = args.split_first().unwrap();
    let sock = sock.display().to_string();
    let mut all = vec![*cmd, "--via", &sock];
    all.extend_from_slice(rest);
    run_dpctl(&all)
}

fn ok(out: &common::Output) -> &str {
    assert!(out.status.success(), "{}{}", out.stdout, out.stderr);
    &out.stdout
}

/// One request line on a fresh connection, its answer.
fn ask(sock: &Path, request: &Value) -> Value {
    let mut c = UnixStream::connect(sock).unwrap();
    writeln!(c, "{request}").unwrap();
    let mut line = String::new();
    BufReader::new(c).read_line(&mut line).unwrap();
    serde_json::from_str(&line).unwrap()
}

#[test]
fn jobs_through_the_masters_control_socket_keep_every_slave_in_data_exchange() {
    let dir = TempDir::new("control-via");
    let bus = Bus::start(4, &[]);
    let _slaves = slaves(&bus);
    let cfg = bus_file(&dir, "writable = [6, 10]");
    let sock = dir.path("plant.sock");
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--latency", "20"])
            .args(["--port", &bus.link_str(0), "--config"])
            .arg(&cfg)
            .arg("--control")
            .arg(&sock)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut lines = Lines::from(&mut master);
    let mut seen = 0;
    let first = status(&mut lines, &mut seen, "every slave in DX", |_| {}, all_dx);
    let restarts = |v: &Value| -> Vec<u64> {
        [BM4, GEN, READER]
            .iter()
            .map(|a| slave_of(v, *a)["restarts"].as_u64().unwrap())
            .collect()
    };
    let restarts0 = restarts(&first);
    assert!(sock.exists());

    // PKW read by variable name (BM4 example table).
    let out = via(
        &sock,
        &["pkw", "--slave", "6", "--json", "read", "di_MyReadVar3"],
    );
    let v: Value = serde_json::from_str(ok(&out).trim()).unwrap();
    assert_eq!(
        (v["request"].clone(), v["value"].clone()),
        (json!("1004 0000 0000 0000"), json!(3000)),
        "{v}"
    );
    // RFID: the reader's version, printed as `dpctl rfid` prints it.
    let out = via(&sock, &["rfid", "--slave", "12", "VER"]);
    assert!(ok(&out).starts_with("> VER\n"), "{}", out.stdout);
    // DP-V1 record write and read over the master's MSAC_C1.
    let out = via(
        &sock,
        &[
            "dpv1", "--slave", "10", "--slot", "1", "--index", "7", "write", "CA FE",
        ],
    );
    assert_eq!(ok(&out).trim(), "slave 10 slot 1 index 7: written");
    let out = via(
        &sock,
        &[
            "dpv1", "--slave", "10", "--slot", "1", "--index", "7", "read", "--length", "2",
        ],
    );
    assert_eq!(ok(&out).trim(), "slave 10 slot 1 index 7: 2 bytes CA FE");
    // I&M0 over class 1.
    let out = via(&sock, &["im", "--slave", "10", "--json"]);
    let im: Value = serde_json::from_str(ok(&out).trim()).unwrap();
    assert_eq!(im["class"], 1);
    assert!(im["im0"]["order_id"].is_string(), "{im}");
    // Diagnosis and configuration: the master owns the slave.
    let out = via(&sock, &["diag", "--slave", "10", "--json"]);
    let d: Value = serde_json::from_str(ok(&out).trim()).unwrap();
    assert_eq!(
        (d["address"].clone(), d["owner"].clone()),
        (json!(10), json!(1)),
        "{d}"
    );
    let out = via(
        &sock,
        &[
            "get-cfg",
            "--slave",
            "10",
            "--json",
            "--gsd",
            &generic_gsd().display().to_string(),
        ],
    );
    let c: Value = serde_json::from_str(ok(&out).trim()).unwrap();
    assert_eq!(c["modules"], json!(["2 words in/out"]), "{c}");

    // What the master cannot serve, in one line.
    let out = via(&sock, &["im", "--slave", "6"]);
    assert_eq!(
        out.stderr.trim(),
        "dpctl: slave 6 is not a DP-V1 slave in the bus file (its GSD has no DPV1_Slave=1)"
    );
    let out = via(&sock, &["dpv1", "--slave", "10", "--class2", "read"]);
    assert!(
        out.stderr.trim().starts_with("dpctl: --via ") && out.stderr.contains("--class2"),
        "{}",
        out.stderr
    );
    // Writes only to writable slaves: the reader is not listed.
    let a = ask(&sock, &json!({"slave": 12, "outputs": "00"}));
    assert!(
        a["error"]
            .as_str()
            .unwrap()
            .contains("slave 12 is not writable"),
        "{a}"
    );
    let out = via(&sock, &["rfid", "--slave", "12", "WD 0 AABB"]);
    assert!(
        out.stderr.contains("refused: slave 12 is not writable"),
        "{}",
        out.stderr
    );
    // A writable slave takes outputs; a raw job answers with its data.
    let a = ask(&sock, &json!({"slave": 10, "outputs": "00 01 00 02"}));
    assert_eq!(a, json!({"ok": true}));
    let a = ask(&sock, &json!({"read_diag": 10}));
    assert_eq!(a["ok"], true, "{a}");
    assert!(a["data"].is_string(), "{a}");

    // The port is held: a command opening it names the master.
    let out = run_dpctl(&[
        "pkw",
        "--port",
        &bus.link_str(0),
        "--config",
        &cfg.display().to_string(),
        "--slave",
        "6",
        "read",
        "1",
    ]);
    assert!(!out.status.success());
    let err = out.stderr.trim();
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains(&format!(
            "dpctl process {} (dpctl master --json",
            master.pid()
        )) && err.contains(&format!("--via {}", sock.display())),
        "{err}"
    );

    // The master's own status lines: every slave in Data_Exchange all
    // along, none started up again.
    let last = status(
        &mut lines,
        &mut seen,
        "a status line after the jobs",
        |v| assert!(all_dx(v), "a slave left Data_Exchange: {v}"),
        |_| true,
    );
    assert_eq!(restarts(&last), restarts0, "{last}");
    assert!(master.terminate(Duration::from_secs(10)).success());
    assert!(!sock.exists(), "the socket is removed on exit");
}

#[test]
fn a_read_only_gateway_socket_serves_reads_and_refuses_writes() {
    let dir = TempDir::new("control-gateway");
    let bus = Bus::start(4, &[]);
    let _slaves = slaves(&bus);
    let port = free_port();
    let _broker = broker(&dir, port);
    let cfg = bus_file(&dir, "writable = [6, 10]");
    let sock = dir.path("gw.sock");
    let _gw = Proc::spawn(
        "dpctl gateway",
        Command::new(dpctl())
            .args(["gateway", "--latency", "20", "--port", &bus.link_str(0)])
            .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}"), "--config"])
            .arg(&cfg)
            .arg("--control")
            .arg(&sock)
            .arg("--control-readonly")
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    common::wait_for("the control socket", WAIT, || sock.exists());
    common::wait_for("slave 10 in Data_Exchange", WAIT, || {
        let s = ask(&sock, &json!({"status": true}));
        s["slaves"].as_array().is_some_and(|a| {
            a.iter()
                .any(|x| x["address"] == 10 && x["state"] == "data_exchange")
        })
    });
    let out = via(&sock, &["diag", "--slave", "10"]);
    assert!(
        ok(&out).starts_with("slave 10: Slave_Diag "),
        "{}",
        out.stdout
    );
    // Writable in the bus file, but the socket is read-only.
    let a = ask(&sock, &json!({"slave": 10, "outputs": "00 01 00 02"}));
    assert!(
        a["error"]
            .as_str()
            .unwrap()
            .contains("read-only control socket"),
        "{a}"
    );
    let out = via(&sock, &["pkw", "--slave", "6", "write", "u_MyWriteVar2=5"]);
    assert!(
        out.stderr.contains("read-only control socket"),
        "{}",
        out.stderr
    );
}
