//! The Lower Layer Interface (LLI) of FMS on master-slave connections,
//! sans-IO: a client (the master, FMS client) and a server (the slave,
//! FMS server) on one communication relationship (an entry of the
//! communication relationship list, KBL/CRL).
//!
//! What the sources say (\[P5\] p.292, the BK3000 manual pp. 61, 66):
//! - FMS services map onto LLI services: Initiate onto Associate (the
//!   Initiate PDU is the Associate's data), Abort onto the LLI's Abort
//!   (no FMS PDU is generated), confirmed services onto
//!   DataTransferConfirmed, unconfirmed ones onto DataTransferUnconfirmed
//!   or …Acknowledged.
//! - A relationship has a local and a remote LSAP (the FDL service access
//!   points of the KBL), a type — MSAZ master-slave acyclic, MSZY
//!   master-slave cyclic — and connection monitoring whose interval the
//!   master chooses when it connects; the slave adapts (BK3000 p.61).
//!
//! How it rides on FDL here: the client sends each LLI PDU as an SRD
//! request from its LSAP to the server's LSAP; the server answers in the
//! SRD response with the LLI PDU it has ready (this server answers a
//! confirmed request in the response to that very SRD), or with no data;
//! a client with an outstanding request and no answer yet polls with
//! empty SRDs. An idle connection is kept alive by Idle PDUs within the
//! monitoring interval; a server that hears nothing from its client for
//! the interval aborts the connection, a client that gets no answer for
//! the interval aborts too.
//!
//! (unverified): the LLI PDU octets ([`LliPdu`]: Associate, Abort, Idle
//! headers and the monitoring interval's encoding in 10 ms units), and
//! that the monitoring interval rides in the Associate PDU. Only the
//! structure above is from the sources.

use core::time::Duration;

use super::pdu::{
    FmsParseError, FmsPdu, InitiateRequest, InitiateResponse, Request, Response, ServiceError,
    MAX_PDU_LEN, REJECT_OTHER,
};
use profibus_fdl::time::Instant;

/// LLI PDU type: Associate request (unverified value).
pub const LLI_ASSOCIATE_REQ: u8 = 0x10;
/// LLI PDU type: Associate response (unverified value).
pub const LLI_ASSOCIATE_RES: u8 = 0x11;
/// LLI PDU type: Abort (unverified value).
pub const LLI_ABORT: u8 = 0x12;
/// LLI PDU type: Idle, keeps a monitored connection alive (unverified).
pub const LLI_IDLE: u8 = 0x13;

/// Abort reason: the peer was silent for the monitoring interval.
pub const ABORT_TIMEOUT: u8 = 1;
/// Abort reason: the user released the connection.
pub const ABORT_USER: u8 = 0;
/// Abort reason: a PDU that this state does not allow.
pub const ABORT_PROTOCOL: u8 = 2;
/// Abort reason: the server refused the Initiate.
pub const ABORT_REFUSED: u8 = 3;

/// An Abort reason code in words (the codes above; unverified values).
pub fn abort_reason(reason: u8) -> &'static str {
    match reason {
        ABORT_USER => "released by the user",
        ABORT_TIMEOUT => "connection monitoring: the peer fell silent",
        ABORT_PROTOCOL => "protocol error",
        ABORT_REFUSED => "Initiate refused",
        _ => "unknown reason",
    }
}

/// The type of a communication relationship (KBL "type" column).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RelationshipType {
    /// Master-slave, acyclic (MSAZ): requests on demand.
    Msaz,
    /// Master-slave, cyclic (MSZY): the master polls cyclically.
    Mszy,
}

/// An LLI PDU: an FMS PDU as data, or one of the LLI's own PDUs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LliPdu {
    /// Associate.req: the monitoring interval the master chooses
    /// (`None`: no monitoring) and the Initiate-Request.
    Associate {
        /// Connection monitoring interval.
        monitoring: Option<Duration>,
        /// The FMS Initiate-Request.
        initiate: InitiateRequest,
    },
    /// Associate.res: the Initiate-Response, or the Initiate-Error code.
    Associated(Result<InitiateResponse, u8>),
    /// Abort: the connection is gone.
    Abort {
        /// Reason ([`ABORT_TIMEOUT`], …).
        reason: u8,
        /// Detail (vendor-specific).
        detail: u8,
    },
    /// Idle: nothing to say, the connection lives.
    Idle,
    /// Data: an FMS PDU (confirmed or unconfirmed service, reject).
    Data(FmsPdu),
}

