//! The class-2 master (DP-V1 MSAC_C2): connections to slaves for acyclic
//! Read, Write and Data_Transport, next to the class-1 master (a PLC)
//! that holds the slaves in Data_Exchange.
//!
//! [`Class2Master`] is the application of an FDL active station
//! ([`MasterApp`]): it joins the token ring as a master of its own and,
//! while it holds the token, runs at most one message cycle per open
//! connection and token visit (low priority: none when the token came
//! late). Sans-IO: the application opens connections and submits requests
//! with the time, [`Class2Master::handle_time`] checks the timeouts, and
//! [`Class2Master::poll_event`] returns what happened.
//!
//! A connection (PDUs in [`crate::pdu::c2`]; wire facts and sources in
//! `shared/reference/dpv1-c2-im-alarms.md` §4.2–4.4):
//!
//! 1. **Initiate**: SRD to the slave's resource manager (DSAP 49) from
//!    SSAP 50 with Initiate.req (Send_Timeout, features, profile,
//!    address parameters). The RM answers with `56 SAP PollTO`, the
//!    connection SAP (0..=48): at once (\[BAL\]), or after a short
//!    acknowledge on an empty poll of SAP 49 (Felser's manual: "a poll
//!    cycle at SAP 49 with response data"); the master polls SAP 49
//!    until it comes and never repeats Initiate.req.
//! 2. The master polls that SAP with empty SRDs until the slave answers
//!    with Initiate.res: the connection is open ([`Class2Event::Opened`]).
//!    A short acknowledge, or a reply without data, means "not ready".
//! 3. **Read / Write / Data_Transport**: the request on the connection
//!    SAP, then empty polls until the answer comes
//!    ([`Class2Event::Answer`]; a negative response is an answer too and
//!    keeps the connection open). One request at a time per connection;
//!    further ones wait in its queue.
//! 4. **Idle**: with nothing to send, the master sends `48 00` once
//!    [`Class2Config::idle_after`] has passed since its last telegram on
//!    the connection, half of Send_Timeout unless set: the slave aborts a
//!    connection on which nothing arrives for Send_Timeout (the reference
//!    calls half "a safe default", not the standard's rule; no second
//!    source gives one).
//! 5. **Abort** (`58 Subnet Instance|Reason Detail`) closes it: sent by
//!    [`Class2Master::close`] (instance user), on a response that does
//!    not answer the request (MSAC_C2, RE) or when an answer takes longer
//!    than [`Class2Config::response_timeout`] (MSAC_C2, TO: our reading,
//!    the sources name no reason for the master's own timeout); received
//!    in place of any answer, it closes the connection with the slave's
//!    instance and reason in words ([`Class2Error::Aborted`]).
//!
//! The master's own supervision: a slave that stops answering at FDL
//! level (no response after the FDL retries) for longer than Send_Timeout
//! has aborted the connection on its side by then; the connection is
//! closed with [`Class2Error::Silent`]. A negative FDL acknowledge (RS:
//! SAP not activated, the answer of a slave without class 2) closes it
//! with [`Class2Error::Refused`].
//!
//! Several connections, to several slaves or to one slave (as far as its
//! `C2_Max_Count_Channels` allows), run at once.

mod run;
#[cfg(test)]
mod tests;

pub use crate::master::records::{RecordAnswer, RecordOp, RecordOps, SingleOp};
use crate::pdu::c2::{
    Abort, AbortReason, AddrParams, C2Pdu, InitiateReq, FEATURE_DPV1_RW, MASTER_SAP, RM_SAP,
};
pub use run::Class2Run;

use crate::master::records::LengthError;
use crate::pdu::dpv1::{Dpv1Error, MAX_DATA_LEN};
use profibus_fdl::station::active::{
    CycleResult, MasterApp, Outcome, Request, Service, TokenContext,
};
use profibus_fdl::time::Instant;
use profibus_fdl::wire::ResponseStatus;
use profibus_fdl::Baud;
use std::collections::VecDeque;
use std::fmt;
use std::time::Duration;

/// Longest answer on a connection: the 4-byte header and 240 data bytes.
const MAX_ANSWER: u8 = 4 + MAX_DATA_LEN as u8;

