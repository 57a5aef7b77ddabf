//! MSAC_C2 in the slave: the resource manager on SAP 49 and the class-2
//! connections on SAPs 0..=48 (IEC 61158-6-3; wire facts in
//! `shared/reference/dpv1-c2-im-alarms.md` §4.2–4.4).
//!
//! ```text
//! master                                   slave
//! SRD DSAP 49 SSAP 50  Initiate.req   →    RM reply  56 SAP PollTO (DL)
//! SRD DSAP SAP SSAP 50 (poll)          →    Initiate.res (DL)
//! SRD DSAP SAP  Read/Write/Data_Transport → SC
//! SRD DSAP SAP (poll)                  →    SC until ready, then the response (DL)
//! SRD DSAP SAP  Idle 48 00             →    Idle 48 00 (DL), or the ready response
//! SRD DSAP SAP  Abort 58 …             →    SC; the connection is closed
//! ```
//!
//! Class 2 does not depend on the DP state: a tool may open connections
//! before any Set_Prm and while a class-1 master holds the slave in
//! Data_Exch. Our reading where the sources leave a choice:
//!
//! - **Connection SAPs** are assigned highest first (48, 47, …), as the
//!   Balluff trace got 48 for its first connection; at most
//!   `C2_Max_Count_Channels` are open at once.
//! - **Refused Initiates.** The resource manager answers an Initiate.req
//!   it does not accept with an **Abort** (`58 00 1x 00`, instance
//!   MSAC_C2) in place of the RM PDU, and opens nothing: reason **RES**
//!   when all channels are in use, **STO** when Send_Timeout is below the
//!   slave's minimum, **IA** for address types or lengths that are not
//!   valid (type 1 only when `Max_Initiate_PDU_Length` allows longer
//!   PDUs), **FE** for a PDU that does not decode or is longer than
//!   `Max_Initiate_PDU_Length`. The Abort reason codes name exactly
//!   these cases; a negative Initiate response would carry no reason a
//!   master could act on.
//! - **Minimum Send_Timeout** (units of 10 ms): 100 (1 s) at 1.5 Mbit/s
//!   and above, 200 (2 s) at 500 kbit/s, 400 (4 s) at 187.5 kbit/s and
//!   below, the values of the profichip VPC3+ software; its table stops at
//!   187.5 kbit/s, slower rates keep 4 s.
//! - **Poll_Timeout** of the RM PDU is the connection's Send_Timeout in
//!   milliseconds (at most 65535): the master has that long to fetch
//!   Initiate.res, as for any later request.
//! - **Polls** are empty SRDs on the connection SAP, as with MSAC_C1; a
//!   repeat of the outstanding request is read as a poll too.
//! - **Idle** is answered at once with Idle (`48 00`), or with the
//!   response when one is ready.
//! - **Send_Timeout supervision**: every request on the connection
//!   restarts it; when it expires the slave closes the connection with
//!   reason **TO**. The slave cannot send on its own, so the next request
//!   of that master on that SAP gets the Abort (`58 00 13 00`) once.
//! - A new request while one is outstanding is a **sequence error**: the
//!   slave answers Abort SE and closes; a PDU that does not decode gets
//!   Abort FE.
//! - A request on a SAP without a connection, or from another master
//!   than the connection's, gets RS (SAP not activated).
//! - A device that answers [`Dpv1Outcome::Pending`] is asked one request
//!   at a time: a class-2 request waits (polls get SC or Idle) while
//!   another class-1 or class-2 request is pending in the device, and a
//!   class-1 request waits while a class-2 one is.

use super::device::{
    Device, Dpv1Outcome, ERR_CLASS_ACCESS, ERR_CLASS_APPLICATION, ERR_FEATURE_NOT_SUPPORTED,
    ERR_INVALID_RANGE, ERR_WRITE_LENGTH,
};
use super::{im, DpSlave, Reason, Service, SlaveEvent, MAX_IO_LEN, NEGATIVE_RS};
use crate::pdu::c2::{
    Abort, AbortReason, C2ParseError, C2Pdu, InitiateReq, InitiateRes, RmReply, FEATURE_DPV1_RW,
    FN_DATA_TRANSPORT, FN_INITIATE, INITIATE_REQ_MIN_LEN, MAX_CONNECTION_SAP,
};
use crate::pdu::dpv1::{Dpv1Error, FN_READ, FN_WRITE, MAX_DATA_LEN};
use crate::pdu::sap::Sap;
use profibus_fdl::station::passive::Reply;
use profibus_fdl::{Baud, DataTelegram, Instant, ResponseStatus};
use std::time::Duration;

