//! An FMS client as the application of an FDL active station: one
//! [`LliClient`] connection to one server, driven by the token (SRD
//! low priority, like class-2 services), and a run of confirmed requests
//! over it ([`FmsRun`]: connect, each request in turn, release) —
//! `dpctl fms`.

use core::time::Duration;

use super::lli::{abort_reason, ClientEvent, LliClient, ABORT_REFUSED, ABORT_TIMEOUT};
use super::od::Description;
use super::pdu::{
    reject_code_text, GetOdRequest, InitiateRequest, Request, Response, ServiceError, MAX_PDU_LEN,
};
use profibus_fdl::station::active::{
    CycleResult, MasterApp, Outcome, Request as FdlRequest, Service, TokenContext,
};
use profibus_fdl::{Instant, ResponseStatus};

/// The LSAP `dpctl fms` sends from (unverified choice: any LSAP the
/// server's KBL accepts; the BK3000's accepts any).
pub const CLIENT_LSAP: u8 = 33;

/// The Initiate a client sends: no access protection, PDUs up to the
/// FDL limit, the five services of [`Request`] as client.
pub fn default_initiate() -> InitiateRequest {
    let max = MAX_PDU_LEN.min(241) as u8;
    InitiateRequest {
        version_od: 0,
        profile: [0, 0],
        access_protection: false,
        password: 0,
        access_groups: 0,
        max_pdu_send_high: 0,
        max_pdu_send_low: max,
        max_pdu_recv_high: 0,
        max_pdu_recv_low: max,
        features: [0; 6],
    }
}

/// What went wrong below the LLI: the FDL answer to one of the
/// connection's SRD requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FdlFailure {
    /// No valid reply after the FDL's retries: no station at the address
    /// (or another baud rate).
    NoAnswer,
    /// A negative acknowledge (RS: the LSAP is not activated, RR, UE):
    /// the station is there but serves no FMS relationship on that LSAP.
    Refused(ResponseStatus),
}

/// The FDL master application of one FMS client connection.
#[derive(Debug)]
pub struct FmsMaster {
    lli: LliClient,
    buf: Vec<u8>,
    inflight: bool,
    fdl_failure: Option<FdlFailure>,
}

impl FmsMaster {
    /// A client for `server`'s relationship on `server_lsap`.
    pub fn new(server: u8, server_lsap: u8, monitoring: Option<Duration>) -> FmsMaster {
        FmsMaster {
            lli: LliClient::new(server, server_lsap, CLIENT_LSAP, monitoring),
            buf: Vec::new(),
            inflight: false,
            fdl_failure: None,
        }
    }

    /// The first FDL failure since the last call, if any.
    pub fn take_fdl_failure(&mut self) -> Option<FdlFailure> {
        self.fdl_failure.take()
    }

    /// The connection.
    pub fn lli(&mut self) -> &mut LliClient {
        &mut self.lli
    }
}

