//! The live view shared by `dpctl master` and `dpctl demo`: events as
//! lines or JSON, a refreshing table of the slaves on a terminal.

pub use crate::describe::hex;
use profibus_devices::channels::{ChannelMap, Direction};
use profibus_dp::diag;
use profibus_dp::gsd::Gsd;
use profibus_dp::master::{DpMaster, MasterEvent};
use profibus_fdl::{Baud, Instant};
use serde_json::{json, Value};
use std::io::Write;
use std::time::Duration;

/// What the view shows of a slave besides the master's state.
pub struct SlaveInfo {
    /// Station address.
    pub address: u8,
    /// Name.
    pub name: String,
    /// The GSD, for diagnosis texts.
    pub gsd: Option<Gsd>,
    /// DP-V1 slave.
    pub dpv1: bool,
    /// Named channels of its process images (a slave given as a device
    /// profile).
    pub channels: Option<ChannelMap>,
}

/// The channels of one image as a JSON object and as `name=value` words.
fn channel_values(map: &ChannelMap, dir: Direction, image: &[u8]) -> (Value, String) {
    let mut obj = serde_json::Map::new();
    let mut words = vec![];
    for (c, v) in map.decode(dir, image) {
        obj.insert(c.name.clone(), json!(v));
        match &c.scale {
            Some(sc) => words.push(format!("{}={v} {}", c.name, sc.unit)),
            None => words.push(format!("{}={v}", c.name)),
        }
    }
    (Value::Object(obj), words.join(" "))
}

impl View {
    pub fn new(json: bool, tty: bool, interval: Duration) -> View {
        View {
            json,
            tty,
            log: Vec::new(),
            last_print: None,
            interval,
        }
    }
}

pub struct View {
    pub json: bool,
    pub tty: bool,
    log: Vec<String>,
    last_print: Option<Instant>,
    interval: Duration,
}

impl View {
    pub fn event(&mut self, v: Value, text: String) {
        if self.json {
            println!("{v}");
        } else if self.tty {
            self.log.push(text);
            let n = self.log.len();
            if n > 12 {
                self.log.drain(..n - 12);
            }
        } else {
            println!("{text}");
        }
    }

    pub fn status(
        &mut self,
        m: &DpMaster,
        slaves_info: &[SlaveInfo],
        baud: Baud,
        now: Instant,
        force: bool,
    ) {
        if !force && self.last_print.is_some_and(|t| now < t + self.interval) {
            return;
        }
        self.last_print = Some(now);
        let c = m.cycle_stats();
        let mut slaves: Vec<Value> = slaves_info
            .iter()
            .map(|s| {
                let a = s.address;
                let st = m.slave_stats(a).unwrap_or_default();
                let mut v = json!({
                    "address": a,
                    "name": s.name,
                    "state": m.slave_state(a).map(|x| x.name()),
                    "inputs": hex(m.inputs(a).unwrap_or(&[])),
                    "outputs": hex(m.outputs(a).unwrap_or(&[])),
                    "data_exchanges": st.data_exchanges,
                    "retries": st.retries,
                    "errors": st.errors,
                    "restarts": st.restarts,
                });
                if let Some(map) = &s.channels {
                    let (i, it) = channel_values(map, Direction::Input, m.inputs(a).unwrap_or(&[]));
                    let (o, ot) =
                        channel_values(map, Direction::Output, m.outputs(a).unwrap_or(&[]));
                    v["channels"] = json!({"inputs": i, "outputs": o});
                    v["channels_text"] = json!(format!("in: {it}  out: {ot}"));
                }
                v
            })
            .collect();
        if self.json {
            for s in &mut slaves {
                if let Some(o) = s.as_object_mut() {
                    o.remove("channels_text");
                }
            }
            println!(
                "{}",
                json!({
                    "event": "status",
                    "t": now.as_nanos() as f64 / 1e9,
                    "cycles": c.cycles,
                    "cycle_us": {
                        "min": c.min_ns / 1000,
                        "avg": c.avg().as_micros() as u64,
                        "max": c.max_ns / 1000,
                    },
                    "operating": format!("{:?}", m.operating_state()).to_lowercase(),
                    "slaves": slaves,
                })
            );
            return;
        }
        let mut out = String::new();
        if self.tty {
            out.push_str("\x1b[H\x1b[2J");
        }
        out.push_str(&format!(
            "master {} at {}  {:?}  cycles {}  cycle min/avg/max {}/{}/{} µs\n",
            m.address(),
            baud,
            m.operating_state(),
            c.cycles,
            c.min_ns / 1000,
            c.avg().as_micros(),
            c.max_ns / 1000
        ));
        for s in &slaves {
            out.push_str(&format!(
                "  {:3} {:<20} {:<13} in: {}  out: {}  (errors {}, retries {})\n",
                s["address"],
                s["name"].as_str().unwrap_or(""),
                s["state"].as_str().unwrap_or(""),
                s["inputs"].as_str().unwrap_or(""),
                s["outputs"].as_str().unwrap_or(""),
                s["errors"],
                s["retries"],
            ));
            if let Some(t) = s["channels_text"].as_str() {
                out.push_str(&format!("      {t}\n"));
            }
        }
        if self.tty {
            for l in &self.log {
                out.push_str(l);
                out.push('\n');
            }
        }
        print!("{out}");
        let _ = std::io::stdout().flush();
    }
}

pub fn drain_events(m: &mut DpMaster, slaves_info: &[SlaveInfo], view: &mut View) {
    while let Some(e) = m.poll_event() {
        match e {
            MasterEvent::StateChanged { address, from, to } => view.event(
                json!({"event": "state", "slave": address, "from": from.name(), "to": to.name()}),
                format!("slave {address}: {} → {}", from.name(), to.name()),
            ),
            MasterEvent::Diag { address } => {
                let raw = m.diag(address).unwrap_or(&[]).to_vec();
                let s = slaves_info.iter().find(|s| s.address == address);
                let words = diag::describe(
                    &raw,
                    s.and_then(|s| s.gsd.as_ref()),
                    s.is_some_and(|s| s.dpv1),
                );
                view.event(
                    json!({"event": "diag", "slave": address, "raw": hex(&raw), "words": words}),
                    format!("slave {address} diagnosis: {}", words.join("; ")),
                );
            }
            MasterEvent::Fault { address, reason } => view.event(
                json!({"event": "fault", "slave": address, "reason": reason.to_string()}),
                format!("slave {address} fault: {reason}"),
            ),
            MasterEvent::JobDone(id) => {
                let r = m.take_result(id);
                let (data, words) = match &r {
                    Some(profibus_dp::master::JobResult::Data(d)) => (Some(hex(d)), "ok".into()),
                    Some(other) => (None, other.describe()),
                    None => (None, "lost".into()),
                };
                view.event(
                    json!({"event": "job", "id": id.0, "data": data, "result": words}),
                    format!(
                        "job {}: {}{}",
                        id.0,
                        words,
                        data.map(|d| format!(" [{d}]")).unwrap_or_default()
                    ),
                );
            }
            MasterEvent::Ring(e) => {
                let text = e.to_string();
                view.event(
                    json!({"event": "ring", "what": text}),
                    format!("ring: {text}"),
                )
            }
        }
    }
}
