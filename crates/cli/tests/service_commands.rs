//! The service commands of commissioning (issue 29) on `dpctl bus`, run
//! from a station of their own while a `dpctl master` holds slave 8 in
//! Data_Exchange: `dpctl diag` and `get-cfg` of the locked slave,
//! `read-io` of it (and the refusal of a slave outside Data_Exchange in
//! words), `set-address` of a free slave (and the refusal of the locked
//! one), `global-control` from a master that does not own the slave
//! (sent); slave 8 stays in Data_Exchange throughout.

mod common;

use common::{all_dx, dpctl, repo, Bus, Lines, Output, Proc, TempDir};
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::Duration;

fn gen_gsd() -> std::path::PathBuf {
    repo().join("crates/devices/gsd/DPCTL_GEN.GSD")
}

fn slave(bus: &Bus, i: usize, addr: u8) -> Proc {
    Proc::spawn(
        &format!("dpctl slave {addr}"),
        Command::new(dpctl())
            .args(["slave", "--port", &bus.link_str(i)])
            .args(["--addr", &addr.to_string(), "--gsd"])
            .arg(gen_gsd())
            .args(["--module", "2 words in/out", "--module", "1 byte in"])
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
}

/// `dpctl ARGS --port LINK2 --addr 3 --latency 50`, to its end.
fn service(bus: &Bus, args: &[&str]) -> Output {
    let mut cmd = Command::new(dpctl());
    cmd.args(args)
        .args(["--port", &bus.link_str(2), "--addr", "3", "--latency", "50"]);
    Proc::spawn_captured(cmd).finish(Duration::from_secs(60))
}

fn ok_json(out: &Output) -> Value {
    assert!(out.status.success(), "failed: {}{}", out.stdout, out.stderr);
    serde_json::from_str(out.stdout.trim()).unwrap_or_else(|e| panic!("{}: {e}", out.stdout))
}

#[test]
fn service_commands_beside_a_running_master() {
    let dir = TempDir::new("service");
    let bus = Bus::start(4, &[]);
    let _s8 = slave(&bus, 1, 8);
    let _s9 = slave(&bus, 3, 9);
    bus.wait_connected(2);
    let toml = dir.path("bus.toml");
    std::fs::write(
        &toml,
        format!(
            "[master]\naddress = 1\nbaud = 19200\n[[slave]]\naddress = 8\ngsd = \"{}\"\n\
             modules = [\"2 words in/out\", \"1 byte in\"]\nwatchdog_ms = 6000\n",
            gen_gsd().display()
        ),
    )
    .unwrap();
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--latency", "50"])
            .args(["--port", &bus.link_str(0), "--config"])
            .arg(&toml)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut lines = Lines::from(&mut master);
    let mut from = 0;
    lines.status_from(&mut from, "every slave in Data_Exchange", all_dx);

    // Slave_Diag and Get_Cfg of the slave master 1 holds.
    let v = ok_json(&service(&bus, &["diag", "--json", "--slave", "8"]));
    assert_eq!(v["owner"], 1, "{v}");
    assert_eq!(v["ident"], "0x0DCE");
    assert!(v["lines"][1] == "parameterised by master 1", "{v}");
    let v = ok_json(&service(&bus, &["get-cfg", "--json", "--slave", "8"]));
    assert_eq!(v["cfg"], "71 10");
    assert_eq!(
        v["modules"],
        serde_json::json!(["2 words in/out", "1 byte in"])
    );
    assert_eq!(v["gsd"], "DPCTL_GEN.GSD (built in)");
    // Rd_Inp / Rd_Outp of the slave in Data_Exchange: 5 bytes in, 4 out.
    let v = ok_json(&service(&bus, &["read-io", "--json", "--slave", "8"]));
    assert_eq!(v["inputs"].as_str().unwrap().len(), 5 * 3 - 1, "{v}");
    assert_eq!(v["outputs"].as_str().unwrap().len(), 4 * 3 - 1, "{v}");
    // A slave outside Data_Exchange refuses Rd_Inp: said in words.
    let out = service(&bus, &["read-io", "--slave", "9"]);
    assert!(!out.status.success());
    assert_eq!(
        out.stderr.trim(),
        "dpctl: slave 9: Rd_Inp refused (RS): a slave answers it in Data_Exchange only"
    );
    // Set_Slave_Add: the locked slave refuses, the free one takes it.
    let out = service(&bus, &["set-address", "--slave", "8", "--new", "30"]);
    assert!(!out.status.success());
    assert!(
        out.stderr
            .starts_with("dpctl: slave 8 refused Set_Slave_Add (RS): a slave takes a new address only in Wait_Prm"),
        "{}",
        out.stderr
    );
    let v = ok_json(&service(
        &bus,
        &["set-address", "--json", "--slave", "9", "--new", "20"],
    ));
    assert_eq!(v["confirmed"], true, "{v}");
    assert_eq!(v["ident"], "0x0DCE");
    let v = ok_json(&service(&bus, &["diag", "--json", "--slave", "20"]));
    assert_eq!(v["owner"], Value::Null);
    // Global_Control from a master that does not own slave 8: sent (a
    // broadcast, never answered).
    let v = ok_json(&service(&bus, &["global-control", "--json", "clear"]));
    assert_eq!(v["bytes"], "02 00");

    // Slave 8 never left Data_Exchange.
    let mut after = lines.1.len();
    lines.status_from(&mut after, "a status line after the commands", |_| true);
    for l in &lines.1[from..] {
        if let Ok(v) = serde_json::from_str::<Value>(l) {
            if v["event"] == "status" {
                assert!(all_dx(&v), "slave 8 left Data_Exchange: {v}");
                assert_eq!(v["operating"], "operate", "{v}");
            }
        }
    }
    master.terminate(Duration::from_secs(5));
}