impl MasterApp for FmsMaster {
    fn poll_request(&mut self, ctx: &TokenContext) -> Option<FdlRequest<'_>> {
        self.lli.handle_timeout(ctx.now);
        if ctx.high_only || ctx.cycles > 0 {
            return None;
        }
        self.buf = self.lli.next_srd(ctx.now)?;
        self.inflight = true;
        Some(FdlRequest {
            da: self.lli.server,
            service: Service::SrdLow,
            dsap: Some(self.lli.server_lsap),
            ssap: Some(self.lli.lsap),
            data: &self.buf,
            max_reply_len: None,
        })
    }

    fn on_result(&mut self, now: Instant, r: &CycleResult<'_>) {
        if !core::mem::take(&mut self.inflight) {
            return;
        }
        match r.outcome {
            Outcome::Response {
                status: ResponseStatus::Dl | ResponseStatus::Dh,
                data,
                ..
            } => self.lli.on_reply(now, Some(data)),
            Outcome::ShortAck => self.lli.on_reply(now, None),
            Outcome::Response { status, .. } if status.is_negative() => {
                self.fdl_failure.get_or_insert(FdlFailure::Refused(status));
            }
            Outcome::NoResponse => {
                self.fdl_failure.get_or_insert(FdlFailure::NoAnswer);
            }
            // Anything else (NR, a reply without data): as no data.
            Outcome::Response { .. } => self.lli.on_reply(now, None),
            Outcome::Sent => {}
        }
    }
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FmsRunError {
    /// The server refused the Initiate.
    #[error("the FMS server refused the connection (Initiate-Error code {0})")]
    Refused(u8),
    /// The server did not answer in time.
    #[error("the FMS server did not answer within the connection monitoring time")]
    Timeout,
    /// The connection was aborted.
    #[error(
        "the FMS connection was aborted by the {}: {} (reason {reason})",
        if *.locally { "client" } else { "server" },
        abort_reason(*.reason)
    )]
    Aborted {
        /// Reason code.
        reason: u8,
        /// Whether this side aborted.
        locally: bool,
    },
    /// The server rejected a request.
    #[error("the FMS server rejected the request: {words} (reject code {code})", words = reject_code_text(*.0), code = .0)]
    Rejected(u8),
    /// The station did not answer an SRD of the connection at all.
    #[error("no answer from the station (no FDL reply after the retries: nothing at that address, or another baud rate)")]
    NoAnswer,
    /// The station answered with a negative acknowledge: it has no FMS
    /// relationship on the LSAP.
    #[error("the station answered {} ({}): it serves no FMS connection on LSAP {lsap}", .status.mnemonic(), status_words(*.status))]
    NotServer {
        /// The FDL answer (RS, RR, UE).
        status: ResponseStatus,
        /// The server LSAP asked for.
        lsap: u8,
    },
}

fn status_words(s: ResponseStatus) -> &'static str {
    match s {
        ResponseStatus::Rs => "SAP not activated",
        ResponseStatus::Rr => "no resources",
        ResponseStatus::Ue => "user error",
        _ => "negative acknowledge",
    }
}

/// An Information-Report the server sent during a run (unconfirmed: the
/// server publishes an object's value).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InformationReport {
    /// Object index.
    pub index: u16,
    /// The value.
    pub data: Vec<u8>,
}

/// `information report: index 2020: 00 CB 03`.
impl core::fmt::Display for InformationReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "information report: index {}: ", self.index)?;
        let hex: Vec<String> = self.data.iter().map(|b| format!("{b:02X}")).collect();
        f.write_str(&hex.join(" "))
    }
}

/// Information-Reports kept at most per run (the oldest go first).
const MAX_REPORTS: usize = 1000;

/// A run of confirmed requests on one connection: connect, each request
/// after the previous one's confirmation, then release. A Get-OD "from
/// index on" whose response says more follow is asked again from the
/// index after its last description until none follow; the pages make one
/// result.
#[derive(Debug)]
pub struct FmsRun {
    requests: Vec<Request>,
    next: usize,
    started: bool,
    /// The next page of a Get-OD, to ask before the next request.
    follow: Option<Request>,
    /// Whether the last result is a Get-OD whose pages are still coming.
    paging: bool,
    /// The confirmations so far, in request order.
    pub results: Vec<(Request, Result<Response, ServiceError>)>,
    /// Why the run failed, if it did.
    pub error: Option<FmsRunError>,
    /// Information-Reports received while the run waited, in order
    /// (at most the last 1000).
    pub reports: Vec<InformationReport>,
    done: bool,
}

impl FmsRun {
    /// A run of `requests`.
    pub fn new(requests: Vec<Request>) -> FmsRun {
        FmsRun {
            requests,
            next: 0,
            started: false,
            follow: None,
            paging: false,
            results: Vec::new(),
            error: None,
            reports: Vec::new(),
            done: false,
        }
    }

    /// Whether the run ended.
    pub fn is_done(&self) -> bool {
        self.done
    }