/// An LLI PDU that cannot be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LliParseError {
    /// The PDU is too short.
    #[error("LLI PDU 0x{kind:02X} is {got} bytes long, needs {needed}")]
    Length {
        /// Type octet.
        kind: u8,
        /// Bytes needed.
        needed: usize,
        /// Bytes present.
        got: usize,
    },
    /// The FMS PDU inside does not decode.
    #[error(transparent)]
    Fms(#[from] FmsParseError),
    /// An Associate PDU whose FMS part is no Initiate.
    #[error("LLI Associate carries {0}, not an Initiate")]
    NotInitiate(&'static str),
}

impl LliPdu {
    /// Decodes the data unit of an SRD telegram of an FMS connection.
    pub fn parse(du: &[u8]) -> Result<LliPdu, LliParseError> {
        let Some(&kind) = du.first() else {
            return Err(FmsParseError::Empty.into());
        };
        let need = |n: usize| {
            if du.len() < n {
                Err(LliParseError::Length {
                    kind,
                    needed: n,
                    got: du.len(),
                })
            } else {
                Ok(())
            }
        };
        match kind {
            LLI_ASSOCIATE_REQ => {
                need(3)?;
                let units = u16::from_be_bytes([du[1], du[2]]);
                match FmsPdu::parse(&du[3..])? {
                    FmsPdu::InitiateRequest(initiate) => Ok(LliPdu::Associate {
                        monitoring: (units != 0)
                            .then(|| Duration::from_millis(u64::from(units) * 10)),
                        initiate,
                    }),
                    other => Err(LliParseError::NotInitiate(other.pdu_type().name())),
                }
            }
            LLI_ASSOCIATE_RES => match FmsPdu::parse(&du[1..])? {
                FmsPdu::InitiateResponse(r) => Ok(LliPdu::Associated(Ok(r))),
                FmsPdu::InitiateError { code } => Ok(LliPdu::Associated(Err(code))),
                other => Err(LliParseError::NotInitiate(other.pdu_type().name())),
            },
            LLI_ABORT => {
                need(3)?;
                if du.len() > 3 {
                    return Err(FmsParseError::Trailing {
                        what: "LLI Abort",
                        extra: du.len() - 3,
                    }
                    .into());
                }
                Ok(LliPdu::Abort {
                    reason: du[1],
                    detail: du[2],
                })
            }
            LLI_IDLE if du.len() == 1 => Ok(LliPdu::Idle),
            LLI_IDLE => Err(FmsParseError::Trailing {
                what: "LLI Idle",
                extra: du.len() - 1,
            }
            .into()),
            _ => Ok(LliPdu::Data(FmsPdu::parse(du)?)),
        }
    }

    /// The encoding, or `None` when longer than an FDL data unit.
    pub fn to_vec(&self) -> Option<Vec<u8>> {
        let v = match self {
            LliPdu::Associate {
                monitoring,
                initiate,
            } => {
                let units = monitoring.map_or(0, |d| {
                    u16::try_from(d.as_millis().div_ceil(10))
                        .unwrap_or(u16::MAX)
                        .max(1)
                });
                let mut v = vec![LLI_ASSOCIATE_REQ];
                v.extend(units.to_be_bytes());
                v.extend(FmsPdu::InitiateRequest(*initiate).to_vec()?);
                v
            }
            LliPdu::Associated(r) => {
                let mut v = vec![LLI_ASSOCIATE_RES];
                v.extend(
                    match r {
                        Ok(r) => FmsPdu::InitiateResponse(*r),
                        Err(code) => FmsPdu::InitiateError { code: *code },
                    }
                    .to_vec()?,
                );
                v
            }
            LliPdu::Abort { reason, detail } => vec![LLI_ABORT, *reason, *detail],
            LliPdu::Idle => vec![LLI_IDLE],
            LliPdu::Data(p) => p.to_vec()?,
        };
        (v.len() <= MAX_PDU_LEN).then_some(v)
    }
}

/// What a server does with FMS requests: the application (an object
/// dictionary). Errors become Confirmed-ErrorPDUs.
pub trait FmsApplication {
    /// Answers the Initiate of a client (`Err(code)` refuses it).
    fn initiate(&mut self, req: &InitiateRequest) -> Result<InitiateResponse, u8>;
    /// Executes one confirmed service.
    fn confirmed(&mut self, now: Instant, req: &Request) -> Result<Response, ServiceError>;
}

/// Something the server tells its user.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ServerEvent {
    /// A client connected.
    Connected {
        /// Its station address.
        client: u8,
        /// The monitoring interval it chose.
        monitoring: Option<Duration>,
    },
    /// The connection ended.
    Aborted {
        /// Reason ([`ABORT_TIMEOUT`] when the client fell silent).
        reason: u8,
        /// Whether this side ended it.
        locally: bool,
    },
}

