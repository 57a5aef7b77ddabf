//! `dpctl sniff --json` decodes the DP layer of what it overhears: on a
//! `dpctl bus` with `dpctl master` and a `dpctl slave`, every DP service
//! of the start-up, the cycle and the master's class-2 and DP-V1 jobs
//! comes with its `"dp"` object.

mod common;

use common::{dpctl, repo, send, Bus, Proc};
use serde_json::{json, Value};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// What the sniffer must show, each a check of one JSON line.
type Check = (&'static str, fn(&Value) -> bool);

fn dp(v: &Value, service: &str, direction: &str) -> bool {
    v["dp"]["service"] == service && v["dp"]["direction"] == direction
}

const CHECKS: &[Check] = &[
    ("Set_Prm request", |v| {
        dp(v, "Set_Prm", "request")
            && v["dp"]["ident_number"] == 0x0DCE
            && v["dp"]["watchdog_ms"] == 5000
            && v["dp"]["groups"] == json!([])
            && v["dp"]["station_status"]
                .as_array()
                .is_some_and(|s| s.contains(&json!("WD_On")))
            && v["dp"]["user_prm_data"].is_string()
    }),
    ("Set_Prm acknowledged", |v| {
        dp(v, "Set_Prm", "response") && v["type"] == "short_ack"
    }),
    ("Chk_Cfg request", |v| {
        dp(v, "Chk_Cfg", "request")
            && v["dp"]["identifiers"]
                == json!([{"raw": "71", "text": "2 words in+out", "input_bytes": 4, "output_bytes": 4}])
    }),
    ("Slave_Diag response", |v| {
        dp(v, "Slave_Diag", "response")
            && v["dp"]["ident_number"] == 0x0DCE
            && v["dp"]["status"].is_array()
            && v["dp"]["valid"] == true
    }),
    ("Get_Cfg response", |v| {
        dp(v, "Get_Cfg", "response") && v["dp"]["identifiers"][0]["raw"] == "71"
    }),
    ("Data_Exchange request", |v| {
        dp(v, "Data_Exchange", "request") && v["dp"]["outputs"] == "01 02 03 04"
    }),
    // Split by the module of the Chk_Cfg the sniffer saw.
    ("Data_Exchange request by module", |v| {
        dp(v, "Data_Exchange", "request")
            && v["dp"]["modules"]
                == json!([{"slot": 1, "name": "2 words in+out", "data": "01 02 03 04"}])
    }),
    ("Data_Exchange response", |v| {
        dp(v, "Data_Exchange", "response") && v["dp"]["inputs"] == "01 02 03 04"
    }),
    ("Global_Control", |v| {
        dp(v, "Global_Control", "request") && v["dp"]["command"].is_array()
    }),
    ("Rd_Inp response", |v| {
        dp(v, "Rd_Inp", "response") && v["dp"]["inputs"] == "01 02 03 04"
    }),
    ("DP-V1 write request", |v| {
        dp(v, "MSAC_C1", "request")
            && v["dp"]["pdu"] == "Write"
            && v["dp"]["slot"] == 1
            && v["dp"]["index"] == 7
            && v["dp"]["data"] == "CA FE"
    }),
    ("DP-V1 read response", |v| {
        dp(v, "MSAC_C1", "response") && v["dp"]["pdu"] == "Read" && v["dp"]["data"] == "CA FE"
    }),
];

#[test]
fn sniff_json_decodes_the_dp_layer_of_each_service() {
    let bus = Bus::start(3, &[]);
    let mut cmd = Command::new(dpctl());
    cmd.args(["sniff", "--json", "--port", &bus.link_str(2)]);
    let sniff = Proc::spawn_captured(cmd);
    // The sniffer listens once the hub sees its pty open.
    bus.wait_connected(1);
    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let _slave = Proc::spawn(
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
            "[master]\naddress = 2\nbaud = \"1.5M\"\n[options]\nlost_after = 20\n\
             [[slave]]\naddress = 10\ngsd = \"{}\"\n\
             modules = [\"2 words in/out\"]\nwatchdog_ms = 5000\ninitial_outputs = [1, 2, 3, 4]\n",
            gsd.display()
        ),
    )
    .unwrap();
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--input", "-", "--latency", "20"])
            .args(["--port", &bus.link_str(0), "--config"])
            .arg(&config)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    let mut seen: Vec<Value> = vec![];
    let mut missing: Vec<&Check> = CHECKS.iter().collect();
    let mut jobs_sent: Option<Instant> = None;
    let end = Instant::now() + Duration::from_secs(90);
    while !missing.is_empty() {
        let left = end.saturating_duration_since(Instant::now());
        let Some(l) = sniff.stdout_line(left) else {
            let names: Vec<&str> = missing.iter().map(|c| c.0).collect();
            let tail = &seen[seen.len().saturating_sub(20)..];
            panic!("dpctl sniff never showed {names:?}; last lines: {tail:#?}");
        };
        let v: Value = serde_json::from_str(&l).unwrap_or_else(|e| panic!("{e}: {l}"));
        missing.retain(|c| !(c.1)(&v));
        // In Data_Exchange: the class-2 and DP-V1 jobs (again when one
        // failed on a loaded machine and its answer never came).
        let resend = jobs_sent.is_some_and(|t| t.elapsed() > Duration::from_secs(10));
        if (jobs_sent.is_none() || resend) && dp(&v, "Data_Exchange", "response") {
            jobs_sent = Some(Instant::now());
            for job in [
                r#"{"get_cfg": 10}"#,
                r#"{"rd_inp": 10}"#,
                r#"{"dpv1_write": 10, "slot": 1, "index": 7, "data": "CA FE"}"#,
                r#"{"dpv1_read": 10, "slot": 1, "index": 7, "length": 2}"#,
            ] {
                send(&mut master, job);
            }
        }
        seen.push(v);
    }
    // Tokens and FDL status requests carry no DP layer.
    let token = seen.iter().find(|v| v["type"] == "token").expect("a token");
    assert!(token.get("dp").is_none(), "{token}");
    master.terminate(Duration::from_secs(10));
    assert!(sniff.stop().status.success());
}
