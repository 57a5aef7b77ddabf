//! An FMS client as the application of an FDL active station: one
//! [`LliClient`] connection to one server, driven by the token (SRD
//! low priority, like class-2 services), and a run of confirmed requests
//! over it ([`FmsRun`]: connect, each request in turn, release) —
//! `dpctl fms`.

use core::time::Duration;

use super::lli::{ClientEvent, LliClient, ABORT_REFUSED, ABORT_TIMEOUT};
use super::pdu::{InitiateRequest, Request, Response, ServiceError, MAX_PDU_LEN};
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

/// The FDL master application of one FMS client connection.
#[derive(Debug)]
pub struct FmsMaster {
    lli: LliClient,
    buf: Vec<u8>,
    inflight: bool,
}

impl FmsMaster {
    /// A client for `server`'s relationship on `server_lsap`.
    pub fn new(server: u8, server_lsap: u8, monitoring: Option<Duration>) -> FmsMaster {
        FmsMaster {
            lli: LliClient::new(server, server_lsap, CLIENT_LSAP, monitoring),
            buf: Vec::new(),
            inflight: false,
        }
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
            // RS, UE, RR: the server's LSAP is not there; no answer:
            // connection monitoring ends the connection in time.
            _ => {}
        }
    }
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FmsRunError {
    /// The server refused the Initiate.
    #[error("the FMS server refused the connection (Initiate error code {0})")]
    Refused(u8),
    /// The server did not answer in time.
    #[error("the FMS server did not answer within the connection monitoring time")]
    Timeout,
    /// The connection was aborted.
    #[error("the FMS connection was aborted (reason {reason}, by the {})", if *.locally { "client" } else { "server" })]
    Aborted {
        /// Reason code.
        reason: u8,
        /// Whether this side aborted.
        locally: bool,
    },
    /// The server rejected a request.
    #[error("the FMS server rejected the request (reject code {0})")]
    Rejected(u8),
}

/// A run of confirmed requests on one connection: connect, each request
/// after the previous one's confirmation, then release.
#[derive(Debug)]
pub struct FmsRun {
    requests: Vec<Request>,
    next: usize,
    started: bool,
    /// The confirmations so far, in request order.
    pub results: Vec<(Request, Result<Response, ServiceError>)>,
    /// Why the run failed, if it did.
    pub error: Option<FmsRunError>,
    done: bool,
}

impl FmsRun {
    /// A run of `requests`.
    pub fn new(requests: Vec<Request>) -> FmsRun {
        FmsRun {
            requests,
            next: 0,
            started: false,
            results: Vec::new(),
            error: None,
            done: false,
        }
    }

    /// Whether the run ended.
    pub fn is_done(&self) -> bool {
        self.done
    }

    /// Advances the run (call after every step of the station).
    pub fn tick(&mut self, m: &mut FmsMaster, now: Instant) {
        if self.done {
            return;
        }
        let lli = m.lli();
        if !self.started {
            self.started = true;
            lli.connect(now, default_initiate());
            return;
        }
        lli.handle_timeout(now);
        for ev in lli.take_events() {
            match ev {
                ClientEvent::Connected(_) | ClientEvent::InformationReport { .. } => {}
                ClientEvent::Refused(code) => {
                    self.error = Some(FmsRunError::Refused(code));
                    self.done = true;
                }
                ClientEvent::Confirmation { result, .. } => {
                    if let Some(req) = self.requests.get(self.next) {
                        self.results.push((req.clone(), result));
                        self.next += 1;
                    }
                }
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
        match self.requests.get(self.next) {
            Some(req) => {
                lli.request(req.clone());
            }
            None => {
                lli.release();
                self.done = true;
            }
        }
    }
}
