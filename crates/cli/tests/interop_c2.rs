//! DP-V1 class 2 (MSAC_C2) against independent peers (issue 28): a raw
//! class-2 client and a scripted raw class-2 slave in Python
//! (tests/interop/raw_c2_client.py, raw_c2_slave.py, with raw_c2.py and
//! raw_fdl.py), written from the wire reference alone
//! (shared/reference/dpv1-c2-im-alarms.md, profibus-dp.md), not from this
//! stack's code.
//!
//! The two peers first run against each other, so that a failure against
//! `dpctl` is not a fault of the peers. Each pair of stations shares a
//! socat pty pair; the Python client is the only active station there.
//!
//! Needs python3 (standard library only) and socat; the tests fail when
//! they are missing (scripts/setup-test-env installs them).

mod common;

use common::{pty_pair, repo, require, Lines, Proc, TempDir};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

/// A finished run of raw_c2_client.py: exit success, its JSON step
/// lines, its stderr.
struct ClientRun {
    ok: bool,
    steps: Vec<Value>,
    stderr: String,
}

impl ClientRun {
    /// The line of `step`; fails with the whole run when it is missing.
    fn step(&self, step: &str) -> &Value {
        self.steps
            .iter()
            .find(|v| v["step"] == step)
            .unwrap_or_else(|| panic!("no step {step}: {:?} {}", self.steps, self.stderr))
    }
}

fn python() -> &'static str {
    require("python3");
    "python3"
}

/// Run raw_c2_client.py on `port` against station 8 with `args` to its
/// end (at most 90 s).
fn client(port: &Path, args: &[&str]) -> ClientRun {
    let mut cmd = Command::new(python());
    cmd.arg(repo().join("tests/interop/raw_c2_client.py"))
        .arg("--port")
        .arg(port)
        .args(["--slave", "8"])
        .args(args);
    let out = Proc::spawn_captured(cmd).finish(Duration::from_secs(90));
    let steps = out
        .stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON: {l}: {e}")))
        .collect();
    ClientRun {
        ok: out.status.success(),
        steps,
        stderr: out.stderr,
    }
}

/// raw_c2_slave.py at address 8 on `port` with `args`; returns once its
/// port is open.
fn scripted_slave(port: &Path, args: &[&str]) -> (Proc, Lines) {
    let mut p = Proc::spawn(
        "raw_c2_slave.py",
        Command::new(python())
            .arg(repo().join("tests/interop/raw_c2_slave.py"))
            .arg("--port")
            .arg(port)
            .args(["--addr", "8"])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit()),
    );
    let mut lines = Lines::from(&mut p);
    assert!(
        lines.wait_for("\"event\": \"ready\"", Duration::from_secs(20)),
        "raw_c2_slave.py did not start: {:?}",
        lines.1
    );
    (p, lines)
}

