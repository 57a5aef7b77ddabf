//! `dpctl gateway --port` stopped by SIGTERM on a real line (`dpctl
//! bus`, a `dpctl slave` process, a real mosquitto): the master's
//! farewell reaches the slave (Global_Control Clear_Data, outputs in
//! their safe state at once, seconds before the slave's 5 s watchdog),
//! before the gateway's offline status reaches the broker and before it
//! exits with status 0. Fails (never skips) when mosquitto or its
//! clients are missing: run `scripts/setup-test-env`.

mod common;

use common::mqtt::{broker, free_port, subscribe, write_bus};
use common::{dpctl, generic_slave, wall, Bus, Proc, TempDir, Timed};
use std::process::{Command, Stdio};
use std::time::Duration;

/// Generous: processes on a loaded 2-core machine.
const WAIT: Duration = Duration::from_secs(60);

#[test]
fn a_terminated_gateway_clears_its_slaves_before_it_goes_offline() {
    let dir = TempDir::new("gw-farewell");
    let port = free_port();
    let _mosq = broker(&dir, port);
    let line = Bus::start(2, &[]);
    let mut slave = Proc::spawn(
        "dpctl slave",
        generic_slave(line.link(1), 3, "1.5M", &["2 words in/out"])
            .arg("--json")
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut events = Timed::from(&mut slave);
    let bus = write_bus(
        &dir,
        "[master]\naddress = 1\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 3\n\
         gsd = \"DPCTL_GEN.GSD\"\nmodules = [\"2 words in/out\"]\nwatchdog_ms = 5000\n\n\
         [mqtt]\nbus = \"line\"\nwritable = [3]\n",
    );
    // The status topic with the time each message arrived (%U: Unix time).
    let (_sub, mut status) = subscribe(
        port,
        &[
            "-t",
            "profibus/line/status",
            "-t",
            "profibus/line/3/inputs",
            "-t",
            "probe/#",
            "-F",
            "%U %t %p",
        ],
        &[],
        "probe/farewell",
    );
    let gw = Proc::spawn_captured({
        let mut c = Command::new(dpctl());
        c.args(["gateway", "--config"])
            .arg(&bus)
            .args(["--port", &line.link_str(0)])
            .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")]);
        c
    });

    // Outputs written over MQTT come back as the echo's inputs: the
    // line is in use.
    assert!(
        status.wait_for(r#""state":"online""#, WAIT),
        "{:#?}",
        status.1
    );
    let set = Command::new("mosquitto_pub")
        .args(["-h", "127.0.0.1", "-p", &port.to_string()])
        .args(["-t", "profibus/line/3/outputs/set"])
        .args(["-m", r#"{"hex": "12345678"}"#])
        .status()
        .unwrap();
    assert!(set.success());
    assert!(
        status.wait_for(r#""hex":"12345678""#, WAIT),
        "the echo never came back: {:#?}",
        status.1
    );
    events.wait("slave 3 in Data_Exchange", |v| v["event"] == "state");

    let asked = wall();
    gw.signal(15);
    let out = gw.finish(Duration::from_secs(10));
    let ended = wall();
    assert!(out.status.success(), "gateway: {}", out.stderr);
    assert!(
        ended - asked < 3.0,
        "the gateway took {:.2} s to stop",
        ended - asked
    );
    // Its log: the master went to Clear after the stop began.
    let at = |l: &str| {
        out.stderr
            .find(l)
            .unwrap_or_else(|| panic!("no `{l}` in:\n{}", out.stderr))
    };
    assert!(at("INFO dpctl::ops: stopping") < at("master now in clear"));
    assert!(at("master now in clear") < at("dpctl gateway stopped"));

    // The slave clears its outputs because of the Global_Control, not
    // its watchdog (5 s), and reports the command.
    let (_, cleared) = events.wait("outputs in the safe state", |v| {
        v["event"] == "outputs_cleared" || v["event"] == "watchdog"
    });
    assert_eq!(cleared["event"], "outputs_cleared", "{cleared}");
    assert_eq!(cleared["reason"], "Global_Control Clear_Data", "{cleared}");
    let (_, g) = events.wait("Global_Control Clear_Data", |v| {
        v["event"] == "global_control" && v["command"].as_str().is_some_and(|c| c.contains("Clear"))
    });
    assert_eq!(g["master"], 1, "{g}");
    let cleared_at = cleared["t"].as_f64().unwrap() + events.offset();
    assert!(
        cleared_at <= ended + 0.05,
        "cleared {:.3} s after the gateway ended",
        cleared_at - ended
    );

    // The offline status was published after the farewell.
    assert!(
        status.wait_for(r#""state":"offline""#, WAIT),
        "no offline status: {:#?}",
        status.1
    );
    let l = status
        .1
        .iter()
        .rev()
        .find(|l| l.contains(r#""state":"offline""#));
    let offline_at: f64 = l.unwrap().split(' ').next().unwrap().parse().unwrap();
    assert!(
        cleared_at <= offline_at + 0.05,
        "the offline status came {:.3} s before the slave was cleared",
        cleared_at - offline_at
    );
    drop(slave);
    line.stop();
}
