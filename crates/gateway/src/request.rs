//! The requests clients send on the request topics (`<addr>/outputs/set`,
//! `…/dpv1/request`, `…/pkw/request`, `…/rfid/request`): their JSON
//! payloads parsed into a typed [`Request`] and where its answer goes
//! ([`ReplyTo`]), and why a request is refused ([`RequestError`]).
//! Payload fields: `docs/gateway.md`.

use crate::field::Field;
use crate::topics::Service;
use profibus_devices::channels::{OutputWriteError, Value};
use profibus_devices::pkw;
use serde::de::IgnoredAny;
use serde::Deserialize;
use std::collections::BTreeMap;

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
    /// [`crate::Gateway::handle_message`] resolves the name into [`Request::Pkw`].
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
    /// The request's MQTT 5 Response Topic property, else its
    /// `"reply_to"` topic; `None`: the service's response topic of the
    /// slave.
    pub topic: Option<String>,
    /// The request's MQTT 5 Correlation Data, returned as the answer's.
    pub correlation_data: Option<Vec<u8>>,
}

impl ReplyTo {
    /// The MQTT 5 properties of a request take the place of its payload
    /// fields: a Response Topic replaces `"reply_to"` (one with wildcards
    /// is refused: the answer then goes to the slave's response topic,
    /// still with the Correlation Data), Correlation Data goes back with
    /// the answer.
    pub fn take_properties(
        &mut self,
        response_topic: Option<&str>,
        correlation_data: Option<&[u8]>,
    ) -> Result<(), RequestError> {
        self.correlation_data = correlation_data.map(<[u8]>::to_vec);
        match response_topic {
            None => Ok(()),
            Some(t) if publishable(t) => {
                self.topic = Some(t.to_string());
                Ok(())
            }
            Some(_) => Err(malformed(
                "the response topic must be a topic without wildcards",
            )),
        }
    }
}

/// The media type of the gateway's payloads (MQTT 5 Content Type).
pub const JSON: &str = "application/json";

/// An MQTT 5 request's Content Type, if it gives one, must name JSON:
/// `application/json`, `text/json` or a `+json` type (parameters after
/// `;` and case do not matter).
pub fn check_content_type(content_type: Option<&str>) -> Result<(), RequestError> {
    let Some(ct) = content_type else {
        return Ok(());
    };
    let media = ct
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    if media == JSON || media == "text/json" || media.ends_with("+json") {
        Ok(())
    } else {
        Err(RequestError::ContentType(ct.to_string()))
    }
}

/// Why a request was refused or failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RequestError {
    /// The payload is not a request of this service.
    #[error("malformed request: {0}")]
    Malformed(String),
    /// An MQTT 5 request whose Content Type is not JSON.
    #[error("content type `{0}` is not JSON (send application/json or no content type)")]
    ContentType(String),
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
    let not_object = || malformed("expected a JSON object");
    // A JSON document's first character tells an object from the rest.
    let object = text
        .trim_start_matches([' ', '\t', '\n', '\r'])
        .starts_with('{');
    let parsed = match (object, service) {
        (true, _) => serde_json::from_str::<Fields>(text).ok(),
        (false, Service::Outputs) => {
            let r = match serde_json::from_str::<Field<String>>(text) {
                Ok(Field::Valid(s)) => image(&s),
                Ok(_) => Err(not_object()),
                Err(_) => image(text),
            };
            return (ReplyTo::default(), r);
        }
        (false, _) => None,
    };
    let f = match parsed {
        Some(f) => f,
        None if service == Service::Outputs => return (ReplyTo::default(), image(text)),
        None => return (ReplyTo::default(), Err(not_object())),
    };
    let mut to = ReplyTo {
        id: match f.id.clone() {
            Field::Valid(v) => Some(v),
            _ => None,
        },
        topic: None,
        correlation_data: None,
    };
    match f.reply_to.clone() {
        Field::Absent => {}
        Field::Valid(t) if publishable(&t) => to.topic = Some(t),
        _ => {
            return (
                to,
                Err(malformed("`reply_to` must be a topic without wildcards")),
            )
        }
    }
    let r = f.request(service);
    (to, r)
}

