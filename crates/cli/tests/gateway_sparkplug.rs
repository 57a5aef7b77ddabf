//! `dpctl gateway --sparkplug` against a real broker (mosquitto on a free
//! localhost port). Every payload is checked by an independent decoder:
//! `protoc --decode` against crates/gateway/proto/sparkplug_b.proto
//! (Debian's protobuf-compiler), and the commands are encoded with
//! `protoc --encode`. Fails (never skips) when mosquitto, its clients or
//! protoc are missing: run `scripts/setup-test-env`.

mod common;

use common::mqtt::{self, broker, echo_bus_text, echo_slave, free_port, write_bus, GATEWAY_SLAVES};
use common::{dpctl, require, Lines, Proc, TempDir};
use std::collections::HashMap;
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const T: Duration = Duration::from_secs(30);
const MESSAGE: &str = "org.eclipse.tahu.protobuf.Payload";

/// A payload as protoc decodes it: the top-level fields and the metrics,
/// each as `field -> value` text (strings keep their quotes).
#[derive(Debug, Clone)]
struct Decoded {
    fields: HashMap<String, String>,
    metrics: Vec<HashMap<String, String>>,
}

impl Decoded {
    fn parse(bytes: &[u8]) -> Decoded {
        let text = String::from_utf8(mqtt::protoc(&format!("--decode={MESSAGE}"), bytes)).unwrap();
        let mut d = Decoded {
            fields: HashMap::new(),
            metrics: vec![],
        };
        let mut metric: Option<HashMap<String, String>> = None;
        for line in text.lines() {
            let l = line.trim();
            if l == "metrics {" {
                metric = Some(HashMap::new());
            } else if l == "}" {
                d.metrics.extend(metric.take());
            } else if let Some((k, v)) = l.split_once(": ") {
                match &mut metric {
                    Some(m) => m.insert(k.into(), v.into()),
                    None => d.fields.insert(k.into(), v.into()),
                };
            }
        }
        d
    }

    fn seq(&self) -> Option<u64> {
        self.fields.get("seq").map(|s| s.parse().unwrap())
    }

    /// The metric named `name`.
    fn metric(&self, name: &str) -> Option<&HashMap<String, String>> {
        let quoted = format!("\"{name}\"");
        self.metrics.iter().find(|m| m.get("name") == Some(&quoted))
    }

    /// `field` of the metric named `name`.
    fn get(&self, name: &str, field: &str) -> Option<&str> {
        self.metric(name)?.get(field).map(String::as_str)
    }
}

/// `mosquitto_sub` on everything Sparkplug, payloads in hex.
struct Sub {
    _p: Proc,
    lines: Lines,
    /// Lines of `lines` decoded so far.
    decoded: usize,
    /// Messages seen and decoded, in order.
    seen: Vec<(String, Decoded)>,
    /// Messages of `seen` that [`Sub::expect`] went past.
    next: usize,
    /// Metric names (quoted) by alias, from the births.
    names: HashMap<String, String>,
    /// The payload of each message of `seen`, as received.
    raw: Vec<Vec<u8>>,
}

const PROBE: &str = "spBv1.0/probe";

impl Sub {
    /// Subscribe; returns once the subscription is in place (a probe
    /// message published after it came back).
    fn start(port: u16) -> Sub {
        let args = ["-t", "spBv1.0/#", "-F", "%t %x"];
        let (p, lines) = mqtt::subscribe(port, &args, &[], PROBE);
        Sub {
            _p: p,
            lines,
            decoded: 0,
            seen: vec![],
            next: 0,
            names: HashMap::new(),
            raw: vec![],
        }
    }

