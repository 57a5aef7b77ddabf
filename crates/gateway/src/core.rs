//! The sans-IO gateway: topics and payloads from a DP master's slaves,
//! and writes and requests from MQTT messages. No broker, no clock: the
//! driver hands in messages and the time, and sends what
//! [`Gateway::poll_publish`] returns.

use crate::outage::Outage;
use crate::payload::{
    to_bytes, Answer, AnswerData, DiagPayload, ImagePayload, OutputsTimeout, SlaveStatePayload,
    Status,
};
use crate::settings::{MqttSettings, PublishMode};
use profibus_devices::channels::{ChannelMap, Direction, OutputWriteError, Value};
use profibus_devices::pkw::client::PkwClient;
use profibus_devices::pkw::{self, Dialect, PKW_LEN};
use profibus_devices::rfid::client::RfidClient;
use profibus_dp::config::gsd::Gsd;
use profibus_dp::master::{
    DpMaster, Job, JobId, JobResult, MasterEvent, OperatingState, SlaveHandle, SlaveState,
};
use profibus_fdl::Instant;
use std::collections::VecDeque;

pub use crate::payload::hex;

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
    /// Ident number (PKW parameters by name: [`profibus_devices::pkw_parameter`]).
    pub ident_number: u16,
    /// Named channels of its images (device profiles), if any.
    pub channels: Option<ChannelMap>,
    /// Its GSD, for diagnosis texts.
    pub gsd: Option<Gsd>,
    /// Whether it is a DP-V1 slave (diagnosis decoding, DP-V1 requests).
    pub dpv1: bool,
    /// The dialect of its PKW channel, if it has one (PKW requests).
    pub pkw: Option<&'static Dialect>,
    /// Whether it is an RFID reader with the 16-byte command handshake
    /// (RFID requests).
    pub rfid: bool,
}

/// The topics of one gateway: `<prefix>/<bus>/…`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topics {
    base: String,
}

/// What a request topic asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Service {
    /// `<addr>/outputs/set`: the output image or named output channels.
    Outputs,
    /// `<addr>/dpv1/request`: a DP-V1 (MSAC_C1) data record read or write.
    Dpv1,
    /// `<addr>/pkw/request`: a parameter job over the PKW channel.
    Pkw,
    /// `<addr>/rfid/request`: one command line to an RFID reader.
    Rfid,
}

impl Service {
    /// Every service.
    pub const ALL: [Service; 4] = [Service::Outputs, Service::Dpv1, Service::Pkw, Service::Rfid];

    /// The request topic's suffix.
    pub fn request(self) -> &'static str {
        match self {
            Service::Outputs => "outputs/set",
            Service::Dpv1 => "dpv1/request",
            Service::Pkw => "pkw/request",
            Service::Rfid => "rfid/request",
        }
    }

    /// The default response topic's suffix.
    pub fn response(self) -> &'static str {
        match self {
            Service::Outputs => "outputs/response",
            Service::Dpv1 => "dpv1/response",
            Service::Pkw => "pkw/response",
            Service::Rfid => "rfid/response",
        }
    }
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
    /// A request topic (subscribed).
    Request(Service),
    /// The default response topic of a service.
    Response(Service),
}

impl SlaveTopic {
    fn suffix(self) -> &'static str {
        match self {
            SlaveTopic::State => "state",
            SlaveTopic::Inputs => "inputs",
            SlaveTopic::Outputs => "outputs",
            SlaveTopic::Diag => "diag",
            SlaveTopic::Request(s) => s.request(),
            SlaveTopic::Response(s) => s.response(),
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

    /// The filters the gateway subscribes to: one per [`Service`].
    pub fn request_filters(&self) -> Vec<String> {
        Service::ALL
            .iter()
            .map(|s| format!("{}/+/{}", self.base, s.request()))
            .collect()
    }

    /// The service and station address of a request topic
    /// (`<prefix>/<bus>/<addr>/outputs/set`, …), `None` for any other
    /// topic. An address that is not a number is an error.
    pub fn parse_request(&self, topic: &str) -> Option<(Service, Result<u8, BadAddress>)> {
        let rest = topic.strip_prefix(&self.base)?.strip_prefix('/')?;
        Service::ALL.iter().find_map(|&s| {
            let addr = rest.strip_suffix(s.request())?.strip_suffix('/')?;
            if addr.contains('/') {
                return None;
            }
            Some((s, addr.parse::<u8>().map_err(|_| BadAddress(addr.into()))))
        })
    }
}

/// The address part of a request topic is not a station address.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` in a request topic is not a station address")]
pub struct BadAddress(pub String);

/// Bytes of a non-empty hex string (as `profibus_fdl::wire::parse_hex`
/// takes it: `0a0b`, `0a 0b`, `0a:0b`, `0x0a,0x0b`).
pub fn parse_hex(text: &str) -> Option<Vec<u8>> {
    profibus_fdl::wire::parse_hex(text)
        .ok()
        .filter(|b| !b.is_empty())
}

/// What a write of outputs asks for: the whole image or named channels,
/// checked by the rule the terminal view shares
/// ([`OutputWrite::check`], [`OutputWrite::apply`]).
pub use profibus_devices::channels::OutputWrite;

/// A request from a message, checked for form (not yet for permission).
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Set outputs.
    Outputs(OutputWrite),
    /// DP-V1 read of a data record.
    Dpv1Read {
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// Bytes wanted (1..=240).
        length: u8,
    },
    /// DP-V1 write of a data record.
    Dpv1Write {
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// Data (1..=240 bytes).
        data: Vec<u8>,
    },
    /// A PKW job.
    Pkw {
        /// Parameter number (0..=2047).
        pnu: u16,
        /// What to do.
        command: pkw::Command,
    },
    /// A PKW job on a parameter the device names (a BM4 variable module);
    /// [`Gateway::handle_message`] resolves the name into [`Request::Pkw`].
    PkwNamed {
        /// The parameter's name.
        name: String,
        /// What to do.
        command: pkw::Command,
    },
    /// An RFID command line (without CR).
    Rfid(Vec<u8>),
}

impl Request {
    /// Whether the request changes the slave (needs write access).
    pub fn writes(&self) -> bool {
        match self {
            Request::Outputs(_) | Request::Dpv1Write { .. } | Request::Rfid(_) => true,
            Request::Dpv1Read { .. } => false,
            Request::Pkw { command, .. } | Request::PkwNamed { command, .. } => !matches!(
                command,
                pkw::Command::Read | pkw::Command::ReadElement(_) | pkw::Command::Describe(_)
            ),
        }
    }
}

/// Where a request's answer goes: the id and topic of the request.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReplyTo {
    /// The request's `"id"` (any JSON value), repeated in the answer.
    pub id: Option<serde_json::Value>,
    /// The request's `"reply_to"` topic; `None`: the service's response
    /// topic of the slave.
    pub topic: Option<String>,
}

