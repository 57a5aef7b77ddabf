//! FMS in the passive monitor: the telegrams of FMS connections
//! ([`FmsStream`], the rule `dpctl sniff` uses) become one event per
//! confirmed service — the request paired with its response by
//! connection and invoke ID — and one per connection event (Initiate
//! accepted or refused, Abort with its reason, an Information-Report),
//! and a summary per connection for the station's status.
//!
//! Values are put in words when the object's description was seen on
//! the wire (a Get-OD response of the same server, long form for the
//! names of the OD's own types; else the standard type numbering of
//! [`od::standard_type`]). Like every FMS decoding here this rests on
//! the (unverified) transfer syntax of [`crate::fms::pdu`] (`docs/fms.md`).

use crate::fms::decode::{Connection, FmsStream};
use crate::fms::lli::{abort_reason, LliPdu};
use crate::fms::od::{self, Description, ObjectCode};
use crate::fms::pdu::{reject_code_text, FmsPdu, Request, Response};
use profibus_fdl::{Instant, Telegram};
use std::collections::BTreeMap;
use std::fmt;

/// One FMS service or connection event seen on the line (JSON: `"event":
/// "fms"`).
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct FmsEvent {
    /// Bus time of the telegram that completed it, in nanoseconds
    /// (serialised as seconds, `time`).
    #[cfg_attr(feature = "serde", serde(rename = "time", serialize_with = "secs"))]
    pub at: Instant,
    /// The client (a master).
    pub master: u8,
    /// The server.
    pub station: u8,
    /// The server's LSAP.
    pub lsap: u8,
    /// The service as the standard names it: `Read`, `Write`, `Get-OD`,
    /// `Status`, `Identify`, `Initiate`, `Abort`, `Information-Report`.
    pub service: &'static str,
    /// `ok`, `error` (a negative response), `reject`, `abort` (the
    /// connection ended before the answer), `accepted` / `refused`
    /// (Initiate), `released` / `aborted` (Abort), `report`
    /// (Information-Report).
    pub outcome: &'static str,
    /// Invoke ID of a confirmed service.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub invoke_id: Option<u8>,
    /// Object index (Read, Write, Get-OD, Information-Report).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub index: Option<u16>,
    /// Element of an array or record.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub subindex: Option<u8>,
    /// The value read, written or reported.
    #[cfg_attr(
        feature = "serde",
        serde(
            skip_serializing_if = "Option::is_none",
            serialize_with = "profibus_fdl::ser::opt_hex"
        )
    )]
    pub data: Option<Vec<u8>>,
    /// The value in words (by the object's description, when seen; the
    /// Status and Identify answers in words).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub value: Option<String>,
    /// The object's name (a long-form Get-OD seen on the wire).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub name: Option<String>,
    /// The object's data type name.
    #[cfg_attr(
        feature = "serde",
        serde(rename = "type", skip_serializing_if = "Option::is_none")
    )]
    pub data_type: Option<String>,
    /// Get-OD: object descriptions in the answer.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub objects: Option<usize>,
    /// Negative response: error class.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error_class: Option<u8>,
    /// Negative response, Initiate-Error: error code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error_code: Option<u8>,
    /// Abort: reason code; Reject: reject code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub reason: Option<u8>,
    /// Abort: who sent it, `client` or `server`.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub by: Option<&'static str>,
    /// Initiate: the connection monitoring interval the client chose
    /// (0: none).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub monitoring_ms: Option<u64>,
    /// What went wrong, in words (error class and code, reject code,
    /// abort reason).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error: Option<String>,
}

#[cfg(feature = "serde")]
fn secs<S: serde::Serializer>(at: &Instant, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_f64(at.as_nanos() as f64 / 1e9)
}

