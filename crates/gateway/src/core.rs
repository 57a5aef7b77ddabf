//! The sans-IO gateway: topics and payloads from a DP master's slaves,
//! and output writes from MQTT messages. No broker, no clock: the driver
//! hands in messages and the wall-clock time, and sends what
//! [`Gateway::poll_publish`] returns.

use crate::settings::{MqttSettings, PublishMode};
use profibus_devices::channels::{ChannelMap, Direction, Value};
use profibus_dp::gsd::Gsd;
use profibus_dp::master::{DpMaster, MasterEvent, SlaveState};
use serde_json::{json, Map};
use std::collections::VecDeque;

/// A message for the broker.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Publish {
    /// Topic.
    pub topic: String,
    /// Payload (JSON text).
    pub payload: Vec<u8>,
    /// Whether the broker keeps it for late subscribers.
    pub retain: bool,
}

/// What the gateway knows of one configured slave.
#[derive(Debug, Clone)]
pub struct SlaveInfo {
    /// Station address.
    pub address: u8,
    /// Name from the bus file.
    pub name: String,
    /// Named channels of its images (device profiles), if any.
    pub channels: Option<ChannelMap>,
    /// Its GSD, for diagnosis texts.
    pub gsd: Option<Gsd>,
    /// Whether it is a DP-V1 slave (diagnosis decoding).
    pub dpv1: bool,
}

/// The topics of one gateway: `<prefix>/<bus>/…`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topics {
    base: String,
}

/// The per-slave topics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlaveTopic {
    /// `<addr>/state`: the slave's state in the master (retained).
    State,
    /// `<addr>/inputs`: the input image (retained).
    Inputs,
    /// `<addr>/outputs`: the output image sent (retained).
    Outputs,
    /// `<addr>/diag`: the last diagnosis (retained).
    Diag,
    /// `<addr>/outputs/set`: writes (subscribed).
    OutputsSet,
    /// `<addr>/outputs/response`: the answer to each write.
    OutputsResponse,
}

impl SlaveTopic {
    fn suffix(self) -> &'static str {
        match self {
            SlaveTopic::State => "state",
            SlaveTopic::Inputs => "inputs",
            SlaveTopic::Outputs => "outputs",
            SlaveTopic::Diag => "diag",
            SlaveTopic::OutputsSet => "outputs/set",
            SlaveTopic::OutputsResponse => "outputs/response",
        }
    }
}

impl Topics {
    /// Topics under `prefix` for the bus `bus`.
    pub fn new(prefix: &str, bus: &str) -> Topics {
        Topics {
            base: format!("{prefix}/{bus}"),
        }
    }

    /// `<prefix>/<bus>/status`: the gateway's status (retained; the last
    /// will sets it offline).
    pub fn status(&self) -> String {
        format!("{}/status", self.base)
    }

    /// A slave's topic.
    pub fn slave(&self, address: u8, t: SlaveTopic) -> String {
        format!("{}/{address}/{}", self.base, t.suffix())
    }

    /// The filter the gateway subscribes to for writes.
    pub fn set_filter(&self) -> String {
        format!("{}/+/outputs/set", self.base)
    }

    /// The station address of a write topic (`<prefix>/<bus>/<addr>/outputs/set`),
    /// `None` for any other topic. An address that is not a number is
    /// `Some(Err(text))`.
    pub fn parse_set(&self, topic: &str) -> Option<Result<u8, String>> {
        let rest = topic.strip_prefix(&self.base)?.strip_prefix('/')?;
        let addr = rest.strip_suffix("/outputs/set")?;
        if addr.contains('/') {
            return None;
        }
        Some(addr.parse::<u8>().map_err(|_| addr.to_string()))
    }
}

/// Lower-case hex of bytes.
pub fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

/// Bytes of a non-empty hex string (spaces, `:`, `_` and a `0x` prefix
/// allowed).
pub fn parse_hex(text: &str) -> Option<Vec<u8>> {
    let t = text.trim();
    let t = t.strip_prefix("0x").unwrap_or(t);
    let digits: Vec<u8> = t
        .bytes()
        .filter(|c| !matches!(c, b' ' | b':' | b'_'))
        .collect();
    if digits.is_empty() || !digits.len().is_multiple_of(2) {
        return None;
    }
    digits
        .chunks(2)
        .map(|p| u8::from_str_radix(std::str::from_utf8(p).ok()?, 16).ok())
        .collect()
}