    /// Decode the lines received so far.
    fn pull(&mut self) {
        while self.decoded < self.lines.1.len() {
            let l = self.lines.1[self.decoded].clone();
            self.decoded += 1;
            let (t, hex) = l.split_once(' ').unwrap_or((&l, ""));
            // The probe, and what mosquitto_sub printed on stderr (an
            // error; [`Sub::expect`] prints it when it fails).
            if t == PROBE || !t.starts_with("spBv1.0/") {
                continue;
            }
            // A primary host's STATE is JSON: kept (for the order) undecoded.
            if t.starts_with("spBv1.0/STATE/") {
                let d = Decoded {
                    fields: HashMap::new(),
                    metrics: vec![],
                };
                self.seen.push((t.to_string(), d));
                self.raw.push(vec![]);
                continue;
            }
            let bytes: Vec<u8> = (0..hex.len() / 2)
                .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
                .collect();
            let mut d = Decoded::parse(&bytes);
            // Births carry name and alias; data messages the alias only
            // (named here from the births).
            for m in &mut d.metrics {
                match (m.get("name"), m.get("alias")) {
                    (Some(n), Some(a)) if t.contains("BIRTH/") => {
                        self.names.insert(a.clone(), n.clone());
                    }
                    (None, Some(a)) if t.contains("DATA/") => {
                        let name = self.names.get(a).expect("an alias from a birth").clone();
                        m.insert("name".into(), name);
                    }
                    (n, _) if t.contains("DATA/") => panic!("a data metric named {n:?}"),
                    _ => {}
                }
            }
            self.seen.push((t.to_string(), d));
            self.raw.push(bytes);
        }
    }

    /// The next message after the last one returned that is on `topic`
    /// and satisfies `ok` (messages skipped on the way stay in `seen`).
    fn expect(&mut self, topic: &str, ok: impl Fn(&Decoded) -> bool) -> Decoded {
        let end = Instant::now() + T;
        loop {
            self.pull();
            while self.next < self.seen.len() {
                let (t, d) = &self.seen[self.next];
                self.next += 1;
                if t == topic && ok(d) {
                    return d.clone();
                }
            }
            if self
                .lines
                .next_line(end.saturating_duration_since(Instant::now()))
                .is_none()
            {
                let other = self.lines.1.iter().filter(|l| !l.starts_with("spBv1.0/"));
                panic!(
                    "no matching message on {topic}; got:\n{:#?}\nmosquitto_sub printed also:\n{}",
                    self.seen
                        .iter()
                        .map(|(t, d)| (t, &d.fields))
                        .collect::<Vec<_>>(),
                    other.cloned().collect::<Vec<_>>().join("\n")
                );
            }
        }
    }

    /// Every message seen so far on `topic`.
    fn all(&mut self, topic: &str) -> Vec<Decoded> {
        self.pull();
        self.seen
            .iter()
            .filter(|(t, _)| t == topic)
            .map(|(_, d)| d.clone())
            .collect()
    }
}

/// Publish a command written in protobuf text format, encoded by protoc.
fn command(port: u16, topic: &str, text: &str) {
    require("mosquitto_pub");
    let payload = mqtt::protoc(&format!("--encode={MESSAGE}"), text.as_bytes());
    let mut p = Command::new("mosquitto_pub")
        .args(["-h", "127.0.0.1", "-p", &port.to_string()])
        .args(["-t", topic, "-s"])
        .stdin(Stdio::piped())
        .spawn()
        .expect("mosquitto_pub");
    p.stdin.take().unwrap().write_all(&payload).unwrap();
    assert!(
        p.wait().unwrap().success(),
        "mosquitto_pub to {topic} failed"
    );
}

fn gateway(bus: &std::path::Path, port: u16, extra: &[&str]) -> Proc {
    let mut c = Command::new(dpctl());
    c.arg("gateway")
        .arg("--config")
        .arg(bus)
        .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")])
        .args(extra);
    Proc::spawn_captured(c)
}

const NBIRTH: &str = "spBv1.0/G/NBIRTH/E";
const NDEATH: &str = "spBv1.0/G/NDEATH/E";

fn dev(t: &str, d: u8) -> String {
    format!("spBv1.0/G/{t}/E/{d}")
}