/// Why a request was refused or failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RequestError {
    /// The payload is not a request of this service.
    #[error("malformed request: {0}")]
    Malformed(String),
    /// The topic's address is not a configured slave.
    #[error("no slave {0} on this bus")]
    UnknownSlave(String),
    /// The bus file's `[mqtt] writable` does not list the slave.
    #[error("slave {0} is not writable over MQTT (see [mqtt] writable)")]
    Unauthorised(u8),
    /// An output write that breaks the rule of output writes (a short
    /// image, an unknown channel, a value that does not fit), or a write
    /// beyond the channels `[mqtt] writable` allows.
    #[error(transparent)]
    Write(#[from] OutputWriteError),
    /// The slave does not offer the service (no PKW channel, not a
    /// reader, not DP-V1).
    #[error("slave {address} has no {what}")]
    Unsupported {
        /// Station address.
        address: u8,
        /// What it lacks.
        what: &'static str,
    },
    /// A PKW request names a parameter the slave's device does not have.
    #[error("slave {address} has no parameter named `{name}`")]
    NoParameter {
        /// Station address.
        address: u8,
        /// The name.
        name: String,
    },
    /// Too many requests waiting for the slave ([`QUEUE_LIMIT`]).
    #[error("slave {0}: too many requests waiting (at most {QUEUE_LIMIT})")]
    Busy(u8),
    /// A payload larger than [`MAX_PAYLOAD`].
    #[error("payload of {size} bytes is larger than the {limit} bytes a request may have")]
    TooLarge {
        /// The payload's size.
        size: usize,
        /// [`MAX_PAYLOAD`].
        limit: usize,
    },
    /// The job ran and failed.
    #[error("{0}")]
    Failed(String),
}

/// The largest request payload the gateway reads, in bytes (an output
/// image is at most 244 bytes, a DP-V1 record 240: this leaves room for
/// hex, JSON and names, and bounds what one message can cost).
pub const MAX_PAYLOAD: usize = 64 * 1024;

fn malformed(text: impl Into<String>) -> RequestError {
    RequestError::Malformed(text.into())
}

/// Whether `t` may be published to (not empty, no wildcards).
fn publishable(t: &str) -> bool {
    !t.is_empty() && !t.contains(['+', '#', '\0'])
}

/// A request parsed from the payload of `service`'s request topic, and
/// where its answer goes (known even when the rest is malformed).
///
/// Payloads are JSON objects with the service's fields and optionally
/// `"id"` (any JSON value, repeated in the answer) and `"reply_to"` (a
/// topic for the answer instead of the slave's response topic). An
/// output write may also be a bare hex string (the whole image).
pub fn parse_request(service: Service, payload: &[u8]) -> (ReplyTo, Result<Request, RequestError>) {
    if payload.len() > MAX_PAYLOAD {
        let e = RequestError::TooLarge {
            size: payload.len(),
            limit: MAX_PAYLOAD,
        };
        return (ReplyTo::default(), Err(e));
    }
    let text = match std::str::from_utf8(payload) {
        Ok(t) => t,
        Err(_) => return (ReplyTo::default(), Err(malformed("payload is not UTF-8"))),
    };
    let image = |s: &str| {
        parse_hex(s)
            .map(|b| Request::Outputs(OutputWrite::Image(b)))
            .ok_or_else(|| malformed("neither a JSON object nor hex"))
    };
    let o = match serde_json::from_str::<serde_json::Value>(text) {
        Ok(serde_json::Value::Object(o)) => o,
        Ok(serde_json::Value::String(s)) if service == Service::Outputs => {
            return (ReplyTo::default(), image(&s))
        }
        Err(_) if service == Service::Outputs => return (ReplyTo::default(), image(text)),
        _ => return (ReplyTo::default(), Err(malformed("expected a JSON object"))),
    };
    let mut to = ReplyTo {
        id: o.get("id").cloned(),
        topic: None,
    };
    match o.get("reply_to") {
        None => {}
        Some(serde_json::Value::String(t)) if publishable(t) => to.topic = Some(t.clone()),
        Some(_) => {
            return (
                to,
                Err(malformed("`reply_to` must be a topic without wildcards")),
            )
        }
    }
    let r = body(service, &o);
    (to, r)
}

type Obj = serde_json::Map<String, serde_json::Value>;

fn only(o: &Obj, keys: &[&str]) -> Result<(), RequestError> {
    match o
        .keys()
        .find(|k| !keys.contains(&k.as_str()) && !matches!(k.as_str(), "id" | "reply_to"))
    {
        Some(k) => Err(malformed(format!("unknown field `{k}`"))),
        None => Ok(()),
    }
}

fn int(o: &Obj, key: &str, min: i64, max: i64) -> Result<Option<i64>, RequestError> {
    match o.get(key) {
        None => Ok(None),
        Some(v) => match v.as_i64() {
            Some(n) if (min..=max).contains(&n) => Ok(Some(n)),
            _ => Err(malformed(format!(
                "`{key}` must be an integer {min}..={max}"
            ))),
        },
    }
}

fn need<T>(v: Option<T>, key: &str) -> Result<T, RequestError> {
    v.ok_or_else(|| malformed(format!("`{key}` is missing")))
}

fn op(o: &Obj, ops: &[&str]) -> Result<String, RequestError> {
    match o.get("op") {
        Some(serde_json::Value::String(s)) if ops.contains(&s.as_str()) => Ok(s.clone()),
        _ => {
            let ops: Vec<String> = ops.iter().map(|o| format!("\"{o}\"")).collect();
            Err(malformed(format!("`op` must be one of {}", ops.join(", "))))
        }
    }
}

fn body(service: Service, o: &Obj) -> Result<Request, RequestError> {
    match service {
        Service::Outputs => {
            only(o, &["hex", "channels"])?;
            outputs_body(o)
        }
        Service::Dpv1 => {
            let slot = need(int(o, "slot", 0, 254)?, "slot")? as u8;
            let index = need(int(o, "index", 0, 254)?, "index")? as u8;
            if op(o, &["read", "write"])? == "read" {
                only(o, &["op", "slot", "index", "length"])?;
                let length = int(o, "length", 1, 240)?.unwrap_or(240) as u8;
                Ok(Request::Dpv1Read {
                    slot,
                    index,
                    length,
                })
            } else {
                only(o, &["op", "slot", "index", "hex"])?;
                let data = match o.get("hex") {
                    Some(serde_json::Value::String(h)) => parse_hex(h)
                        .filter(|d| d.len() <= profibus_dp::pdu::dpv1::MAX_DATA_LEN)
                        .ok_or_else(|| malformed("`hex` must be 1..=240 bytes of hex"))?,
                    _ => return Err(malformed("`hex` is missing")),
                };
                Ok(Request::Dpv1Write { slot, index, data })
            }
        }
        Service::Pkw => {
            only(o, &["op", "pnu", "index", "value", "dword", "element"])?;
            let pnu = match o.get("pnu") {
                Some(serde_json::Value::String(n)) if !n.is_empty() => Err(n.clone()),
                _ => Ok(need(int(o, "pnu", 0, 0x7FF)?, "pnu")? as u16),
            };
            let index = int(o, "index", 0, 0xFFFF)?.map(|i| i as u16);
            let command = match op(o, &["read", "write", "describe"])?.as_str() {
                "read" => index.map_or(pkw::Command::Read, pkw::Command::ReadElement),
                "describe" => {
                    pkw::Command::Describe(need(int(o, "element", 0, 0xFFFF)?, "element")? as u16)
                }
                _ => {
                    let v = need(int(o, "value", i32::MIN as i64, u32::MAX as i64)?, "value")?;
                    let dword = match o.get("dword") {
                        None => !(-0x8000..=0xFFFF).contains(&v),
                        Some(serde_json::Value::Bool(b)) => *b,
                        Some(_) => return Err(malformed("`dword` must be true or false")),
                    };
                    if !dword && !(-0x8000..=0xFFFF).contains(&v) {
                        return Err(malformed("`value` does not fit a word"));
                    }
                    let (w, d) = (v as u16, v as u32);
                    match (index, dword) {
                        (None, false) => pkw::Command::WriteWord(w),
                        (None, true) => pkw::Command::WriteDword(d),
                        (Some(index), false) => pkw::Command::WriteElementWord { index, value: w },
                        (Some(index), true) => pkw::Command::WriteElementDword { index, value: d },
                    }
                }
            };
            Ok(match pnu {
                Ok(pnu) => Request::Pkw { pnu, command },
                Err(name) => Request::PkwNamed { name, command },
            })
        }
        Service::Rfid => {
            only(o, &["command"])?;
            match o.get("command") {
                Some(serde_json::Value::String(c)) if !c.is_empty() && c.is_ascii() => {
                    Ok(Request::Rfid(c.trim_end_matches('\r').as_bytes().to_vec()))
                }
                _ => Err(malformed("`command` must be a non-empty ASCII string")),
            }
        }
    }
}