/// A number of a named output channel.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(untagged)]
enum Number {
    Bool(bool),
    Int(i64),
    Float(f64),
}

/// A PKW parameter: its number or the name the device gives it.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum Pnu {
    Number(i64),
    Name(String),
}

/// The fields of a request object, as written (every service's; each
/// service takes its own).
#[derive(Debug, Default, Deserialize)]
#[serde(default)]
struct Fields {
    id: Field<serde_json::Value>,
    reply_to: Field<String>,
    op: Field<String>,
    slot: Field<i64>,
    index: Field<i64>,
    length: Field<i64>,
    hex: Field<String>,
    channels: Field<BTreeMap<String, Field<Number>>>,
    pnu: Field<Pnu>,
    value: Field<i64>,
    dword: Field<bool>,
    element: Field<i64>,
    command: Field<String>,
    /// Any other field (refused by name).
    #[serde(flatten)]
    other: BTreeMap<String, IgnoredAny>,
}

/// An integer field in `min..=max`, when given.
fn int(v: &Field<i64>, key: &str, min: i64, max: i64) -> Result<Option<i64>, RequestError> {
    match v {
        Field::Absent => Ok(None),
        Field::Valid(n) if (min..=max).contains(n) => Ok(Some(*n)),
        _ => Err(malformed(format!(
            "`{key}` must be an integer {min}..={max}"
        ))),
    }
}

fn need<T>(v: Option<T>, key: &str) -> Result<T, RequestError> {
    v.ok_or_else(|| malformed(format!("`{key}` is missing")))
}

impl Fields {
    /// The names of the fields given.
    fn given(&self) -> Vec<&str> {
        let mut names: Vec<&str> = [
            ("op", self.op.is_given()),
            ("slot", self.slot.is_given()),
            ("index", self.index.is_given()),
            ("length", self.length.is_given()),
            ("hex", self.hex.is_given()),
            ("channels", self.channels.is_given()),
            ("pnu", self.pnu.is_given()),
            ("value", self.value.is_given()),
            ("dword", self.dword.is_given()),
            ("element", self.element.is_given()),
            ("command", self.command.is_given()),
        ]
        .into_iter()
        .filter_map(|(n, given)| given.then_some(n))
        .chain(self.other.keys().map(String::as_str))
        .collect();
        names.sort_unstable();
        names
    }

    /// Only `keys` (besides `id` and `reply_to`): the first other field
    /// by name is refused.
    fn only(&self, keys: &[&str]) -> Result<(), RequestError> {
        match self.given().into_iter().find(|k| !keys.contains(k)) {
            Some(k) => Err(malformed(format!("unknown field `{k}`"))),
            None => Ok(()),
        }
    }

    fn op(&self, ops: &[&str]) -> Result<String, RequestError> {
        match &self.op {
            Field::Valid(s) if ops.contains(&s.as_str()) => Ok(s.clone()),
            _ => {
                let ops: Vec<String> = ops.iter().map(|o| format!("\"{o}\"")).collect();
                Err(malformed(format!("`op` must be one of {}", ops.join(", "))))
            }
        }
    }