impl FmsEvent {
    fn new(at: Instant, c: Connection, service: &'static str, outcome: &'static str) -> FmsEvent {
        FmsEvent {
            at,
            master: c.master,
            station: c.station,
            lsap: c.lsap,
            service,
            outcome,
            invoke_id: None,
            index: None,
            subindex: None,
            data: None,
            value: None,
            name: None,
            data_type: None,
            objects: None,
            error_class: None,
            error_code: None,
            reason: None,
            by: None,
            monitoring_ms: None,
            error: None,
        }
    }

    /// Whether the service or connection failed.
    pub fn failed(&self) -> bool {
        matches!(
            self.outcome,
            "error" | "reject" | "abort" | "refused" | "aborted"
        )
    }

    /// The service in a few words (`Read 2020 ok`), the summary's "last".
    pub fn short(&self) -> String {
        let mut s = self.service.to_string();
        if let Some(i) = self.index {
            s.push_str(&format!(" {i}"));
        }
        if let Some(x) = self.subindex {
            s.push_str(&format!(".{x}"));
        }
        s.push(' ');
        s.push_str(self.outcome);
        s
    }
}

/// `FMS 3→5/40 Read 2020 ok: 00 CB 03 = [0, 203, 3] (1.KL3102.1 input)`.
impl fmt::Display for FmsEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "FMS {}→{}/{} {}",
            self.master, self.station, self.lsap, self.service
        )?;
        if let Some(i) = self.index {
            write!(f, " {i}")?;
        }
        if let Some(x) = self.subindex {
            write!(f, " subindex {x}")?;
        }
        write!(f, " {}", self.outcome)?;
        if let Some(m) = self.monitoring_ms {
            match m {
                0 => write!(f, " (no connection monitoring)")?,
                m => write!(f, " (connection monitoring {m} ms)")?,
            }
        }
        if let Some(b) = self.by {
            write!(f, " by the {b}")?;
        }
        if let Some(n) = self.objects {
            write!(f, ": {n} object descriptions")?;
        }
        if let Some(d) = &self.data {
            write!(f, ": {}", hex(d))?;
            if let Some(v) = &self.value {
                write!(f, " = {v}")?;
            }
        } else if let Some(v) = &self.value {
            write!(f, ": {v}")?;
        }
        if let Some(n) = &self.name {
            write!(f, " ({n})")?;
        }
        if let Some(e) = &self.error {
            write!(f, ": {e}")?;
        }
        Ok(())
    }
}

fn hex(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// One FMS connection of a station, as far as the line showed it.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct FmsConnectionStatus {
    /// The client.
    pub master: u8,
    /// The server's LSAP.
    pub lsap: u8,
    /// `connecting` (Initiate sent), `connected`, `refused`, `aborted`,
    /// `released`.
    pub state: &'static str,
    /// Connection monitoring interval of the Initiate (0: none; absent:
    /// the Initiate was not seen).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub monitoring_ms: Option<u64>,
    /// Confirmed services completed (positive or not).
    pub services: u64,
    /// Services answered with an error or reject, or cut by an abort.
    pub errors: u64,
    /// The last service in a few words (`Read 2020 ok`).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub last: Option<String>,
}

/// `FMS master 3 LSAP 40: connected (monitoring 2000 ms), services 4, errors 1, last Read 2020 ok`.
impl fmt::Display for FmsConnectionStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "FMS master {} LSAP {}: {}",
            self.master, self.lsap, self.state
        )?;
        if let Some(m) = self.monitoring_ms.filter(|m| *m > 0) {
            write!(f, " (monitoring {m} ms)")?;
        }
        write!(f, ", services {}, errors {}", self.services, self.errors)?;
        if let Some(l) = &self.last {
            write!(f, ", last {l}")?;
        }
        Ok(())
    }
}

/// A request waiting for its confirmation.
#[derive(Debug, Clone)]
struct Outstanding {
    request: Request,
}

