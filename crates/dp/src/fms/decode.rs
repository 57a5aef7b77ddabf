//! FMS telegrams described for people and scripts: the LLI PDU and the
//! FMS PDU inside the data unit of an FDL telegram on an FMS connection,
//! as one line (`Display`) and, with the feature `serde`, as the `"fms"`
//! object of `dpctl sniff --json`.
//!
//! [`describe`] is sans-IO and stateless: a data unit and its direction
//! give an [`FmsTelegram`]; nothing it is given makes it panic, and what
//! does not decode comes out as `malformed` with the reason. Which
//! telegrams are FMS at all is decided on the stream
//! ([`crate::pdu::decode::Exchanges::decode_layer`]): a request or
//! response with both SAPs, the slave's SAP one DP-V1 leaves to
//! connections (0..=48), and a data unit that starts with an LLI or FMS
//! type octet ([`starts_lli_pdu`]); an empty one on a connection seen
//! carrying FMS before (a poll, or an answer with nothing to say).
//!
//! Every decoding here rests on the (unverified) transfer syntax of
//! [`crate::fms::pdu`] and [`crate::fms::lli`] (`docs/fms.md`): it reads
//! what this project's client and server send; a third-party device's
//! bytes may decode differently or as `malformed`.
//!
//! ```
//! use profibus_dp::fms::decode::describe;
//!
//! // A Read.req of object 2022 with invoke ID 3, and its answer.
//! let req = describe(&[1, 3, 2, 0x07, 0xE6], true);
//! assert_eq!(req.to_string(), "FMS Read.req invoke 3 index 2022");
//! assert_eq!((req.pdu, req.invoke_id, req.index), (Some("read_req"), Some(3), Some(2022)));
//! let res = describe(&[2, 3, 2, 0x00, 0x12, 0x34], false);
//! assert_eq!(res.to_string(), "FMS Read.resp invoke 3 data 00 12 34");
//! // Garbage is flagged, never a panic.
//! let bad = describe(&[1, 3, 9], true);
//! assert_eq!(bad.lli, "malformed");
//! ```

use core::fmt;
use std::collections::{BTreeMap, BTreeSet};

use profibus_fdl::wire::{FunctionCode, Telegram};

use super::lli::{self, LliParseError, LliPdu, LLI_ASSOCIATE_REQ, LLI_IDLE};
use super::pdu::{FmsPdu, PduType, Request, Response, Service};

/// Whether a data unit's first octet is an LLI PDU type or an FMS PDU
/// type (the values of [`crate::fms::lli`] and [`PduType`]; none of them
/// is a DP-V1 function number, so they tell FMS from MSAC_C2 on the same
/// SAPs).
pub fn starts_lli_pdu(du: &[u8]) -> bool {
    du.first().is_some_and(|&b| {
        PduType::from_u8(b).is_some() || (LLI_ASSOCIATE_REQ..=LLI_IDLE).contains(&b)
    })
}