/// What a write asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum WriteRequest {
    /// The whole output image.
    Image(Vec<u8>),
    /// Named output channels; the rest of the image stays as it is.
    Channels(Vec<(String, Value)>),
}

/// Why a write was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WriteError {
    /// The payload is neither hex nor a JSON write object.
    #[error("malformed write: {0}")]
    Malformed(String),
    /// The topic's address is not a configured slave.
    #[error("no slave {0} on this bus")]
    UnknownSlave(String),
    /// The bus file's `[mqtt] writable` does not list the slave.
    #[error("slave {0} is not writable over MQTT (see [mqtt] writable)")]
    Unauthorised(u8),
    /// A whole image of the wrong length.
    #[error("slave {address} has {expected} output bytes, the write has {got}")]
    Length {
        /// Station address.
        address: u8,
        /// Output image length.
        expected: usize,
        /// Bytes written.
        got: usize,
    },
    /// A named channel the slave lacks, or a value out of its range.
    #[error("{0}")]
    Channel(String),
}

/// A write request parsed from a payload, with its correlation id.
///
/// Payloads: a bare hex string (`0a0b`), or a JSON object with `"hex"`
/// (the whole image) or `"channels"` (`{"name": value}`), and an optional
/// `"correlation_id"` (any JSON value) that the reply repeats.
pub fn parse_write(
    payload: &[u8],
) -> Result<(WriteRequest, Option<serde_json::Value>), WriteError> {
    let text = std::str::from_utf8(payload)
        .map_err(|_| WriteError::Malformed("payload is not UTF-8".into()))?;
    let v: serde_json::Value = match serde_json::from_str(text) {
        Ok(v) => v,
        Err(_) => {
            return parse_hex(text)
                .map(|b| (WriteRequest::Image(b), None))
                .ok_or_else(|| WriteError::Malformed("neither JSON nor hex".into()))
        }
    };
    let serde_json::Value::Object(o) = v else {
        return match v {
            serde_json::Value::String(s) => parse_hex(&s)
                .map(|b| (WriteRequest::Image(b), None))
                .ok_or_else(|| WriteError::Malformed("string is not hex".into())),
            _ => Err(WriteError::Malformed("expected a JSON object".into())),
        };
    };
    let corr = o.get("correlation_id").cloned();
    if let Some(k) = o
        .keys()
        .find(|k| !matches!(k.as_str(), "hex" | "channels" | "correlation_id"))
    {
        return Err(WriteError::Malformed(format!("unknown field `{k}`")));
    }
    let req = match (o.get("hex"), o.get("channels")) {
        (Some(serde_json::Value::String(h)), None) => WriteRequest::Image(
            parse_hex(h).ok_or_else(|| WriteError::Malformed("`hex` is not hex".into()))?,
        ),
        (None, Some(serde_json::Value::Object(c))) if !c.is_empty() => WriteRequest::Channels(
            c.iter()
                .map(|(k, v)| {
                    let val = match v {
                        serde_json::Value::Bool(b) => Value::Bool(*b),
                        serde_json::Value::Number(n) => match n.as_i64() {
                            Some(i) => Value::Int(i),
                            None => Value::Float(n.as_f64().unwrap_or(f64::NAN)),
                        },
                        _ => {
                            return Err(WriteError::Malformed(format!(
                                "channel `{k}`: value must be a number or a boolean"
                            )))
                        }
                    };
                    Ok((k.clone(), val))
                })
                .collect::<Result<_, _>>()?,
        ),
        _ => {
            return Err(WriteError::Malformed(
                "give either `hex` (a string) or `channels` (an object)".into(),
            ))
        }
    };
    Ok((req, corr))
}

fn value_json(v: Value) -> serde_json::Value {
    match v {
        Value::Bool(b) => b.into(),
        Value::Int(i) => i.into(),
        Value::Float(x) => x.into(),
    }
}

/// The last published state of a slave.
#[derive(Debug, Default, Clone)]
struct Published {
    state: Option<SlaveState>,
    inputs: Option<Vec<u8>>,
    outputs: Option<Vec<u8>>,
    diag: Option<Vec<u8>>,
}

#[derive(Debug)]
struct Entry {
    info: SlaveInfo,
    published: Published,
    fault: Option<String>,
}

/// A write waiting for the next cycle boundary.
#[derive(Debug)]
struct Pending {
    address: u8,
    request: WriteRequest,
    correlation: Option<serde_json::Value>,
}