/// Settings of a class-2 master, the same for all its connections.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Class2Config {
    /// Send_Timeout of Initiate.req: the slave aborts a connection on
    /// which nothing arrives for this long. Sent in units of 10 ms
    /// (rounded up, 10 ms ..= 655.35 s).
    pub send_timeout: Duration,
    /// Idle after this long without a telegram on an open connection;
    /// `None`: half of [`Class2Config::send_timeout`].
    pub idle_interval: Option<Duration>,
    /// How long a connection set-up or a request may take until its
    /// answer (the GSD's `C2_Response_Timeout` is the slave's figure).
    pub response_timeout: Duration,
    /// Features_Supported_1 of Initiate.req (bit 0: Read/Write).
    pub features_supported_1: u8,
    /// Features_Supported_2.
    pub features_supported_2: u8,
    /// Profile_Features_Supported.
    pub profile_features_supported: u16,
    /// Profile_Ident_Number (0: no profile).
    pub profile_ident_number: u16,
}

impl Class2Config {
    /// Settings for a bus at `baud`: Send_Timeout twice the smallest one
    /// a slave must accept at that rate (the VPC3+: 1 s at 1.5 Mbit/s
    /// and above, 2 s at 500 kbit/s, 4 s below; reference §4.4), so a
    /// late token does not end the connection; a response timeout of
    /// 10 s; Read/Write supported, no profile.
    pub fn for_baud(baud: Baud) -> Class2Config {
        let min = match baud.bps() {
            1_500_000.. => 1,
            500_000.. => 2,
            _ => 4,
        };
        Class2Config {
            send_timeout: Duration::from_secs(2 * min),
            idle_interval: None,
            response_timeout: Duration::from_secs(10),
            features_supported_1: FEATURE_DPV1_RW,
            features_supported_2: 0,
            profile_features_supported: 0,
            profile_ident_number: 0,
        }
    }

    /// Send_Timeout as Initiate.req carries it: units of 10 ms, rounded
    /// up, 1..=65535.
    pub fn send_timeout_units(&self) -> u16 {
        self.send_timeout
            .as_millis()
            .div_ceil(10)
            .clamp(1, u16::MAX as u128) as u16
    }

    /// When an open connection with nothing to send gets an Idle.
    pub fn idle_after(&self) -> Duration {
        self.idle_interval.unwrap_or(self.send_timeout / 2)
    }
}

/// A connection of a [`Class2Master`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ConnId(pub u32);

impl fmt::Display for ConnId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "connection {}", self.0)
    }
}

/// A request on a connection, as the class-2 PDU it is sent as.
fn op_pdu(op: &RecordOp) -> C2Pdu<'_> {
    match op {
        &RecordOp::Read {
            slot,
            index,
            length,
        } => C2Pdu::ReadReq {
            slot,
            index,
            length,
        },
        RecordOp::Write { slot, index, data } => C2Pdu::WriteReq {
            slot: *slot,
            index: *index,
            data,
        },
        RecordOp::Transport { slot, index, data } => C2Pdu::DataTransportReq {
            slot: *slot,
            index: *index,
            data,
        },
    }
}

/// What the slave said in Initiate.res.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Opened {
    /// The connection SAP the resource manager assigned.
    pub sap: u8,
    /// The RM's Poll_Timeout (ms, see [`crate::pdu::c2::RmReply`]).
    pub poll_timeout: u16,
    /// Max_Len_Data_Unit.
    pub max_len_data_unit: u8,
    /// Features_Supported_1.
    pub features_supported_1: u8,
    /// Profile_Ident_Number.
    pub profile_ident_number: u16,
}

/// What happened on a connection.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Class2Event {
    /// The slave accepted the connection.
    Opened {
        /// The connection.
        conn: ConnId,
        /// Its slave.
        slave: u8,
        /// The slave's Initiate.res.
        info: Opened,
    },
    /// A request was answered.
    Answer {
        /// The connection.
        conn: ConnId,
        /// Its slave.
        slave: u8,
        /// The request.
        op: RecordOp,
        /// The answer.
        answer: RecordAnswer,
    },
    /// The connection is closed.
    Closed {
        /// The connection.
        conn: ConnId,
        /// Its slave.
        slave: u8,
        /// Why, unless the application closed it ([`Class2Master::close`]).
        error: Option<Class2Error>,
        /// The Abort this master sent, if it sent one.
        abort_sent: Option<Abort>,
    },
}