fn outputs_body(o: &Obj) -> Result<Request, RequestError> {
    let req = match (o.get("hex"), o.get("channels")) {
        (Some(serde_json::Value::String(h)), None) => {
            OutputWrite::Image(parse_hex(h).ok_or_else(|| malformed("`hex` is not hex"))?)
        }
        (None, Some(serde_json::Value::Object(c))) if !c.is_empty() => OutputWrite::Channels(
            c.iter()
                .map(|(k, v)| {
                    let val = match v {
                        serde_json::Value::Bool(b) => Value::Bool(*b),
                        serde_json::Value::Number(n) => match n.as_i64() {
                            Some(i) => Value::Int(i),
                            None => Value::Float(n.as_f64().unwrap_or(f64::NAN)),
                        },
                        _ => {
                            return Err(malformed(format!(
                                "channel `{k}`: value must be a number or a boolean"
                            )))
                        }
                    };
                    Ok((k.clone(), val))
                })
                .collect::<Result<_, _>>()?,
        ),
        _ => {
            return Err(malformed(
                "give either `hex` (a string) or `channels` (an object)",
            ))
        }
    };
    Ok(Request::Outputs(req))
}

/// The last published state of a slave.
#[derive(Debug, Default, Clone)]
struct Published {
    state: Option<SlaveState>,
    inputs: Option<Vec<u8>>,
    outputs: Option<Vec<u8>>,
    diag: Option<Vec<u8>>,
}

/// Where an answer goes: service, slave, id, topic.
#[derive(Debug, Clone)]
struct Target {
    service: Service,
    address: u8,
    to: ReplyTo,
}

/// A PKW or RFID job waiting for the slave's client.
#[derive(Debug)]
struct Queued {
    request: Request,
    target: Target,
}

/// Requests one slave may have waiting in each of its two queues: output
/// writes and DP-V1 jobs until the next [`Gateway::step`], PKW or RFID
/// jobs for the slave's client. One more is answered
/// [`RequestError::Busy`] and changes nothing.
pub const QUEUE_LIMIT: usize = 8;

#[derive(Debug)]
struct Entry {
    info: SlaveInfo,
    published: Published,
    fault: Option<String>,
    /// Output writes and DP-V1 jobs for the next step.
    pending: VecDeque<Queued>,
    /// PKW or RFID jobs waiting for the client.
    queue: VecDeque<Queued>,
    pkw: Option<PkwClient>,
    rfid: Option<RfidClient>,
    /// The job the client runs.
    running: Option<Target>,
}

/// An answer's body: the result's fields on success, the error otherwise.
type Outcome = Result<Option<AnswerData>, RequestError>;

/// The gateway between one DP master and one MQTT broker.
///
/// Drive it from the master's application step (between two polls of the
/// master, i.e. at a cycle boundary): [`Gateway::handle_message`] for each
/// message received, [`Gateway::step`] with the master, then send
/// everything [`Gateway::poll_publish`] returns. After each (re)connection
/// call [`Gateway::connected`]: the status and every retained topic are
/// published again; after a loss [`Gateway::disconnected`].
#[derive(Debug)]
pub struct Gateway {
    settings: MqttSettings,
    topics: Topics,
    slaves: Vec<Entry>,
    /// DP-V1 jobs the master runs.
    jobs: Vec<(JobId, Target)>,
    out: VecDeque<Publish>,
    next_interval_ms: u64,
    online: bool,
    /// The master state in the last status published (`None`: due).
    status_master: Option<OperatingState>,
    /// The broker outage and the outputs' safe state.
    outage: Outage,
}

impl Gateway {
    /// A gateway for these slaves.
    pub fn new(settings: MqttSettings, slaves: Vec<SlaveInfo>) -> Gateway {
        let timeout = settings.job_timeout;
        Gateway {
            topics: Topics::new(&settings.prefix, &settings.bus),
            settings,
            slaves: slaves
                .into_iter()
                .map(|info| Entry {
                    pkw: info.pkw.map(|d| PkwClient::new(d, timeout)),
                    rfid: info.rfid.then(|| RfidClient::new(timeout)),
                    info,
                    published: Published::default(),
                    fault: None,
                    pending: VecDeque::new(),
                    queue: VecDeque::new(),
                    running: None,
                })
                .collect(),
            jobs: vec![],
            out: VecDeque::new(),
            next_interval_ms: 0,
            online: false,
            status_master: None,
            outage: Outage::default(),
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
            payload: to_bytes(&Status::Offline),
            retain: true,
        }
    }

    /// The broker accepted the connection: at the next [`Gateway::step`]
    /// the status (online) and every retained slave topic are published.
    pub fn connected(&mut self, _ts_ms: u64) {
        self.online = true;
        self.outage.connected();
        self.status_master = None;
        for e in &mut self.slaves {
            e.published = Published::default();
        }
    }

    /// The connection was lost at `ts_ms`: nothing is queued until
    /// [`Gateway::connected`]; after `outputs_timeout` the safe state.
    pub fn disconnected(&mut self, ts_ms: u64) {
        self.outage.disconnected(self.online, ts_ms);
        self.online = false;
        self.out.clear();
    }

    fn push(&mut self, topic: String, payload: &impl serde::Serialize, retain: bool) {
        if self.online {
            self.out.push_back(Publish {
                topic,
                payload: to_bytes(payload),
                retain,
            });
        }
    }

    fn answer(&mut self, t: Target, outcome: Outcome, ts_ms: u64) {
        let (data, error) = match outcome {
            Ok(data) => (data, None),
            Err(e) => {
                tracing::warn!(address = t.address, service = t.service.request(), error = %e, "MQTT request refused or failed");
                (None, Some(e.to_string()))
            }
        };
        let a = Answer {
            ok: error.is_none(),
            error,
            data,
            id: t.to.id,
            ts: ts_ms,
        };
        let topic = t.to.topic.unwrap_or_else(|| {
            self.topics
                .slave(t.address, SlaveTopic::Response(t.service))
        });
        self.push(topic, &a, false);
    }