/// The gateway between one DP master and one MQTT broker.
///
/// Drive it from the master's application step (between two polls of the
/// master, i.e. at a cycle boundary): [`Gateway::handle_message`] for each
/// message received, [`Gateway::step`] with the master, then send
/// everything [`Gateway::poll_publish`] returns. After each (re)connection
/// call [`Gateway::connected`]: the status and every retained topic are
/// published again.
#[derive(Debug)]
pub struct Gateway {
    settings: MqttSettings,
    topics: Topics,
    slaves: Vec<Entry>,
    pending: Vec<Pending>,
    out: VecDeque<Publish>,
    next_interval_ms: u64,
    online: bool,
}

impl Gateway {
    /// A gateway for these slaves.
    pub fn new(settings: MqttSettings, slaves: Vec<SlaveInfo>) -> Gateway {
        Gateway {
            topics: Topics::new(&settings.prefix, &settings.bus),
            settings,
            slaves: slaves
                .into_iter()
                .map(|info| Entry {
                    info,
                    published: Published::default(),
                    fault: None,
                })
                .collect(),
            pending: vec![],
            out: VecDeque::new(),
            next_interval_ms: 0,
            online: false,
        }
    }

    /// The settings.
    pub fn settings(&self) -> &MqttSettings {
        &self.settings
    }

    /// The topics.
    pub fn topics(&self) -> &Topics {
        &self.topics
    }

    /// The last will to register when connecting: the status, offline,
    /// retained.
    pub fn last_will(&self) -> Publish {
        Publish {
            topic: self.topics.status(),
            payload: json!({"state": "offline"}).to_string().into_bytes(),
            retain: true,
        }
    }

    /// The broker accepted the connection: publish the status (online)
    /// and, at the next [`Gateway::step`], every retained slave topic.
    pub fn connected(&mut self, ts_ms: u64) {
        self.online = true;
        for e in &mut self.slaves {
            e.published = Published::default();
        }
        let slaves: Vec<u8> = self.slaves.iter().map(|e| e.info.address).collect();
        self.push(
            self.topics.status(),
            json!({"state": "online", "ts": ts_ms, "slaves": slaves,
                   "writable": self.settings.writable}),
            true,
        );
    }

    /// The connection was lost: nothing is queued until
    /// [`Gateway::connected`].
    pub fn disconnected(&mut self) {
        self.online = false;
        self.out.clear();
    }

    fn push(&mut self, topic: String, payload: serde_json::Value, retain: bool) {
        self.out.push_back(Publish {
            topic,
            payload: payload.to_string().into_bytes(),
            retain,
        });
    }

    fn reply(
        &mut self,
        address: u8,
        corr: Option<serde_json::Value>,
        result: Result<(), String>,
        ts_ms: u64,
    ) {
        let mut o = Map::new();
        o.insert("ok".into(), result.is_ok().into());
        if let Err(e) = &result {
            o.insert("error".into(), e.clone().into());
        }
        if let Some(c) = corr {
            o.insert("correlation_id".into(), c);
        }
        o.insert("ts".into(), ts_ms.into());
        self.push(
            self.topics.slave(address, SlaveTopic::OutputsResponse),
            serde_json::Value::Object(o),
            false,
        );
    }

    fn refuse(&mut self, address: u8, corr: Option<serde_json::Value>, e: WriteError, ts_ms: u64) {
        tracing::warn!(address, error = %e, "MQTT write refused");
        self.reply(address, corr, Err(e.to_string()), ts_ms);
    }

    /// A message from the broker. Writes are checked now (a refused one
    /// is answered at once and changes nothing) and applied at the next
    /// [`Gateway::step`]. Messages on other topics are ignored.
    pub fn handle_message(&mut self, topic: &str, payload: &[u8], ts_ms: u64) {
        let address = match self.topics.parse_set(topic) {
            None => return,
            Some(Ok(a)) => a,
            Some(Err(text)) => {
                // No station to answer for: logged only.
                tracing::warn!(topic, address = text, "MQTT write names no station");
                return;
            }
        };
        let (request, corr) = match parse_write(payload) {
            Ok(r) => r,
            Err(e) => return self.refuse(address, None, e, ts_ms),
        };
        let Some(entry) = self.slaves.iter().find(|e| e.info.address == address) else {
            return self.refuse(
                address,
                corr,
                WriteError::UnknownSlave(address.to_string()),
                ts_ms,
            );
        };
        if !self.settings.writable.contains(&address) {
            return self.refuse(address, corr, WriteError::Unauthorised(address), ts_ms);
        }
        if let WriteRequest::Channels(values) = &request {
            let Some(map) = &entry.info.channels else {
                return self.refuse(
                    address,
                    corr,
                    WriteError::Channel(format!(
                        "slave {address} has no named channels: write `hex`"
                    )),
                    ts_ms,
                );
            };
            if let Some((n, _)) = values
                .iter()
                .find(|(n, _)| map.find(Direction::Output, n).is_none())
            {
                let e = WriteError::Channel(format!("slave {address} has no output channel `{n}`"));
                return self.refuse(address, corr, e, ts_ms);
            }
        }
        self.pending.push(Pending {
            address,
            request,
            correlation: corr,
        });
    }

