//! `dpctl gateway --sparkplug` with `[mqtt] sparkplug_templates = true`
//! against a real broker: template definitions in the NBIRTH, instances
//! in the DBIRTHs, changed members in DDATA, a DCMD as a template
//! instance. Every payload is read by two independent decoders: `protoc
//! --decode` against crates/gateway/proto/sparkplug_b.proto (the
//! specification's schema) and the protobuf module of pysparkplug (PyPI,
//! compiled by its authors from the specification). Fails (never skips)
//! when mosquitto, protoc or pysparkplug are missing: run
//! `scripts/setup-test-env`.

mod common;

use common::mqtt::{self, broker, free_port, write_bus, GATEWAY_SLAVES};
use common::{dpctl, require, Lines, Proc, TempDir};
use serde_json::{json, Map, Value};
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const T: Duration = Duration::from_secs(30);
const MESSAGE: &str = "org.eclipse.tahu.protobuf.Payload";
/// The template of the GSD slaves (DPCTL_GEN.GSD's `Model_Name`).
const GENERIC: &str = "dpctl generic slave";

/// A payload as protoc decodes it, as a [`text_tree`].
fn decode(payload: &[u8]) -> Value {
    let text = mqtt::protoc(&format!("--decode={MESSAGE}"), payload);
    text_tree(&String::from_utf8(text).unwrap())
}

/// protoc's text format as JSON: every field name maps to the list of
/// its values (nested messages as objects, scalars as their text).
fn text_tree(text: &str) -> Value {
    let mut stack = vec![Map::new()];
    let mut names = vec![];
    for l in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        if let Some(name) = l.strip_suffix(" {") {
            names.push(name.to_string());
            stack.push(Map::new());
        } else if l == "}" {
            let done = Value::Object(stack.pop().unwrap());
            push(stack.last_mut().unwrap(), names.pop().unwrap(), done);
        } else {
            let (k, v) = l.split_once(": ").unwrap_or_else(|| panic!("{l}"));
            let v = v.trim_matches('"').to_string();
            push(stack.last_mut().unwrap(), k.into(), Value::String(v));
        }
    }
    Value::Object(stack.pop().unwrap())
}

fn push(m: &mut Map<String, Value>, k: String, v: Value) {
    m.entry(k)
        .or_insert_with(|| json!([]))
        .as_array_mut()
        .unwrap()
        .push(v);
}

/// The first value of `field` in a [`text_tree`] node, as text.
fn one<'a>(node: &'a Value, field: &str) -> Option<&'a str> {
    node[field][0].as_str()
}

/// The metrics of a [`text_tree`] node (a payload or a template).
fn metrics(node: &Value) -> Vec<Value> {
    node["metrics"].as_array().cloned().unwrap_or_default()
}

fn named(ms: &[Value], name: &str) -> Value {
    ms.iter()
        .find(|m| one(m, "name") == Some(name))
        .unwrap_or_else(|| panic!("no metric {name} in {ms:#?}"))
        .clone()
}

/// Messages received on `spBv1.0/#`, payloads as bytes.
struct Sub {
    _p: Proc,
    lines: Lines,
    read: usize,
    seen: Vec<(String, Vec<u8>)>,
}

const PROBE: &str = "spBv1.0/probe";

impl Sub {
    fn start(port: u16) -> Sub {
        let (p, lines) = mqtt::subscribe(port, &["-t", "spBv1.0/#", "-F", "%t %x"], &[], PROBE);
        Sub {
            _p: p,
            lines,
            read: 0,
            seen: vec![],
        }
    }

    /// The first message on `topic` after message `from` whose payload
    /// satisfies `ok`: its index.
    fn expect(&mut self, topic: &str, from: usize, ok: impl Fn(&[u8]) -> bool) -> usize {
        let end = Instant::now() + T;
        loop {
            while self.read < self.lines.1.len() {
                let l = self.lines.1[self.read].clone();
                self.read += 1;
                let (t, hex) = l.split_once(' ').unwrap_or((&l, ""));
                if t.starts_with("spBv1.0/") && t != PROBE {
                    let bytes = (0..hex.len() / 2)
                        .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
                        .collect();
                    self.seen.push((t.to_string(), bytes));
                }
            }
            if let Some(i) =
                (from..self.seen.len()).find(|&i| self.seen[i].0 == topic && ok(&self.seen[i].1))
            {
                return i;
            }
            let left = end.saturating_duration_since(Instant::now());
            assert!(
                self.lines.next_line(left).is_some(),
                "nothing on {topic}; got {:?}",
                self.seen.iter().map(|(t, _)| t).collect::<Vec<_>>()
            );
        }
    }
}