    /// A confirmation of the request sent last.
    fn confirmed(&mut self, result: Result<Response, ServiceError>) {
        let Some(req) = self.requests.get(self.next).cloned() else {
            return;
        };
        let mut follow = None;
        if let (
            Request::GetOd(g),
            Ok(Response::GetOd {
                more_follows: true,
                descriptions,
            }),
        ) = (&req, &result)
        {
            // The next page starts after the last index this one had
            // (only forward: a server that repeats itself ends the run).
            let last = descriptions
                .last()
                .and_then(|d| Description::parse(d).ok())
                .map(|d| d.index);
            if let Some(last) = last.filter(|l| g.from_index && *l >= g.index && *l < u16::MAX) {
                follow = Some(Request::GetOd(GetOdRequest {
                    index: last + 1,
                    ..*g
                }));
            }
        }
        if self.paging {
            // A further page: into the result of the first one. A page
            // that fails leaves the pages so far, still saying more follow.
            if let (
                Some((
                    _,
                    Ok(Response::GetOd {
                        more_follows,
                        descriptions,
                    }),
                )),
                Ok(Response::GetOd {
                    descriptions: page, ..
                }),
            ) = (self.results.last_mut(), result)
            {
                *more_follows = follow.is_some();
                descriptions.extend(page);
            }
        } else {
            let mut result = result;
            if let Ok(Response::GetOd { more_follows, .. }) = &mut result {
                *more_follows &= follow.is_some();
            }
            self.results.push((req, result));
        }
        self.paging = follow.is_some();
        match follow {
            Some(f) => self.follow = Some(f),
            None => self.next += 1,
        }
    }