/// Why a connection or a request failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Class2Error {
    /// No FDL answer from the slave for longer than Send_Timeout.
    #[error(
        "slave {slave} does not answer: silent for longer than the Send_Timeout of {} ms",
        send_timeout.as_millis()
    )]
    Silent {
        /// The slave.
        slave: u8,
        /// The connection's Send_Timeout.
        send_timeout: Duration,
    },
    /// The answer to the set-up or to a request did not come in time.
    #[error(
        "slave {slave}: no answer to the {op} within {} ms",
        after.as_millis()
    )]
    Timeout {
        /// The slave.
        slave: u8,
        /// `initiate`, `read`, `write` or `transport`.
        op: &'static str,
        /// The response timeout.
        after: Duration,
    },
    /// The slave aborted the connection.
    #[error("slave {slave} aborted the connection: {}", abort.describe())]
    Aborted {
        /// The slave.
        slave: u8,
        /// Its Abort.
        abort: Abort,
    },
    /// The slave refused the connection with a negative response.
    #[error("slave {slave} refused the connection: {}", error.describe())]
    InitiateRefused {
        /// The slave.
        slave: u8,
        /// Its negative response.
        error: Dpv1Error,
    },
    /// The slave answered with a negative FDL acknowledge.
    #[error(
        "slave {slave} refused {}: {} ({})",
        if *sap == RM_SAP { "class 2 (SAP 49, MSAC_C2 Initiate)".to_string() } else { format!("connection SAP {sap}") },
        status_words(*status),
        status.mnemonic()
    )]
    Refused {
        /// The slave.
        slave: u8,
        /// The SAP it refused.
        sap: u8,
        /// Its acknowledge.
        status: ResponseStatus,
    },
    /// The slave's answer did not answer the request; the connection was
    /// aborted (RE).
    #[error(
        "slave {slave} answered the {op} with {what}: connection aborted (invalid response PDU)"
    )]
    BadResponse {
        /// The slave.
        slave: u8,
        /// What was asked.
        op: &'static str,
        /// What came, in words.
        what: String,
    },
    /// The connection is not (or no longer) there.
    #[error("{0} is closed")]
    NotOpen(ConnId),
    /// A request of no bytes or more than 240.
    #[error(transparent)]
    Length(#[from] LengthError),
}

fn status_words(s: ResponseStatus) -> &'static str {
    match s {
        ResponseStatus::Rs => "SAP not activated",
        ResponseStatus::Rr => "no resources",
        ResponseStatus::Ue => "user error",
        ResponseStatus::Rdl | ResponseStatus::Rdh => "data not received",
        _ => "negative acknowledge",
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Initiate.req to the RM is due.
    Initiate,
    /// Initiate.req acknowledged without data: polling the RM (SAP 49)
    /// with empty SRDs for its reply. Felser's PROFIBUS manual has the
    /// RM reply come on "a poll cycle at SAP 49"; the \[BAL\] narrative has
    /// it in the answer to Initiate.req itself. Both are taken; a second
    /// Initiate.req would ask the RM for a second connection.
    AwaitRm,
    /// Polling the connection SAP for Initiate.res.
    Opening,
    /// Open; the current op (if any) is not sent yet.
    Open,
    /// The current op is sent; polling for its answer.
    Polling,
    /// Idle sent, its answer due.
    Idling,
    /// The Abort is due; then closed.
    Aborting,
}

/// What the cycle in flight carried.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Sent {
    Initiate,
    Poll,
    Request,
    Idle,
    Abort,
}