    /// The request of `service` these fields make.
    fn request(&self, service: Service) -> Result<Request, RequestError> {
        match service {
            Service::Outputs => {
                self.only(&["hex", "channels"])?;
                self.outputs()
            }
            Service::Dpv1 => {
                let slot = need(int(&self.slot, "slot", 0, 254)?, "slot")? as u8;
                let index = need(int(&self.index, "index", 0, 254)?, "index")? as u8;
                if self.op(&["read", "write"])? == "read" {
                    self.only(&["op", "slot", "index", "length"])?;
                    let length = int(&self.length, "length", 1, 240)?.unwrap_or(240) as u8;
                    Ok(Request::Dpv1Read {
                        slot,
                        index,
                        length,
                    })
                } else {
                    self.only(&["op", "slot", "index", "hex"])?;
                    let data = match &self.hex {
                        Field::Valid(h) => parse_hex(h)
                            .filter(|d| d.len() <= profibus_dp::pdu::dpv1::MAX_DATA_LEN)
                            .ok_or_else(|| malformed("`hex` must be 1..=240 bytes of hex"))?,
                        _ => return Err(malformed("`hex` is missing")),
                    };
                    Ok(Request::Dpv1Write { slot, index, data })
                }
            }
            Service::Pkw => {
                self.only(&["op", "pnu", "index", "value", "dword", "element"])?;
                let pnu = match &self.pnu {
                    Field::Valid(Pnu::Name(n)) if !n.is_empty() => Err(n.clone()),
                    p => {
                        let p = match p {
                            Field::Valid(Pnu::Number(n)) => Field::Valid(*n),
                            Field::Absent => Field::Absent,
                            _ => Field::Invalid,
                        };
                        Ok(need(int(&p, "pnu", 0, 0x7FF)?, "pnu")? as u16)
                    }
                };
                let index = int(&self.index, "index", 0, 0xFFFF)?.map(|i| i as u16);
                let command = match self.op(&["read", "write", "describe"])?.as_str() {
                    "read" => index.map_or(pkw::Command::Read, pkw::Command::ReadElement),
                    "describe" => pkw::Command::Describe(need(
                        int(&self.element, "element", 0, 0xFFFF)?,
                        "element",
                    )? as u16),
                    _ => {
                        let range = (i32::MIN as i64, u32::MAX as i64);
                        let v = need(int(&self.value, "value", range.0, range.1)?, "value")?;
                        let dword = match self.dword {
                            Field::Absent => !(-0x8000..=0xFFFF).contains(&v),
                            Field::Valid(b) => b,
                            Field::Invalid => {
                                return Err(malformed("`dword` must be true or false"))
                            }
                        };
                        if !dword && !(-0x8000..=0xFFFF).contains(&v) {
                            return Err(malformed("`value` does not fit a word"));
                        }
                        let (w, d) = (v as u16, v as u32);
                        match (index, dword) {
                            (None, false) => pkw::Command::WriteWord(w),
                            (None, true) => pkw::Command::WriteDword(d),
                            (Some(index), false) => {
                                pkw::Command::WriteElementWord { index, value: w }
                            }
                            (Some(index), true) => {
                                pkw::Command::WriteElementDword { index, value: d }
                            }
                        }
                    }
                };
                Ok(match pnu {
                    Ok(pnu) => Request::Pkw { pnu, command },
                    Err(name) => Request::PkwNamed { name, command },
                })
            }
            Service::Rfid => {
                self.only(&["command"])?;
                match &self.command {
                    Field::Valid(c) if !c.is_empty() && c.is_ascii() => {
                        Ok(Request::Rfid(c.trim_end_matches('\r').as_bytes().to_vec()))
                    }
                    _ => Err(malformed("`command` must be a non-empty ASCII string")),
                }
            }
        }
    }