/// One FDL data unit of an FMS connection, decoded. The fields that do
/// not apply are `None` (left out of the JSON object).
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct FmsTelegram {
    /// The LLI PDU: `associate` (carries the Initiate-Request),
    /// `associate_res` (the Initiate-Response or -Error), `abort`,
    /// `idle`, `data` (an FMS PDU), `poll` (a request without data: the
    /// client asks for the answer), `empty` (a response without data),
    /// `malformed`.
    pub lli: &'static str,
    /// The FMS PDU: `initiate_req`, `initiate_resp`, `initiate_error`,
    /// `SERVICE_req`, `SERVICE_resp` (SERVICE `status`, `identify`,
    /// `read`, `write`, `get_od`), `error` (a negative response),
    /// `information_report`, `reject`.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub pdu: Option<&'static str>,
    /// The confirmed service as the standard names it (`Read`, `Get-OD`, …).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub service: Option<&'static str>,
    /// Invoke ID of a confirmed service.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub invoke_id: Option<u8>,
    /// Object index (Read, Write, Get-OD, Information-Report).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub index: Option<u16>,
    /// Subindex: one element of an array or record.
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
    /// Get-OD.req: all attributes (long form).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub long_form: Option<bool>,
    /// Get-OD.req: the index and those after it.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub from_index: Option<bool>,
    /// Get-OD.res: more descriptions follow.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub more_follows: Option<bool>,
    /// Get-OD.res: the object descriptions, each in hex.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub descriptions: Option<Vec<String>>,
    /// Status.res: logical status code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub logical_status: Option<u8>,
    /// Status.res: physical status code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub physical_status: Option<u8>,
    /// Status.res: local detail (3 octets).
    #[cfg_attr(
        feature = "serde",
        serde(
            skip_serializing_if = "Option::is_none",
            serialize_with = "profibus_fdl::ser::opt_hex"
        )
    )]
    pub local_detail: Option<Vec<u8>>,
    /// Status.res in words (`ready for communication, operational`).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub status_text: Option<String>,
    /// Identify.res: vendor name.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub vendor: Option<String>,
    /// Identify.res: model name.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub model: Option<String>,
    /// Identify.res: revision.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub revision: Option<String>,
    /// Negative response: error class.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error_class: Option<u8>,
    /// Negative response: error code; Initiate-Error: its code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error_code: Option<u8>,
    /// Negative response: additional code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub additional_code: Option<u16>,
    /// Reject: the invoke ID of the rejected PDU.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub original_invoke_id: Option<u8>,
    /// Reject: the type octet of the rejected PDU.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub rejected_pdu_type: Option<u8>,
    /// Reject: the reject code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub reject_code: Option<u8>,
    /// Initiate: the version of the sender's object dictionary.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub version_od: Option<i16>,
    /// Initiate: profile number (2 octets).
    #[cfg_attr(
        feature = "serde",
        serde(
            skip_serializing_if = "Option::is_none",
            serialize_with = "profibus_fdl::ser::opt_hex"
        )
    )]
    pub profile: Option<Vec<u8>>,
    /// Initiate: access protection supported.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub access_protection: Option<bool>,
    /// Initiate: password.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub password: Option<u8>,
    /// Initiate: access groups.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub access_groups: Option<u8>,
    /// Initiate-Request: max PDU sending, high and low priority, and
    /// receiving, high and low priority.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub max_pdu: Option<[u8; 4]>,
    /// Initiate-Request: FMS Features Supported (6 octets).
    #[cfg_attr(
        feature = "serde",
        serde(
            skip_serializing_if = "Option::is_none",
            serialize_with = "profibus_fdl::ser::opt_hex"
        )
    )]
    pub features: Option<Vec<u8>>,
    /// LLI Associate: the connection monitoring interval the client
    /// chose (0: none).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub monitoring_ms: Option<u64>,
    /// LLI Abort: reason code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub reason: Option<u8>,
    /// LLI Abort: detail octet.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub detail: Option<u8>,
    /// In words: a negative response's error, an Abort's reason, or why
    /// the data unit does not decode (`malformed`).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub error: Option<String>,
    /// What was decoded, for the text line.
    #[cfg_attr(feature = "serde", serde(skip))]
    parsed: Parsed,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Parsed {
    /// No data: a poll (request) or nothing to say (response).
    Empty {
        request: bool,
    },
    Pdu(LliPdu),
    Malformed(LliParseError),
}

fn req_word(s: Service) -> &'static str {
    match s {
        Service::Status => "status_req",
        Service::Identify => "identify_req",
        Service::Read => "read_req",
        Service::Write => "write_req",
        Service::GetOd => "get_od_req",
    }
}

