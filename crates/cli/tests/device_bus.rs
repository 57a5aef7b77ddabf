//! A bus file that names a device profile (`device = "omega"` plus its
//! options) end to end: `dpctl master` configures the slave from the
//! profile, shows its named channels and takes outputs by channel name;
//! `dpctl slave --device omega` on the other end of a socat pty pair.
//! (A file of its own: its processes do not run next to the other
//! profile tests.)

mod common;

use common::*;
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::Duration;

const BUS: &str = "[master]
address = 2
baud = \"1.5M\"

[[slave]]
address = 25
device = \"omega\"
setpoints = 2
actual_values = 2
watchdog_ms = 1000
";

const COMMANDS: &str = r#"{"slave": 25, "set": {"setpoint1": 1234, "setpoint2": -5}}
{"slave": 25, "set": {"nope": 1}}
"#;

#[test]
fn the_master_shows_and_sets_the_channels_of_a_profile_slave() {
    let dir = TempDir::new("device-bus");
    let (master_end, slave_end) = (dir.path("m"), dir.path("s"));
    let _socat = pty_pair(&master_end, &slave_end);
    let mut slave = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args([
                "slave", "--device", "omega", "--addr", "25", "--json", "--port",
            ])
            .arg(&slave_end)
            // The drive enables itself: no PLC enable sequence here.
            .args(["--device-opt", "drive-enable=auto"])
            .stdout(Stdio::piped())
            .stdin(Stdio::null()),
    );
    let _slave_out = started(&mut slave, Duration::from_secs(10));
    let (bus, cmds) = (dir.path("bus.toml"), dir.path("cmds.jsonl"));
    std::fs::write(&bus, BUS).unwrap();
    std::fs::write(&cmds, COMMANDS).unwrap();
    let out = run_ok(
        Command::new(dpctl())
            // Until 60 Data_Exchange cycles, however long the start-up takes
            // on a busy machine; late replies within 100 ms are not lost ones.
            .args(["master", "--exchanges", "60", "--timeout", "120"])
            .args(["--latency", "100", "--json", "--port"])
            .arg(&master_end)
            .arg("--config")
            .arg(&bus)
            .arg("--input")
            .arg(&cmds),
    );
    let lines = json_lines(String::from_utf8_lossy(&out.stdout).lines());
    assert!(
        lines
            .iter()
            .any(|v| v["event"] == "state" && v["slave"] == 25 && v["to"] == "data_exchange"),
        "{lines:?}"
    );
    // The last inputs received: the drive follows its setpoints (actual
    // value i = setpoint i) and reports Remote, operation enabled and
    // setpoint reached in status word 1.
    let st = lines.iter().rev().find(|v| v["event"] == "status").unwrap();
    let ch = &st["slaves"][0]["channels"];
    assert_eq!(ch["outputs"]["setpoint1"], 1234, "{ch}");
    assert_eq!(ch["inputs"]["actual1"], 1234, "{ch}");
    assert_eq!(ch["inputs"]["actual2"], -5, "{ch}");
    assert_eq!(ch["inputs"]["status1"], 0x0637, "{ch}");
    // A wrong channel name is refused with the name, nothing written.
    assert!(
        lines
            .iter()
            .any(|v| v["event"] == "error" && v["error"].as_str().unwrap().contains("`nope`")),
        "{lines:?}"
    );
    // In words: a line of `name=value` under the slave.
    let out = run_ok(
        Command::new(dpctl())
            .args(["master", "--exchanges", "60", "--timeout", "120"])
            .args(["--latency", "100", "--port"])
            .arg(&master_end)
            .arg("--config")
            .arg(&bus),
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.lines().any(|l| l.trim_start().starts_with("in: pke=")
            && l.contains(" status1=")
            && l.contains("out: pke=")),
        "{text}"
    );
    assert!(slave.terminate(Duration::from_secs(10)).success());
}

#[test]
fn profile_options_from_the_command_line_are_typed_and_checked() {
    let slave = |args: &[&str]| {
        Command::new(dpctl())
            .args(["slave", "--port", "/nonexistent/x", "--addr", "25"])
            .args(args)
            .output()
            .unwrap()
    };
    // Every registered profile is listed, with its options.
    let o = Command::new(dpctl())
        .args(["slave", "--list-devices"])
        .output()
        .unwrap();
    let list = String::from_utf8_lossy(&o.stdout);
    for name in ["generic", "bm4", "omega"] {
        assert!(list.lines().any(|l| l.starts_with(name)), "{list}");
    }
    // A key the profile does not have, a value of the wrong type, and
    // contradicting options: exit 1 with one line naming the problem.
    for (args, needle) in [
        (
            vec!["--device", "omega", "--device-opt", "no-such=1"],
            "no_such",
        ),
        (
            vec!["--device", "omega", "--device-opt", "setpoints=many"],
            "many",
        ),
        (
            vec!["--device", "omega", "--device-opt", "setpoints=2"],
            "--actual-values",
        ),
        (
            vec!["--device", "omega", "--device-opt", "switch=0x80"],
            "0x80",
        ),
    ] {
        let o = slave(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

#[test]
fn a_bm4_slave_of_a_bus_file_answers_pkw_by_variable_name() {
    let dir = TempDir::new("device-bus-bm4");
    let (master_end, slave_end) = (dir.path("m"), dir.path("s"));
    let _socat = pty_pair(&master_end, &slave_end);
    let mut slave = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--device", "bm4", "--addr", "6", "--json"])
            .args(["--device-opt", "example=true", "--port"])
            .arg(&slave_end)
            .stdout(Stdio::piped())
            .stdin(Stdio::null()),
    );
    let _slave_out = started(&mut slave, Duration::from_secs(10));
    // The master side from the same profile: the example table, PKW
    // module first, two of its variables.
    let bus = dir.path("bus.toml");
    std::fs::write(
        &bus,
        "[master]\naddress = 2\nbaud = \"1.5M\"\n[[slave]]\naddress = 6\ndevice = \"bm4\"\nexample = true\nvariables = [\"ud_MyReadVar1\", \"u_MyWriteVar2\"]\n",
    )
    .unwrap();
    let out = Command::new(dpctl())
        .args(["pkw", "--slave", "6", "--json", "--port"])
        .arg(&master_end)
        .arg("--config")
        .arg(&bus)
        .args(["read", "di_MyReadVar3"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_str(stdout.lines().next().unwrap()).unwrap();
    assert_eq!(v["request"], "1004 0000 0000 0000", "{v}");
    assert_eq!(v["value"], 3000, "{v}");
    assert!(slave.terminate(Duration::from_secs(10)).success());
}