#[derive(Debug)]
struct Conn {
    id: ConnId,
    slave: u8,
    phase: Phase,
    /// The connection SAP (49 until the RM assigned one).
    sap: u8,
    poll_timeout: u16,
    queue: VecDeque<RecordOp>,
    current: Option<RecordOp>,
    /// When the set-up or the current op began (its response timeout).
    since: Instant,
    /// When this master last sent on the connection (Idle is due after
    /// [`Class2Config::idle_after`]).
    last_sent: Instant,
    /// Since when the slave has not answered at FDL level.
    silent_since: Option<Instant>,
    /// Sent in this token visit already.
    visited: bool,
    /// The Abort to send, and why the connection closes.
    abort: Option<(Abort, Option<Class2Error>)>,
}

/// The class-2 master; see the module docs.
#[derive(Debug)]
pub struct Class2Master {
    cfg: Class2Config,
    conns: Vec<Conn>,
    next_id: u32,
    /// Round-robin start of the next token visit.
    turn: usize,
    inflight: Option<(ConnId, Sent)>,
    events: VecDeque<Class2Event>,
    req: [u8; 256],
}

impl Class2Master {
    /// A master with no connections.
    pub fn new(cfg: Class2Config) -> Class2Master {
        Class2Master {
            cfg,
            conns: Vec::new(),
            next_id: 1,
            turn: 0,
            inflight: None,
            events: VecDeque::new(),
            req: [0; 256],
        }
    }

    /// Its settings.
    pub fn config(&self) -> &Class2Config {
        &self.cfg
    }

    /// Open a connection to `slave` (Initiate on the next token visit).
    pub fn connect(&mut self, slave: u8, now: Instant) -> ConnId {
        let id = ConnId(self.next_id);
        self.next_id += 1;
        self.conns.push(Conn {
            id,
            slave,
            phase: Phase::Initiate,
            sap: RM_SAP,
            poll_timeout: 0,
            queue: VecDeque::new(),
            current: None,
            since: now,
            last_sent: now,
            silent_since: None,
            visited: false,
            abort: None,
        });
        id
    }

    /// Queue a request on `conn` (sent once the connection is open and
    /// the requests before it are answered).
    pub fn request(&mut self, conn: ConnId, op: RecordOp) -> Result<(), Class2Error> {
        op.check()?;
        let c = self
            .conn_mut(conn)
            .filter(|c| c.abort.is_none())
            .ok_or(Class2Error::NotOpen(conn))?;
        c.queue.push_back(op);
        Ok(())
    }

    /// Close `conn`: queued requests are dropped, an Abort (instance
    /// user, reason 0) goes out once a SAP is assigned, then
    /// [`Class2Event::Closed`] without error.
    pub fn close(&mut self, conn: ConnId) {
        let Some(i) = self.index(conn) else { return };
        if matches!(self.conns[i].phase, Phase::Initiate | Phase::AwaitRm) {
            self.finish(i, None, None);
        } else if self.conns[i].abort.is_none() {
            self.abort(i, Abort::user(0), None);
        }
    }

    /// Whether `conn` is open (Initiate.res received, not closing).
    pub fn is_open(&self, conn: ConnId) -> bool {
        self.conns.iter().any(|c| {
            c.id == conn
                && c.abort.is_none()
                && matches!(c.phase, Phase::Open | Phase::Polling | Phase::Idling)
        })
    }

    /// Connections not yet closed.
    pub fn connections(&self) -> usize {
        self.conns.len()
    }

    /// The next event, if any.
    pub fn poll_event(&mut self) -> Option<Class2Event> {
        self.events.pop_front()
    }

    /// Check the timeouts at `now` (also done on every token visit).
    pub fn handle_time(&mut self, now: Instant) {
        let mut i = 0;
        while i < self.conns.len() {
            let before = self.conns.len();
            self.check_time(i, now);
            if self.conns.len() == before {
                i += 1;
            }
        }
    }