/// Follows the FMS connections of a line; see the module docs.
#[derive(Debug, Default, Clone)]
pub struct FmsWatch {
    stream: FmsStream,
    /// Requests by connection and invoke ID.
    outstanding: BTreeMap<(Connection, u8), Outstanding>,
    /// Associate requests waiting for their answer: the monitoring
    /// interval.
    associating: BTreeMap<Connection, u64>,
    /// Per connection, keyed (station, master, LSAP) so a station's
    /// connections sort together.
    connections: BTreeMap<(u8, u8, u8), FmsConnectionStatus>,
    /// Object descriptions seen in Get-OD answers, per station.
    od: BTreeMap<u8, BTreeMap<u16, Description>>,
}

/// Connections kept at most (a garbled line cannot grow the maps
/// without end).
const MAX_KEPT: usize = 1024;

impl FmsWatch {
    /// The next telegram of the line at `at`: the FMS events it
    /// completes (none for DP telegrams).
    pub fn observe(&mut self, at: Instant, telegram: &Telegram<'_>) -> Vec<FmsEvent> {
        let Some((c, t)) = self.stream.telegram(telegram) else {
            return vec![];
        };
        let request = matches!(telegram, Telegram::Data(d) if d.fc.is_request());
        let Some(pdu) = t.lli_pdu() else {
            return vec![];
        };
        let mut out = vec![];
        match pdu {
            LliPdu::Associate { monitoring, .. } => {
                let ms = monitoring.map_or(0, |d| d.as_millis() as u64);
                self.bounded_insert_assoc(c, ms);
                let s = self.connection(c);
                s.state = "connecting";
                s.monitoring_ms = Some(ms);
            }
            LliPdu::Associated(r) => {
                let ms = self.associating.remove(&c);
                let mut e = FmsEvent::new(at, c, "Initiate", "accepted");
                e.monitoring_ms = ms;
                if let Err(code) = r {
                    e.outcome = "refused";
                    e.error_code = Some(*code);
                    e.error = Some(format!("Initiate-Error code {code}"));
                }
                let s = self.connection(c);
                s.state = if r.is_ok() { "connected" } else { "refused" };
                if ms.is_some() {
                    s.monitoring_ms = ms;
                }
                out.push(e);
            }
            LliPdu::Abort { reason, .. } => {
                self.associating.remove(&c);
                let mut e = FmsEvent::new(
                    at,
                    c,
                    "Abort",
                    if *reason == crate::fms::lli::ABORT_USER {
                        "released"
                    } else {
                        "aborted"
                    },
                );
                e.reason = Some(*reason);
                e.by = Some(if request { "client" } else { "server" });
                e.error = Some(abort_reason(*reason).to_string());
                // Requests still open end with the connection.
                let cut: Vec<(Connection, u8)> = self
                    .outstanding
                    .range((c, 0)..=(c, u8::MAX))
                    .map(|(k, _)| *k)
                    .collect();
                for k in cut {
                    if let Some(o) = self.outstanding.remove(&k) {
                        let mut x = self.service_event(at, c, k.1, &o.request, "abort");
                        x.error = Some(format!("connection aborted: {}", abort_reason(*reason)));
                        self.count(c, &x);
                        out.push(x);
                    }
                }
                self.connection(c).state = e.outcome;
                out.push(e);
            }
            LliPdu::Idle => {
                self.seen(c);
            }
            LliPdu::Data(p) => {
                self.seen(c);
                if let Some(e) = self.data(at, c, p, request) {
                    if e.invoke_id.is_some() {
                        self.count(c, &e);
                    }
                    out.push(e);
                }
            }
        }
        out
    }

    /// The FMS connections of `station`, sorted by master and LSAP.
    pub fn connections_of(&self, station: u8) -> Vec<FmsConnectionStatus> {
        self.connections
            .range((station, 0, 0)..=(station, u8::MAX, u8::MAX))
            .map(|(_, s)| s.clone())
            .collect()
    }

    fn bounded_insert_assoc(&mut self, c: Connection, ms: u64) {
        if self.associating.len() >= MAX_KEPT {
            self.associating.clear();
        }
        self.associating.insert(c, ms);
    }