    /// Check `request` for slave `address` against the configuration and
    /// the permissions.
    fn check(&self, address: u8, request: &Request) -> Result<(), RequestError> {
        let Some(entry) = self.slaves.iter().find(|e| e.info.address == address) else {
            return Err(RequestError::UnknownSlave(address.to_string()));
        };
        let unsupported = |what| Err(RequestError::Unsupported { address, what });
        match request {
            Request::Dpv1Read { .. } | Request::Dpv1Write { .. } if !entry.info.dpv1 => {
                return unsupported("DP-V1 (`dpv1 = true` in the bus file)")
            }
            Request::Pkw { .. } | Request::PkwNamed { .. } if entry.info.pkw.is_none() => {
                return unsupported("PKW channel")
            }
            Request::Rfid(_) if !entry.info.rfid => return unsupported("RFID reader handshake"),
            _ => {}
        }
        if !request.writes() {
            return Ok(());
        }
        let access = self
            .settings
            .access(address)
            .ok_or(RequestError::Unauthorised(address))?;
        let allowed = access.channels.as_deref();
        match (request, allowed) {
            (Request::Outputs(w), _) => w.check(address, entry.info.channels.as_ref(), allowed)?,
            // Channel access only: no other writes.
            (_, Some(allowed)) => {
                return Err(OutputWriteError::ChannelsOnly {
                    address,
                    allowed: allowed.to_vec(),
                }
                .into())
            }
            (_, None) => {}
        }
        Ok(())
    }

    /// A PKW request by name as one by number: the device profile's
    /// parameter of that name ([`profibus_devices::pkw_parameter`]).
    fn resolve(&self, address: u8, r: Request) -> Result<Request, RequestError> {
        let Request::PkwNamed { name, command } = r else {
            return Ok(r);
        };
        let info = &self
            .slaves
            .iter()
            .find(|e| e.info.address == address)
            .expect("checked")
            .info;
        info.gsd
            .as_ref()
            .and_then(|g| profibus_devices::pkw_parameter(info.ident_number, g, &name))
            .map(|pnu| Request::Pkw { pnu, command })
            .ok_or(RequestError::NoParameter { address, name })
    }

    /// A message from the broker. Requests are checked now (a refused
    /// one is answered at once and changes nothing) and carried out from
    /// the next [`Gateway::step`]. Messages on other topics are ignored.
    pub fn handle_message(&mut self, topic: &str, payload: &[u8], ts_ms: u64) {
        let (service, address) = match self.topics.parse_request(topic) {
            None => return,
            Some((s, Ok(a))) => (s, a),
            Some((_, Err(e))) => {
                // No station to answer for: logged only.
                tracing::warn!(topic, error = %e, "MQTT request refused");
                return;
            }
        };
        let (to, request) = parse_request(service, payload);
        let target = Target {
            service,
            address,
            to,
        };
        let request = request
            .and_then(|r| self.check(address, &r).map(|()| r))
            .and_then(|r| self.resolve(address, r));
        let request = match request {
            Ok(r) => r,
            Err(e) => return self.answer(target, Err(e), ts_ms),
        };
        let q = Queued { request, target };
        let e = self
            .slaves
            .iter_mut()
            .find(|e| e.info.address == address)
            .expect("checked");
        let waiting = match q.request {
            Request::Outputs(_) | Request::Dpv1Read { .. } | Request::Dpv1Write { .. } => {
                &mut e.pending
            }
            Request::Pkw { .. } | Request::PkwNamed { .. } | Request::Rfid(_) => &mut e.queue,
        };
        if waiting.len() >= QUEUE_LIMIT {
            return self.answer(q.target, Err(RequestError::Busy(address)), ts_ms);
        }
        waiting.push_back(q);
    }

    /// One step at a cycle boundary; `now` is the master's time,
    /// `ts_ms` the wall-clock time in ms since the Unix epoch.
    ///
    /// Takes the master's events (DP-V1 job results, faults), applies the
    /// pending output writes (each to one slave's whole image at once, so
    /// one Data_Exchange carries all of it), starts DP-V1 jobs, drives
    /// the PKW and RFID clients, puts the outputs into the safe state
    /// when the broker has been away for `outputs_timeout`, then queues
    /// what changed (and, in interval mode, what is due).
    pub fn step(&mut self, m: &mut DpMaster, now: Instant, ts_ms: u64) {
        let mut answers: Vec<(Target, Outcome)> = vec![];
        while let Some(ev) = m.poll_event() {
            match ev {
                MasterEvent::Fault { address, reason } => {
                    tracing::warn!(address, %reason, "slave fault");
                    if let Some(e) = self.slaves.iter_mut().find(|e| e.info.address == address) {
                        e.fault = Some(reason.to_string());
                        e.published.state = None;
                    }
                }
                MasterEvent::JobDone(id) => {
                    if let Some(i) = self.jobs.iter().position(|(j, _)| *j == id) {
                        let t = self.jobs.swap_remove(i).1;
                        let outcome = match m.take_result(id) {
                            Some(JobResult::Data(d)) => {
                                Ok(Some(AnswerData::Record { hex: hex(&d) }))
                            }
                            Some(JobResult::Done) => Ok(None),
                            Some(r) => Err(RequestError::Failed(r.describe())),
                            None => Err(RequestError::Failed("result lost".into())),
                        };
                        answers.push((t, outcome));
                    }
                }
                _ => {}
            }
        }
        self.outage.step(&self.settings, self.online, m, ts_ms);
        let pending: Vec<Queued> = self
            .slaves
            .iter_mut()
            .flat_map(|e| e.pending.drain(..))
            .collect();
        for q in pending {
            let outcome = self.carry_out(m, &q);
            if let Some(o) = outcome {
                if o.is_ok() {
                    tracing::info!(address = q.target.address, "MQTT write applied");
                }
                answers.push((q.target, o));
            }
        }
        for e in &mut self.slaves {
            drive(e, m, now, &mut answers);
        }
        for (t, o) in answers {
            self.answer(t, o, ts_ms);
        }
        if self.online {
            self.publish_state(m, ts_ms);
        }
    }

    /// Apply an output write (`Some(outcome)`) or start a DP-V1 job
    /// (`None` while it runs).
    fn carry_out(&mut self, m: &mut DpMaster, q: &Queued) -> Option<Outcome> {
        let a = q.target.address;
        let job = match &q.request {
            Request::Outputs(w) => return Some(self.apply(m, a, w).map(|()| None)),
            Request::Dpv1Read {
                slot,
                index,
                length,
            } => Job::Dpv1Read {
                address: a,
                slot: *slot,
                index: *index,
                length: *length,
            },
            Request::Dpv1Write { slot, index, data } => Job::Dpv1Write {
                address: a,
                slot: *slot,
                index: *index,
                data: data.clone(),
            },
            Request::Pkw { .. } | Request::PkwNamed { .. } | Request::Rfid(_) => return None,
        };
        match m.submit(job) {
            Some(id) => {
                self.jobs.push((id, q.target.clone()));
                None
            }
            None => Some(Err(RequestError::Busy(a))),
        }
    }

    fn apply(&self, m: &mut DpMaster, address: u8, w: &OutputWrite) -> Result<(), RequestError> {
        let current = m
            .outputs(address)
            .ok_or_else(|| RequestError::UnknownSlave(address.to_string()))?;
        let map = self
            .slaves
            .iter()
            .find(|e| e.info.address == address)
            .and_then(|e| e.info.channels.as_ref());
        let allowed = self
            .settings
            .access(address)
            .and_then(|a| a.channels.as_deref());
        let image = w.apply(address, current, map, allowed)?;
        m.set_outputs(address, &image);
        Ok(())
    }

