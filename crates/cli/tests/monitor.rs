//! `dpctl monitor` end to end: on a further port of a `dpctl bus` it
//! follows `dpctl master` polling two `dpctl slave` processes, and it
//! never sends a byte.

mod common;

use common::*;
use profibus::dp::pdu::sap;
use profibus::fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus};
use profibus::fdl::Telegram;
use serde_json::Value;
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::Duration;

/// Master 2 with the echo slave at 3 and an Omega drive at 25.
const BUS: &str = include_str!("data/monitor_bus.toml");

const COMMANDS: &str = r#"{"slave": 3, "outputs": "12 34 56 78"}
{"slave": 25, "set": {"setpoint1": 1234, "setpoint2": -5}}
"#;

fn bus_file(dir: &TempDir) -> std::path::PathBuf {
    std::fs::copy(
        repo().join("crates/devices/gsd/DPCTL_GEN.GSD"),
        dir.path("DPCTL_GEN.GSD"),
    )
    .unwrap();
    let bus = dir.path("bus.toml");
    std::fs::write(&bus, BUS).unwrap();
    bus
}

/// The JSON line `l`, if it is one.
fn json(l: &str) -> Option<Value> {
    serde_json::from_str(l).ok()
}

#[test]
fn monitor_follows_a_master_and_its_slaves_to_data_exchange() {
    let line = Bus::start(4, &[]);
    let dir = TempDir::new("monitor");
    let bus = bus_file(&dir);
    let mut monitor = Proc::spawn(
        "dpctl monitor",
        Command::new(dpctl())
            .args(["monitor", "--json", "--interval", "100", "--port"])
            .arg(line.link(3))
            .arg("--config")
            .arg(&bus)
            .stdout(Stdio::piped())
            .stdin(Stdio::null()),
    );
    let mut seen = Lines::from(&mut monitor);
    // The monitor is listening once its first status comes.
    assert!(seen.wait_for("\"event\":\"status\"", Duration::from_secs(20)));
    let _echo = Proc::spawn(
        "dpctl slave (generic)",
        &mut generic_slave(line.link(1), 3, "1.5M", &["1 byte in", "2 words in/out"]),
    );
    let _omega = Proc::spawn(
        "dpctl slave (omega)",
        Command::new(dpctl())
            .args(["slave", "--device", "omega", "--addr", "25"])
            .args(["--device-opt", "drive-enable=auto"])
            .args(["--baud", "1.5M", "--port"])
            .arg(line.link(2))
            .stdout(Stdio::null())
            .stdin(Stdio::null()),
    );
    let cmds = dir.path("cmds.jsonl");
    std::fs::write(&cmds, COMMANDS).unwrap();
    let _master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--latency", "100", "--json", "--port"])
            .arg(line.link(0))
            .arg("--config")
            .arg(&bus)
            .arg("--input")
            .arg(&cmds)
            .stdout(Stdio::null())
            .stdin(Stdio::null()),
    );
    // Both slaves reach Data_Exchange, as the monitor sees it.
    for a in [3, 25] {
        let ok = (|| loop {
            let l = seen.next_line(Duration::from_secs(60))?;
            let v = json(&l)?;
            if v["event"] == "state" && v["slave"] == a && v["to"] == "data_exchange" {
                return Some(v);
            }
        })();
        let v = ok.unwrap_or_else(|| panic!("slave {a} not in data_exchange: {:?}", seen.1));
        assert_eq!(v["master"], 2, "{v}");
    }
    // A status with their data: the echo slave's modules, the drive's
    // channels by name, and the master in the token ring.
    let status = (|| loop {
        let v = json(&seen.next_line(Duration::from_secs(60))?)?;
        if v["event"] != "status" {
            continue;
        }
        let slaves = v["slaves"].as_array()?;
        let echo = slaves.iter().find(|s| s["address"] == 3)?;
        let omega = slaves.iter().find(|s| s["address"] == 25)?;
        if echo["outputs"] == "12 34 56 78" && omega["channels"]["inputs"]["actual1"] == 1234 {
            return Some(v);
        }
    })()
    .unwrap_or_else(|| panic!("no status with the data: {:?}", seen.1));
    let slaves = status["slaves"].as_array().unwrap();
    let echo = slaves.iter().find(|s| s["address"] == 3).unwrap();
    assert_eq!(echo["state"], "data_exchange");
    assert_eq!(echo["name"], "echo");
    assert_eq!(echo["modules"][1]["name"], "2 words in/out");
    assert_eq!(echo["modules"][1]["outputs"], "12 34 56 78");
    assert_eq!(echo["modules"][0]["inputs"].as_str().unwrap().len(), 2);
    assert!(echo["data_exchanges"].as_u64().unwrap() > 0);
    assert!(echo["cycle_us"]["avg"].as_u64().unwrap() > 0);
    assert!(
        echo["diag"][0]
            .as_str()
            .unwrap()
            .starts_with("station status"),
        "{echo}"
    );
    let omega = slaves.iter().find(|s| s["address"] == 25).unwrap();
    assert_eq!(omega["channels"]["outputs"]["setpoint1"], 1234, "{omega}");
    assert_eq!(omega["channels"]["inputs"]["actual2"], -5, "{omega}");
    let masters = status["masters"].as_array().unwrap();
    assert!(
        masters
            .iter()
            .any(|m| m["address"] == 2 && m["in_ring"] == true && m["operating"] == "operate"),
        "{status}"
    );
    // The same fields as `dpctl master --json` prints for a slave.
    for k in [
        "address",
        "name",
        "state",
        "inputs",
        "outputs",
        "data_exchanges",
        "retries",
        "errors",
        "restarts",
    ] {
        assert!(echo.get(k).is_some(), "{k} missing: {echo}");
    }
    assert!(monitor.terminate(Duration::from_secs(10)).success());
}

