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
