//! The requests clients send on the request topics (`<addr>/outputs/set`,
//! `…/dpv1/request`, `…/pkw/request`, `…/rfid/request`): their JSON
//! payloads parsed into a typed [`Request`] and where its answer goes
//! ([`ReplyTo`]), and why a request is refused ([`RequestError`]).
//! Payload fields: `docs/gateway.md`.

use crate::topics::Service;
use profibus_devices::channels::{OutputWriteError, Value};
use profibus_devices::pkw;

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

/// Requests one slave may have waiting in each of its two queues: output
/// writes and DP-V1 jobs until the next [`Gateway::step`], PKW or RFID
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
}
