//! `dpctl fms` with real processes on `dpctl bus` (issue 35's check): a
//! `dpctl slave --device bk3000` with KL3102 and KL4002 in DP/FMS mixed
//! mode (`--device-opt fms=mixed`) in Data_Exchange with `dpctl master`,
//! and `dpctl fms` as a third master on the same bus: Read of a KL3102
//! channel object is the status byte plus the very bytes Data_Exchange
//! carries, Write of a KL4002 output channel object changes the terminal
//! output, Get-OD lists the objects, Identify and Status answer; the
//! master keeps Data_Exchange throughout (no restart). A coupler in
//! DP-only mode, an absent station and a refused object are told in
//! words.

mod common;

use common::{dpctl, run_dpctl, slave_of, Bus, Lines, Proc, TempDir};
use serde_json::Value;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};

const WAIT: Duration = Duration::from_secs(40);
const STRIP: &str = "KL3102,KL4002,KL9010";

/// `dpctl slave --device bk3000` at `addr` with `fms=MODE`, its events
/// as JSON on stdout and control lines on stdin.
fn coupler(link: &Path, addr: u8, mode: &str) -> (Proc, ChildStdin, Lines) {
    let mut p = Proc::spawn(
        &format!("dpctl slave {addr}"),
        Command::new(dpctl())
            .args(["slave", "--device", "bk3000", "--terminals", STRIP])
            .args(["--device-opt", &format!("fms={mode}")])
            .args(["--addr", &addr.to_string(), "--baud", "1.5M"])
            .args(["--json", "--control", "-", "--port"])
            .arg(link)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let stdin = p.child.as_mut().unwrap().stdin.take().unwrap();
    let lines = Lines::from(&mut p);
    (p, stdin, lines)
}

fn bus_file(dir: &TempDir) -> PathBuf {
    let list: Vec<String> = STRIP.split(',').map(|t| format!("\"{t}\"")).collect();
    let p = dir.path("bus.toml");
    std::fs::write(
        &p,
        format!(
            "[master]\naddress = 2\nbaud = \"1.5M\"\n[options]\nreprobe_ms = 50\n\
             [[slave]]\naddress = 5\ndevice = \"bk3000\"\nterminals = [{}]\n\
             watchdog_ms = 5000\n",
            list.join(", ")
        ),
    )
    .unwrap();
    p
}

/// `dpctl fms --port LINK --addr 3 --baud 1.5M … ARGS`.
fn fms(link: &Path, station: u8, args: &[&str]) -> common::Output {
    let link = link.display().to_string();
    let station = station.to_string();
    let mut all = vec![
        "fms",
        "--port",
        &link,
        "--station",
        &station,
        "--addr",
        "3",
        "--baud",
        "1.5M",
        "--latency",
        "100",
    ];
    // Joining the ring of a loaded machine's `dpctl master` can take
    // longer than the default 20 s.
    if !args.contains(&"--timeout") {
        all.extend_from_slice(&["--timeout", "60"]);
    }
    all.extend_from_slice(args);
    run_dpctl(&all)
}

/// The one JSON line of a successful `dpctl fms --json`.
fn ok_json(out: &common::Output) -> Value {
    assert!(out.status.success(), "{out:?}");
    let v: Value =
        serde_json::from_str(out.stdout.trim()).unwrap_or_else(|e| panic!("{e}: {out:?}"));
    assert_eq!(v["ok"], true, "{v}");
    v
}

fn bytes(hex: &Value) -> Vec<u8> {
    hex.as_str()
        .unwrap()
        .split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

#[test]
fn fms_reads_writes_and_lists_a_bk3000_while_its_master_keeps_data_exchange() {
    let dir = TempDir::new("fms");
    let bus = Bus::start(4, &[]);
    let (_s, mut control, mut events) = coupler(&bus.link(1), 5, "mixed");
    let (_dp, _dp_in, _dp_events) = coupler(&bus.link(3), 6, "dp");
    // Fixed inputs: what the master sees and what FMS reads must agree
    // byte for byte.
    writeln!(control, "set 1.KL3102.1 2.5").unwrap();
    writeln!(control, "set 1.KL3102.2 -1.25").unwrap();
    control.flush().unwrap();
    assert!(
        events.wait_for("pinned to -1.250 V", WAIT),
        "{:?}",
        events.1
    );
    let cfg = bus_file(&dir);
    let mut m = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--latency", "100"])
            .arg("--port")
            .arg(bus.link(2))
            .arg("--config")
            .arg(&cfg)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut lines = Lines::from(&mut m);
    let pinned = |v: &Value| {
        let s = slave_of(v, 5);
        s["state"] == "data_exchange"
            && s["channels"]["inputs"]["1.KL3102.2"]
                .as_f64()
                .is_some_and(|x| (x + 1.25).abs() < 0.01)
    };
    let dx0 = lines.status_from(&mut 0, "data exchange with pinned inputs", pinned);
    let dx0 = slave_of(&dx0, 5)["data_exchanges"].as_u64().unwrap();
    let link = bus.link(0);

    // Read the KL3102's channel objects (slot 1: 2020, 2022): status byte
    // plus the bytes the master's Data_Exchange carries (the BK3000's
    // default compact mapping: channel 1 in input bytes 0-1, channel 2 in
    // 2-3, no status byte, so it reads 0).
    let r1 = ok_json(&fms(&link, 5, &["--json", "read", "2020"]));
    let r2 = ok_json(&fms(&link, 5, &["--json", "read", "2022"]));
    let seen = lines.status_from(&mut 0, "a status after the reads", pinned);
    let dx_inputs = bytes(&slave_of(&seen, 5)["inputs"]);
    let (c1, c2) = (bytes(&r1["data"]), bytes(&r2["data"]));
    assert_eq!(c1.len(), 3, "{r1}");
    assert_eq!(c1[0], 0, "status byte: {r1}");
    assert_eq!(c1[1..], dx_inputs[0..2], "{r1} vs {seen}");
    assert_eq!(c2[1..], dx_inputs[2..4], "{r2} vs {seen}");
    assert_eq!(r1["name"], "1.KL3102.1 input");
    assert_eq!(r1["type"], "Unsigned8");
    assert_eq!(r1["value"][1], c1[1], "decoded by the description: {r1}");

    // Write the KL4002's channel 1 (slot 2: 2041): 0x2000 = 2.5 V at the
    // terminal; the master's unchanged outputs keep it.
    let w = fms(&link, 5, &["write", "2041", "00 20 00"]);
    assert!(w.status.success(), "{w:?}");
    assert_eq!(
        w.stdout.trim(),
        "station 5: index 2041: ok (wrote 00 20 00)"
    );
    assert!(
        events.wait_for("2.KL4002.1=2.500 V", WAIT),
        "the terminal output did not change: {:?}",
        events.1
    );
    let back = ok_json(&fms(&link, 5, &["--json", "read", "2041"]));
    assert_eq!(back["data"], "00 20 00", "{back}");

    // The object dictionary, in JSON and as a table.
    let od = ok_json(&fms(&link, 5, &["--json", "get-od"]));
    let objects = od["objects"].as_array().unwrap();
    let find = |i: u64| {
        objects
            .iter()
            .find(|o| o["index"] == i)
            .unwrap_or_else(|| panic!("no object {i}: {od}"))
    };
    for (i, name, access) in [
        (2020, "1.KL3102.1 input", "r"),
        (2022, "1.KL3102.2 input", "r"),
        (2041, "2.KL4002.1 output", "rw"),
        (2043, "2.KL4002.2 output", "rw"),
    ] {
        let o = find(i);
        assert_eq!(
            (&o["name"], &o["access"], &o["object_code"], &o["length"]),
            (
                &Value::from(name),
                &Value::from(access),
                &Value::from("Array"),
                &Value::from(3)
            ),
            "{o}"
        );
    }
    assert_eq!(find(5)["object_code"], "Data Type");
    assert_eq!(od["header"]["objects"].as_u64(), Some(objects.len() as u64));
    let table = fms(&link, 5, &["get-od"]);
    assert!(table.status.success(), "{table:?}");
    assert!(
        table
            .stdout
            .lines()
            .any(|l| l.split_whitespace().collect::<Vec<_>>()
                == [
                    "2041",
                    "Array",
                    "Unsigned8",
                    "3",
                    "rw",
                    "2.KL4002.1",
                    "output"
                ]),
        "{}",
        table.stdout
    );

    // Identify and Status in words.
    let id = fms(&link, 5, &["identify"]);
    assert_eq!(
        id.stdout.trim(),
        "station 5: vendor Beckhoff, model BK3000, revision emulated",
        "{id:?}"
    );
    let st = ok_json(&fms(&link, 5, &["--json", "status"]));
    assert_eq!(
        (&st["logical"], &st["physical"]),
        (
            &Value::from("ready for communication"),
            &Value::from("operational")
        )
    );

    // Errors in words: a read-only object, a missing one, a coupler in
    // DP-only mode, an absent station.
    let e = fms(&link, 5, &["write", "2020", "00 00 00"]);
    assert!(!e.status.success());
    assert_eq!(
        e.stderr.trim(),
        "dpctl: station 5: Write index 2020: object access denied (class 6, code 3, additional code 0)"
    );
    let e = fms(&link, 5, &["--json", "read", "2999"]);
    assert!(!e.status.success());
    let v: Value = serde_json::from_str(e.stdout.trim()).unwrap();
    assert_eq!(
        (&v["ok"], &v["error_class"], &v["error_code"]),
        (&Value::from(false), &Value::from(6), &Value::from(7)),
        "{v}"
    );
    assert!(
        v["error"]
            .as_str()
            .unwrap()
            .contains("object does not exist"),
        "{v}"
    );
    let e = fms(&link, 6, &["identify"]);
    assert!(!e.status.success());
    assert!(
        e.stderr.starts_with(
            "dpctl: station 6: the station answered RS (SAP not activated): \
             it serves no FMS connection on LSAP 40"
        ),
        "{e:?}"
    );
    let e = fms(&link, 9, &["status"]);
    assert!(!e.status.success());
    assert!(
        e.stderr
            .starts_with("dpctl: station 9: no answer from the station"),
        "{e:?}"
    );

    // The class-1 master kept its slave all along.
    let v = lines.status_from(&mut 0, "data exchange goes on", |v| {
        slave_of(v, 5)["data_exchanges"].as_u64().unwrap() > dx0 + 20
    });
    assert_eq!(slave_of(&v, 5)["state"], "data_exchange");
    assert_eq!(slave_of(&v, 5)["restarts"], 0, "{v}");
    let left: Vec<&String> = lines
        .1
        .iter()
        .filter(|l| l.contains(r#""event":"state""#) && l.contains(r#""from":"data_exchange""#))
        .collect();
    assert!(left.is_empty(), "the slave left Data_Exchange: {left:#?}");
    // The coupler saw each connection come and go.
    assert!(
        events
            .1
            .iter()
            .any(|l| l.contains("client 3 connected") && l.contains("\"fms\"")),
        "{:?}",
        events.1
    );
    m.terminate(Duration::from_secs(5));
}

/// The `"event":"fms"` lines of `dpctl monitor --json`.
fn fms_events(lines: &Lines) -> Vec<Value> {
    lines
        .1
        .iter()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| v["event"] == "fms")
        .collect()
}

/// `dpctl monitor --json` on a further link follows the FMS services of
/// `dpctl fms` with a mixed-mode BK3000 beside the master's
/// Data_Exchange: one event per confirmed service (request and response
/// paired), values decoded by the descriptions it saw in Get-OD answers,
/// the connections' Initiate and Abort, and a per-connection summary in
/// the slave's status.
#[test]
fn monitor_follows_the_fms_services_of_a_client_beside_data_exchange() {
    let dir = TempDir::new("fms-monitor");
    let bus = Bus::start(4, &[]);
    let (_s, mut control, mut events) = coupler(&bus.link(1), 5, "mixed");
    writeln!(control, "set 1.KL3102.1 2.5").unwrap();
    control.flush().unwrap();
    assert!(events.wait_for("pinned to 2.500 V", WAIT), "{:?}", events.1);
    let cfg = bus_file(&dir);
    let mut mon = Proc::spawn(
        "dpctl monitor",
        Command::new(dpctl())
            .args(["monitor", "--json", "--interval", "100", "--port"])
            .arg(bus.link(3))
            .arg("--config")
            .arg(&cfg)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut seen = Lines::from(&mut mon);
    assert!(seen.wait_for("\"event\":\"status\"", WAIT), "{:?}", seen.1);
    let mut m = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--latency", "100"])
            .arg("--port")
            .arg(bus.link(2))
            .arg("--config")
            .arg(&cfg)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut lines = Lines::from(&mut m);
    lines.status_from(&mut 0, "data exchange", |v| {
        slave_of(v, 5)["state"] == "data_exchange"
    });
    let link = bus.link(0);
    let od = ok_json(&fms(&link, 5, &["--json", "get-od"]));
    let read = ok_json(&fms(&link, 5, &["--json", "read", "2020"]));
    let w = fms(&link, 5, &["write", "2041", "00 20 00"]);
    assert!(w.status.success(), "{w:?}");
    let e = fms(&link, 5, &["read", "2999"]);
    assert!(!e.status.success(), "{e:?}");

    // The monitor's events: wait for the fourth connection's release.
    let end = Instant::now() + WAIT;
    while fms_events(&seen)
        .iter()
        .filter(|v| v["service"] == "Abort")
        .count()
        < 4
    {
        assert!(Instant::now() < end, "not 4 Aborts: {:#?}", seen.1);
        seen.next_line(Duration::from_millis(100));
    }
    let ev = fms_events(&seen);
    for v in &ev {
        assert_eq!(
            (&v["master"], &v["station"], &v["lsap"]),
            (&Value::from(3), &Value::from(5), &Value::from(40)),
            "{v}"
        );
        assert!(v["time"].as_f64().is_some(), "{v}");
    }
    let one = |service: &str, index: Option<u64>| -> &Value {
        ev.iter()
            .find(|v| v["service"] == service && index.is_none_or(|i| v["index"] == i))
            .unwrap_or_else(|| panic!("no {service} {index:?} event: {ev:#?}"))
    };
    // Four connections, each accepted with the client's monitoring and
    // released by the client.
    let count = |service: &str, outcome: &str| {
        ev.iter()
            .filter(|v| v["service"] == service && v["outcome"] == outcome)
            .count()
    };
    assert_eq!(count("Initiate", "accepted"), 4, "{ev:#?}");
    assert_eq!(one("Initiate", None)["monitoring_ms"], 2000);
    assert_eq!(count("Abort", "released"), 4, "{ev:#?}");
    assert_eq!(one("Abort", None)["by"], "client");
    // `dpctl fms get-od` (the first connection): the header, then the
    // descriptions from index 1 on, page by page — as many as it listed.
    let first: Vec<&Value> = ev.iter().take_while(|v| v["service"] != "Abort").collect();
    assert!(first.iter().all(|v| v["outcome"] != "error"), "{first:#?}");
    let pages = first
        .iter()
        .filter(|v| v["service"] == "Get-OD" && v["index"] != 0);
    let listed: u64 = pages.map(|v| v["objects"].as_u64().unwrap()).sum();
    assert_eq!(
        listed as usize,
        od["objects"].as_array().unwrap().len(),
        "{first:#?}"
    );
    // The Read: the same bytes `dpctl fms` printed, in words by the
    // description the monitor saw.
    let r = ev
        .iter()
        .find(|v| v["service"] == "Read" && v["index"] == 2020)
        .unwrap_or_else(|| panic!("no Read 2020: {ev:#?}"));
    assert_eq!(r["outcome"], "ok", "{r}");
    assert_eq!(r["data"], read["data"], "{r} vs {read}");
    let words: Vec<String> = read["value"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.to_string())
        .collect();
    assert_eq!(r["value"], format!("[{}]", words.join(", ")), "{r}");
    assert_eq!(r["name"], "1.KL3102.1 input");
    assert_eq!(r["type"], "Unsigned8");
    assert!(r["invoke_id"].as_u64().is_some(), "{r}");
    let w = one("Write", Some(2041));
    assert_eq!(
        (&w["outcome"], &w["data"], &w["value"], &w["name"]),
        (
            &Value::from("ok"),
            &Value::from("00 20 00"),
            &Value::from("[0, 32, 0]"),
            &Value::from("2.KL4002.1 output")
        ),
        "{w}"
    );
    // `dpctl fms read` asks for the description first: both fail.
    let e = one("Get-OD", Some(2999));
    assert_eq!(
        (&e["outcome"], &e["error_class"]),
        (&Value::from("error"), &Value::from(7)),
        "{e}"
    );
    let e = one("Read", Some(2999));
    assert_eq!(
        (&e["outcome"], &e["error_class"], &e["error_code"]),
        (&Value::from("error"), &Value::from(6), &Value::from(7)),
        "{e}"
    );
    assert!(
        e["error"]
            .as_str()
            .unwrap()
            .contains("object does not exist"),
        "{e}"
    );

    // The coupler's status: Data_Exchange, and its FMS connection.
    let end = Instant::now() + WAIT;
    let st = loop {
        let last = seen
            .1
            .iter()
            .rev()
            .filter_map(|l| serde_json::from_str::<Value>(l).ok())
            .find(|v| v["event"] == "status" && !slave_of(v, 5)["fms"].is_null());
        if let Some(v) = last {
            if slave_of(&v, 5)["fms"][0]["last"] == "Read 2999 error" {
                break v;
            }
        }
        assert!(Instant::now() < end, "no FMS summary: {:#?}", seen.1);
        seen.next_line(Duration::from_millis(100));
    };
    let s = slave_of(&st, 5);
    assert_eq!(s["state"], "data_exchange", "{s}");
    let c = &s["fms"][0];
    assert_eq!(
        (&c["master"], &c["lsap"], &c["state"], &c["monitoring_ms"]),
        (
            &Value::from(3),
            &Value::from(40),
            &Value::from("released"),
            &Value::from(2000)
        ),
        "{c}"
    );
    // get-od: 2 or more (the header, pages), read: 2, write: 1, read
    // 2999: 2 (both errors).
    assert!(c["services"].as_u64().unwrap() >= 7, "{c}");
    assert_eq!(c["errors"], 2, "{c}");
    m.terminate(Duration::from_secs(5));
    assert!(mon.terminate(Duration::from_secs(10)).success());
}

/// `dpctl fms read|write INDEX --subindex N` on a mixed-mode BK3000:
/// one octet of a channel object (Array of Unsigned8: 1 the status or
/// control byte, 2… the data), the other elements kept by a Write; a
/// subindex beyond the array is refused as FMS refuses an impermissible
/// subindex (class 6 code 5), a read-only object stays read-only.
#[test]
fn subindex_reads_and_writes_one_element_of_a_channel_object() {
    let bus = Bus::start(2, &[]);
    let (_s, mut control, mut events) = coupler(&bus.link(1), 5, "mixed");
    writeln!(control, "set 1.KL3102.1 2.5").unwrap();
    control.flush().unwrap();
    assert!(events.wait_for("pinned to 2.500 V", WAIT), "{:?}", events.1);
    let link = bus.link(0);
    let whole = bytes(&ok_json(&fms(&link, 5, &["--json", "read", "2020"]))["data"]);
    assert_eq!(whole.len(), 3);
    for s in 1..=3 {
        let sub = s.to_string();
        let e = ok_json(&fms(
            &link,
            5,
            &["--json", "read", "2020", "--subindex", &sub],
        ));
        assert_eq!(e["subindex"], s, "{e}");
        assert_eq!(bytes(&e["data"]), [whole[s - 1]], "{e}");
        assert_eq!(e["value"], whole[s - 1], "one Unsigned8: {e}");
        assert_eq!(e["name"], "1.KL3102.1 input");
    }
    let text = fms(&link, 5, &["read", "2020", "--subindex", "2"]);
    assert_eq!(
        text.stdout.trim(),
        format!(
            "station 5: index 2020 subindex 2 (1.KL3102.1 input, Array of Unsigned8): {:02X} = {}",
            whole[1], whole[1]
        ),
        "{text:?}"
    );

    // Write the whole KL4002 channel, then only its low data byte.
    let w = fms(&link, 5, &["write", "2041", "00 20 00"]);
    assert!(w.status.success(), "{w:?}");
    let w = fms(&link, 5, &["write", "2041", "FF", "--subindex", "3"]);
    assert_eq!(
        w.stdout.trim(),
        "station 5: index 2041 subindex 3: ok (wrote FF)",
        "{w:?}"
    );
    let back = ok_json(&fms(&link, 5, &["--json", "read", "2041"]));
    assert_eq!(back["data"], "00 20 FF", "{back}");
    assert!(
        events.wait_for("2.KL4002.1=2.578 V", WAIT),
        "the terminal output did not follow: {:?}",
        events.1
    );

    // Errors in words.
    let e = fms(&link, 5, &["read", "2020", "--subindex", "4"]);
    assert!(!e.status.success());
    assert_eq!(
        e.stderr.trim(),
        "dpctl: station 5: Read index 2020 subindex 4: object attribute inconsistent \
         (class 6, code 5, additional code 0)"
    );
    let e = fms(
        &link,
        5,
        &["--json", "write", "2041", "01 02", "--subindex", "1"],
    );
    let v: Value = serde_json::from_str(e.stdout.trim()).unwrap();
    assert_eq!(
        (&v["error_class"], &v["error_code"]),
        (&Value::from(6), &Value::from(10)),
        "{v}"
    );
    let e = fms(&link, 5, &["write", "2020", "00", "--subindex", "1"]);
    assert!(
        e.stderr
            .contains("Write index 2020 subindex 1: object access denied"),
        "{e:?}"
    );
    let e = run_dpctl(&[
        "fms",
        "--port",
        "/nonexistent",
        "--station",
        "5",
        "read",
        "2020",
        "--subindex",
        "0",
    ]);
    assert!(!e.status.success());
    assert!(e.stderr.contains("--subindex"), "{e:?}");
}

#[test]
fn usage_errors_are_one_line() {
    let e = run_dpctl(&[
        "fms",
        "--port",
        "/nonexistent",
        "--station",
        "5",
        "--addr",
        "5",
        "identify",
    ]);
    assert!(!e.status.success());
    assert_eq!(
        e.stderr.trim(),
        "dpctl: --addr 5 is the server's address: the FMS client needs its own"
    );
    let e = run_dpctl(&[
        "fms",
        "--port",
        "/nonexistent",
        "--station",
        "5",
        "write",
        "2041",
        "0g",
    ]);
    assert!(!e.status.success());
    assert!(e.stderr.starts_with("dpctl: "), "{e:?}");
    assert_eq!(e.stderr.trim().lines().count(), 1, "{e:?}");
}