    fn connection(&mut self, c: Connection) -> &mut FmsConnectionStatus {
        if self.connections.len() >= MAX_KEPT
            && !self
                .connections
                .contains_key(&(c.station, c.master, c.lsap))
        {
            self.connections.clear();
        }
        self.connections
            .entry((c.station, c.master, c.lsap))
            .or_insert(FmsConnectionStatus {
                master: c.master,
                lsap: c.lsap,
                state: "connected",
                monitoring_ms: None,
                services: 0,
                errors: 0,
                last: None,
            })
    }

    /// Traffic on a connection: it lives (the monitor may have started
    /// after its Initiate).
    fn seen(&mut self, c: Connection) {
        let s = self.connection(c);
        if s.state != "connected" && s.state != "connecting" {
            s.state = "connected";
        }
    }

    fn count(&mut self, c: Connection, e: &FmsEvent) {
        let s = self.connection(c);
        s.services += 1;
        if e.failed() {
            s.errors += 1;
        }
        s.last = Some(e.short());
    }

    /// An FMS PDU on `c`; `request`: it went client → server. Requests
    /// count only that way, confirmations only the other.
    fn data(&mut self, at: Instant, c: Connection, p: &FmsPdu, request: bool) -> Option<FmsEvent> {
        let confirmation = matches!(
            p,
            FmsPdu::Response { .. } | FmsPdu::Error { .. } | FmsPdu::Reject { .. }
        );
        if (request && confirmation) || (!request && matches!(p, FmsPdu::Request { .. })) {
            return None;
        }
        match p {
            FmsPdu::Request { invoke_id, request } => {
                if self.outstanding.len() >= MAX_KEPT {
                    self.outstanding.clear();
                }
                self.outstanding.insert(
                    (c, *invoke_id),
                    Outstanding {
                        request: request.clone(),
                    },
                );
                None
            }
            FmsPdu::Response {
                invoke_id,
                response,
            } => {
                let o = self.outstanding.remove(&(c, *invoke_id))?;
                let mut e = self.service_event(at, c, *invoke_id, &o.request, "ok");
                match response {
                    Response::Read(data) => {
                        e.value = self.value_of(c.station, &o.request, data);
                        e.data = Some(data.clone());
                    }
                    Response::Write => {}
                    Response::Status(s) => {
                        e.value = Some(format!(
                            "logical status: {}; physical status: {}",
                            s.logical_text(),
                            s.physical_text()
                        ));
                    }
                    Response::Identify(i) => {
                        e.value = Some(format!(
                            "vendor {}, model {}, revision {}",
                            i.vendor, i.model, i.revision
                        ));
                    }
                    Response::GetOd { descriptions, .. } => {
                        e.objects = Some(descriptions.len());
                        let od = self.od.entry(c.station).or_default();
                        for d in descriptions
                            .iter()
                            .filter_map(|d| Description::parse(d).ok())
                        {
                            if od.len() < 4096 || od.contains_key(&d.index) {
                                od.insert(d.index, d);
                            }
                        }
                    }
                }
                Some(e)
            }
            FmsPdu::Error {
                invoke_id, error, ..
            } => {
                let o = self.outstanding.remove(&(c, *invoke_id))?;
                let mut e = self.service_event(at, c, *invoke_id, &o.request, "error");
                e.error_class = Some(error.class);
                e.error_code = Some(error.code);
                e.error = Some(error.describe());
                Some(e)
            }
            FmsPdu::Reject {
                original_invoke_id,
                code,
                ..
            } => {
                let o = self.outstanding.remove(&(c, *original_invoke_id));
                let mut e = match o {
                    Some(o) => self.service_event(at, c, *original_invoke_id, &o.request, "reject"),
                    None => FmsEvent::new(at, c, "Reject", "reject"),
                };
                e.reason = Some(*code);
                e.error = Some(format!("rejected: {}", reject_code_text(*code)));
                Some(e)
            }
            FmsPdu::InformationReport { index, data } => {
                let mut e = FmsEvent::new(at, c, "Information-Report", "report");
                e.index = Some(*index);
                let read = Request::Read {
                    index: *index,
                    subindex: None,
                };
                e.value = self.value_of(c.station, &read, data);
                self.name_of(c.station, *index, &mut e);
                e.data = Some(data.clone());
                Some(e)
            }
            // Initiate PDUs ride on the LLI's Associate (above).
            FmsPdu::InitiateRequest(_)
            | FmsPdu::InitiateResponse(_)
            | FmsPdu::InitiateError { .. } => None,
        }
    }