/// One FMS server relationship (one KBL entry of a slave).
#[derive(Debug)]
pub struct LliServer {
    /// The server's LSAP (the DSAP clients address).
    pub lsap: u8,
    /// Relationship type.
    pub kind: RelationshipType,
    /// The remote LSAP the KBL allows (`None`: any).
    pub remote_lsap: Option<u8>,
    open: Option<Open>,
    events: Vec<ServerEvent>,
}

#[derive(Debug, Clone, Copy)]
struct Open {
    client: u8,
    client_lsap: u8,
    monitoring: Option<Duration>,
    last_heard: Instant,
}

impl LliServer {
    /// A closed relationship on `lsap`.
    pub fn new(lsap: u8, kind: RelationshipType, remote_lsap: Option<u8>) -> LliServer {
        LliServer {
            lsap,
            kind,
            remote_lsap,
            open: None,
            events: Vec::new(),
        }
    }

    /// The connected client's address, if any.
    pub fn client(&self) -> Option<u8> {
        self.open.map(|o| o.client)
    }

    /// An SRD request to this relationship's LSAP: `from` station, its
    /// `ssap`, the data unit. Returns the data unit of the SRD response
    /// (`None`: answer without data).
    pub fn on_srd(
        &mut self,
        now: Instant,
        from: u8,
        ssap: u8,
        du: &[u8],
        app: &mut dyn FmsApplication,
    ) -> Option<Vec<u8>> {
        if self.remote_lsap.is_some_and(|r| r != ssap) {
            return None;
        }
        let pdu = if du.is_empty() {
            None
        } else {
            match LliPdu::parse(du) {
                Ok(p) => Some(p),
                Err(_) if self.is_peer(from, ssap) => {
                    // An undecodable PDU on a live connection: reject it
                    // (the invoke ID is unknown, 0) and keep the connection.
                    if let Some(o) = &mut self.open {
                        o.last_heard = now;
                    }
                    return LliPdu::Data(FmsPdu::Reject {
                        original_invoke_id: 0,
                        pdu_type: du[0],
                        code: REJECT_OTHER,
                    })
                    .to_vec();
                }
                Err(_) => return None,
            }
        };
        match pdu {
            Some(LliPdu::Associate {
                monitoring,
                initiate,
            }) => {
                if self.open.is_some() {
                    self.close(ABORT_PROTOCOL, true);
                }
                let answer = app.initiate(&initiate);
                if answer.is_ok() {
                    self.open = Some(Open {
                        client: from,
                        client_lsap: ssap,
                        monitoring,
                        last_heard: now,
                    });
                    self.events.push(ServerEvent::Connected {
                        client: from,
                        monitoring,
                    });
                }
                LliPdu::Associated(answer).to_vec()
            }
            _ if !self.is_peer(from, ssap) => {
                // Not connected to this station: tell it so.
                LliPdu::Abort {
                    reason: ABORT_PROTOCOL,
                    detail: 0,
                }
                .to_vec()
            }
            other => {
                if let Some(o) = &mut self.open {
                    o.last_heard = now;
                }
                match other {
                    None | Some(LliPdu::Idle) => None,
                    Some(LliPdu::Abort { reason, .. }) => {
                        self.close(reason, false);
                        None
                    }
                    Some(LliPdu::Data(FmsPdu::Request { invoke_id, request })) => {
                        let pdu = match app.confirmed(now, &request) {
                            Ok(response) => FmsPdu::Response {
                                invoke_id,
                                response,
                            },
                            Err(error) => FmsPdu::Error {
                                invoke_id,
                                service: request.service(),
                                error,
                            },
                        };
                        // A response too long for one telegram: an error.
                        LliPdu::Data(pdu).to_vec().or_else(|| {
                            LliPdu::Data(FmsPdu::Error {
                                invoke_id,
                                service: request.service(),
                                error: ServiceError::new(
                                    super::pdu::ERROR_CLASS_ACCESS,
                                    super::pdu::ACCESS_TYPE_CONFLICT,
                                ),
                            })
                            .to_vec()
                        })
                    }
                    Some(LliPdu::Data(other)) => LliPdu::Data(FmsPdu::Reject {
                        original_invoke_id: other.invoke_id().unwrap_or(0),
                        pdu_type: other.pdu_type() as u8,
                        code: REJECT_OTHER,
                    })
                    .to_vec(),
                    Some(LliPdu::Associated(_)) | Some(LliPdu::Associate { .. }) => {
                        self.close(ABORT_PROTOCOL, true);
                        LliPdu::Abort {
                            reason: ABORT_PROTOCOL,
                            detail: 0,
                        }
                        .to_vec()
                    }
                }
            }
        }
    }