/// Bytes of a data telegram.
fn tg(da: u8, sa: u8, fc: FunctionCode, saps: Option<(u8, u8)>, du: &[u8]) -> Vec<u8> {
    let (dsap, ssap) = saps.unzip();
    let t = DataTelegram::new(da, sa, fc, du).with_saps(dsap, ssap);
    Telegram::Data(t).to_vec().unwrap()
}

/// A master (2) and a slave (3) as canned telegrams: a start-up and one
/// Data_Exchange, with a token at each end.
fn startup() -> Vec<Vec<u8>> {
    let req = |sap: Option<u8>, fcb: bool, fcv: bool, du: &[u8]| {
        let fc = FunctionCode::Request {
            kind: RequestKind::SrdHigh,
            fcb,
            fcv,
        };
        tg(3, 2, fc, sap.map(|s| (s, sap::MASTER)), du)
    };
    let resp = |sap: Option<u8>, du: &[u8]| {
        let fc = FunctionCode::slave_response(ResponseStatus::Dl);
        tg(2, 3, fc, sap.map(|s| (sap::MASTER, s)), du)
    };
    vec![
        vec![0xDC, 2, 2],
        req(Some(sap::SLAVE_DIAG), true, false, &[]),
        resp(Some(sap::SLAVE_DIAG), &[0x02, 0x05, 0, 0xFF, 0x0E, 0xD0]),
        req(
            Some(sap::SET_PRM),
            false,
            true,
            &[0x80, 1, 1, 0x0B, 0, 0x0E, 0xD0],
        ),
        vec![0xE5],
        req(Some(sap::CHK_CFG), true, true, &[0x71]),
        vec![0xE5],
        req(Some(sap::SLAVE_DIAG), false, true, &[]),
        resp(Some(sap::SLAVE_DIAG), &[0x00, 0x0C, 0, 0x02, 0x0E, 0xD0]),
        req(None, true, true, &[1, 2, 3, 4]),
        resp(None, &[5, 6, 7, 8]),
        vec![0xDC, 2, 2],
    ]
}