/// The births of the node and its three devices, from the next NBIRTH
/// on: its bdSeq; checks seq 0, 1, 2, 3 and the birth metrics.
fn births(sub: &mut Sub) -> u64 {
    let nb = sub.expect(NBIRTH, |_| true);
    assert_eq!(nb.seq(), Some(0), "{nb:?}");
    assert_eq!(nb.get("bdSeq", "datatype"), Some("4"), "Int64");
    assert_eq!(nb.get("Node Control/Rebirth", "datatype"), Some("11"));
    assert_eq!(
        nb.get("Node Control/Rebirth", "boolean_value"),
        Some("false")
    );
    assert!(nb.fields.contains_key("timestamp"));
    let bd: u64 = nb.get("bdSeq", "long_value").unwrap().parse().unwrap();
    let mut seqs = vec![];
    for a in [3, 4, 25] {
        let b = sub.expect(&dev("DBIRTH", a), |_| true);
        seqs.push(b.seq().unwrap());
        // Every metric has a name, a datatype and a value (or is null).
        for m in &b.metrics {
            assert!(
                m.contains_key("name") && m.contains_key("datatype"),
                "{m:?}"
            );
        }
        assert_eq!(
            b.get("Properties/Address", "int_value"),
            Some(a.to_string().as_str())
        );
        assert_eq!(b.get("Image/Inputs", "datatype"), Some("17"), "Bytes");
    }
    seqs.sort();
    assert_eq!(seqs, [1, 2, 3], "DBIRTHs follow the NBIRTH");
    bd
}

/// The seq of every message the edge node sent, in the order received:
/// NBIRTH 0, then each one more than the one before, 255 followed by 0.
fn check_seq(sub: &Sub) {
    let mut last: Option<u64> = None;
    for (t, d) in &sub.seen {
        let Some(s) = d.seq() else { continue };
        if t == NBIRTH {
            assert_eq!(s, 0);
        } else if let Some(l) = last {
            assert_eq!(s, (l + 1) % 256, "{t} after seq {l}");
        }
        last = Some(s);
    }
    assert!(last.is_some());
}