    fn check_time(&mut self, i: usize, now: Instant) {
        let (send_timeout, response_timeout) = (self.cfg.send_timeout, self.cfg.response_timeout);
        let c = &self.conns[i];
        if self.inflight.is_some_and(|(id, _)| id == c.id) {
            return;
        }
        let slave = c.slave;
        if c.silent_since
            .is_some_and(|t| now.saturating_duration_since(t) > send_timeout)
        {
            // The slave has dropped the connection on its side by now:
            // nothing is sent any more.
            let e = Class2Error::Silent {
                slave,
                send_timeout,
            };
            let sent = c.abort.as_ref().map(|(a, _)| *a);
            let error = c.abort.as_ref().and_then(|(_, e)| e.clone()).or(Some(e));
            self.finish(i, error, sent);
            return;
        }
        let waiting = match c.phase {
            Phase::Initiate | Phase::AwaitRm | Phase::Opening => Some("initiate"),
            Phase::Open | Phase::Polling => c.current.as_ref().map(RecordOp::name),
            Phase::Idling | Phase::Aborting => None,
        };
        if let Some(op) = waiting {
            if c.abort.is_none() && now.saturating_duration_since(c.since) > response_timeout {
                let e = Class2Error::Timeout {
                    slave,
                    op,
                    after: response_timeout,
                };
                if matches!(c.phase, Phase::Initiate | Phase::AwaitRm) {
                    self.finish(i, Some(e), None);
                } else {
                    self.abort(i, Abort::msac_c2(AbortReason::Timeout), Some(e));
                }
            }
        }
    }

    fn index(&self, conn: ConnId) -> Option<usize> {
        self.conns.iter().position(|c| c.id == conn)
    }

    fn conn_mut(&mut self, conn: ConnId) -> Option<&mut Conn> {
        self.conns.iter_mut().find(|c| c.id == conn)
    }

    /// Send `abort` next, then close with `error`.
    fn abort(&mut self, i: usize, abort: Abort, error: Option<Class2Error>) {
        let c = &mut self.conns[i];
        tracing::debug!(slave = c.slave, sap = c.sap, abort = %abort.describe(), "class-2 abort");
        c.abort = Some((abort, error));
        c.phase = Phase::Aborting;
        c.queue.clear();
        c.current = None;
    }

    fn finish(&mut self, i: usize, error: Option<Class2Error>, abort_sent: Option<Abort>) {
        let c = self.conns.remove(i);
        if let Some(e) = &error {
            tracing::debug!(slave = c.slave, %e, "class-2 connection closed");
        }
        self.events.push_back(Class2Event::Closed {
            conn: c.id,
            slave: c.slave,
            error,
            abort_sent,
        });
    }

    /// What connection `i` sends now, if anything.
    fn next_for(&mut self, i: usize, now: Instant) -> Option<(Sent, usize)> {
        let idle_after = self.cfg.idle_after();
        let c = &mut self.conns[i];
        let pdu_len = |pdu: C2Pdu<'_>, buf: &mut [u8]| pdu.emit(buf).unwrap_or(0);
        let (sent, len) = match c.phase {
            Phase::Initiate => {
                let pdu = C2Pdu::InitiateReq(InitiateReq {
                    send_timeout: self.cfg.send_timeout_units(),
                    features_supported_1: self.cfg.features_supported_1,
                    features_supported_2: self.cfg.features_supported_2,
                    profile_features_supported: self.cfg.profile_features_supported,
                    profile_ident_number: self.cfg.profile_ident_number,
                    source: AddrParams::default(),
                    destination: AddrParams::default(),
                });
                (Sent::Initiate, pdu_len(pdu, &mut self.req))
            }
            Phase::AwaitRm | Phase::Opening | Phase::Polling | Phase::Idling => (Sent::Poll, 0),
            Phase::Aborting => {
                let abort = c.abort.as_ref()?.0;
                (Sent::Abort, pdu_len(C2Pdu::Abort(abort), &mut self.req))
            }
            Phase::Open => {
                if c.current.is_none() {
                    c.current = c.queue.pop_front();
                    if c.current.is_some() {
                        c.since = now;
                    }
                }
                match &c.current {
                    Some(op) => (Sent::Request, pdu_len(op_pdu(op), &mut self.req)),
                    None if now.saturating_duration_since(c.last_sent) >= idle_after => {
                        (Sent::Idle, pdu_len(C2Pdu::Idle, &mut self.req))
                    }
                    None => return None,
                }
            }
        };
        Some((sent, len))
    }