#[test]
fn monitor_never_sends_a_byte() {
    let line = Bus::start(2, &[]);
    let dir = TempDir::new("monitor-quiet");
    let bus = dir.path("bus.toml");
    std::fs::write(&bus, "[master]\naddress = 2\nbaud = \"1.5M\"\n").unwrap();
    let mut monitor = Proc::spawn(
        "dpctl monitor",
        Command::new(dpctl())
            .args(["monitor", "--interval", "50", "--port"])
            .arg(line.link(1))
            .arg("--config")
            .arg(&bus)
            .stdout(Stdio::piped())
            .stdin(Stdio::null()),
    );
    let mut seen = Lines::from(&mut monitor);
    assert!(seen.wait_for("status", Duration::from_secs(20)));
    // Everything the line carries comes from this test: the hub's count
    // of characters must be exactly what it wrote.
    let mut port = std::fs::OpenOptions::new()
        .write(true)
        .open(line.link(0))
        .unwrap();
    let mut written = 0;
    for t in startup() {
        port.write_all(&t).unwrap();
        written += t.len();
        // Telegram by telegram, as a line carries them.
        port.flush().unwrap();
    }
    assert!(
        seen.wait_for(
            "slave 3: check_diag → data_exchange (master 2)",
            Duration::from_secs(20)
        ),
        "{:?}",
        seen.1
    );
    assert!(seen.wait_for("in: 05 06 07 08  out: 01 02 03 04", Duration::from_secs(20)));
    assert!(seen.1.iter().any(|l| l == "master 2 in the token ring"));
    assert!(monitor.terminate(Duration::from_secs(10)).success());
    drop(port);
    let out = line.stop();
    assert!(
        out.stderr.contains(&format!(" chars {written},")),
        "the hub carried more than the test wrote ({written} chars): {}",
        out.stderr
    );
}

/// When the master stops, the slave it had in Data_Exchange leaves it
/// after `--master-timeout`: the monitor prints the state change.
#[test]
fn monitor_takes_slaves_out_of_data_exchange_when_their_master_stops() {
    let line = Bus::start(3, &[]);
    let dir = TempDir::new("monitor-stop");
    let bus = dir.path("bus.toml");
    std::fs::write(
        &bus,
        "[master]\naddress = 2\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 3\nname = \"echo\"\n\
         gsd = \"DPCTL_GEN.GSD\"\nmodules = [\"1 byte in\"]\n",
    )
    .unwrap();
    std::fs::copy(
        repo().join("crates/devices/gsd/DPCTL_GEN.GSD"),
        dir.path("DPCTL_GEN.GSD"),
    )
    .unwrap();
    let mut monitor = Proc::spawn(
        "dpctl monitor",
        Command::new(dpctl())
            .args(["monitor", "--json", "--interval", "100"])
            .args(["--master-timeout", "300", "--port"])
            .arg(line.link(2))
            .arg("--config")
            .arg(&bus)
            .stdout(Stdio::piped())
            .stdin(Stdio::null()),
    );
    let mut seen = Lines::from(&mut monitor);
    assert!(seen.wait_for("\"event\":\"status\"", Duration::from_secs(20)));
    let _slave = Proc::spawn(
        "dpctl slave",
        &mut generic_slave(line.link(1), 3, "1.5M", &["1 byte in"]),
    );
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--latency", "100", "--port"])
            .arg(line.link(0))
            .arg("--config")
            .arg(&bus)
            .stdout(Stdio::null())
            .stdin(Stdio::null()),
    );
    // The state event, within a bound (status lines keep coming).
    let state = |seen: &mut Lines, from: &str, to: &str| {
        let end = std::time::Instant::now() + Duration::from_secs(60);
        loop {
            let left = end.saturating_duration_since(std::time::Instant::now());
            let l = seen.next_line(left)?;
            let Some(v) = json(&l) else { continue };
            if v["event"] == "state" && v["slave"] == 3 && v["from"] == from && v["to"] == to {
                return Some(v);
            }
        }
    };
    let tail = |seen: &Lines| seen.1[seen.1.len().saturating_sub(10)..].to_vec();
    state(&mut seen, "check_diag", "data_exchange")
        .unwrap_or_else(|| panic!("slave 3 not in data_exchange: {:#?}", tail(&seen)));
    master.terminate(Duration::from_secs(10));
    let v = state(&mut seen, "data_exchange", "offline")
        .unwrap_or_else(|| panic!("slave 3 stayed in data_exchange: {:#?}", tail(&seen)));
    assert_eq!(v["master"], 2, "{v}");
    assert!(monitor.terminate(Duration::from_secs(10)).success());
}