    fn is_peer(&self, from: u8, ssap: u8) -> bool {
        self.open
            .is_some_and(|o| o.client == from && o.client_lsap == ssap)
    }

    fn close(&mut self, reason: u8, locally: bool) {
        if self.open.take().is_some() {
            self.events.push(ServerEvent::Aborted { reason, locally });
        }
    }

    /// When connection monitoring next needs [`LliServer::handle_timeout`].
    pub fn poll_timeout(&self) -> Option<Instant> {
        let o = self.open?;
        Some(o.last_heard + o.monitoring?)
    }

    /// Connection monitoring: a client silent for its interval is
    /// aborted.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.poll_timeout().is_some_and(|t| t <= now) {
            self.close(ABORT_TIMEOUT, true);
        }
    }

    /// The events since the last call.
    pub fn take_events(&mut self) -> Vec<ServerEvent> {
        core::mem::take(&mut self.events)
    }
}

/// Something the client tells its user.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ClientEvent {
    /// The server accepted the Initiate.
    Connected(InitiateResponse),
    /// The server refused the Initiate (Initiate-Error code).
    Refused(u8),
    /// A confirmed service ended.
    Confirmation {
        /// Its invoke ID.
        invoke_id: u8,
        /// The response or the server's error.
        result: Result<Response, ServiceError>,
    },
    /// The server rejected a PDU.
    Rejected {
        /// Invoke ID of the rejected PDU.
        invoke_id: u8,
        /// Reject code.
        code: u8,
    },
    /// The server published an object.
    InformationReport {
        /// Object index.
        index: u16,
        /// Value.
        data: Vec<u8>,
    },
    /// The connection ended.
    Aborted {
        /// Reason.
        reason: u8,
        /// Whether this side ended it.
        locally: bool,
    },
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum ClientState {
    Closed,
    Connecting,
    Open,
}

/// The client (master) end of one FMS relationship.
#[derive(Debug)]
pub struct LliClient {
    /// The server's station address.
    pub server: u8,
    /// The server's LSAP.
    pub server_lsap: u8,
    /// This client's LSAP.
    pub lsap: u8,
    monitoring: Option<Duration>,
    state: ClientState,
    /// PDUs to send, oldest first.
    queue: Vec<LliPdu>,
    /// Invoke ID of the outstanding confirmed request, if any.
    outstanding: Option<u8>,
    next_invoke: u8,
    last_answer: Instant,
    last_sent: Instant,
    events: Vec<ClientEvent>,
}

impl LliClient {
    /// A closed client for `server`'s relationship on `server_lsap`, from
    /// `lsap`, with connection monitoring `monitoring`.
    pub fn new(server: u8, server_lsap: u8, lsap: u8, monitoring: Option<Duration>) -> LliClient {
        LliClient {
            server,
            server_lsap,
            lsap,
            monitoring,
            state: ClientState::Closed,
            queue: Vec::new(),
            outstanding: None,
            next_invoke: 1,
            last_answer: Instant::ZERO,
            last_sent: Instant::ZERO,
            events: Vec::new(),
        }
    }

    /// Whether the connection is open.
    pub fn is_open(&self) -> bool {
        self.state == ClientState::Open
    }

    /// Whether PDUs wait to be sent (a release's Abort, …).
    pub fn has_queued(&self) -> bool {
        !self.queue.is_empty()
    }

    /// Whether a confirmed request or the Initiate waits for its answer.
    pub fn is_busy(&self) -> bool {
        self.outstanding.is_some() || self.state == ClientState::Connecting
    }