fn resp_word(s: Service) -> &'static str {
    match s {
        Service::Status => "status_resp",
        Service::Identify => "identify_resp",
        Service::Read => "read_resp",
        Service::Write => "write_resp",
        Service::GetOd => "get_od_resp",
    }
}

fn hex(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The data unit `du` of a telegram on an FMS connection, decoded;
/// `request`: a request (client → server), else a response.
pub fn describe(du: &[u8], request: bool) -> FmsTelegram {
    let mut t = FmsTelegram {
        lli: "",
        pdu: None,
        service: None,
        invoke_id: None,
        index: None,
        subindex: None,
        data: None,
        long_form: None,
        from_index: None,
        more_follows: None,
        descriptions: None,
        logical_status: None,
        physical_status: None,
        local_detail: None,
        status_text: None,
        vendor: None,
        model: None,
        revision: None,
        error_class: None,
        error_code: None,
        additional_code: None,
        original_invoke_id: None,
        rejected_pdu_type: None,
        reject_code: None,
        version_od: None,
        profile: None,
        access_protection: None,
        password: None,
        access_groups: None,
        max_pdu: None,
        features: None,
        monitoring_ms: None,
        reason: None,
        detail: None,
        error: None,
        parsed: Parsed::Empty { request },
    };
    if du.is_empty() {
        t.lli = if request { "poll" } else { "empty" };
        return t;
    }
    let pdu = match LliPdu::parse(du) {
        Ok(p) => p,
        Err(e) => {
            t.lli = "malformed";
            t.error = Some(e.to_string());
            t.parsed = Parsed::Malformed(e);
            return t;
        }
    };
    match &pdu {
        LliPdu::Associate {
            monitoring,
            initiate,
        } => {
            t.lli = "associate";
            t.monitoring_ms = Some(monitoring.map_or(0, |d| d.as_millis() as u64));
            t.fill(&FmsPdu::InitiateRequest(*initiate));
        }
        LliPdu::Associated(r) => {
            t.lli = "associate_res";
            t.fill(&match r {
                Ok(r) => FmsPdu::InitiateResponse(*r),
                Err(code) => FmsPdu::InitiateError { code: *code },
            });
        }
        LliPdu::Abort { reason, detail } => {
            t.lli = "abort";
            t.reason = Some(*reason);
            t.detail = Some(*detail);
            t.error = Some(lli::abort_reason(*reason).to_string());
        }
        LliPdu::Idle => t.lli = "idle",
        LliPdu::Data(p) => {
            t.lli = "data";
            t.fill(p);
        }
    }
    t.parsed = Parsed::Pdu(pdu);
    t
}

impl FmsTelegram {
    /// The fields of the FMS PDU `p`.
    fn fill(&mut self, p: &FmsPdu) {
        self.invoke_id = p.invoke_id();
        match p {
            FmsPdu::Request { request, .. } => {
                let s = request.service();
                self.pdu = Some(req_word(s));
                self.service = Some(s.name());
                match request {
                    Request::Status | Request::Identify => {}
                    Request::Read { index, subindex } => {
                        self.index = Some(*index);
                        self.subindex = *subindex;
                    }
                    Request::Write {
                        index,
                        subindex,
                        data,
                    } => {
                        self.index = Some(*index);
                        self.subindex = *subindex;
                        self.data = Some(data.clone());
                    }
                    Request::GetOd(g) => {
                        self.index = Some(g.index);
                        self.long_form = Some(g.long_form);
                        self.from_index = Some(g.from_index);
                    }
                }
            }
            FmsPdu::Response { response, .. } => {
                let s = response.service();
                self.pdu = Some(resp_word(s));
                self.service = Some(s.name());
                match response {
                    Response::Status(st) => {
                        self.logical_status = Some(st.logical);
                        self.physical_status = Some(st.physical);
                        self.local_detail = Some(st.local_detail.to_vec());
                        self.status_text =
                            Some(format!("{}, {}", st.logical_text(), st.physical_text()));
                    }
                    Response::Identify(i) => {
                        self.vendor = Some(i.vendor.clone());
                        self.model = Some(i.model.clone());
                        self.revision = Some(i.revision.clone());
                    }
                    Response::Read(d) => self.data = Some(d.clone()),
                    Response::Write => {}
                    Response::GetOd {
                        more_follows,
                        descriptions,
                    } => {
                        self.more_follows = Some(*more_follows);
                        self.descriptions = Some(descriptions.iter().map(|d| hex(d)).collect());
                    }
                }
            }
            FmsPdu::Error { service, error, .. } => {
                self.pdu = Some("error");
                self.service = Some(service.name());
                self.error_class = Some(error.class);
                self.error_code = Some(error.code);
                self.additional_code = Some(error.additional);
                self.error = Some(error.meaning().to_string());
            }
            FmsPdu::InformationReport { index, data } => {
                self.pdu = Some("information_report");
                self.index = Some(*index);
                self.data = Some(data.clone());
            }
            FmsPdu::Reject {
                original_invoke_id,
                pdu_type,
                code,
            } => {
                self.pdu = Some("reject");
                self.original_invoke_id = Some(*original_invoke_id);
                self.rejected_pdu_type = Some(*pdu_type);
                self.reject_code = Some(*code);
            }
            FmsPdu::InitiateRequest(i) => {
                self.pdu = Some("initiate_req");
                self.version_od = Some(i.version_od);
                self.profile = Some(i.profile.to_vec());
                self.access_protection = Some(i.access_protection);
                self.password = Some(i.password);
                self.access_groups = Some(i.access_groups);
                self.max_pdu = Some([
                    i.max_pdu_send_high,
                    i.max_pdu_send_low,
                    i.max_pdu_recv_high,
                    i.max_pdu_recv_low,
                ]);
                self.features = Some(i.features.to_vec());
            }
            FmsPdu::InitiateResponse(i) => {
                self.pdu = Some("initiate_resp");
                self.version_od = Some(i.version_od);
                self.profile = Some(i.profile.to_vec());
                self.access_protection = Some(i.access_protection);
                self.password = Some(i.password);
                self.access_groups = Some(i.access_groups);
            }
            FmsPdu::InitiateError { code } => {
                self.pdu = Some("initiate_error");
                self.error_code = Some(*code);
            }
        }
    }

    /// Whether the data unit decoded (not `malformed`).
    pub fn is_ok(&self) -> bool {
        !matches!(self.parsed, Parsed::Malformed(_))
    }

    /// The LLI PDU decoded (`None`: no data, or `malformed`).
    pub fn lli_pdu(&self) -> Option<&LliPdu> {
        match &self.parsed {
            Parsed::Pdu(p) => Some(p),
            _ => None,
        }
    }
}

/// One FMS connection as the line shows it: the client (a master), the
/// server and the server's LSAP.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Connection {
    /// The client (the requester).
    pub master: u8,
    /// The server (the responder).
    pub station: u8,
    /// The server's LSAP (without the segment bit).
    pub lsap: u8,
}