    /// Advances the run (call after every step of the station).
    pub fn tick(&mut self, m: &mut FmsMaster, now: Instant) {
        if self.done {
            return;
        }
        let failure = m.take_fdl_failure();
        let lli = m.lli();
        if !self.started {
            self.started = true;
            lli.connect(now, default_initiate());
            return;
        }
        if let Some(f) = failure {
            // The FDL already retried: the station is not there, or it
            // has no FMS on the LSAP. Nothing to release.
            self.error = Some(match f {
                FdlFailure::NoAnswer => FmsRunError::NoAnswer,
                FdlFailure::Refused(status) => FmsRunError::NotServer {
                    status,
                    lsap: lli.server_lsap,
                },
            });
            self.done = true;
            return;
        }
        lli.handle_timeout(now);
        for ev in lli.take_events() {
            match ev {
                ClientEvent::Connected(_) => {}
                ClientEvent::InformationReport { index, data } => {
                    if self.reports.len() >= MAX_REPORTS {
                        self.reports.remove(0);
                    }
                    self.reports.push(InformationReport { index, data });
                }
                ClientEvent::Refused(code) => {
                    self.error = Some(FmsRunError::Refused(code));
                    self.done = true;
                }
                ClientEvent::Confirmation { result, .. } => self.confirmed(result),
                ClientEvent::Rejected { code, .. } => {
                    self.error = Some(FmsRunError::Rejected(code));
                    lli.release();
                    self.done = true;
                }
                ClientEvent::Aborted { reason, locally } => {
                    if !self.done {
                        self.error = Some(match (reason, locally) {
                            (ABORT_TIMEOUT, true) => FmsRunError::Timeout,
                            (ABORT_REFUSED, _) => FmsRunError::Refused(0),
                            _ => FmsRunError::Aborted { reason, locally },
                        });
                        self.done = true;
                    }
                }
            }
        }
        if self.done || !lli.is_open() || lli.is_busy() {
            return;
        }
        match self
            .follow
            .take()
            .or_else(|| self.requests.get(self.next).cloned())
        {
            Some(req) => {
                lli.request(req);
            }
            None => {
                lli.release();
                self.done = true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::lli::{FmsApplication, LliServer, RelationshipType};
    use super::super::od::Description;
    use super::super::pdu::InitiateResponse;
    use super::*;
    use core::time::Duration;

    /// A server whose OD holds objects 10..=16, two descriptions a page.
    struct Paged;

    impl FmsApplication for Paged {
        fn initiate(&mut self, _: &InitiateRequest) -> Result<InitiateResponse, u8> {
            Ok(InitiateResponse {
                version_od: 1,
                profile: [0, 0],
                access_protection: false,
                password: 0,
                access_groups: 0,
            })
        }
        fn confirmed(&mut self, _: Instant, req: &Request) -> Result<Response, ServiceError> {
            let Request::GetOd(g) = req else {
                return Err(ServiceError::new(6, 7));
            };
            let first = g.index.max(10);
            let descriptions: Vec<Vec<u8>> = (first..=16)
                .take(2)
                .map(|index| {
                    Description {
                        index,
                        code: 7,
                        data_type: 5,
                        length: 1,
                        access: 1,
                        name: None,
                    }
                    .encode()
                })
                .collect();
            Ok(Response::GetOd {
                more_follows: first + 2 <= 16,
                descriptions,
            })
        }
    }

    #[test]
    fn information_reports_received_while_waiting_are_kept_in_order() {
        use super::super::lli::LliPdu;
        use super::super::pdu::FmsPdu;
        let mut m = FmsMaster::new(5, 40, Some(Duration::from_millis(500)));
        let mut s = LliServer::new(40, RelationshipType::Msaz, None);
        let mut run = FmsRun::new(vec![Request::Identify, Request::Status]);
        let mut t = Instant::ZERO;
        let mut reported = 0;
        // The server's answer held back while a report goes first.
        let mut held: Option<Option<Vec<u8>>> = None;
        for _ in 0..50 {
            run.tick(&mut m, t);
            let lli = m.lli();
            if let Some(du) = lli.next_srd(t) {
                let reply = match held.take() {
                    // The client polls for its confirmation.
                    Some(r) => r,
                    None => {
                        let r = s.on_srd(t, 3, CLIENT_LSAP, &du, &mut Paged);
                        if lli.is_open() && reported < 2 {
                            // A report comes before each answer.
                            reported += 1;
                            held = Some(r);
                            LliPdu::Data(FmsPdu::InformationReport {
                                index: 2019 + reported,
                                data: vec![0, reported as u8],
                            })
                            .to_vec()
                        } else {
                            r
                        }
                    }
                };
                lli.on_reply(t, reply.as_deref());
            }
            t += Duration::from_millis(1);
            if run.is_done() {
                break;
            }
        }
        assert!(run.is_done(), "{run:?}");
        assert_eq!(run.results.len(), 2, "the answers still count: {run:?}");
        let got: Vec<String> = run.reports.iter().map(|r| r.to_string()).collect();
        assert_eq!(
            got,
            [
                "information report: index 2020: 00 01",
                "information report: index 2021: 00 02"
            ]
        );
    }

    #[test]
    fn a_get_od_from_an_index_collects_every_page_into_one_result() {
        let mut m = FmsMaster::new(5, 40, Some(Duration::from_millis(500)));
        let mut s = LliServer::new(40, RelationshipType::Msaz, None);
        let mut run = FmsRun::new(vec![
            Request::GetOd(GetOdRequest {
                long_form: false,
                from_index: true,
                index: 1,
            }),
            Request::Identify,
        ]);
        let mut t = Instant::ZERO;
        for _ in 0..50 {
            run.tick(&mut m, t);
            let lli = m.lli();
            if let Some(du) = lli.next_srd(t) {
                let reply = s.on_srd(t, 3, CLIENT_LSAP, &du, &mut Paged);
                lli.on_reply(t, reply.as_deref());
            }
            t += Duration::from_millis(1);
            if run.is_done() {
                break;
            }
        }
        assert!(run.is_done() && run.error.is_none(), "{run:?}");
        assert_eq!(run.results.len(), 2, "{run:?}");
        let Ok(Response::GetOd {
            more_follows,
            descriptions,
        }) = &run.results[0].1
        else {
            panic!("{run:?}")
        };
        let idx: Vec<u16> = descriptions
            .iter()
            .map(|d| Description::parse(d).unwrap().index)
            .collect();
        assert_eq!(idx, [10, 11, 12, 13, 14, 15, 16]);
        assert!(!more_follows);
        assert!(run.results[1].1.is_err(), "Identify: the server's error");
    }
}