    /// Connects (Associate with Initiate).
    pub fn connect(&mut self, now: Instant, initiate: InitiateRequest) {
        self.state = ClientState::Connecting;
        self.last_answer = now;
        self.queue.clear();
        self.outstanding = None;
        self.queue.push(LliPdu::Associate {
            monitoring: self.monitoring,
            initiate,
        });
    }

    /// Queues a confirmed request; returns its invoke ID, or `None` when
    /// the connection is not open or a request is outstanding (this client
    /// keeps one request outstanding at a time).
    pub fn request(&mut self, request: Request) -> Option<u8> {
        if !self.is_open() || self.outstanding.is_some() {
            return None;
        }
        let invoke_id = self.next_invoke;
        self.next_invoke = self.next_invoke.wrapping_add(1).max(1);
        self.outstanding = Some(invoke_id);
        self.queue
            .push(LliPdu::Data(FmsPdu::Request { invoke_id, request }));
        Some(invoke_id)
    }

    /// Releases the connection (Abort, reason user).
    pub fn release(&mut self) {
        if self.state != ClientState::Closed {
            self.queue.clear();
            self.queue.push(LliPdu::Abort {
                reason: ABORT_USER,
                detail: 0,
            });
            self.end(ABORT_USER, true);
        }
    }

    fn end(&mut self, reason: u8, locally: bool) {
        if self.state != ClientState::Closed {
            self.state = ClientState::Closed;
            self.outstanding = None;
            self.events.push(ClientEvent::Aborted { reason, locally });
        }
    }

    /// The data unit of the next SRD to send to the server, if one is
    /// due: a queued PDU, an empty poll while an answer is outstanding, an
    /// Idle when half the monitoring interval passed without traffic.
    pub fn next_srd(&mut self, now: Instant) -> Option<Vec<u8>> {
        let du = if !self.queue.is_empty() {
            let pdu = self.queue.remove(0);
            pdu.to_vec().unwrap_or_default()
        } else if self.state == ClientState::Closed {
            return None;
        } else if self.is_busy() {
            Vec::new()
        } else if self
            .monitoring
            .is_some_and(|m| now >= self.last_sent + m / 2)
        {
            LliPdu::Idle.to_vec().unwrap_or_default()
        } else {
            return None;
        };
        self.last_sent = now;
        Some(du)
    }

    /// The server's SRD response (`None`: it answered without data) to
    /// the last [`LliClient::next_srd`].
    pub fn on_reply(&mut self, now: Instant, du: Option<&[u8]>) {
        self.last_answer = now;
        let Some(du) = du.filter(|d| !d.is_empty()) else {
            return;
        };
        let pdu = match LliPdu::parse(du) {
            Ok(p) => p,
            Err(_) => {
                self.queue.clear();
                self.queue.push(LliPdu::Abort {
                    reason: ABORT_PROTOCOL,
                    detail: 0,
                });
                self.end(ABORT_PROTOCOL, true);
                return;
            }
        };
        match (self.state.clone(), pdu) {
            (ClientState::Connecting, LliPdu::Associated(Ok(r))) => {
                self.state = ClientState::Open;
                self.events.push(ClientEvent::Connected(r));
            }
            (ClientState::Connecting, LliPdu::Associated(Err(code))) => {
                self.state = ClientState::Closed;
                self.events.push(ClientEvent::Refused(code));
            }
            (_, LliPdu::Abort { reason, .. }) => self.end(reason, false),
            (ClientState::Open, LliPdu::Data(pdu)) => {
                let event = match pdu {
                    FmsPdu::Response {
                        invoke_id,
                        response,
                    } => Some((invoke_id, Ok(response))),
                    FmsPdu::Error {
                        invoke_id, error, ..
                    } => Some((invoke_id, Err(error))),
                    FmsPdu::Reject {
                        original_invoke_id,
                        code,
                        ..
                    } => {
                        if self.outstanding == Some(original_invoke_id) {
                            self.outstanding = None;
                        }
                        self.events.push(ClientEvent::Rejected {
                            invoke_id: original_invoke_id,
                            code,
                        });
                        None
                    }
                    FmsPdu::InformationReport { index, data } => {
                        self.events
                            .push(ClientEvent::InformationReport { index, data });
                        None
                    }
                    _ => {
                        self.end(ABORT_PROTOCOL, true);
                        None
                    }
                };
                if let Some((invoke_id, result)) = event {
                    if self.outstanding == Some(invoke_id) {
                        self.outstanding = None;
                        self.events
                            .push(ClientEvent::Confirmation { invoke_id, result });
                    } else {
                        // A confirmation nobody asked for (\[P5\] p.225,
                        // transition 63: abort).
                        self.queue.push(LliPdu::Abort {
                            reason: ABORT_PROTOCOL,
                            detail: 0,
                        });
                        self.end(ABORT_PROTOCOL, true);
                    }
                }
            }
            (_, LliPdu::Idle) => {}
            _ => self.end(ABORT_PROTOCOL, true),
        }
    }