/// Tells the telegrams of FMS connections on a stream of telegrams (the
/// one rule of `dpctl sniff`, `dpctl monitor` and
/// [`crate::pdu::decode::Exchanges::decode_layer`]): a request or
/// response with both SAPs, the server's SAP 0..=48 (which DP-V1 leaves
/// to MSAC_C2 connections and FMS shares), and a data unit that starts
/// with an LLI or FMS type octet ([`starts_lli_pdu`]); an empty one (a
/// poll, a short acknowledge, a response without SAPs) only on a
/// connection seen carrying FMS. A DP-V1 PDU on the same SAP ends that.
#[derive(Debug, Default, Clone)]
pub struct FmsStream {
    /// The last request that waits for its answer: a short acknowledge
    /// answers it.
    pending: Option<(u8, u8, Option<u8>)>,
    /// The destination SAP of the last request per (master, station).
    last: BTreeMap<(u8, u8), Option<u8>>,
    /// Connections seen carrying FMS.
    fms: BTreeSet<Connection>,
}

impl FmsStream {
    /// The next telegram of the stream: its connection and its LLI/FMS
    /// PDUs when it belongs to an FMS connection, else `None`.
    pub fn telegram(&mut self, telegram: &Telegram<'_>) -> Option<(Connection, FmsTelegram)> {
        let found = self.classify(telegram);
        match telegram {
            Telegram::Token { .. } => self.pending = None,
            Telegram::ShortAck => self.pending = None,
            Telegram::Data(d) => match d.fc {
                FunctionCode::Request { kind, .. } => {
                    let dsap = d.dsap.map(|s| s & 0x3F);
                    self.pending =
                        (kind.expects_reply() && !d.is_broadcast()).then_some((d.sa, d.da, dsap));
                    if self.pending.is_some() {
                        self.last.insert((d.sa, d.da), dsap);
                    }
                }
                FunctionCode::Response { .. } => self.pending = None,
            },
        }
        found
    }