/// Most class-2 connections a slave can have: one per SAP 0..=48.
pub const MAX_C2_CHANNELS: u8 = 49;

/// The smallest Send_Timeout (units of 10 ms) the slave accepts at
/// `baud` (see the module docs).
pub fn min_send_timeout(baud: Option<Baud>) -> u16 {
    match baud {
        Some(Baud::B500000) => 200,
        Some(b) if b < Baud::B500000 => 400,
        _ => 100,
    }
}

/// State of the request on a class-2 connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum C2Job {
    /// Nothing outstanding.
    None,
    /// The request (in `req`) waits until the device is free.
    Queued,
    /// The device is preparing the answer.
    Pending {
        function: u8,
        slot: u8,
        index: u8,
        /// Requested read length, or the written length.
        len: u8,
    },
    /// The response is in `buf[..len]`.
    Ready { len: usize },
}

/// One open class-2 connection.
#[derive(Debug, Clone)]
pub(super) struct Connection {
    sap: u8,
    master: u8,
    send_timeout: Duration,
    deadline: Instant,
    job: C2Job,
    /// The outstanding request.
    req: [u8; MAX_IO_LEN],
    req_len: usize,
    /// The response being prepared or ready.
    buf: [u8; MAX_IO_LEN],
    /// The I&M record selected on this connection.
    im: im::Selection,
}

/// The class-2 side of a slave: open connections, and the aborts the
/// masters have not heard of yet.
#[derive(Debug, Clone, Default)]
pub(super) struct C2State {
    conns: Vec<Connection>,
    /// (SAP, master, abort): a connection the slave closed on its own.
    notices: Vec<(u8, u8, Abort)>,
}

impl C2State {
    /// Room for `channels` connections, allocated once.
    pub(super) fn new(channels: u8) -> C2State {
        let n = channels.min(MAX_C2_CHANNELS) as usize;
        C2State {
            conns: Vec::with_capacity(n),
            notices: Vec::with_capacity(n),
        }
    }

    /// Whether a class-2 request is pending in the device.
    pub(super) fn device_busy(&self) -> bool {
        self.conns
            .iter()
            .any(|c| matches!(c.job, C2Job::Pending { .. }))
    }

    /// The earliest Send_Timeout deadline.
    pub(super) fn deadline(&self) -> Option<Instant> {
        self.conns.iter().map(|c| c.deadline).min()
    }

    /// Open connections as (SAP, master).
    pub(super) fn connections(&self) -> impl Iterator<Item = (u8, u8)> + '_ {
        self.conns.iter().map(|c| (c.sap, c.master))
    }
}

fn data_reply(req: &DataTelegram<'_>, len: usize) -> Reply {
    Reply::Data {
        status: ResponseStatus::Dl,
        dsap: req.ssap,
        ssap: req.dsap,
        len,
    }
}

impl<D: Device> DpSlave<D> {
    /// The slave offers class 2 (SAP 49 and the connection SAPs active).
    pub(super) fn c2_offered(&self) -> bool {
        self.features.dpv1 && self.features.c2_read_write
    }

    fn c2_max_len(&self) -> usize {
        (self.features.c2_max_data_len as usize).clamp(1, MAX_DATA_LEN)
    }