#[test]
fn sparkplug_births_data_commands_rebirth_and_last_will() {
    let dir = TempDir::new("sparkplug");
    let mqtt = "[mqtt]\nbus = \"line\"\nwritable = [3, 25]\n";
    let bus = write_bus(&dir, &format!("{GATEWAY_SLAVES}pkw = false\n\n{mqtt}"));
    let port = free_port();
    let mut mosq = broker(&dir, port);
    let mut sub = Sub::start(port);
    let gw = gateway(&bus, port, &["--sim", "--sparkplug", "G/E"]);

    // NBIRTH with bdSeq 0, then one DBIRTH per slave in Data_Exchange.
    assert_eq!(births(&mut sub), 0);
    let b3 = &sub.all(&dev("DBIRTH", 3))[0];
    assert_eq!(b3.get("Properties/Name", "string_value"), Some("\"echo\""));
    // GSD module channels: one UInt8 per byte.
    assert_eq!(b3.get("Inputs/2 words in_out[0]", "datatype"), Some("5"));
    let b25 = &sub.all(&dev("DBIRTH", 25))[0];
    // Omega profile channels with their types: UInt16 status, Int32 setpoint.
    assert_eq!(b25.get("Inputs/status1", "datatype"), Some("6"));
    assert_eq!(b25.get("Outputs/setpoint1", "datatype"), Some("3"));

    // DCMD, the whole image: the echo slave's inputs change, reported
    // by DDATA (only what changed; no datatypes in data messages).
    command(
        port,
        &dev("DCMD", 3),
        r#"timestamp: 1 metrics { name: "Image/Outputs" bytes_value: "\x12\x34\x56\x78" }"#,
    );
    let dd = sub.expect(&dev("DDATA", 3), |d| {
        d.get("Inputs/2 words in_out[3]", "int_value") == Some("120")
    });
    assert_eq!(dd.get("Inputs/2 words in_out[0]", "int_value"), Some("18"));
    assert!(dd.get("Inputs/2 words in_out[0]", "datatype").is_none());
    assert!(dd.metric("Properties/Name").is_none(), "{dd:?}");
    assert!(dd.seq().unwrap() >= 4);

    // DCMD by channel name, a negative value on a signed channel (two's
    // complement in int_value) and a positive one.
    for (timestamp, value) in [(2, "4294967294"), (3, "4321")] {
        let metric = format!(r#"metrics {{ name: "Outputs/setpoint1" int_value: {value} }}"#);
        command(
            port,
            &dev("DCMD", 25),
            &format!("timestamp: {timestamp} {metric}"),
        );
        sub.expect(&dev("DDATA", 25), |d| {
            d.get("Outputs/setpoint1", "int_value") == Some(value)
        });
    }

    // Refused, nothing written: a slave not in `writable`, and a command
    // with one unknown metric next to a good one. A later good write
    // shows the refused ones never reached an image.
    command(
        port,
        &dev("DCMD", 4),
        r#"timestamp: 4 metrics { name: "Image/Outputs" bytes_value: "\x01\x01\x01\x01" }"#,
    );
    command(
        port,
        &dev("DCMD", 3),
        r#"timestamp: 5 metrics { name: "Outputs/2 words in_out[0]" int_value: 99 } metrics { name: "Outputs/nope" int_value: 1 }"#,
    );
    command(
        port,
        &dev("DCMD", 3),
        r#"timestamp: 6 metrics { name: "Outputs/2 words in_out[1]" int_value: 7 }"#,
    );
    let dd = sub.expect(&dev("DDATA", 3), |d| {
        d.get("Inputs/2 words in_out[1]", "int_value") == Some("7")
    });
    assert!(dd.get("Inputs/2 words in_out[0]", "int_value").is_none());
    assert!(sub
        .all(&dev("DDATA", 4))
        .iter()
        .all(|d| d.metric("Image/Outputs").is_none()));
    assert!(sub
        .all(&dev("DDATA", 3))
        .iter()
        .all(|d| d.get("Outputs/2 words in_out[0]", "int_value") != Some("99")));

    // NCMD rebirth: NBIRTH (seq 0, same bdSeq) and every DBIRTH again,
    // with the current values.
    command(
        port,
        "spBv1.0/G/NCMD/E",
        r#"timestamp: 7 metrics { name: "Node Control/Rebirth" datatype: 11 boolean_value: true }"#,
    );
    assert_eq!(births(&mut sub), 0);
    let b3 = sub.all(&dev("DBIRTH", 3)).pop().unwrap();
    // (`births` checked the seqs 0..=3.)
    assert_eq!(b3.get("Inputs/2 words in_out[1]", "int_value"), Some("7"));

    check_seq(&sub);

    // The broker dies and comes back: every CONNECT carries the next
    // bdSeq in its will, and the NBIRTH after it the same one.
    mosq.signal(9);
    mosq.wait(T);
    let _mosq = broker(&dir, port);
    let mut sub = Sub::start(port);
    // The births after the reconnection may have come before the
    // subscription: ask for them again (the NBIRTH of a rebirth has the
    // bdSeq of the connection).
    command(
        port,
        "spBv1.0/G/NCMD/E",
        r#"timestamp: 8 metrics { name: "Node Control/Rebirth" datatype: 11 boolean_value: true }"#,
    );
    let bd = births(&mut sub);
    assert!(bd >= 1, "bdSeq counts the connections: {bd}");

    // Killed: the broker publishes the last will, NDEATH with the bdSeq
    // of the NBIRTH and no seq.
    gw.signal(9);
    let nd = sub.expect(NDEATH, |_| true);
    assert_eq!(nd.get("bdSeq", "long_value"), Some(bd.to_string().as_str()));
    assert_eq!(nd.seq(), None);
    assert_eq!(nd.metrics.len(), 1);
    let _ = gw.finish(T);
}

/// The gateway as a master on a line (`dpctl bus`, a `dpctl slave`
/// process), Sparkplug from the bus file's `[mqtt] sparkplug`: the
/// slave's process dies (DDEATH) and comes back (DBIRTH); a clean stop
/// publishes NDEATH.
#[test]
fn sparkplug_on_a_line_ddeath_dbirth_and_clean_ndeath() {
    let dir = TempDir::new("sparkplug-line");
    let port = free_port();
    let _mosq = broker(&dir, port);
    let line = common::Bus::start(2, &[]);
    let mut s = echo_slave(&line.link(1));
    let bus = write_bus(
        &dir,
        &echo_bus_text("sparkplug = \"G/E\"\nwritable = [3]\n"),
    );
    let mut sub = Sub::start(port);
    let gw = gateway(&bus, port, &["--port", &line.link_str(0)]);
    let nb = sub.expect(NBIRTH, |_| true);
    assert_eq!(nb.get("bdSeq", "long_value"), Some("0"));
    sub.expect(&dev("DBIRTH", 3), |_| true);
    command(
        port,
        &dev("DCMD", 3),
        r#"timestamp: 1 metrics { name: "Image/Outputs" bytes_value: "\xa5\xa5\x01\x02" }"#,
    );
    sub.expect(&dev("DDATA", 3), |d| {
        d.get("Inputs/2 words in_out[0]", "int_value") == Some("165")
    });

    // The slave's process dies: DDEATH (seq and timestamp only).
    s.signal(9);
    s.wait(T);
    let dd = sub.expect(&dev("DDEATH", 3), |_| true);
    assert!(dd.metrics.is_empty() && dd.fields.contains_key("timestamp"));
    // It comes back: DBIRTH again.
    let _s = echo_slave(&line.link(1));
    sub.expect(&dev("DBIRTH", 3), |_| true);

    // SIGTERM: the gateway publishes NDEATH itself before disconnecting.
    gw.signal(15);
    let nd = sub.expect(NDEATH, |_| true);
    assert_eq!(nd.get("bdSeq", "long_value"), Some("0"));
    check_seq(&sub);
    let out = gw.finish(T);
    assert!(out.status.success(), "gateway failed: {}", out.stderr);
}

/// A DP-V1 slave whose GSD declares diagnostic, process and pull/plug
/// alarms: an `Alarms/…` metric per type in its DBIRTH (null), and the
/// alarm the slave raises in a DDATA of its type's metric, as the JSON of
/// the master's alarm event.
#[test]
fn sparkplug_alarm_metrics_per_alarm_type() {
    let dir = TempDir::new("sparkplug-alarms");
    let port = free_port();
    let _mosq = broker(&dir, port);
    let line = common::Bus::start(2, &[]);
    let gsd = common::repo().join("crates/cli/tests/data/DPCTL_ALM.GSD");
    let mut slave = Proc::spawn(
        "dpctl slave 9",
        Command::new(dpctl())
            .args(["slave", "--port"])
            .arg(line.link(1))
            .args(["--addr", "9", "--baud", "1.5M", "--gsd"])
            .arg(&gsd)
            .args(["--module", "2 words in/out", "--control", "-"])
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    let bus = dir.path("bus.toml");
    std::fs::write(
        &bus,
        format!(
            "[master]\naddress = 1\nbaud = \"1.5M\"\n[[slave]]\naddress = 9\ngsd = \"{}\"\n\
             modules = [\"2 words in/out\"]\n[mqtt]\nsparkplug = \"G/E\"\n",
            gsd.display()
        ),
    )
    .unwrap();
    let mut sub = Sub::start(port);
    let gw = gateway(&bus, port, &["--port", &line.link_str(0)]);
    let birth = sub.expect(&dev("DBIRTH", 9), |_| true);
    for t in ["diagnostic", "process", "pull", "plug"] {
        let m = birth.metric(&format!("Alarms/{t}"));
        assert!(m.is_some(), "Alarms/{t} in {birth:#?}");
        assert_eq!(m.unwrap().get("is_null").map(String::as_str), Some("true"));
    }
    assert!(birth.metric("Alarms/update").is_none(), "not declared");
    common::send(&mut slave, "alarm plug 3 appears");
    let data = sub.expect(&dev("DDATA", 9), |d| d.metric("Alarms/plug").is_some());
    let json = data.get("Alarms/plug", "string_value").unwrap();
    // protoc prints the string quoted, with `"` escaped.
    let json: serde_json::Value =
        serde_json::from_str(&json[1..json.len() - 1].replace("\\\"", "\"")).unwrap();
    assert_eq!(json["type"], "plug", "{json}");
    assert_eq!(json["slot"], 3, "{json}");
    assert_eq!(json["acknowledged"], true, "{json}");
    gw.signal(15);
    let out = gw.finish(T);
    assert!(out.status.success(), "gateway failed: {}", out.stderr);
    slave.terminate(T);
}

/// A primary host application's STATE (Sparkplug 3.0), retained.
fn host_state(port: u16, online: bool, ts: u64) {
    let ok = Command::new("mosquitto_pub")
        .args(["-h", "127.0.0.1", "-p", &port.to_string(), "-q", "1", "-r"])
        .args(["-t", "spBv1.0/STATE/scada"])
        .args([
            "-m",
            &format!(r#"{{"online": {online}, "timestamp": {ts}}}"#),
        ])
        .status()
        .expect("mosquitto_pub")
        .success();
    assert!(ok, "mosquitto_pub of the STATE failed");
}

/// With `primary_host`: the edge node waits for the host's STATE online
/// before its NBIRTH, holds births and data while the host is offline
/// (a DCMD taken meanwhile is applied, its echo not published), and is
/// reborn (NBIRTH seq 0, every DBIRTH, the echo in it) when the host is
/// back.
#[test]
fn sparkplug_primary_host_state_holds_and_rebirths() {
    let dir = TempDir::new("sparkplug-state");
    let mqtt = "[mqtt]\nbus = \"line\"\nwritable = [3]\nprimary_host = \"scada\"\n";
    let bus = write_bus(&dir, &format!("{GATEWAY_SLAVES}pkw = false\n\n{mqtt}"));
    let port = free_port();
    let _mosq = broker(&dir, port);
    let mut sub = Sub::start(port);
    let mut c = Command::new(dpctl());
    c.env("DPCTL_LOG", "warn,profibus_gateway=info")
        .arg("gateway")
        .arg("--config")
        .arg(&bus)
        .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")])
        .args(["--sim", "--sparkplug", "G/E"]);
    let gw = Proc::spawn_captured(c);
    let log = |what: &str| {
        let end = Instant::now() + T;
        while let Some(l) = gw.stderr_line(end.saturating_duration_since(Instant::now())) {
            if l.contains(what) {
                return;
            }
        }
        panic!("no `{what}` in the gateway's log");
    };
    log("connected to the MQTT broker");
    host_state(port, true, 1);
    births(&mut sub);
    let at = |sub: &Sub, topic: &str, from: usize| {
        (sub.seen.iter().skip(from))
            .position(|(t, _)| t == topic)
            .map(|i| i + from)
    };
    let state = "spBv1.0/STATE/scada";
    assert!(
        at(&sub, state, 0) < at(&sub, NBIRTH, 0),
        "no NBIRTH before the host is online"
    );
    // The host goes offline; a write meanwhile is applied, not published.
    host_state(port, false, 2);
    log("primary host application offline");
    command(
        port,
        &dev("DCMD", 3),
        r#"timestamp: 1 metrics { name: "Image/Outputs" bytes_value: "\x11\x22\x33\x44" }"#,
    );
    log("Sparkplug DCMD applied");
    host_state(port, true, 3);
    let echoed = |d: &Decoded| d.get("Image/Inputs", "bytes_value") == Some(r#""\021\"3D""#);
    let nb = sub.expect(NBIRTH, |_| true);
    assert_eq!(nb.seq(), Some(0));
    sub.expect(&dev("DBIRTH", 3), echoed);
    // Between the offline and the online STATE: not a message with the
    // write's echo.
    let off = (sub.seen.iter())
        .enumerate()
        .filter(|(_, (t, _))| t == state)
        .map(|(i, _)| i)
        .collect::<Vec<_>>();
    assert!(off.len() >= 3, "three STATEs seen");
    assert!(
        sub.seen[off[1]..off[2]].iter().all(|(_, d)| !echoed(d)),
        "nothing published while the host is offline"
    );
    drop(gw);
}

/// Decodes `TYPE HEX` lines with pysparkplug (PyPI; an independent
/// Sparkplug B implementation): births through its message classes (which
/// check datatypes and values), data messages, whose metrics carry no
/// datatype, through its protobuf module with the datatype of the alias
/// from the birth. Prints one JSON line per message.
const PYSPARKPLUG: &str = r#"
import sys, json
import pysparkplug as spb
from pysparkplug._protobuf import sparkplug_b_pb2 as pb
types = {}
def show(v):
    return v.hex() if isinstance(v, (bytes, bytearray)) else v
for line in sys.stdin:
    kind, data = line.split()
    raw = bytes.fromhex(data)
    if kind in ("NBIRTH", "DBIRTH"):
        msg = (spb.NBirth if kind == "NBIRTH" else spb.DBirth).decode(raw)
        ms = [{"name": m.name, "alias": m.alias, "value": show(m.value)} for m in msg.metrics]
        for m in msg.metrics:
            if m.alias is not None:
                types[m.alias] = m.datatype
        print(json.dumps({"type": kind, "seq": msg.seq, "metrics": ms}))
    else:
        p = pb.Payload()
        p.ParseFromString(raw)
        ms = []
        for m in p.metrics:
            dt = types[m.alias]
            v = dt.decode(getattr(m, m.WhichOneof("value")))
            ms.append({"name": m.name if m.HasField("name") else None, "alias": m.alias, "value": show(v)})
        print(json.dumps({"type": kind, "seq": p.seq, "metrics": ms}))
"#;

/// NBIRTH, DBIRTH and DDATA as pysparkplug reads them: names, aliases
/// and values agree with what the gateway meant.
#[test]
fn sparkplug_payloads_decode_with_pysparkplug() {
    let dir = TempDir::new("sparkplug-py");
    let mqtt = "[mqtt]\nbus = \"line\"\nwritable = [3]\n";
    let bus = write_bus(&dir, &format!("{GATEWAY_SLAVES}pkw = false\n\n{mqtt}"));
    let port = free_port();
    let _mosq = broker(&dir, port);
    let mut sub = Sub::start(port);
    let _gw = gateway(&bus, port, &["--sim", "--sparkplug", "G/E"]);
    births(&mut sub);
    command(
        port,
        &dev("DCMD", 3),
        r#"timestamp: 1 metrics { name: "Image/Outputs" bytes_value: "\x11\x22\x33\x44" }"#,
    );
    sub.expect(&dev("DDATA", 3), |d| {
        d.get("Image/Inputs", "bytes_value") == Some(r#""\021\"3D""#)
    });
    let mut input = String::new();
    for ((t, _), raw) in sub.seen.iter().zip(&sub.raw) {
        let kind = t.split('/').nth(2).unwrap();
        if ["NBIRTH", "DBIRTH", "DDATA"].contains(&kind) && (kind == "NBIRTH" || t.ends_with("/3"))
        {
            let hex: String = raw.iter().map(|b| format!("{b:02x}")).collect();
            input += &format!("{kind} {hex}\n");
        }
    }
    let msgs = mqtt::pysparkplug(PYSPARKPLUG, &input);
    let metric = |m: &serde_json::Value, name: &str| {
        m["metrics"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["name"] == name)
            .cloned()
    };
    let nbirth = &msgs[0];
    assert_eq!(
        (nbirth["type"].as_str(), nbirth["seq"].as_u64()),
        (Some("NBIRTH"), Some(0))
    );
    assert_eq!(metric(nbirth, "Node Control/Rebirth").unwrap()["alias"], 0);
    assert_eq!(metric(nbirth, "Bus/State").unwrap()["value"], "operate");
    let dbirth = msgs.iter().find(|m| m["type"] == "DBIRTH").unwrap();
    assert_eq!(metric(dbirth, "Properties/Name").unwrap()["value"], "echo");
    let inputs = metric(dbirth, "Image/Inputs").unwrap()["alias"].clone();
    assert!(inputs.as_u64().is_some());
    // The DDATA: by alias, no name, the echoed image.
    let echoed =
        msgs.iter().any(|m| {
            m["type"] == "DDATA"
                && m["metrics"].as_array().unwrap().iter().any(|x| {
                    x["alias"] == inputs && x["name"].is_null() && x["value"] == "11223344"
                })
        });
    assert!(echoed, "{msgs:#?}");
}