    fn classify(&mut self, telegram: &Telegram<'_>) -> Option<(Connection, FmsTelegram)> {
        let (key, request, du) = match telegram {
            Telegram::Token { .. } => return None,
            Telegram::ShortAck => {
                let (master, station, dsap) = self.pending?;
                let lsap = dsap?;
                (
                    Connection {
                        master,
                        station,
                        lsap,
                    },
                    false,
                    &[][..],
                )
            }
            Telegram::Data(d) => {
                let request = d.fc.is_request();
                let (master, station) = if request { (d.sa, d.da) } else { (d.da, d.sa) };
                let lsap = match (d.dsap, d.ssap) {
                    (Some(ds), Some(_)) if request => ds & 0x3F,
                    (Some(_), Some(ss)) => ss & 0x3F,
                    (None, None) if !request => (*self.last.get(&(master, station))?)?,
                    _ => return None,
                };
                (
                    Connection {
                        master,
                        station,
                        lsap,
                    },
                    request,
                    d.data,
                )
            }
        };
        if key.lsap > crate::pdu::c2::MAX_CONNECTION_SAP {
            return None;
        }
        if du.is_empty() {
            return self
                .fms
                .contains(&key)
                .then(|| (key, describe(du, request)));
        }
        if starts_lli_pdu(du) {
            self.fms.insert(key);
            Some((key, describe(du, request)))
        } else {
            self.fms.remove(&key);
            None
        }
    }
}