    /// When the client gives up waiting for its server.
    pub fn poll_timeout(&self) -> Option<Instant> {
        if self.state == ClientState::Closed {
            return None;
        }
        Some(self.last_answer + self.monitoring.unwrap_or(Duration::from_secs(5)))
    }

    /// Connection monitoring: no answer from the server for the interval
    /// (5 s without monitoring) ends the connection.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.poll_timeout().is_some_and(|t| t <= now) {
            self.end(ABORT_TIMEOUT, true);
        }
    }

    /// The events since the last call.
    pub fn take_events(&mut self) -> Vec<ClientEvent> {
        core::mem::take(&mut self.events)
    }
}

#[cfg(test)]
mod tests {
    use super::super::pdu::{GetOdRequest, IdentifyResponse};
    use super::*;

    struct Echo;

    impl FmsApplication for Echo {
        fn initiate(&mut self, req: &InitiateRequest) -> Result<InitiateResponse, u8> {
            if req.password != 0 {
                return Err(1);
            }
            Ok(InitiateResponse {
                version_od: 1,
                profile: [0, 0],
                access_protection: false,
                password: 0,
                access_groups: 0,
            })
        }
        fn confirmed(&mut self, _now: Instant, req: &Request) -> Result<Response, ServiceError> {
            match req {
                Request::Identify => Ok(Response::Identify(IdentifyResponse {
                    vendor: "v".into(),
                    model: "m".into(),
                    revision: "r".into(),
                })),
                Request::Read { index: 7, .. } => Ok(Response::Read(vec![1, 2])),
                _ => Err(ServiceError::new(6, 7)),
            }
        }
    }

    fn initiate() -> InitiateRequest {
        InitiateRequest {
            version_od: 0,
            profile: [0, 0],
            access_protection: false,
            password: 0,
            access_groups: 0,
            max_pdu_send_high: 0,
            max_pdu_send_low: 241,
            max_pdu_recv_high: 0,
            max_pdu_recv_low: 241,
            features: [0; 6],
        }
    }

    fn at(ms: u64) -> Instant {
        Instant::ZERO + Duration::from_millis(ms)
    }

    /// One SRD from the client to the server and back.
    fn exchange(c: &mut LliClient, s: &mut LliServer, now: Instant) -> bool {
        let Some(du) = c.next_srd(now) else {
            return false;
        };
        let reply = s.on_srd(now, 2, c.lsap, &du, &mut Echo);
        c.on_reply(now, reply.as_deref());
        true
    }

    #[test]
    fn a_client_connects_reads_and_gets_errors_in_words() {
        let mut s = LliServer::new(40, RelationshipType::Msaz, None);
        let mut c = LliClient::new(5, 40, 41, Some(Duration::from_millis(500)));
        c.connect(at(0), initiate());
        assert!(exchange(&mut c, &mut s, at(1)));
        assert!(matches!(c.take_events()[..], [ClientEvent::Connected(_)]));
        assert_eq!(
            s.take_events(),
            [ServerEvent::Connected {
                client: 2,
                monitoring: Some(Duration::from_millis(500))
            }]
        );
        let id = c
            .request(Request::Read {
                index: 7,
                subindex: None,
            })
            .unwrap();
        assert_eq!(c.request(Request::Identify), None, "one at a time");
        exchange(&mut c, &mut s, at(2));
        assert_eq!(
            c.take_events(),
            [ClientEvent::Confirmation {
                invoke_id: id,
                result: Ok(Response::Read(vec![1, 2]))
            }]
        );
        let id = c.request(Request::GetOd(GetOdRequest {
            long_form: false,
            from_index: false,
            index: 9,
        }));
        exchange(&mut c, &mut s, at(3));
        assert_eq!(
            c.take_events(),
            [ClientEvent::Confirmation {
                invoke_id: id.unwrap(),
                result: Err(ServiceError::new(6, 7))
            }]
        );
    }