    fn answered(&mut self, i: usize, now: Instant, sent: Sent, outcome: &Outcome<'_>) {
        let c = &mut self.conns[i];
        let slave = c.slave;
        let data: &[u8] = match *outcome {
            Outcome::NoResponse | Outcome::Sent => {
                c.silent_since.get_or_insert(now);
                if sent == Sent::Abort {
                    let (a, e) = c.abort.take().unzip();
                    self.finish(i, e.flatten(), a);
                }
                return;
            }
            Outcome::ShortAck => &[],
            Outcome::Response { status, data, .. } => {
                if status.is_negative() {
                    let sap = c.sap;
                    let sent_abort = c.abort.as_ref().map(|(a, _)| *a);
                    let error = match c.abort.take() {
                        Some((_, e)) => e,
                        None => Some(Class2Error::Refused { slave, sap, status }),
                    };
                    self.finish(i, error, sent_abort);
                    return;
                }
                data
            }
        };
        c.silent_since = None;
        if sent == Sent::Abort {
            let (a, e) = c.abort.take().unzip();
            self.finish(i, e.flatten(), a);
            return;
        }
        if sent == Sent::Request {
            c.phase = Phase::Polling;
        }
        if data.is_empty() {
            // Not ready: poll on (Initiate: poll the RM for its reply).
            // An Idle acknowledged at FDL level has reached the slave.
            if sent == Sent::Idle {
                c.phase = Phase::Open;
            }
            if sent == Sent::Initiate {
                c.phase = Phase::AwaitRm;
            }
            return;
        }
        let pdu = match C2Pdu::parse_response(data) {
            Ok(pdu) => pdu,
            Err(e) => return self.bad_response(i, e.to_string()),
        };
        if let C2Pdu::Abort(abort) = pdu {
            let error = Class2Error::Aborted { slave, abort };
            return self.finish(i, Some(error), None);
        }
        match (c.phase, pdu) {
            (Phase::Initiate | Phase::AwaitRm, C2Pdu::Rm(rm))
                if rm.sap <= crate::pdu::c2::MAX_CONNECTION_SAP =>
            {
                c.sap = rm.sap;
                c.poll_timeout = rm.poll_timeout;
                c.phase = Phase::Opening;
            }
            (Phase::Initiate | Phase::AwaitRm | Phase::Opening, C2Pdu::Error(error)) => {
                let error = Class2Error::InitiateRefused { slave, error };
                self.finish(i, Some(error), None);
            }
            (Phase::Opening, C2Pdu::InitiateRes(res)) => {
                c.phase = Phase::Open;
                c.last_sent = now;
                let info = Opened {
                    sap: c.sap,
                    poll_timeout: c.poll_timeout,
                    max_len_data_unit: res.max_len_data_unit,
                    features_supported_1: res.features_supported_1,
                    profile_ident_number: res.profile_ident_number,
                };
                let conn = c.id;
                self.events
                    .push_back(Class2Event::Opened { conn, slave, info });
            }
            (Phase::Idling | Phase::Polling, C2Pdu::Idle) if c.current.is_none() => {
                c.phase = Phase::Open;
            }
            // An Idle while a request is out: the answer is not ready.
            (Phase::Polling, C2Pdu::Idle) => {}
            (Phase::Polling, pdu) => {
                let Some(op) = c.current.take() else {
                    return self.bad_response(i, format!("an unasked {}", words(&pdu)));
                };
                let answer = match (&op, pdu) {
                    (_, C2Pdu::Error(e)) if e.function & 0x7F == op_pdu(&op).function() => {
                        RecordAnswer::Negative(e)
                    }
                    (RecordOp::Read { .. }, C2Pdu::ReadRes { data, .. }) => {
                        RecordAnswer::Read(data.to_vec())
                    }
                    (RecordOp::Write { .. }, C2Pdu::WriteRes { length, .. }) => {
                        RecordAnswer::Written(length)
                    }
                    (RecordOp::Transport { .. }, C2Pdu::DataTransportRes { data, .. }) => {
                        RecordAnswer::Transport(data.to_vec())
                    }
                    (op, pdu) => {
                        let what = words(&pdu);
                        let op = op.name();
                        let c = &mut self.conns[i];
                        c.current = None;
                        let e = Class2Error::BadResponse { slave, op, what };
                        return self.abort(
                            i,
                            Abort::msac_c2(AbortReason::InvalidResponse),
                            Some(e),
                        );
                    }
                };
                c.phase = Phase::Open;
                let conn = c.id;
                self.events.push_back(Class2Event::Answer {
                    conn,
                    slave,
                    op,
                    answer,
                });
            }
            (_, pdu) => self.bad_response(i, format!("an unexpected {}", words(&pdu))),
        }
    }