/// The FMS PDU `p` in words, as the sniffer prints it.
fn pdu_text(f: &mut fmt::Formatter<'_>, p: &FmsPdu) -> fmt::Result {
    match p {
        FmsPdu::Request { invoke_id, request } => {
            write!(f, "FMS {}.req invoke {invoke_id}", request.service().name())?;
            match request {
                Request::Status | Request::Identify => Ok(()),
                Request::Read { index, subindex } => {
                    write!(f, " index {index}")?;
                    subindex.map_or(Ok(()), |s| write!(f, " subindex {s}"))
                }
                Request::Write {
                    index,
                    subindex,
                    data,
                } => {
                    write!(f, " index {index}")?;
                    if let Some(s) = subindex {
                        write!(f, " subindex {s}")?;
                    }
                    write!(f, " data {}", hex(data))
                }
                Request::GetOd(g) => write!(
                    f,
                    " index {}{}, {} form",
                    g.index,
                    if g.from_index { " onwards" } else { "" },
                    if g.long_form { "long" } else { "short" }
                ),
            }
        }
        FmsPdu::Response {
            invoke_id,
            response,
        } => {
            write!(
                f,
                "FMS {}.resp invoke {invoke_id}",
                response.service().name()
            )?;
            match response {
                Response::Status(s) => write!(
                    f,
                    ": {}, {} (logical 0x{:02X}, physical 0x{:02X}, detail {})",
                    s.logical_text(),
                    s.physical_text(),
                    s.logical,
                    s.physical,
                    hex(&s.local_detail)
                ),
                Response::Identify(i) => write!(
                    f,
                    ": vendor \"{}\" model \"{}\" revision \"{}\"",
                    i.vendor, i.model, i.revision
                ),
                Response::Read(d) => write!(f, " data {}", hex(d)),
                Response::Write => Ok(()),
                Response::GetOd {
                    more_follows,
                    descriptions,
                } => {
                    let n = descriptions.len();
                    write!(
                        f,
                        ": {n} description{}{}",
                        if n == 1 { "" } else { "s" },
                        if *more_follows { ", more follow" } else { "" }
                    )
                }
            }
        }
        FmsPdu::Error {
            invoke_id,
            service,
            error,
        } => write!(
            f,
            "FMS Error invoke {invoke_id} ({}) class {} code {} additional {}: {}",
            service.name(),
            error.class,
            error.code,
            error.additional,
            error.meaning()
        ),
        FmsPdu::InformationReport { index, data } => {
            write!(f, "FMS Information-Report index {index} data {}", hex(data))
        }
        FmsPdu::Reject {
            original_invoke_id,
            pdu_type,
            code,
        } => write!(
            f,
            "FMS Reject invoke {original_invoke_id} (PDU type {pdu_type}) code {code}"
        ),
        FmsPdu::InitiateRequest(i) => write!(
            f,
            "FMS Initiate.req OD version {}, profile {}, max PDU send {}/{} receive {}/{}, \
             features {}",
            i.version_od,
            hex(&i.profile),
            i.max_pdu_send_high,
            i.max_pdu_send_low,
            i.max_pdu_recv_high,
            i.max_pdu_recv_low,
            hex(&i.features)
        ),
        FmsPdu::InitiateResponse(i) => write!(
            f,
            "FMS Initiate.resp OD version {}, profile {}",
            i.version_od,
            hex(&i.profile)
        ),
        FmsPdu::InitiateError { code } => write!(f, "FMS Initiate error code {code}"),
    }
}

impl fmt::Display for FmsTelegram {
    /// One line: `FMS Read.req invoke 3 index 2022`, `LLI Associate
    /// (monitoring 500 ms): FMS Initiate.req …`, `LLI Abort reason 1: …`,
    /// `FMS malformed: …`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.parsed {
            Parsed::Empty { request: true } => f.write_str("LLI poll"),
            Parsed::Empty { request: false } => f.write_str("LLI no data"),
            Parsed::Malformed(e) => write!(f, "FMS malformed: {e}"),
            Parsed::Pdu(LliPdu::Associate {
                monitoring,
                initiate,
            }) => {
                match monitoring {
                    Some(m) => write!(f, "LLI Associate (monitoring {} ms): ", m.as_millis())?,
                    None => f.write_str("LLI Associate (no monitoring): ")?,
                }
                pdu_text(f, &FmsPdu::InitiateRequest(*initiate))
            }
            Parsed::Pdu(LliPdu::Associated(r)) => {
                f.write_str("LLI Associate.resp: ")?;
                match r {
                    Ok(r) => pdu_text(f, &FmsPdu::InitiateResponse(*r)),
                    Err(code) => pdu_text(f, &FmsPdu::InitiateError { code: *code }),
                }
            }
            Parsed::Pdu(LliPdu::Abort { reason, detail }) => write!(
                f,
                "LLI Abort reason {reason} detail {detail}: {}",
                lli::abort_reason(*reason)
            ),
            Parsed::Pdu(LliPdu::Idle) => f.write_str("LLI Idle"),
            Parsed::Pdu(LliPdu::Data(p)) => pdu_text(f, p),
        }
    }
}

#[cfg(test)]
mod tests;