    fn status(&self, m: &DpMaster, ts_ms: u64) -> Status {
        Status::Online {
            master: m.operating_state(),
            ts: ts_ms,
            slaves: self.slaves.iter().map(|e| e.info.address).collect(),
            writable: self.settings.writable.iter().map(|w| w.address).collect(),
            outputs_timeout: self.outage.safe_applied().map(|at| OutputsTimeout {
                safe_state: self.settings.safe_state,
                at,
            }),
        }
    }

    fn publish_state(&mut self, m: &mut DpMaster, ts_ms: u64) {
        if self.status_master != Some(m.operating_state()) {
            self.status_master = Some(m.operating_state());
            let s = self.status(m, ts_ms);
            self.push(self.topics.status(), &s, true);
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
            let mut msgs = vec![];
            if e.published.state != Some(v.state) {
                e.published.state = Some(v.state);
                let p = SlaveStatePayload {
                    address: addr,
                    name: &e.info.name,
                    state: v.state,
                    fault: e.fault.as_deref(),
                    ts: ts_ms,
                    cycle,
                };
                msgs.push((SlaveTopic::State, to_bytes(&p)));
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
                    // The library's decoded image: `{"name": value}`.
                    let values = e.info.channels.as_ref().map(|map| match dir {
                        Direction::Input => map.values(img, &[]).inputs,
                        Direction::Output => map.values(&[], img).outputs,
                    });
                    let p = ImagePayload::new(addr, img, values, ts_ms, cycle);
                    msgs.push((t, to_bytes(&p)));
                }
            }
            if e.published.diag.as_deref() != Some(v.diag) {
                e.published.diag = Some(v.diag.to_vec());
                let text = if v.diag.is_empty() {
                    vec![]
                } else {
                    profibus_dp::pdu::diag::describe(v.diag, e.info.gsd.as_ref(), e.info.dpv1)
                };
                let p = DiagPayload::new(addr, v.diag, text, ts_ms, cycle);
                msgs.push((SlaveTopic::Diag, to_bytes(&p)));
            }
            if self.online {
                for (t, payload) in msgs {
                    self.out.push_back(Publish {
                        topic: self.topics.slave(addr, t),
                        payload,
                        retain: true,
                    });
                }
            }
        }
    }

    /// The next message to send, if any.
    pub fn poll_publish(&mut self) -> Option<Publish> {
        self.out.pop_front()
    }
}

fn failed(e: impl std::fmt::Display) -> RequestError {
    RequestError::Failed(e.to_string())
}

/// A slave's job client as [`drive`] runs it: PKW or RFID.
trait JobClient {
    fn is_idle(&self) -> bool;
    /// Start `r`; `None` when it is not this client's kind.
    fn begin(&mut self, now: Instant, r: &Request) -> Option<Result<(), RequestError>>;
    /// Drive the running job; its outcome when it ends.
    fn poll(&mut self, now: Instant, m: &mut DpMaster, h: SlaveHandle) -> Option<Outcome>;
}

impl JobClient for PkwClient {
    fn is_idle(&self) -> bool {
        PkwClient::is_idle(self)
    }
    fn begin(&mut self, now: Instant, r: &Request) -> Option<Result<(), RequestError>> {
        let Request::Pkw { pnu, command } = r else {
            return None;
        };
        Some(self.start(now, *pnu, *command).map_err(failed))
    }
    fn poll(&mut self, now: Instant, m: &mut DpMaster, h: SlaveHandle) -> Option<Outcome> {
        let words = |p: pkw::Pkw| {
            let mut b = [0u8; PKW_LEN];
            p.emit(&mut b);
            hex(&b)
        };
        let r = self.drive(now, m, h)?;
        Some(
            r.map(|a| {
                Some(AnswerData::Pkw {
                    value: a.reply.value(),
                    dword: a.reply.is_dword(),
                    request: words(a.request),
                    response: words(a.response),
                })
            })
            .map_err(failed),
        )
    }
}

impl JobClient for RfidClient {
    fn is_idle(&self) -> bool {
        RfidClient::is_idle(self)
    }
    fn begin(&mut self, now: Instant, r: &Request) -> Option<Result<(), RequestError>> {
        let Request::Rfid(line) = r else {
            return None;
        };
        Some(self.start(now, line).map_err(failed))
    }
    fn poll(&mut self, now: Instant, m: &mut DpMaster, h: SlaveHandle) -> Option<Outcome> {
        let r = self.poll_master(now, m, h)?;
        Some(
            r.map(|a| {
                let text = String::from_utf8_lossy(a);
                Some(AnswerData::Rfid {
                    answer: text.trim_end_matches('\r').into(),
                    hex: hex(a),
                })
            })
            .map_err(failed),
        )
    }
}