    fn bad_response(&mut self, i: usize, what: String) {
        let c = &self.conns[i];
        let op = match c.phase {
            Phase::Initiate | Phase::AwaitRm | Phase::Opening => "initiate",
            _ => c.current.as_ref().map_or("idle", RecordOp::name),
        };
        let e = Class2Error::BadResponse {
            slave: c.slave,
            op,
            what,
        };
        if matches!(c.phase, Phase::Initiate | Phase::AwaitRm) {
            // No connection SAP yet: nothing to abort.
            return self.finish(i, Some(e), None);
        }
        self.abort(i, Abort::msac_c2(AbortReason::InvalidResponse), Some(e));
    }
}

/// A PDU in a few words, for [`Class2Error::BadResponse`].
fn words(pdu: &C2Pdu<'_>) -> String {
    let name = match pdu {
        C2Pdu::InitiateReq(_) => "Initiate.req",
        C2Pdu::InitiateRes(_) => "Initiate.res",
        C2Pdu::Rm(_) => "RM reply",
        C2Pdu::ReadReq { .. } => "Read.req",
        C2Pdu::ReadRes { .. } => "Read.res",
        C2Pdu::WriteReq { .. } => "Write.req",
        C2Pdu::WriteRes { .. } => "Write.res",
        C2Pdu::DataTransportReq { .. } => "Data_Transport.req",
        C2Pdu::DataTransportRes { .. } => "Data_Transport.res",
        C2Pdu::Idle => "Idle",
        C2Pdu::Abort(_) => "Abort",
        C2Pdu::Error(_) => "negative response",
    };
    format!("{name} (function 0x{:02X})", pdu.function())
}

impl MasterApp for Class2Master {
    fn poll_request(&mut self, ctx: &TokenContext) -> Option<Request<'_>> {
        let now = ctx.now;
        if ctx.cycles == 0 {
            self.handle_time(now);
            for c in &mut self.conns {
                c.visited = false;
            }
        }
        // Class-2 services are low priority: none on a late token.
        if ctx.high_only || self.conns.is_empty() {
            return None;
        }
        let n = self.conns.len();
        for k in 0..n {
            let i = (self.turn + k) % n;
            if self.conns[i].visited {
                continue;
            }
            self.conns[i].visited = true;
            let Some((sent, len)) = self.next_for(i, now) else {
                continue;
            };
            self.turn = (i + 1) % n;
            let c = &mut self.conns[i];
            c.last_sent = now;
            if sent == Sent::Idle {
                c.phase = Phase::Idling;
            }
            self.inflight = Some((c.id, sent));
            let max_reply_len = match sent {
                // An RM reply, or a negative response: 4 bytes.
                Sent::Initiate => Some(4),
                Sent::Abort => Some(0),
                // Initiate.res may carry long addresses.
                Sent::Poll if c.phase == Phase::Opening => None,
                _ => Some(MAX_ANSWER),
            };
            return Some(Request {
                da: c.slave,
                service: Service::SrdLow,
                dsap: Some(c.sap),
                ssap: Some(MASTER_SAP),
                data: &self.req[..len],
                max_reply_len,
            });
        }
        None
    }

    fn on_result(&mut self, now: Instant, r: &CycleResult<'_>) {
        let Some((id, sent)) = self.inflight.take() else {
            return;
        };
        if let Some(i) = self.index(id) {
            self.answered(i, now, sent, &r.outcome);
        }
    }
}