/// Publish a payload written in protobuf text format, encoded by protoc.
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
    assert!(p.wait().unwrap().success(), "mosquitto_pub to {topic}");
}

/// Decodes `HEX` lines with pysparkplug's protobuf module (the
/// specification's schema, compiled by pysparkplug's authors) and prints
/// each payload as JSON with the schema's field names.
const PYSPARKPLUG: &str = r#"
import sys
from google.protobuf import json_format
from pysparkplug._protobuf import sparkplug_b_pb2 as pb
for line in sys.stdin:
    p = pb.Payload()
    p.ParseFromString(bytes.fromhex(line.strip()))
    print(json_format.MessageToJson(p, preserving_proto_field_name=True, indent=None))
"#;

fn pysparkplug(payloads: &[&[u8]]) -> Vec<Value> {
    let input: String = payloads
        .iter()
        .map(|p| p.iter().map(|b| format!("{b:02x}")).collect::<String>() + "\n")
        .collect();
    mqtt::pysparkplug(PYSPARKPLUG, &input)
}

fn py_named<'a>(ms: &'a Value, name: &str) -> &'a Value {
    ms.as_array()
        .unwrap()
        .iter()
        .find(|m| m["name"] == name)
        .unwrap_or_else(|| panic!("no metric {name} in {ms:#}"))
}