    /// The event of a confirmed service, with what its request says.
    fn service_event(
        &self,
        at: Instant,
        c: Connection,
        invoke_id: u8,
        request: &Request,
        outcome: &'static str,
    ) -> FmsEvent {
        let mut e = FmsEvent::new(at, c, request.service().name(), outcome);
        e.invoke_id = Some(invoke_id);
        match request {
            Request::Read { index, subindex } => {
                e.index = Some(*index);
                e.subindex = *subindex;
                self.name_of(c.station, *index, &mut e);
            }
            Request::Write {
                index,
                subindex,
                data,
            } => {
                e.index = Some(*index);
                e.subindex = *subindex;
                e.data = Some(data.clone());
                e.value = self.value_of(c.station, request, data);
                self.name_of(c.station, *index, &mut e);
            }
            Request::GetOd(g) => e.index = Some(g.index),
            Request::Status | Request::Identify => {}
        }
        e
    }

    fn name_of(&self, station: u8, index: u16, e: &mut FmsEvent) {
        let Some(d) = self.od.get(&station).and_then(|od| od.get(&index)) else {
            return;
        };
        e.name = d.name.clone();
        e.data_type = Some(self.type_name(station, d.data_type));
    }

    /// A type index's name: the server's own type descriptions (long
    /// form), else the standard numbering.
    fn type_name(&self, station: u8, index: u16) -> String {
        self.od
            .get(&station)
            .and_then(|od| od.get(&index))
            .filter(|d| d.object_code() == Some(ObjectCode::DataType))
            .and_then(|d| d.name.clone())
            .or_else(|| od::standard_type(index).map(str::to_string))
            .unwrap_or_else(|| format!("type {index}"))
    }