    fn outputs(&self) -> Result<Request, RequestError> {
        let req = match (&self.hex, &self.channels) {
            (Field::Valid(h), Field::Absent) => {
                OutputWrite::Image(parse_hex(h).ok_or_else(|| malformed("`hex` is not hex"))?)
            }
            (Field::Absent, Field::Valid(c)) if !c.is_empty() => OutputWrite::Channels(
                c.iter()
                    .map(|(k, v)| {
                        let val = match v {
                            Field::Valid(Number::Bool(b)) => Value::Bool(*b),
                            Field::Valid(Number::Int(i)) => Value::Int(*i),
                            Field::Valid(Number::Float(x)) => Value::Float(*x),
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
}

/// Requests one slave may have waiting in each of its two queues: output
/// writes and DP-V1 jobs until the next [`crate::Gateway::step`], PKW or RFID
/// jobs for the slave's client. One more is answered
/// [`RequestError::Busy`] and changes nothing.
pub const QUEUE_LIMIT: usize = 8;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_strings() {
        assert_eq!(parse_hex("0x00 ab:01"), Some(vec![0, 0xab, 1]));
        assert_eq!(parse_hex("abc"), None);
        assert_eq!(parse_hex("zz"), None);
        assert_eq!(parse_hex(""), None);
    }

    #[test]
    fn each_malformed_request_has_its_message() {
        use Service::*;
        for (service, payload, message) in [
            (Outputs, &b"zz"[..], "neither a JSON object nor hex"),
            (Outputs, b"[1]", "expected a JSON object"),
            (
                Outputs,
                b"{\"hex\": 1}",
                "give either `hex` (a string) or `channels` (an object)",
            ),
            (Outputs, b"{\"hex\": \"zz\"}", "`hex` is not hex"),
            (
                Outputs,
                b"{\"hex\": \"01\", \"b\": 1, \"a\": 2}",
                "unknown field `a`",
            ),
            (
                Outputs,
                b"{\"channels\": {\"a\": null}}",
                "channel `a`: value must be a number or a boolean",
            ),
            (
                Outputs,
                b"{\"hex\": \"01\", \"reply_to\": 7}",
                "`reply_to` must be a topic without wildcards",
            ),
            (Dpv1, b"\"0102\"", "expected a JSON object"),
            (Dpv1, b"{\"op\": \"read\"}", "`slot` is missing"),
            (
                Dpv1,
                b"{\"op\": \"read\", \"slot\": null, \"index\": 1}",
                "`slot` must be an integer 0..=254",
            ),
            (
                Dpv1,
                b"{\"op\": \"read\", \"slot\": 1, \"index\": 255}",
                "`index` must be an integer 0..=254",
            ),
            (
                Dpv1,
                b"{\"op\": \"erase\", \"slot\": 1, \"index\": 2}",
                "`op` must be one of \"read\", \"write\"",
            ),
            (
                Dpv1,
                b"{\"op\": \"read\", \"slot\": 1, \"index\": 2, \"hex\": \"01\"}",
                "unknown field `hex`",
            ),
            (
                Dpv1,
                b"{\"op\": \"write\", \"slot\": 1, \"index\": 2}",
                "`hex` is missing",
            ),
            (
                Dpv1,
                b"{\"op\": \"write\", \"slot\": 1, \"index\": 2, \"hex\": \"\"}",
                "`hex` must be 1..=240 bytes of hex",
            ),
            (Pkw, b"{\"op\": \"read\"}", "`pnu` is missing"),
            (
                Pkw,
                b"{\"op\": \"read\", \"pnu\": \"\"}",
                "`pnu` must be an integer 0..=2047",
            ),
            (
                Pkw,
                b"{\"op\": \"read\", \"pnu\": 1, \"index\": -1}",
                "`index` must be an integer 0..=65535",
            ),
            (
                Pkw,
                b"{\"op\": \"describe\", \"pnu\": 1}",
                "`element` is missing",
            ),
            (
                Pkw,
                b"{\"op\": \"write\", \"pnu\": 1}",
                "`value` is missing",
            ),
            (
                Pkw,
                b"{\"op\": \"write\", \"pnu\": 1, \"value\": 1, \"dword\": 1}",
                "`dword` must be true or false",
            ),
            (
                Pkw,
                b"{\"op\": \"write\", \"pnu\": 1, \"value\": 70000, \"dword\": false}",
                "`value` does not fit a word",
            ),
            (
                Pkw,
                b"{\"op\": \"write\", \"pnu\": 1, \"value\": 5000000000}",
                "`value` must be an integer -2147483648..=4294967295",
            ),
            (
                Pkw,
                b"{\"op\": \"read\", \"pnu\": 1, \"slot\": 1}",
                "unknown field `slot`",
            ),
            (
                Rfid,
                b"{\"command\": \"\"}",
                "`command` must be a non-empty ASCII string",
            ),
            (Rfid, b"{}", "`command` must be a non-empty ASCII string"),
        ] {
            let e = parse_request(service, payload).1.unwrap_err();
            let text = String::from_utf8_lossy(payload);
            assert_eq!(
                e.to_string(),
                format!("malformed request: {message}"),
                "{text}"
            );
        }
        // `null` is an id like any other JSON value.
        let (to, _) = parse_request(Outputs, br#"{"hex": "01", "id": null}"#);
        assert_eq!(to.id, Some(serde_json::Value::Null));
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
                topic: Some("me/r".into()),
                correlation_data: None,
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
}