    /// One step at a cycle boundary: apply the pending writes (each to
    /// one slave's whole image at once, so one Data_Exchange carries all
    /// of it), then queue what changed (and, in interval mode, what is
    /// due). `ts_ms` is the wall-clock time in ms since the Unix epoch.
    pub fn step(&mut self, m: &mut DpMaster, ts_ms: u64) {
        while let Some(ev) = m.poll_event() {
            if let MasterEvent::Fault { address, reason } = ev {
                tracing::warn!(address, %reason, "slave fault");
                if let Some(e) = self.slaves.iter_mut().find(|e| e.info.address == address) {
                    e.fault = Some(reason.to_string());
                    e.published.state = None;
                }
            }
        }
        for p in std::mem::take(&mut self.pending) {
            let result = self.apply(m, &p);
            match result {
                Ok(()) => {
                    tracing::info!(address = p.address, "MQTT write applied");
                    self.reply(p.address, p.correlation, Ok(()), ts_ms);
                }
                Err(e) => self.refuse(p.address, p.correlation, e, ts_ms),
            }
        }
        if !self.online {
            return;
        }
        let interval_due =
            self.settings.publish != PublishMode::OnChange && ts_ms >= self.next_interval_ms;
        if interval_due {
            self.next_interval_ms = ts_ms + self.settings.interval.as_millis() as u64;
        }
        let on_change = self.settings.publish != PublishMode::Interval;
        let cycle = m.cycle_stats().cycles;
        for i in 0..self.slaves.len() {
            let addr = self.slaves[i].info.address;
            let Some(h) = m.handle(addr) else { continue };
            let v = m.slave(h);
            let e = &mut self.slaves[i];
            let name = e.info.name.clone();
            let mut msgs = vec![];
            if e.published.state != Some(v.state) {
                e.published.state = Some(v.state);
                let mut o = json!({"address": addr, "name": name, "state": v.state.name(),
                                   "ts": ts_ms, "cycle": cycle});
                if let Some(f) = &e.fault {
                    o["fault"] = f.clone().into();
                }
                msgs.push((SlaveTopic::State, o));
            }
            for (t, dir, img, last) in [
                (
                    SlaveTopic::Inputs,
                    Direction::Input,
                    v.inputs,
                    &mut e.published.inputs,
                ),
                (
                    SlaveTopic::Outputs,
                    Direction::Output,
                    v.outputs,
                    &mut e.published.outputs,
                ),
            ] {
                let changed = last.as_deref() != Some(img);
                if (on_change && changed) || interval_due || last.is_none() {
                    *last = Some(img.to_vec());
                    let mut o =
                        json!({"address": addr, "hex": hex(img), "ts": ts_ms, "cycle": cycle});
                    if let Some(map) = &e.info.channels {
                        let values: Map<String, serde_json::Value> = map
                            .decode(dir, img)
                            .map(|(c, val)| (c.name.clone(), value_json(val)))
                            .collect();
                        o["values"] = values.into();
                    }
                    msgs.push((t, o));
                }
            }
            if e.published.diag.as_deref() != Some(v.diag) {
                e.published.diag = Some(v.diag.to_vec());
                let text = if v.diag.is_empty() {
                    vec![]
                } else {
                    profibus_dp::diag::describe(v.diag, e.info.gsd.as_ref(), e.info.dpv1)
                };
                msgs.push((
                    SlaveTopic::Diag,
                    json!({"address": addr, "hex": hex(v.diag), "text": text, "ts": ts_ms, "cycle": cycle}),
                ));
            }
            for (t, o) in msgs {
                self.push(self.topics.slave(addr, t), o, true);
            }
        }
    }