    /// The value in words, when the object's description was seen.
    fn value_of(&self, station: u8, request: &Request, data: &[u8]) -> Option<String> {
        let (Request::Read { index, subindex }
        | Request::Write {
            index, subindex, ..
        }) = request
        else {
            return None;
        };
        let d = self.od.get(&station)?.get(index)?;
        let t = self.type_name(station, d.data_type);
        match subindex {
            Some(s) if *s > 0 => d.decode_element(&t, data),
            _ => d.decode_value(&t, data),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fms::client::default_initiate;
    use crate::fms::lli::ABORT_TIMEOUT;
    use crate::fms::pdu::{GetOdRequest, InitiateResponse, ServiceError};
    use crate::monitor::{Monitor, MonitorEvent, MonitorOptions};
    use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus};
    use std::time::Duration;

    const CLIENT: u8 = 3;
    const SERVER: u8 = 5;
    const LSAP: u8 = 40;

    fn srd(du: &[u8]) -> Vec<u8> {
        let fc = FunctionCode::Request {
            kind: RequestKind::SrdLow,
            fcb: false,
            fcv: false,
        };
        let t = DataTelegram::new(SERVER, CLIENT, fc, du).with_saps(Some(LSAP), Some(LSAP + 1));
        Telegram::Data(t).to_vec().unwrap()
    }

    fn answer(du: &[u8]) -> Vec<u8> {
        let fc = FunctionCode::slave_response(ResponseStatus::Dl);
        let t = DataTelegram::new(CLIENT, SERVER, fc, du).with_saps(Some(LSAP + 1), Some(LSAP));
        Telegram::Data(t).to_vec().unwrap()
    }

    fn data(p: FmsPdu) -> Vec<u8> {
        LliPdu::Data(p).to_vec().unwrap()
    }

    fn events(telegrams: &[Vec<u8>]) -> (Monitor, Vec<FmsEvent>) {
        let mut m = Monitor::new(vec![], MonitorOptions::default());
        for (i, bytes) in telegrams.iter().enumerate() {
            let (t, _) = Telegram::parse(bytes).unwrap();
            m.observe(Instant::from_nanos(i as u64 * 1_000_000), &t);
        }
        let ev = std::iter::from_fn(|| m.poll_event())
            .filter_map(|e| match e {
                MonitorEvent::Fms(f) => Some(f),
                _ => None,
            })
            .collect();
        (m, ev)
    }

    #[test]
    fn services_pair_with_their_answers_and_values_come_from_the_od_seen() {
        let input = Description {
            index: 2020,
            code: ObjectCode::Array as u8,
            data_type: 5,
            length: 3,
            access: 1,
            name: Some("1.KL3102.1 input".into()),
        };
        let associate = LliPdu::Associate {
            monitoring: Some(Duration::from_millis(2000)),
            initiate: default_initiate(),
        };
        let accepted = LliPdu::Associated(Ok(InitiateResponse {
            version_od: 1,
            profile: [0, 0],
            access_protection: false,
            password: 0,
            access_groups: 0,
        }));
        let read = |invoke_id, index| {
            data(FmsPdu::Request {
                invoke_id,
                request: Request::Read {
                    index,
                    subindex: None,
                },
            })
        };
        let (m, ev) = events(&[
            srd(&associate.to_vec().unwrap()),
            answer(&accepted.to_vec().unwrap()),
            srd(&data(FmsPdu::Request {
                invoke_id: 1,
                request: Request::GetOd(GetOdRequest {
                    long_form: true,
                    from_index: false,
                    index: 2020,
                }),
            })),
            answer(&data(FmsPdu::Response {
                invoke_id: 1,
                response: Response::GetOd {
                    more_follows: false,
                    descriptions: vec![input.encode()],
                },
            })),
            // The answer comes to a poll (an empty request).
            srd(&read(2, 2020)),
            answer(&[]),
            srd(&[]),
            answer(&data(FmsPdu::Response {
                invoke_id: 2,
                response: Response::Read(vec![0x00, 0xCB, 0x03]),
            })),
            srd(&read(3, 9999)),
            answer(&data(FmsPdu::Error {
                invoke_id: 3,
                service: crate::fms::pdu::Service::Read,
                error: ServiceError::new(6, 7),
            })),
            srd(&read(4, 2020)),
            answer(
                &LliPdu::Abort {
                    reason: ABORT_TIMEOUT,
                    detail: 0,
                }
                .to_vec()
                .unwrap(),
            ),
        ]);
        let got: Vec<String> = ev.iter().map(|e| e.short()).collect();
        assert_eq!(
            got,
            [
                "Initiate accepted",
                "Get-OD 2020 ok",
                "Read 2020 ok",
                "Read 9999 error",
                "Read 2020 abort",
                "Abort aborted"
            ]
        );
        assert!(ev
            .iter()
            .all(|e| (e.master, e.station, e.lsap) == (CLIENT, SERVER, LSAP)));
        assert_eq!(ev[0].monitoring_ms, Some(2000));
        assert_eq!(ev[1].objects, Some(1));
        let r = &ev[2];
        assert_eq!(r.invoke_id, Some(2));
        assert_eq!(r.data.as_deref(), Some(&[0x00, 0xCB, 0x03][..]));
        assert_eq!(r.value.as_deref(), Some("[0, 203, 3]"));
        assert_eq!(r.name.as_deref(), Some("1.KL3102.1 input"));
        assert_eq!(r.data_type.as_deref(), Some("Unsigned8"));
        assert_eq!(r.at, Instant::from_nanos(7_000_000));
        assert_eq!(
            r.to_string(),
            "FMS 3→5/40 Read 2020 ok: 00 CB 03 = [0, 203, 3] (1.KL3102.1 input)"
        );
        let e = &ev[3];
        assert_eq!((e.error_class, e.error_code), (Some(6), Some(7)));
        assert!(
            e.error.as_deref().unwrap().contains("does not exist"),
            "{e:?}"
        );
        assert_eq!(ev[5].by, Some("server"));
        assert_eq!(ev[5].reason, Some(ABORT_TIMEOUT));
        assert!(
            ev[5].to_string().contains("connection monitoring"),
            "{}",
            ev[5]
        );
        // The server's summary.
        let st = m.status();
        let s = st.slaves.iter().find(|s| s.address == SERVER).unwrap();
        assert_eq!(s.fms.len(), 1);
        let c = &s.fms[0];
        assert_eq!((c.master, c.lsap, c.state), (CLIENT, LSAP, "aborted"));
        assert_eq!((c.services, c.errors), (4, 2));
        assert_eq!(c.monitoring_ms, Some(2000));
        assert_eq!(
            c.to_string(),
            "FMS master 3 LSAP 40: aborted (monitoring 2000 ms), services 4, errors 2, last Read 2020 abort"
        );
        #[cfg(feature = "serde")]
        {
            let j = serde_json::to_value(MonitorEvent::Fms(ev[2].clone())).unwrap();
            assert_eq!(j["event"], "fms");
            assert_eq!(j["service"], "Read");
            assert_eq!(j["index"], 2020);
            assert_eq!(j["data"], "00 CB 03");
            assert_eq!(j["time"], 0.007);
            assert_eq!(j["type"], "Unsigned8");
        }
    }

    proptest::proptest! {
        /// Any data units on an FMS connection, either way, in any
        /// order: no panic, and every service event is one the line
        /// asked for (its invoke ID was in a request seen before).
        #[test]
        fn garbage_on_an_fms_connection_never_panics(
            stream in proptest::collection::vec(
                (proptest::bool::ANY, proptest::collection::vec(proptest::num::u8::ANY, 0..24)),
                0..120,
            )
        ) {
            let mut w = FmsWatch::default();
            let mut asked = std::collections::BTreeSet::new();
            for (i, (request, du)) in stream.into_iter().enumerate() {
                // A type octet of the LLI or FMS now and then.
                let mut du = du;
                if let Some(b) = du.first_mut() {
                    *b = [1, 2, 3, 4, 5, 6, 7, 8, 0x10, 0x11, 0x12, 0x13, *b][*b as usize % 13];
                }
                let bytes = if request { srd(&du) } else { answer(&du) };
                if request {
                    if let Ok(LliPdu::Data(FmsPdu::Request { invoke_id, .. })) = LliPdu::parse(&du) {
                        asked.insert(invoke_id);
                    }
                }
                let (t, _) = Telegram::parse(&bytes).unwrap();
                for e in w.observe(Instant::from_nanos(i as u64 * 1000), &t) {
                    if let (Some(id), false) = (e.invoke_id, e.service == "Reject") {
                        proptest::prop_assert!(asked.contains(&id), "{e:?}");
                    }
                    let _ = e.to_string();
                }
            }
            for c in w.connections_of(SERVER) {
                proptest::prop_assert!(c.errors <= c.services);
                let _ = c.to_string();
            }
        }
    }

    #[test]
    fn a_refused_initiate_and_dp_traffic_beside_fms() {
        let associate = LliPdu::Associate {
            monitoring: None,
            initiate: default_initiate(),
        };
        let de = {
            let fc = FunctionCode::Request {
                kind: RequestKind::SrdHigh,
                fcb: true,
                fcv: true,
            };
            Telegram::Data(DataTelegram::new(SERVER, 1, fc, &[1, 2]))
                .to_vec()
                .unwrap()
        };
        let (_, ev) = events(&[
            de.clone(),
            srd(&associate.to_vec().unwrap()),
            answer(&LliPdu::Associated(Err(1)).to_vec().unwrap()),
            de,
        ]);
        assert_eq!(ev.len(), 1, "{ev:?}");
        assert_eq!(ev[0].short(), "Initiate refused");
        assert_eq!(ev[0].error_code, Some(1));
        assert_eq!(ev[0].monitoring_ms, Some(0));
    }
}