/// Start the next PKW or RFID job of a slave when its client is idle,
/// and drive the running one.
fn drive(e: &mut Entry, m: &mut DpMaster, now: Instant, answers: &mut Vec<(Target, Outcome)>) {
    let Some(h) = m.handle(e.info.address) else {
        return;
    };
    let client: Option<&mut dyn JobClient> = match (&mut e.pkw, &mut e.rfid) {
        (Some(c), _) => Some(c),
        (None, Some(c)) => Some(c),
        (None, None) => None,
    };
    let Some(c) = client else { return };
    while c.is_idle() && e.running.is_none() {
        let Some(q) = e.queue.pop_front() else { break };
        match c.begin(now, &q.request) {
            None => continue,
            Some(Ok(())) => e.running = Some(q.target),
            Some(Err(err)) => answers.push((q.target, Err(err))),
        }
    }
    if !c.is_idle() {
        if let Some(outcome) = c.poll(now, m, h) {
            if let Some(t) = e.running.take() {
                answers.push((t, outcome));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::SafeState;
    use profibus_devices::channels::ChannelType;
    use profibus_dp::master::{MasterConfig, MasterOptions, SlaveParams};
    use profibus_fdl::{Baud, BusParams};
    use serde_json::json;

    type Msgs = Vec<(String, serde_json::Value, bool)>;

    /// A master with slave 3 (2 words in/out, writable, named channels),
    /// slave 4 (2 bytes out, not writable) and slave 5 (only channel
    /// `speed` writable).
    fn setup() -> (Gateway, DpMaster) {
        let cfg = MasterConfig {
            address: 1,
            params: BusParams::defaults(Baud::B1500000),
            slaves: vec![
                SlaveParams::new(3, 0x1234, vec![0x71]),
                SlaveParams::new(4, 0x1234, vec![0x21]),
                SlaveParams::new(5, 0x1234, vec![0x71]),
            ],
            options: MasterOptions::default(),
        };
        let m = DpMaster::new(&cfg).unwrap();
        let mut ch = ChannelMap::new();
        ch.push("speed", Direction::Output, 0, ChannelType::I16);
        ch.push("torque", Direction::Output, 2, ChannelType::I16);
        ch.push("actual", Direction::Input, 0, ChannelType::I16);
        let t: toml::Table =
            toml::from_str("writable = [3, { address = 5, channels = [\"speed\"] }]").unwrap();
        let settings = crate::MqttSettings::from_table(Some(&t), "l1").unwrap();
        let info = |address, channels| SlaveInfo {
            address,
            name: format!("s{address}"),
            ident_number: 0x1234,
            channels,
            gsd: None,
            dpv1: false,
            pkw: None,
            rfid: false,
        };
        let g = Gateway::new(
            settings,
            vec![info(3, Some(ch.clone())), info(4, None), info(5, Some(ch))],
        );
        (g, m)
    }

    fn drain(g: &mut Gateway) -> Msgs {
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

    fn find<'a>(msgs: &'a Msgs, topic: &str) -> Option<&'a serde_json::Value> {
        msgs.iter().find(|(t, _, _)| t == topic).map(|(_, v, _)| v)
    }

    #[test]
    fn topics_and_hex() {
        let t = Topics::new("plant/a", "seg1");
        assert_eq!(t.status(), "plant/a/seg1/status");
        assert_eq!(t.slave(7, SlaveTopic::Inputs), "plant/a/seg1/7/inputs");
        assert_eq!(
            t.request_filters(),
            [
                "plant/a/seg1/+/outputs/set",
                "plant/a/seg1/+/dpv1/request",
                "plant/a/seg1/+/pkw/request",
                "plant/a/seg1/+/rfid/request"
            ]
        );
        assert_eq!(
            t.parse_request("plant/a/seg1/7/outputs/set"),
            Some((Service::Outputs, Ok(7)))
        );
        assert_eq!(
            t.parse_request("plant/a/seg1/7/pkw/request"),
            Some((Service::Pkw, Ok(7)))
        );
        assert_eq!(
            t.parse_request("plant/a/seg1/x/outputs/set"),
            Some((Service::Outputs, Err(BadAddress("x".into()))))
        );
        assert_eq!(t.parse_request("plant/a/seg1/7/outputs"), None);
        assert_eq!(t.parse_request("plant/a/seg1/7/pkw/response"), None);
        assert_eq!(t.parse_request("plant/a/seg2/7/outputs/set"), None);
        assert_eq!(hex(&[0, 0xab]), "00ab");
        assert_eq!(parse_hex("0x00 ab:01"), Some(vec![0, 0xab, 1]));
        assert_eq!(parse_hex("abc"), None);
        assert_eq!(parse_hex("zz"), None);
        assert_eq!(parse_hex(""), None);
    }

    #[test]
    fn request_payloads() {
        let out = |p: &[u8]| parse_request(Service::Outputs, p);
        assert_eq!(
            out(b"0102").1.unwrap(),
            Request::Outputs(OutputWrite::Image(vec![1, 2]))
        );
        assert_eq!(
            out(b"\"0102\"").1.unwrap(),
            Request::Outputs(OutputWrite::Image(vec![1, 2]))
        );
        let (to, r) =
            out(br#"{"channels": {"a": 1, "b": true, "c": 1.5}, "id": "x", "reply_to": "me/r"}"#);
        assert_eq!(
            to,
            ReplyTo {
                id: Some("x".into()),
                topic: Some("me/r".into())
            }
        );
        assert_eq!(
            r.unwrap(),
            Request::Outputs(OutputWrite::Channels(vec![
                ("a".into(), Value::Int(1)),
                ("b".into(), Value::Bool(true)),
                ("c".into(), Value::Float(1.5)),
            ]))
        );
        // The id is known even when the rest is malformed.
        let (to, r) = out(br#"{"hexx": "01", "id": 4}"#);
        assert_eq!(to.id, Some(4.into()));
        assert!(matches!(r, Err(RequestError::Malformed(_))));
        for bad in [
            &b"{\"hex\": \"01\", \"channels\": {}}"[..],
            b"{\"channels\": {\"a\": \"1\"}}",
            b"{\"hex\": \"01\", \"reply_to\": \"a/#\"}",
            b"[1]",
            b"\xff",
            b"",
        ] {
            assert!(
                matches!(out(bad).1, Err(RequestError::Malformed(_))),
                "{bad:?}"
            );
        }
        let pkw = |p: &[u8]| parse_request(Service::Pkw, p).1;
        assert_eq!(
            pkw(br#"{"op": "read", "pnu": 1000}"#).unwrap(),
            Request::Pkw {
                pnu: 1000,
                command: pkw::Command::Read
            }
        );
        assert_eq!(
            pkw(br#"{"op": "write", "pnu": 5, "value": -2}"#).unwrap(),
            Request::Pkw {
                pnu: 5,
                command: pkw::Command::WriteWord(0xfffe)
            }
        );
        assert_eq!(
            pkw(br#"{"op": "write", "pnu": 5, "value": 70000, "index": 2}"#).unwrap(),
            Request::Pkw {
                pnu: 5,
                command: pkw::Command::WriteElementDword {
                    index: 2,
                    value: 70000
                }
            }
        );
        assert!(pkw(br#"{"op": "write", "pnu": 5, "value": 70000, "dword": false}"#).is_err());
        assert!(pkw(br#"{"op": "read", "pnu": 3000}"#).is_err());
        assert!(pkw(br#"{"op": "erase", "pnu": 3}"#).is_err());
        assert!(pkw(b"0102").is_err());
        let dpv1 = |p: &[u8]| parse_request(Service::Dpv1, p).1;
        assert_eq!(
            dpv1(br#"{"op": "write", "slot": 1, "index": 2, "hex": "0a0b"}"#).unwrap(),
            Request::Dpv1Write {
                slot: 1,
                index: 2,
                data: vec![10, 11]
            }
        );
        assert!(dpv1(br#"{"op": "read", "slot": 1}"#).is_err());
        assert!(dpv1(br#"{"op": "read", "slot": 1, "index": 2, "length": 0}"#).is_err());
        assert_eq!(
            parse_request(Service::Rfid, br#"{"command": "VER"}"#)
                .1
                .unwrap(),
            Request::Rfid(b"VER".to_vec())
        );
    }

    #[test]
    fn publishes_retained_state_and_republishes_after_reconnect() {
        let (mut g, mut m) = setup();
        g.step(&mut m, Instant::ZERO, 5);
        assert!(
            drain(&mut g).is_empty(),
            "nothing before the first connection"
        );
        g.connected(10);
        g.step(&mut m, Instant::ZERO, 11);
        let msgs = drain(&mut g);
        let st = find(&msgs, "profibus/l1/status").unwrap();
        assert_eq!(
            (st["state"].as_str(), st["master"].as_str()),
            (Some("online"), Some("operate"))
        );
        assert_eq!(st["writable"], json!([3, 5]));
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
        assert!(msgs.iter().all(|(_, _, r)| *r));
        // Nothing changed: nothing new.
        g.step(&mut m, Instant::ZERO, 12);
        assert!(drain(&mut g).is_empty());
        // The master goes to Clear: the status says so at once.
        m.set_operating_state(OperatingState::Clear);
        g.step(&mut m, Instant::ZERO, 13);
        let msgs = drain(&mut g);
        assert_eq!(
            find(&msgs, "profibus/l1/status").unwrap()["master"],
            "clear"
        );
        m.set_operating_state(OperatingState::Operate);
        g.step(&mut m, Instant::ZERO, 14);
        drain(&mut g);
        // A new connection: everything again.
        g.disconnected(15);
        g.connected(20);
        g.step(&mut m, Instant::ZERO, 21);
        assert_eq!(drain(&mut g).len(), 1 + 3 * 4);
        assert_eq!(g.last_will().payload, br#"{"state":"offline"}"#);
    }

    #[test]
    fn writes_are_checked_then_applied_at_the_step() {
        let (mut g, mut m) = setup();
        g.connected(0);
        g.step(&mut m, Instant::ZERO, 0);
        drain(&mut g);
        g.handle_message(
            "profibus/l1/3/outputs/set",
            br#"{"channels": {"speed": -2, "torque": 3}, "id": 1}"#,
            1,
        );
        assert_eq!(
            m.outputs(3).unwrap(),
            [0, 0, 0, 0],
            "applied at the step, not before"
        );
        g.step(&mut m, Instant::ZERO, 2);
        assert_eq!(m.outputs(3).unwrap(), [0xff, 0xfe, 0, 3]);
        let msgs = drain(&mut g);
        let r = find(&msgs, "profibus/l1/3/outputs/response").unwrap();
        assert_eq!((r["ok"].as_bool(), r["id"].as_i64()), (Some(true), Some(1)));
        assert_eq!(
            find(&msgs, "profibus/l1/3/outputs").unwrap()["values"]["speed"],
            -2
        );
        // Slave 5 takes its `speed` channel, answered on `reply_to`.
        g.handle_message(
            "profibus/l1/5/outputs/set",
            br#"{"channels": {"speed": 7}, "id": "s", "reply_to": "client/9"}"#,
            3,
        );
        g.step(&mut m, Instant::ZERO, 4);
        let msgs = drain(&mut g);
        assert_eq!(find(&msgs, "client/9").unwrap()["ok"], true);
        assert_eq!(m.outputs(5).unwrap(), [0, 7, 0, 0]);

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
            (
                "profibus/l1/5/outputs/set",
                b"{\"channels\": {\"speed\": 1, \"torque\": 1}}",
                "only the output channels `speed` are writable",
            ),
            ("profibus/l1/5/outputs/set", b"00010001", "only the output"),
            (
                "profibus/l1/3/pkw/request",
                b"{\"op\": \"read\", \"pnu\": 1}",
                "no PKW channel",
            ),
            (
                "profibus/l1/3/rfid/request",
                b"{\"command\": \"VER\"}",
                "no RFID",
            ),
            (
                "profibus/l1/3/dpv1/request",
                b"{\"op\": \"read\", \"slot\": 0, \"index\": 1}",
                "no DP-V1",
            ),
        ] {
            g.handle_message(topic, payload, 5);
            g.step(&mut m, Instant::ZERO, 6);
            let msgs = drain(&mut g);
            let response = topic
                .replace("/set", "/response")
                .replace("/request", "/response");
            let r = find(&msgs, &response).unwrap_or_else(|| panic!("{msgs:?}"));
            assert_eq!(r["ok"], false, "{topic} {payload:?}");
            assert!(r["error"].as_str().unwrap().contains(error), "{r}");
            assert_eq!(m.outputs(3).unwrap(), [0xff, 0xfe, 0, 3]);
            assert_eq!(m.outputs(4).unwrap(), [0, 0]);
            assert_eq!(m.outputs(5).unwrap(), [0, 7, 0, 0]);
        }
        // Other topics are not ours.
        g.handle_message("profibus/l1/3/outputs", b"0000", 7);
        g.step(&mut m, Instant::ZERO, 8);
        assert!(drain(&mut g).is_empty());
    }

    #[test]
    fn a_full_write_queue_refuses_the_next_write_and_changes_nothing() {
        let (mut g, mut m) = setup();
        g.connected(0);
        g.step(&mut m, Instant::ZERO, 0);
        drain(&mut g);
        for i in 0..=QUEUE_LIMIT {
            let p = format!(r#"{{"hex": "000000{i:02x}", "id": {i}}}"#);
            g.handle_message("profibus/l1/3/outputs/set", p.as_bytes(), 1);
        }
        // The write over the limit is answered at once: busy.
        let msgs = drain(&mut g);
        assert_eq!(msgs.len(), 1, "{msgs:?}");
        let r = find(&msgs, "profibus/l1/3/outputs/response").unwrap();
        assert_eq!(
            (r["ok"].as_bool(), r["id"].as_u64()),
            (Some(false), Some(QUEUE_LIMIT as u64))
        );
        let e = r["error"].as_str().unwrap();
        assert!(e.contains("too many requests waiting (at most 8)"), "{e}");
        // Another slave has a queue of its own.
        g.handle_message(
            "profibus/l1/5/outputs/set",
            br#"{"channels": {"speed": 9}}"#,
            1,
        );
        g.step(&mut m, Instant::ZERO, 2);
        let msgs = drain(&mut g);
        let ok = |t: &str| {
            msgs.iter()
                .filter(|(topic, v, _)| topic == t && v["ok"] == true)
                .count()
        };
        assert_eq!(ok("profibus/l1/3/outputs/response"), QUEUE_LIMIT);
        assert_eq!(ok("profibus/l1/5/outputs/response"), 1);
        // The queued writes applied in order; the refused one did not.
        assert_eq!(m.outputs(3).unwrap(), [0, 0, 0, QUEUE_LIMIT as u8 - 1]);
        assert_eq!(m.outputs(5).unwrap(), [0, 9, 0, 0]);
        // The step emptied the queue: writes are taken again.
        g.handle_message("profibus/l1/3/outputs/set", b"00000063", 3);
        g.step(&mut m, Instant::ZERO, 4);
        assert_eq!(m.outputs(3).unwrap(), [0, 0, 0, 0x63]);
    }

    #[test]
    fn outputs_timeout_puts_the_outputs_in_the_safe_state_once() {
        for (safe, want3, master) in [
            ("keep", [0xff, 0xfe, 0, 3], "operate"),
            ("zero", [0, 0, 0, 0], "operate"),
            ("clear", [0xff, 0xfe, 0, 3], "clear"),
        ] {
            let (g, mut m) = setup();
            let mut s = g.settings().clone();
            s.outputs_timeout = Some(std::time::Duration::from_millis(100));
            s.safe_state = match safe {
                "keep" => SafeState::Keep,
                "zero" => SafeState::Zero,
                _ => SafeState::Clear,
            };
            let mut g = Gateway::new(s, g.slaves.iter().map(|e| e.info.clone()).collect());
            g.connected(0);
            g.handle_message("profibus/l1/3/outputs/set", b"fffe0003", 0);
            g.step(&mut m, Instant::ZERO, 0);
            g.disconnected(1000);
            g.step(&mut m, Instant::ZERO, 1099);
            assert_eq!(
                m.outputs(3).unwrap(),
                [0xff, 0xfe, 0, 3],
                "{safe}: too early"
            );
            g.step(&mut m, Instant::ZERO, 1100);
            assert_eq!(m.outputs(3).unwrap(), want3, "{safe}");
            assert_eq!(m.operating_state().as_str(), master, "{safe}");
            // The broker is back: reported in the status; Clear ends.
            g.connected(2000);
            g.step(&mut m, Instant::ZERO, 2000);
            let msgs = drain(&mut g);
            let st = find(&msgs, "profibus/l1/status").unwrap();
            assert_eq!(st["outputs_timeout"]["safe_state"], safe, "{st}");
            assert_eq!(st["outputs_timeout"]["at"], 1100, "{st}");
            assert_eq!(st["master"], "operate", "{st}");
            assert_eq!(m.operating_state(), OperatingState::Operate);
        }
    }

    /// A simulated plant: a generic DP-V1 slave (3), an Omega drive with
    /// PKW (25) and an RFID reader (30), all writable but the reader.
    fn plant() -> (Gateway, crate::sim::SimPlant) {
        let dir =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../devices/gsd/plant.toml");
        let text = "[master]\naddress = 1\nbaud = \"1.5M\"\n\n\
            [[slave]]\naddress = 3\ngsd = \"DPCTL_GEN.GSD\"\nmodules = [\"2 words in/out\"]\n\n\
            [[slave]]\naddress = 25\ndevice = \"omega\"\n\n\
            [[slave]]\naddress = 30\ndevice = \"rfid\"\n\n\
            [[slave]]\naddress = 40\ndevice = \"bk3000\"\nterminals = [\"KL3102\", \"KL9010\"]\n\n\
            [[slave]]\naddress = 26\ndevice = \"bm4\"\nexample = true\nvariables = [\"ud_MyReadVar1\"]\n\n\
            [mqtt]\nbus = \"p\"\nwritable = [3, 25]\n";
        let bus = profibus_devices::bus::ProfiledBus::parse(&dir, text).unwrap();
        let s = crate::MqttSettings::from_table(bus.file.mqtt.as_ref(), "p").unwrap();
        let g = Gateway::new(s, crate::sim::slave_infos(&bus).unwrap());
        (g, crate::sim::SimPlant::new(&bus).unwrap())
    }

    /// Run the plant 1 ms at a time until a message on `topic` (at most
    /// 2 s of bus time).
    fn run_until(g: &mut Gateway, p: &mut crate::sim::SimPlant, topic: &str) -> serde_json::Value {
        for _ in 0..2000 {
            let t = p.now() + std::time::Duration::from_millis(1);
            p.run_until(t);
            let ms = p.now().as_nanos() / 1_000_000;
            g.step(p.master(), t, ms);
            if let Some(v) = find(&drain(g), topic) {
                return v.clone();
            }
        }
        panic!("no message on {topic}");
    }

    #[test]
    fn dpv1_pkw_and_rfid_requests_are_answered() {
        let (mut g, mut p) = plant();
        g.connected(0);
        let mut seen = vec![];
        for _ in 0..2000 {
            let t = p.now() + std::time::Duration::from_millis(1);
            p.run_until(t);
            g.step(p.master(), t, 0);
            seen.extend(drain(&mut g));
            let m = p.master();
            if [3, 25, 26, 30, 40]
                .iter()
                .all(|&a| m.slave_state(a) == Some(SlaveState::DataExchange))
            {
                break;
            }
        }
        // Decoded values next to the hex: GSD module bytes of the generic
        // slave, the Omega's profile channels.
        let v = &find(&seen, "profibus/p/3/outputs").unwrap()["values"];
        assert_eq!(v["2 words in/out[0]"], 0, "{v}");
        let v = &find(&seen, "profibus/p/25/inputs").unwrap()["values"];
        assert!(v.get("status1").is_some() && v.get("pke").is_some(), "{v}");
        // Units where the profile scales a channel: the BK3000's KL3102
        // (±10 V); the diagnosis decoded by its standard bytes.
        let last = |topic: &str| {
            seen.iter()
                .rev()
                .find(|(t, _, _)| t == topic)
                .map(|(_, v, _)| v.clone())
                .unwrap()
        };
        let bk = last("profibus/p/40/inputs");
        assert_eq!(bk["units"]["1.KL3102.1"], "V", "{bk}");
        assert!(bk["values"]["1.KL3102.1"].is_f64(), "{bk}");
        let d = last("profibus/p/3/diag");
        assert_eq!(d["master"], 1, "{d}");
        assert_eq!(d["station_status"], "WD_On", "{d}");
        assert!(d["ident_number"].is_u64() && d["text"].is_array(), "{d}");
        // DP-V1: write a record, read it back.
        g.handle_message(
            "profibus/p/3/dpv1/request",
            br#"{"op": "write", "slot": 1, "index": 7, "hex": "cafe", "id": 1}"#,
            0,
        );
        let r = run_until(&mut g, &mut p, "profibus/p/3/dpv1/response");
        assert_eq!(
            (r["ok"].as_bool(), r["id"].as_i64()),
            (Some(true), Some(1)),
            "{r}"
        );
        g.handle_message(
            "profibus/p/3/dpv1/request",
            br#"{"op": "read", "slot": 1, "index": 7, "id": 2}"#,
            0,
        );
        let r = run_until(&mut g, &mut p, "profibus/p/3/dpv1/response");
        assert_eq!(r["hex"], "cafe", "{r}");
        g.handle_message(
            "profibus/p/3/dpv1/request",
            br#"{"op": "read", "slot": 1, "index": 99, "id": 3}"#,
            0,
        );
        let r = run_until(&mut g, &mut p, "profibus/p/3/dpv1/response");
        assert_eq!(r["ok"], false, "{r}");
        // PKW: two jobs queued at once run one after the other.
        g.handle_message(
            "profibus/p/25/pkw/request",
            br#"{"op": "write", "pnu": 1000, "value": 305419896, "id": "w"}"#,
            0,
        );
        g.handle_message(
            "profibus/p/25/pkw/request",
            br#"{"op": "read", "pnu": 1000, "id": "r", "reply_to": "me/pkw"}"#,
            0,
        );
        let r = run_until(&mut g, &mut p, "profibus/p/25/pkw/response");
        assert_eq!(
            (r["ok"].as_bool(), r["id"].as_str()),
            (Some(true), Some("w")),
            "{r}"
        );
        let r = run_until(&mut g, &mut p, "me/pkw");
        assert_eq!(r["value"], 0x1234_5678, "{r}");
        assert_eq!(r["response"], "23e8000012345678", "{r}");
        // PKW by name: a BM4 variable module of the GSD is its parameter
        // (`di_MyReadVar3`: PNU 4); an unknown name is refused.
        g.handle_message(
            "profibus/p/26/pkw/request",
            br#"{"op": "read", "pnu": "di_MyReadVar3", "id": "n"}"#,
            0,
        );
        let r = run_until(&mut g, &mut p, "profibus/p/26/pkw/response");
        assert_eq!(
            (r["ok"].as_bool(), r["id"].as_str()),
            (Some(true), Some("n")),
            "{r}"
        );
        assert_eq!(&r["request"].as_str().unwrap()[..4], "1004", "{r}");
        g.handle_message(
            "profibus/p/26/pkw/request",
            br#"{"op": "read", "pnu": "nope"}"#,
            0,
        );
        let r = run_until(&mut g, &mut p, "profibus/p/26/pkw/response");
        assert_eq!(r["error"], "slave 26 has no parameter named `nope`", "{r}");
        // RFID: the reader is not writable; a read-only request would be
        // answered, a command is refused.
        g.handle_message("profibus/p/30/rfid/request", br#"{"command": "VER"}"#, 0);
        let r = run_until(&mut g, &mut p, "profibus/p/30/rfid/response");
        assert!(r["error"].as_str().unwrap().contains("not writable"), "{r}");
        let mut s = g.settings().clone();
        s.writable.push(crate::settings::WriteAccess::full(30));
        let infos = g.slaves.iter().map(|e| e.info.clone()).collect();
        let mut g = Gateway::new(s, infos);
        g.connected(0);
        g.handle_message(
            "profibus/p/30/rfid/request",
            br#"{"command": "VER", "id": 5}"#,
            0,
        );
        let r = run_until(&mut g, &mut p, "profibus/p/30/rfid/response");
        assert_eq!(r["ok"], true, "{r}");
        assert!(!r["answer"].as_str().unwrap().is_empty(), "{r}");
    }
}