    fn apply(&self, m: &mut DpMaster, p: &Pending) -> Result<(), WriteError> {
        let current = m
            .outputs(p.address)
            .ok_or_else(|| WriteError::UnknownSlave(p.address.to_string()))?;
        let image = match &p.request {
            WriteRequest::Image(b) => {
                if b.len() != current.len() {
                    return Err(WriteError::Length {
                        address: p.address,
                        expected: current.len(),
                        got: b.len(),
                    });
                }
                b.clone()
            }
            WriteRequest::Channels(values) => {
                let map = self
                    .slaves
                    .iter()
                    .find(|e| e.info.address == p.address)
                    .and_then(|e| e.info.channels.as_ref())
                    .ok_or_else(|| WriteError::Channel("no named channels".into()))?;
                let mut img = current.to_vec();
                map.write_outputs(values.iter().map(|(n, v)| (n.as_str(), *v)), &mut img)
                    .map_err(|e| WriteError::Channel(e.to_string()))?;
                img
            }
        };
        m.set_outputs(p.address, &image);
        Ok(())
    }

    /// The next message to send, if any.
    pub fn poll_publish(&mut self) -> Option<Publish> {
        self.out.pop_front()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_devices::channels::ChannelType;
    use profibus_dp::master::{MasterConfig, MasterOptions, SlaveParams};
    use profibus_fdl::{Baud, BusParams};

    /// A master with slave 3 (2 words in/out, writable, named channels)
    /// and slave 4 (2 bytes out, not writable).
    fn setup() -> (Gateway, DpMaster) {
        let cfg = MasterConfig {
            address: 1,
            params: BusParams::defaults(Baud::B1500000),
            slaves: vec![
                SlaveParams::new(3, 0x1234, vec![0x71]),
                SlaveParams::new(4, 0x1234, vec![0x21]),
            ],
            options: MasterOptions::default(),
        };
        let m = DpMaster::new(&cfg).unwrap();
        let mut ch = ChannelMap::new();
        ch.push("speed", Direction::Output, 0, ChannelType::I16);
        ch.push("actual", Direction::Input, 0, ChannelType::I16);
        let mut settings = crate::MqttSettings::from_table(None, "l1").unwrap();
        settings.writable = vec![3];
        let info = |address, channels| SlaveInfo {
            address,
            name: format!("s{address}"),
            channels,
            gsd: None,
            dpv1: false,
        };
        let g = Gateway::new(settings, vec![info(3, Some(ch)), info(4, None)]);
        (g, m)
    }

    fn drain(g: &mut Gateway) -> Vec<(String, serde_json::Value, bool)> {
        std::iter::from_fn(|| g.poll_publish())
            .map(|p| {
                (
                    p.topic,
                    serde_json::from_slice(&p.payload).unwrap(),
                    p.retain,
                )
            })
            .collect()
    }

    fn find<'a>(
        msgs: &'a [(String, serde_json::Value, bool)],
        topic: &str,
    ) -> Option<&'a serde_json::Value> {
        msgs.iter().find(|(t, _, _)| t == topic).map(|(_, v, _)| v)
    }

    #[test]
    fn topics_and_hex() {
        let t = Topics::new("plant/a", "seg1");
        assert_eq!(t.status(), "plant/a/seg1/status");
        assert_eq!(t.slave(7, SlaveTopic::Inputs), "plant/a/seg1/7/inputs");
        assert_eq!(t.set_filter(), "plant/a/seg1/+/outputs/set");
        assert_eq!(t.parse_set("plant/a/seg1/7/outputs/set"), Some(Ok(7)));
        assert_eq!(
            t.parse_set("plant/a/seg1/x/outputs/set"),
            Some(Err("x".into()))
        );
        assert_eq!(t.parse_set("plant/a/seg1/7/outputs"), None);
        assert_eq!(t.parse_set("plant/a/seg2/7/outputs/set"), None);
        assert_eq!(hex(&[0, 0xab]), "00ab");
        assert_eq!(parse_hex("0x00 ab:01"), Some(vec![0, 0xab, 1]));
        assert_eq!(parse_hex("abc"), None);
        assert_eq!(parse_hex("zz"), None);
    }

    #[test]
    fn write_payloads() {
        assert_eq!(
            parse_write(b"0102").unwrap().0,
            WriteRequest::Image(vec![1, 2])
        );
        assert_eq!(
            parse_write(b"\"0102\"").unwrap().0,
            WriteRequest::Image(vec![1, 2])
        );
        let (r, c) =
            parse_write(br#"{"channels": {"a": 1, "b": true, "c": 1.5}, "correlation_id": "x"}"#)
                .unwrap();
        assert_eq!(c, Some("x".into()));
        assert_eq!(
            r,
            WriteRequest::Channels(vec![
                ("a".into(), Value::Int(1)),
                ("b".into(), Value::Bool(true)),
                ("c".into(), Value::Float(1.5)),
            ])
        );
        for bad in [
            &b"{\"hex\": \"01\", \"channels\": {}}"[..],
            b"{\"hexx\": \"01\"}",
            b"{\"channels\": {\"a\": \"1\"}}",
            b"[1]",
            b"\xff",
            b"",
        ] {
            assert!(
                matches!(parse_write(bad), Err(WriteError::Malformed(_))),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn publishes_retained_state_and_republishes_after_reconnect() {
        let (mut g, mut m) = setup();
        g.step(&mut m, 5);
        assert!(
            drain(&mut g).is_empty(),
            "nothing before the first connection"
        );
        g.connected(10);
        g.step(&mut m, 11);
        let msgs = drain(&mut g);
        assert_eq!(
            find(&msgs, "profibus/l1/status").unwrap()["state"],
            "online"
        );
        let st = find(&msgs, "profibus/l1/3/state").unwrap();
        assert_eq!(
            (st["state"].as_str(), st["name"].as_str()),
            (Some(SlaveState::Diag.name()), Some("s3"))
        );
        let inp = find(&msgs, "profibus/l1/3/inputs").unwrap();
        assert_eq!(inp["hex"], "00000000");
        assert_eq!(inp["values"]["actual"], 0);
        assert!(find(&msgs, "profibus/l1/4/outputs")
            .unwrap()
            .get("values")
            .is_none());
        assert!(msgs.iter().all(|(t, _, r)| *r || t.ends_with("response")));
        // Nothing changed: nothing new.
        g.step(&mut m, 12);
        assert!(drain(&mut g).is_empty());
        // A new connection: everything again.
        g.disconnected();
        g.connected(20);
        g.step(&mut m, 21);
        assert_eq!(drain(&mut g).len(), msgs.len());
        assert_eq!(g.last_will().payload, br#"{"state":"offline"}"#);
    }

    #[test]
    fn writes_are_checked_then_applied_at_the_step() {
        let (mut g, mut m) = setup();
        g.connected(0);
        g.step(&mut m, 0);
        drain(&mut g);
        g.handle_message(
            "profibus/l1/3/outputs/set",
            br#"{"channels": {"speed": -2}, "correlation_id": 1}"#,
            1,
        );
        assert_eq!(
            m.outputs(3).unwrap(),
            [0, 0, 0, 0],
            "applied at the step, not before"
        );
        g.step(&mut m, 2);
        assert_eq!(m.outputs(3).unwrap(), [0xff, 0xfe, 0, 0]);
        let msgs = drain(&mut g);
        let r = find(&msgs, "profibus/l1/3/outputs/response").unwrap();
        assert_eq!(
            (r["ok"].as_bool(), r["correlation_id"].as_i64()),
            (Some(true), Some(1))
        );
        assert_eq!(
            find(&msgs, "profibus/l1/3/outputs").unwrap()["values"]["speed"],
            -2
        );

        // Refused writes change nothing and are answered.
        for (topic, payload, error) in [
            ("profibus/l1/4/outputs/set", &b"0001"[..], "not writable"),
            ("profibus/l1/9/outputs/set", b"0001", "no slave 9"),
            ("profibus/l1/3/outputs/set", b"01", "4 output bytes"),
            (
                "profibus/l1/3/outputs/set",
                b"{\"channels\": {\"nope\": 1}}",
                "no output channel",
            ),
            (
                "profibus/l1/3/outputs/set",
                b"{\"channels\": {\"speed\": 70000}}",
                "",
            ),
            ("profibus/l1/3/outputs/set", b"junk", "malformed"),
        ] {
            g.handle_message(topic, payload, 3);
            g.step(&mut m, 4);
            let msgs = drain(&mut g);
            let addr = topic.split('/').nth(2).unwrap();
            let r = find(&msgs, &format!("profibus/l1/{addr}/outputs/response")).unwrap();
            assert_eq!(r["ok"], false, "{topic} {payload:?}");
            assert!(r["error"].as_str().unwrap().contains(error), "{r}");
            assert_eq!(m.outputs(3).unwrap(), [0xff, 0xfe, 0, 0]);
            assert_eq!(m.outputs(4).unwrap(), [0, 0]);
        }
        // Other topics are not ours.
        g.handle_message("profibus/l1/3/outputs", b"0000", 5);
        g.step(&mut m, 6);
        assert!(drain(&mut g).is_empty());
    }
}