#[test]
fn sparkplug_templates_define_types_in_nbirth_and_instances_in_dbirth() {
    let dir = TempDir::new("sparkplug-templates");
    let mqtt = "[mqtt]\nbus = \"line\"\nwritable = [3, 25]\nsparkplug_templates = true\n";
    let bus = write_bus(&dir, &format!("{GATEWAY_SLAVES}pkw = false\n\n{mqtt}"));
    let port = free_port();
    let _mosq = broker(&dir, port);
    let mut sub = Sub::start(port);
    let _gw = Proc::spawn_captured({
        let mut c = Command::new(dpctl());
        c.arg("gateway")
            .arg("--config")
            .arg(&bus)
            .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")])
            .args(["--sim", "--sparkplug", "G/E"]);
        c
    });
    let nb = sub.expect("spBv1.0/G/NBIRTH/E", 0, |_| true);
    let db3 = sub.expect("spBv1.0/G/DBIRTH/E/3", nb, |_| true);
    let db25 = sub.expect("spBv1.0/G/DBIRTH/E/25", nb, |_| true);

    // protoc: the definitions in the NBIRTH, one per device type (the
    // two GSD slaves share one), is_definition true, no template_ref,
    // members with names and datatypes, the parameters.
    let nbirth = decode(&sub.seen[nb].1);
    let ms = metrics(&nbirth);
    let defs: Vec<&Value> = ms
        .iter()
        .filter(|m| one(m, "datatype") == Some("19"))
        .collect();
    let names: Vec<_> = defs.iter().map(|d| one(d, "name").unwrap()).collect();
    assert_eq!(names, [GENERIC, "omega"], "{ms:#?}");
    let generic = &named(&ms, GENERIC)["template_value"][0];
    assert_eq!(one(generic, "is_definition"), Some("true"));
    assert_eq!(one(generic, "template_ref"), None);
    assert_eq!(one(generic, "version").map(str::len), Some(8));
    let members = metrics(generic);
    let member = named(&members, "Inputs/2 words in_out[0]");
    assert_eq!(one(&member, "datatype"), Some("5"), "UInt8");
    assert_eq!(one(&member, "is_null"), Some("true"));
    assert!(one(&member, "alias").is_none());
    assert!(members
        .iter()
        .any(|m| one(m, "name") == Some("Outputs/2 words in_out[3]")));
    let params: Vec<_> = generic["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (one(p, "name").unwrap(), one(p, "type").unwrap()))
        .collect();
    assert_eq!(params, [("Address", "5"), ("Name", "12")]);
    let omega = &named(&ms, "omega")["template_value"][0];
    let om = metrics(omega);
    assert_eq!(one(&named(&om, "Inputs/status1"), "datatype"), Some("6"));
    assert_eq!(one(&named(&om, "Outputs/setpoint1"), "datatype"), Some("3"));

    // The DBIRTHs: the channels as one instance `Channels` of the
    // device's definition (template_ref), every member with its value and
    // alias; the other metrics flat as before.
    let dbirth = decode(&sub.seen[db3].1);
    let ms = metrics(&dbirth);
    assert_eq!(
        one(&named(&ms, "Properties/Address"), "int_value"),
        Some("3")
    );
    assert!(ms
        .iter()
        .all(|m| !one(m, "name").unwrap().starts_with("Inputs/")));
    let inst = named(&ms, "Channels");
    assert_eq!(one(&inst, "datatype"), Some("19"));
    let inst_alias = one(&inst, "alias").unwrap().to_string();
    let t = &inst["template_value"][0];
    assert_eq!(one(t, "is_definition"), Some("false"));
    assert_eq!(one(t, "template_ref"), Some(GENERIC));
    let im = metrics(t);
    assert_eq!(
        im.iter()
            .map(|m| one(m, "name").unwrap())
            .collect::<Vec<_>>(),
        members
            .iter()
            .map(|m| one(m, "name").unwrap())
            .collect::<Vec<_>>(),
        "an instance in a birth has every member of its definition"
    );
    let in0 = named(&im, "Inputs/2 words in_out[0]");
    assert_eq!(one(&in0, "datatype"), Some("5"));
    assert_eq!(one(&in0, "int_value"), Some("0"));
    let in0_alias = one(&in0, "alias").unwrap().to_string();
    let p: Vec<_> = t["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                one(p, "name").unwrap(),
                one(p, "int_value").or(one(p, "string_value")).unwrap(),
            )
        })
        .collect();
    assert_eq!(p, [("Address", "3"), ("Name", "echo")]);
    let d25 = decode(&sub.seen[db25].1);
    let t25 = &named(&metrics(&d25), "Channels")["template_value"][0];
    assert_eq!(one(t25, "template_ref"), Some("omega"));
    assert_eq!(
        one(&named(&metrics(t25), "Outputs/setpoint1"), "datatype"),
        Some("3")
    );

    // A DCMD as an instance with one member: the echo's inputs follow,
    // reported in a DDATA as the instance (by alias) with the changed
    // members by alias.
    command(
        port,
        "spBv1.0/G/DCMD/E/3",
        r#"timestamp: 1 metrics { name: "Channels" datatype: 19 template_value { is_definition: false template_ref: "dpctl generic slave" metrics { name: "Outputs/2 words in_out[0]" datatype: 5 int_value: 18 } } }"#,
    );
    let dd = sub.expect("spBv1.0/G/DDATA/E/3", db3, |b| {
        metrics(&decode(b)).iter().any(|m| {
            m["template_value"][0]["metrics"]
                .as_array()
                .is_some_and(|ms| {
                    ms.iter().any(|x| {
                        one(x, "alias") == Some(in0_alias.as_str())
                            && one(x, "int_value") == Some("18")
                    })
                })
        })
    });
    let ddata = decode(&sub.seen[dd].1);
    let inst = metrics(&ddata)
        .into_iter()
        .find(|m| one(m, "alias") == Some(inst_alias.as_str()))
        .expect("the instance by its alias");
    assert!(
        one(&inst, "name").is_none() && one(&inst, "datatype").is_none(),
        "{inst:#?}"
    );
    let t = &inst["template_value"][0];
    assert_eq!(one(t, "template_ref"), Some(GENERIC));
    assert_eq!(one(t, "is_definition"), Some("false"));
    assert!(
        metrics(t).iter().all(|m| one(m, "name").is_none()),
        "members by alias only"
    );
    assert!(metrics(t).len() < im.len(), "only what changed");

    // pysparkplug's decoder reads the same.
    let py = pysparkplug(&[&sub.seen[nb].1, &sub.seen[db3].1, &sub.seen[dd].1]);
    let def = &py_named(&py[0]["metrics"], GENERIC)["template_value"];
    assert_eq!(def["is_definition"], true);
    assert!(def.get("template_ref").is_none());
    assert_eq!(
        py_named(&def["metrics"], "Inputs/2 words in_out[1]")["datatype"],
        5
    );
    let inst = &py_named(&py[1]["metrics"], "Channels");
    assert_eq!(inst["datatype"], 19);
    assert_eq!(inst["template_value"]["template_ref"], GENERIC);
    assert_eq!(inst["template_value"]["is_definition"], false);
    assert_eq!(
        py_named(
            &inst["template_value"]["metrics"],
            "Outputs/2 words in_out[0]"
        )["int_value"],
        0
    );
    let data = py[2]["metrics"].as_array().unwrap();
    let changed = data
        .iter()
        .find(|m| m["alias"] == inst_alias.as_str())
        .expect("the instance in the DDATA");
    let member = changed["template_value"]["metrics"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["alias"] == in0_alias.as_str())
        .expect("the echoed member");
    assert_eq!(member["int_value"], 18);
}