/// The JSON lines the scripted slave logged so far (after `wait_for`).
fn slave_events(lines: &Lines) -> Vec<Value> {
    lines
        .1
        .iter()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// The full sequence of the client (Initiate, RM, polls until
/// Initiate.res, I&M0 through the call header, a record written and read
/// back, Data_Transport, Idles across more than Send_Timeout, Abort, the
/// SAP refused afterwards) against the scripted slave, with the RM reply
/// in either of the two ways the sources describe.
#[test]
fn raw_client_and_scripted_slave_agree_on_the_whole_connection() {
    for rm in ["poll", "immediate"] {
        let dir = TempDir::new("c2-peers");
        let (a, b) = (dir.path("client"), dir.path("slave"));
        let _socat = pty_pair(&a, &b);
        let (_slave, mut log) = scripted_slave(
            &b,
            &["--rm", rm, "--order-id", "PEER-ORDER", "--serial", "S-42"],
        );
        let run = client(
            &a,
            &[
                "--send-timeout",
                "100",
                "--slot",
                "1",
                "--index",
                "7",
                "--data",
                "0A 0B 0C",
                "--transport",
                "01 02 03",
                "--idle-for",
                "1.5",
            ],
        );
        assert!(run.ok, "rm {rm}: {}\n{:?}", run.stderr, run.steps);
        let init = run.step("initiate");
        assert_eq!(init["request"].as_str().unwrap().len(), 20 * 3 - 1);
        assert_eq!(init["sap"], 48, "the highest connection SAP first");
        assert_eq!(run.step("connect")["max_len_data_unit"], 240);
        let im0 = run.step("im0");
        assert_eq!(im0["order_id"], "PEER-ORDER");
        assert_eq!(im0["serial_number"], "S-42");
        assert_eq!(im0["software_revision"], "V1.2.3");
        assert_eq!(run.step("read")["data"], "0A 0B 0C");
        assert_eq!(run.step("transport")["data"], "03 02 01");
        // 1.5 s of Idles every 0.5 s kept a 1 s Send_Timeout connection.
        assert!(run.step("idle")["idles"].as_u64().unwrap() >= 3);
        assert_eq!(run.step("closed")["refused"], "RS");
        run.step("done");
        assert!(log.wait_for("Abort received", Duration::from_secs(10)));
        let ev = slave_events(&log);
        let abort = ev
            .iter()
            .find(|v| v["event"] == "abort" && v["direction"] == "received")
            .expect("the slave logged the Abort");
        assert_eq!(abort["instance"], "User");
        assert!(
            !ev.iter()
                .any(|v| v["event"] == "abort" && v["direction"] == "sent"),
            "the slave aborted: {ev:?}"
        );
    }
}

/// The scripted slave's Send_Timeout supervision and STO refusal, as the
/// client sees them: silence longer than Send_Timeout ends the connection
/// (Abort TO on the next request); a Send_Timeout below the slave's
/// minimum is refused with Abort STO, and the client says so in words.
#[test]
fn scripted_slave_aborts_a_silent_connection_and_refuses_a_short_send_timeout() {
    let dir = TempDir::new("c2-timeout");
    let (a, b) = (dir.path("client"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    let (_slave, mut log) = scripted_slave(&b, &["--min-send-timeout", "100"]);
    let run = client(
        &a,
        &["--send-timeout", "100", "--no-im", "--silent-for", "1.6"],
    );
    assert!(run.ok, "{}\n{:?}", run.stderr, run.steps);
    let refused = run.step("silent")["refused"].as_str().unwrap().to_string();
    assert!(refused.contains("TO (connection timeout)"), "{refused}");
    assert!(log.wait_for("Send_Timeout", Duration::from_secs(10)));

    let run = client(&a, &["--send-timeout", "50"]);
    assert!(!run.ok);
    assert!(
        run.stderr
            .contains("initiate: the slave aborted: Abort by MSAC_C2: STO"),
        "{}",
        run.stderr
    );
}

/// Python on a loaded machine: room on the slot time for its scheduling.
/// A retry of a first request (FCV=0) cannot be told from a new one by
/// the slave, so a retried Initiate.req would open a second connection.
const LATENCY: [&str; 2] = ["--latency", "200"];

/// Run `dpctl` with `args` to its end (at most 90 s): (success, stdout,
/// stderr).
fn run_dpctl(args: &[&str]) -> (bool, String, String) {
    let out = common::run_dpctl(args);
    (out.status.success(), out.stdout, out.stderr)
}

/// `dpctl dpv1 --class2 … --json` against station 8 on `port`: its
/// JSON object.
fn dpv1_class2(port: &Path, args: &[&str]) -> Value {
    let port = port.to_str().unwrap();
    let mut all = vec!["dpv1", "--class2", "--port", port, "--slave", "8", "--json"];
    all.extend_from_slice(&LATENCY);
    all.extend_from_slice(args);
    let (_, stdout, stderr) = run_dpctl(&all);
    serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("{all:?}: not one JSON object: {e}: {stdout} {stderr}"))
}

/// Our class-2 master (`dpctl dpv1 --class2`) against the scripted
/// slave, with the RM reply in either of the two ways the sources
/// describe: a preset record read, a record written and read back,
/// Data_Transport; every connection initiated once and closed with an
/// Abort of instance User.
#[test]
fn dpctl_dpv1_class2_reads_writes_and_transports_with_the_scripted_slave() {
    for rm in ["poll", "immediate"] {
        let dir = TempDir::new("c2-dpv1");
        let (a, b) = (dir.path("master"), dir.path("slave"));
        let _socat = pty_pair(&a, &b);
        let (_slave, mut log) = scripted_slave(&b, &["--rm", rm, "--record", "1:7=CAFE"]);
        let v = dpv1_class2(
            &a,
            &["--slot", "1", "--index", "7", "read", "--length", "2"],
        );
        assert_eq!(
            (&v["ok"], &v["data"]),
            (&Value::Bool(true), &"CA FE".into()),
            "rm {rm}: {v}"
        );
        let v = dpv1_class2(&a, &["--slot", "2", "--index", "9", "write", "01 02 03"]);
        assert_eq!(v["ok"], true, "rm {rm}: {v}");
        let v = dpv1_class2(&a, &["--slot", "2", "--index", "9", "read"]);
        assert_eq!(v["data"], "01 02 03", "rm {rm}: {v}");
        let v = dpv1_class2(&a, &["--slot", "2", "--index", "9", "transport", "0A 0B"]);
        assert_eq!(v["data"], "0B 0A", "rm {rm}: {v}");
        // Four commands: four connections, each initiated once (a second
        // Initiate.req would ask for a second connection) and aborted.
        let aborts = |log: &Lines| {
            slave_events(log)
                .iter()
                .filter(|v| v["event"] == "abort" && v["direction"] == "received")
                .count()
        };
        common::wait_for("four Aborts", Duration::from_secs(20), || {
            log.wait_for("\"never\"", Duration::from_millis(50));
            aborts(&log) >= 4
        });
        let ev = slave_events(&log);
        let initiates: Vec<&Value> = ev
            .iter()
            .filter(|v| v["event"] == "rx" && v["service"] == "initiate")
            .collect();
        assert_eq!(initiates.len(), 4, "rm {rm}: {initiates:?}");
        for i in &initiates {
            let pdu = i["pdu"].as_str().unwrap();
            assert!(pdu.starts_with("57 00 00 00 "), "{pdu}");
            assert!(
                pdu.ends_with(" 00 02 00 02 00 00 00 00"),
                "type 0 addresses: {pdu}"
            );
        }
        assert!(
            ev.iter().all(|v| v["event"] != "initiate_refused"),
            "{ev:?}"
        );
        assert!(
            ev.iter()
                .filter(|v| v["event"] == "abort" && v["direction"] == "received")
                .all(|v| v["instance"] == "User"),
            "{ev:?}"
        );
    }
}

/// `dpctl im --class2` against the scripted slave: I&M0 in fields, I&M1
/// written with `--write-tag` and read back, I&M2..4 as the slave keeps
/// them.
#[test]
fn dpctl_im_class2_reads_im0_and_writes_the_tag_of_the_scripted_slave() {
    let dir = TempDir::new("c2-im");
    let (a, b) = (dir.path("master"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    let (_slave, _log) = scripted_slave(
        &b,
        &[
            "--order-id",
            "PEER-ORDER",
            "--serial",
            "S-42",
            "--manufacturer-id",
            "0x011E",
        ],
    );
    let port = a.to_str().unwrap();
    let (ok, stdout, stderr) = run_dpctl(&[
        "im",
        "--class2",
        "--port",
        port,
        "--slave",
        "8",
        "--json",
        "--write-tag",
        "pump 3",
        "hall B",
        LATENCY[0],
        LATENCY[1],
    ]);
    assert!(ok, "{stdout} {stderr}");
    let v: Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(v["class"], 2, "{v}");
    let im0 = &v["im0"];
    assert_eq!(im0["order_id"], "PEER-ORDER", "{v}");
    assert_eq!(im0["serial_number"], "S-42", "{v}");
    assert_eq!(im0["manufacturer_id"], 0x011E, "{v}");
    assert_eq!(im0["software_revision"], "V1.2.3", "{v}");
    assert_eq!(im0["im_supported"]["raw"], "0x001E", "{v}");
    assert_eq!(v["im1"]["tag_function"], "pump 3", "{v}");
    assert_eq!(v["im1"]["tag_location"], "hall B", "{v}");
    assert_eq!(v["im2"]["installation_date"], "", "{v}");
}

/// Aborts and silence of the independent slave, in words: a
/// Send_Timeout below the slave's minimum is refused with Abort STO; a
/// slave that falls silent after Initiate.res gives a timeout, not a hang.
#[test]
fn dpctl_dpv1_class2_reports_the_scripted_slaves_abort_and_silence_in_words() {
    let dir = TempDir::new("c2-abort");
    let (a, b) = (dir.path("master"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    {
        let (_slave, _log) = scripted_slave(&b, &["--min-send-timeout", "1000"]);
        let v = dpv1_class2(&a, &["--send-timeout", "2000", "read"]);
        assert_eq!(v["ok"], false, "{v}");
        let e = v["error"].as_str().unwrap();
        assert!(
            e.contains("aborted by MSAC_C2: Send_Timeout too small (STO)"),
            "{e}"
        );
    }
    // Initiate (SC), RM poll, one poll SC, Initiate.res, Read.req (SC);
    // then nothing more.
    let (_slave, _log) = scripted_slave(&b, &["--mute-after", "5"]);
    let v = dpv1_class2(
        &a,
        &[
            "--send-timeout",
            "1000",
            "--response-timeout",
            "2000",
            "read",
        ],
    );
    assert_eq!(v["ok"], false, "{v}");
    let e = v["error"].as_str().unwrap();
    assert!(e.contains("answer"), "{e}");
}

/// `dpctl slave` emulating tests/data/C2PEER.GSD (DP-V1 with class 2, two
/// channels).
fn dpctl_c2_slave(port: &Path) -> (Proc, Lines) {
    let gsd = repo().join("crates/cli/tests/data/C2PEER.GSD");
    let mut p = Proc::spawn(
        "dpctl slave",
        Command::new(common::dpctl())
            .args(["slave", "--port"])
            .arg(port)
            .args(["--addr", "8", "--gsd"])
            .arg(&gsd)
            .args(["--module", "2 words in/out", "--json"])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit()),
    );
    let lines = common::started(&mut p, Duration::from_secs(20));
    (p, lines)
}

/// The independent client against `dpctl slave`: I&M0 from the GSD
/// (OrderNumber, Hardware_Release, Software_Release), a record written
/// and read back over class 2, Idles across more than half of
/// Send_Timeout, Abort, the SAP refused afterwards. Send_Timeout 8 s: the
/// slave's minimum below 500 kbit/s is 4 s (reference §4.4, [VPC3]).
#[test]
fn raw_client_reads_im0_and_a_record_of_dpctl_slave() {
    let dir = TempDir::new("c2-dpctl-slave");
    let (a, b) = (dir.path("client"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    let (_slave, mut out) = dpctl_c2_slave(&b);
    let run = client(
        &a,
        &[
            "--send-timeout",
            "800",
            "--slot",
            "1",
            "--index",
            "3",
            "--data",
            "11 22 33 44 55",
            "--idle-for",
            "1",
        ],
    );
    assert!(run.ok, "{}\n{:?}", run.stderr, run.steps);
    assert!(run.step("initiate")["sap"].as_u64().unwrap() <= 48);
    let im0 = run.step("im0");
    assert_eq!(im0["order_id"], "DPCTL-C2-PEER", "{im0}");
    assert_eq!(im0["hardware_revision"], 3, "{im0}");
    assert_eq!(im0["software_revision"], "V1.2.3", "{im0}");
    assert_eq!(run.step("read")["data"], "11 22 33 44 55");
    run.step("abort");
    run.step("closed");
    run.step("done");
    assert!(
        out.wait_for("closed by the master", Duration::from_secs(10)),
        "{:?}",
        out.1
    );
}

/// `dpctl slave`'s Send_Timeout supervision seen from the independent
/// client: after silence longer than Send_Timeout (4 s, the slave's
/// minimum at 19.2 kbit/s) the next Idle is refused.
#[test]
fn dpctl_slave_drops_a_class2_connection_whose_master_falls_silent() {
    let dir = TempDir::new("c2-dpctl-silent");
    let (a, b) = (dir.path("client"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    let (_slave, mut out) = dpctl_c2_slave(&b);
    let run = client(
        &a,
        &["--send-timeout", "400", "--no-im", "--silent-for", "4.8"],
    );
    assert!(run.ok, "{}\n{:?}", run.stderr, run.steps);
    let refused = run.step("silent")["refused"].as_str().unwrap().to_string();
    assert!(refused.contains("TO"), "{refused}");
    assert!(
        out.wait_for("connection timeout (TO)", Duration::from_secs(10)),
        "{:?}",
        out.1
    );
}

/// A Send_Timeout below the slave's minimum is refused with Abort STO,
/// and the independent client says so.
#[test]
fn dpctl_slave_refuses_a_send_timeout_below_its_minimum() {
    let dir = TempDir::new("c2-dpctl-sto");
    let (a, b) = (dir.path("client"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    let (_slave, _out) = dpctl_c2_slave(&b);
    let run = client(&a, &["--send-timeout", "300"]);
    assert!(!run.ok);
    assert!(
        run.stderr
            .contains("initiate: the slave aborted: Abort by MSAC_C2: STO"),
        "{}",
        run.stderr
    );
}