    /// Open class-2 connections as (SAP, master).
    pub fn c2_connections(&self) -> impl Iterator<Item = (u8, u8)> + '_ {
        self.c2.connections()
    }

    /// The resource manager (SAP 49): Initiate.req.
    pub(super) fn c2_resource_manager(
        &mut self,
        now: Instant,
        req: &DataTelegram<'_>,
        out: &mut [u8],
    ) -> Reply {
        let from = req.sa;
        if !self.c2_offered() {
            self.refuse(
                from,
                Service::Sap(Sap::MsacC2Initiate),
                Reason::C2Unsupported,
            );
            return NEGATIVE_RS;
        }
        if req.data.is_empty() {
            return Reply::ShortAck;
        }
        let initiate = match C2Pdu::parse_request(req.data) {
            Ok(C2Pdu::InitiateReq(r)) => self.c2_check_initiate(req.data.len(), &r).map(|()| r),
            // Nothing is open on the RM's SAP: an Abort there is a no-op.
            Ok(C2Pdu::Abort(_)) => return Reply::ShortAck,
            Err(C2ParseError::Address { .. }) => Err(AbortReason::InvalidAddress),
            Ok(_) | Err(_) => Err(AbortReason::InvalidRequest),
        };
        let r = match initiate {
            Ok(r) => r,
            Err(reason) => {
                let abort = Abort::msac_c2(reason);
                self.refuse(
                    from,
                    Service::Sap(Sap::MsacC2Initiate),
                    Reason::C2InitiateRefused {
                        abort: abort.describe(),
                    },
                );
                let len = C2Pdu::Abort(abort).emit(out).unwrap_or(0);
                return data_reply(req, len);
            }
        };
        let Some(sap) = (0..=MAX_CONNECTION_SAP)
            .rev()
            .find(|s| !self.c2.conns.iter().any(|c| c.sap == *s))
        else {
            return NEGATIVE_RS;
        };
        self.c2.notices.retain(|n| n.0 != sap);
        let send_timeout = Duration::from_millis(r.send_timeout as u64 * 10);
        let mut conn = Connection {
            sap,
            master: from,
            send_timeout,
            deadline: now + send_timeout,
            job: C2Job::None,
            req: [0; MAX_IO_LEN],
            req_len: 0,
            buf: [0; MAX_IO_LEN],
            im: None,
        };
        let res = C2Pdu::InitiateRes(InitiateRes {
            max_len_data_unit: self.c2_max_len() as u8,
            features_supported_1: FEATURE_DPV1_RW,
            features_supported_2: 0,
            profile_features_supported: 0,
            profile_ident_number: 0,
            source: r.destination,
            destination: r.source,
        });
        let len = res.emit(&mut conn.buf).unwrap_or(0);
        conn.job = C2Job::Ready { len };
        self.c2.conns.push(conn);
        self.event(SlaveEvent::C2Opened {
            master: from,
            sap,
            send_timeout,
        });
        let rm = C2Pdu::Rm(RmReply {
            sap,
            poll_timeout: (send_timeout.as_millis()).min(u16::MAX as u128) as u16,
        });
        let len = rm.emit(out).unwrap_or(0);
        data_reply(req, len)
    }

    /// Why an Initiate.req of `len` bytes is refused, if it is.
    fn c2_check_initiate(&self, len: usize, r: &InitiateReq<'_>) -> Result<(), AbortReason> {
        let f = self.features;
        let extended = r.source.extension.is_some() || r.destination.extension.is_some();
        if extended && f.max_initiate_pdu_length == 0 {
            return Err(AbortReason::InvalidAddress);
        }
        let max = match f.max_initiate_pdu_length {
            0 => INITIATE_REQ_MIN_LEN,
            n => n as usize,
        };
        if len > max {
            return Err(AbortReason::InvalidRequest);
        }
        if r.send_timeout < min_send_timeout(self.baud) {
            return Err(AbortReason::SendTimeoutTooSmall);
        }
        let channels = f.c2_max_count_channels.clamp(1, MAX_C2_CHANNELS) as usize;
        if self.c2.conns.len() >= channels {
            return Err(AbortReason::Resource);
        }
        Ok(())
    }

    /// A request on a connection SAP (0..=48).
    pub(super) fn c2_connection(
        &mut self,
        now: Instant,
        req: &DataTelegram<'_>,
        out: &mut [u8],
    ) -> Reply {
        let (from, sap) = (req.sa, req.dsap.unwrap_or(0));
        let service = Service::Sap(Sap::from_code(sap));
        if !self.c2_offered() {
            self.refuse(from, service, Reason::C2Unsupported);
            return NEGATIVE_RS;
        }
        let Some(i) = self.c2.conns.iter().position(|c| c.sap == sap) else {
            if let Some(k) = (self.c2.notices.iter()).position(|n| n.0 == sap && n.1 == from) {
                let (_, _, abort) = self.c2.notices.swap_remove(k);
                let len = C2Pdu::Abort(abort).emit(out).unwrap_or(0);
                return data_reply(req, len);
            }
            self.refuse(from, service, Reason::C2NoConnection);
            return NEGATIVE_RS;
        };
        let owner = self.c2.conns[i].master;
        if owner != from {
            self.refuse(from, service, Reason::C2OtherMaster { owner });
            return NEGATIVE_RS;
        }
        let conn = &mut self.c2.conns[i];
        conn.deadline = now + conn.send_timeout;
        let du = req.data;
        if du.is_empty() {
            return self.c2_poll(now, i, false, req, out);
        }
        let repeat = du == &conn.req[..conn.req_len] && conn.job != C2Job::None;
        match C2Pdu::parse_request(du) {
            Ok(C2Pdu::Idle) => self.c2_poll(now, i, true, req, out),
            Ok(C2Pdu::Abort(abort)) => {
                self.c2_close(i, true, abort);
                Reply::ShortAck
            }
            Ok(C2Pdu::InitiateReq(_))
                if matches!(conn.job, C2Job::Ready { .. }) && conn.buf[0] == FN_INITIATE =>
            {
                // The master repeats its Initiate instead of polling.
                self.c2_poll(now, i, false, req, out)
            }
            Ok(C2Pdu::ReadReq { .. } | C2Pdu::WriteReq { .. } | C2Pdu::DataTransportReq { .. })
                if repeat =>
            {
                self.c2_poll(now, i, false, req, out)
            }
            Ok(C2Pdu::ReadReq { .. } | C2Pdu::WriteReq { .. } | C2Pdu::DataTransportReq { .. })
                if conn.job == C2Job::None =>
            {
                conn.req[..du.len()].copy_from_slice(du);
                conn.req_len = du.len();
                conn.job = C2Job::Queued;
                self.c2_progress(now, i);
                Reply::ShortAck
            }
            Ok(_) => self.c2_abort_reply(i, AbortReason::SequenceError, req, out),
            Err(_) => self.c2_abort_reply(i, AbortReason::InvalidRequest, req, out),
        }
    }

    /// A poll (empty SRD, or Idle when `idle`): the ready response, else
    /// SC (Idle for an Idle).
    fn c2_poll(
        &mut self,
        now: Instant,
        i: usize,
        idle: bool,
        req: &DataTelegram<'_>,
        out: &mut [u8],
    ) -> Reply {
        self.c2_progress(now, i);
        let conn = &mut self.c2.conns[i];
        match conn.job {
            C2Job::Ready { len } if len <= out.len() => {
                out[..len].copy_from_slice(&conn.buf[..len]);
                conn.job = C2Job::None;
                conn.req_len = 0;
                data_reply(req, len)
            }
            _ if idle => {
                let len = C2Pdu::Idle.emit(out).unwrap_or(0);
                data_reply(req, len)
            }
            _ => Reply::ShortAck,
        }
    }

    /// Move connection `i`'s job on: start a queued request when the
    /// device is free, ask the device again for a pending one.
    fn c2_progress(&mut self, now: Instant, i: usize) {
        match self.c2.conns[i].job {
            C2Job::Queued if !self.device_busy() => self.c2_start(now, i),
            C2Job::Pending {
                function,
                slot,
                index,
                len,
            } => {
                let conn = &mut self.c2.conns[i];
                let n = if function == FN_WRITE {
                    0
                } else {
                    len as usize
                };
                let outcome = self.device.dpv1_poll(now, &mut conn.buf[4..4 + n]);
                c2_finish(conn, function, slot, index, len, outcome);
            }
            _ => {}
        }
    }

    /// Whether a request is pending in the device (class 1 or 2).
    pub(super) fn device_busy(&self) -> bool {
        matches!(self.c1, super::C1Job::Pending { .. }) || self.c2.device_busy()
    }

    /// Hand connection `i`'s request to the device (lengths are checked
    /// first, as for MSAC_C1, against C2_Max_Data_Len).
    fn c2_start(&mut self, now: Instant, i: usize) {
        let limit = self.c2_max_len();
        let im_on = self.features.dpv1 && self.features.im;
        let conn = &mut self.c2.conns[i];
        let Connection {
            req,
            req_len,
            buf,
            im: selection,
            ..
        } = conn;
        let du = &req[..*req_len];
        let function = du[0];
        let error = |e: Dpv1Error| Dpv1Outcome::Error(e);
        let (function, slot, index, len, outcome) = match C2Pdu::parse_request(du) {
            Ok(C2Pdu::ReadReq { length, .. }) if length == 0 || length as usize > limit => (
                FN_READ,
                0,
                0,
                0,
                error(Dpv1Error::dpv1(
                    FN_READ,
                    ERR_CLASS_ACCESS,
                    ERR_INVALID_RANGE,
                )),
            ),
            Ok(C2Pdu::WriteReq { data, .. } | C2Pdu::DataTransportReq { data, .. })
                if data.is_empty() || data.len() > limit =>
            {
                (
                    function,
                    0,
                    0,
                    0,
                    error(Dpv1Error::dpv1(
                        function,
                        ERR_CLASS_ACCESS,
                        ERR_WRITE_LENGTH,
                    )),
                )
            }
            Ok(C2Pdu::ReadReq {
                slot,
                index,
                length,
            }) => {
                let n = length as usize;
                let out = &mut buf[4..4 + n];
                let outcome = if im::is_call(im_on, slot, index) {
                    im::read(&mut self.device, *selection, out)
                } else {
                    self.device.dpv1_read(now, slot, index, out)
                };
                (FN_READ, slot, index, length, outcome)
            }
            Ok(C2Pdu::WriteReq { slot, index, data }) => {
                let outcome = if im::is_call(im_on, slot, index) {
                    im::write(&mut self.device, now, selection, data)
                } else {
                    self.device.dpv1_write(now, slot, index, data)
                };
                (FN_WRITE, slot, index, data.len() as u8, outcome)
            }
            Ok(C2Pdu::DataTransportReq { slot, index, data }) => {
                let out = &mut buf[4..4 + limit];
                let outcome = self.device.dpv1_data_transport(now, slot, index, data, out);
                (FN_DATA_TRANSPORT, slot, index, limit as u8, outcome)
            }
            _ => (
                function,
                0,
                0,
                0,
                error(Dpv1Error::dpv1(
                    function,
                    ERR_CLASS_APPLICATION,
                    ERR_FEATURE_NOT_SUPPORTED,
                )),
            ),
        };
        c2_finish(conn, function, slot, index, len, outcome);
    }

    /// Answer with an Abort for `reason` and close connection `i`.
    fn c2_abort_reply(
        &mut self,
        i: usize,
        reason: AbortReason,
        req: &DataTelegram<'_>,
        out: &mut [u8],
    ) -> Reply {
        let abort = Abort::msac_c2(reason);
        self.c2_close(i, false, abort);
        let len = C2Pdu::Abort(abort).emit(out).unwrap_or(0);
        data_reply(req, len)
    }

    /// Close connection `i`.
    fn c2_close(&mut self, i: usize, by_master: bool, abort: Abort) {
        let conn = self.c2.conns.swap_remove(i);
        self.event(SlaveEvent::C2Closed {
            master: conn.master,
            sap: conn.sap,
            by_master,
            abort,
        });
    }

    /// Close the connections whose Send_Timeout expired (reason TO); the
    /// master hears the Abort with its next request on the SAP.
    pub(super) fn c2_expire(&mut self, now: Instant) {
        while let Some(i) = self.c2.conns.iter().position(|c| c.deadline <= now) {
            let abort = Abort::msac_c2(AbortReason::Timeout);
            let (sap, master) = (self.c2.conns[i].sap, self.c2.conns[i].master);
            self.c2_close(i, false, abort);
            if self.c2.notices.len() < MAX_C2_CHANNELS as usize {
                self.c2.notices.push((sap, master, abort));
            }
        }
    }

    /// The device restarted: every connection is gone.
    pub(super) fn c2_reset(&mut self) {
        self.c2.conns.clear();
        self.c2.notices.clear();
    }
}

/// Store the device's outcome for a class-2 request as the connection's
/// job (the response PDU when done).
fn c2_finish(
    conn: &mut Connection,
    function: u8,
    slot: u8,
    index: u8,
    len: u8,
    outcome: Dpv1Outcome,
) {
    match outcome {
        Dpv1Outcome::Pending => {
            conn.job = C2Job::Pending {
                function,
                slot,
                index,
                len,
            }
        }
        Dpv1Outcome::Error(mut e) => {
            e.function = function | 0x80;
            let n = C2Pdu::Error(e).emit(&mut conn.buf).unwrap_or(0);
            conn.job = C2Job::Ready { len: n };
        }
        Dpv1Outcome::Done(n) => {
            let n = match function {
                FN_WRITE => n.min(255),
                _ => n.min(len as usize),
            };
            conn.buf[..4].copy_from_slice(&[function, slot, index, n as u8]);
            let total = if function == FN_WRITE { 4 } else { 4 + n };
            conn.job = C2Job::Ready { len: total };
        }
    }
}