    #[test]
    fn connection_monitoring_aborts_a_silent_client() {
        let mut s = LliServer::new(40, RelationshipType::Msaz, None);
        let mut c = LliClient::new(5, 40, 41, Some(Duration::from_millis(500)));
        c.connect(at(0), initiate());
        exchange(&mut c, &mut s, at(0));
        assert!(matches!(c.take_events()[..], [ClientEvent::Connected(_)]));
        // Idle PDUs keep it alive for far longer than the interval.
        for t in (0..3000).step_by(50) {
            exchange(&mut c, &mut s, at(t));
            s.handle_timeout(at(t));
            c.handle_timeout(at(t));
        }
        assert_eq!(s.client(), Some(2));
        assert!(c.is_open());
        // Then the client falls silent.
        let deadline = s.poll_timeout().unwrap();
        assert!(deadline >= at(2950), "heard within the last interval");
        s.handle_timeout(Instant::from_nanos(deadline.as_nanos() - 1));
        assert_eq!(s.client(), Some(2));
        s.handle_timeout(deadline);
        assert_eq!(s.client(), None);
        let ev = s.take_events();
        assert_eq!(
            ev.last(),
            Some(&ServerEvent::Aborted {
                reason: ABORT_TIMEOUT,
                locally: true
            })
        );
        // The client's next request is told the connection is gone.
        c.request(Request::Identify).unwrap();
        exchange(&mut c, &mut s, deadline + Duration::from_millis(10));
        assert!(!c.is_open());
        assert!(matches!(
            c.take_events()[..],
            [ClientEvent::Aborted { locally: false, .. }]
        ));
    }

    #[test]
    fn a_silent_server_ends_the_clients_connection() {
        let mut c = LliClient::new(5, 40, 41, Some(Duration::from_millis(200)));
        c.connect(at(0), initiate());
        assert!(c.next_srd(at(0)).is_some());
        c.on_reply(at(0), None);
        assert_eq!(c.next_srd(at(10)), Some(vec![]), "polls while waiting");
        c.handle_timeout(at(199));
        assert!(c.is_busy());
        c.handle_timeout(at(200));
        assert_eq!(
            c.take_events(),
            [ClientEvent::Aborted {
                reason: ABORT_TIMEOUT,
                locally: true
            }]
        );
        assert_eq!(c.next_srd(at(300)), None);
    }

    #[test]
    fn a_refused_initiate_and_a_stranger_are_told_so() {
        let mut s = LliServer::new(40, RelationshipType::Msaz, Some(41));
        let mut c = LliClient::new(5, 40, 41, None);
        let mut bad = initiate();
        bad.password = 9;
        c.connect(at(0), bad);
        exchange(&mut c, &mut s, at(0));
        assert_eq!(c.take_events(), [ClientEvent::Refused(1)]);
        // A data PDU from a station that never connected.
        let du = LliPdu::Data(FmsPdu::Request {
            invoke_id: 1,
            request: Request::Identify,
        })
        .to_vec()
        .unwrap();
        let reply = s.on_srd(at(1), 3, 41, &du, &mut Echo).unwrap();
        assert!(matches!(
            LliPdu::parse(&reply),
            Ok(LliPdu::Abort {
                reason: ABORT_PROTOCOL,
                ..
            })
        ));
        // The wrong remote LSAP is not answered at all.
        assert_eq!(s.on_srd(at(1), 3, 50, &du, &mut Echo), None);
    }

    #[test]
    fn lli_pdus_round_trip() {
        for p in [
            LliPdu::Associate {
                monitoring: Some(Duration::from_millis(1000)),
                initiate: initiate(),
            },
            LliPdu::Associate {
                monitoring: None,
                initiate: initiate(),
            },
            LliPdu::Associated(Err(4)),
            LliPdu::Abort {
                reason: 1,
                detail: 2,
            },
            LliPdu::Idle,
        ] {
            let v = p.to_vec().unwrap();
            assert_eq!(LliPdu::parse(&v), Ok(p));
        }
        assert!(LliPdu::parse(&[LLI_ABORT, 1]).is_err());
    }
}
