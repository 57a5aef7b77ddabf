//! The passive station (responder): the layer-2 side of a DP slave.
//!
//! [`PassiveStation`] frames requests addressed to the station's address
//! (or broadcast), and:
//!
//! - answers **FDL Status** itself (FC 0x00: OK, passive station);
//! - keeps the **FCB rule** (IEC 61158-4-3): it stores the
//!   source address and FCB of the last SRD/SDA with its response; a
//!   request from the same source with FCV = 1 and the same FCB is a retry
//!   of a request whose response was lost, and gets the stored response
//!   again without being executed twice. A request from another source
//!   address is not checked against the stored FCB;
//! - hands every other request to its [`Responder`] (the DP slave core),
//!   which writes the response data into a buffer the station owns;
//! - sends the response no earlier than min TSDR after the request's last
//!   character (the larger of the bus parameter and the responder's own
//!   value, e.g. from Set_Prm).
//!
//! Requests without a reply (SDN, broadcasts) are handed over and never
//! answered. Telegrams not addressed to the station are ignored.

use super::{earliest, RxPath, Station};
#[allow(unused_imports)]
use crate::prelude::*;
use crate::time::Instant;
use crate::timing::BusParams;
use crate::wire::{
    consts, DataTelegram, FunctionCode, RequestKind, ResponseStatus, StationType, Telegram,
};

/// What the responder answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply {
    /// Send nothing.
    Silence,
    /// The short acknowledge SC (0xE5).
    ShortAck,
    /// A response telegram with this status, the given SAPs (swapped
    /// against the request's by the responder) and the first `len` bytes
    /// of the response buffer as data unit.
    Data {
        /// Response status (DL, DH, RS, …).
        status: ResponseStatus,
        /// DSAP of the response (the request's SSAP).
        dsap: Option<u8>,
        /// SSAP of the response (the request's DSAP).
        ssap: Option<u8>,
        /// Bytes of the data unit written into the buffer.
        len: usize,
    },
}

impl Reply {
    /// A response with status `status` and no data unit, SAPs swapped from
    /// `req`.
    pub fn status_only(req: &DataTelegram<'_>, status: ResponseStatus) -> Reply {
        Reply::Data {
            status,
            dsap: req.ssap,
            ssap: req.dsap,
            len: 0,
        }
    }
}

/// The application behind a passive station (the DP slave core).
pub trait Responder {
    /// The station's current address (it may change, e.g. through
    /// Set_Slave_Add).
    fn address(&self) -> u8;

    /// Minimum station delay in bit times required by the application
    /// (Set_Prm's min TSDR), on top of the bus parameter's.
    fn min_tsdr(&self) -> u32 {
        0
    }

    /// The station runs at `baud` (told when the station is built, e.g.
    /// again after a baud-rate search). Default: nothing.
    fn set_baud(&mut self, _baud: crate::timing::Baud) {}

    /// A request addressed to this station, or broadcast. Write the data
    /// unit of the response into `out` (up to 246 bytes) and say what to
    /// send. Called once per request; FCB repeats do not reach it.
    fn on_request(&mut self, now: Instant, req: &DataTelegram<'_>, out: &mut [u8]) -> Reply;

    /// When the application next needs [`Responder::handle_timeout`]
    /// (e.g. its watchdog).
    fn poll_timeout(&self) -> Option<Instant> {
        None
    }

    /// Time has advanced.
    fn handle_timeout(&mut self, _now: Instant) {}
}

/// Counters of a passive station.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PassiveStats {
    /// Requests addressed to this station (or broadcast) received.
    pub requests: u64,
    /// Responses sent (including short acknowledges and repeats).
    pub responses: u64,
    /// Responses repeated because of a repeated FCB.
    pub fcb_repeats: u64,
    /// FDL Status requests answered.
    pub fdl_status: u64,
}

/// A passive FDL station driving a [`Responder`]; see the module docs.
#[derive(Debug)]
pub struct PassiveStation<R> {
    app: R,
    params: BusParams,
    rx: RxPath,
    /// Response telegram being sent or held for an FCB repeat.
    tx: [u8; consts::MAX_TELEGRAM_LEN],
    tx_len: usize,
    /// When the pending response may go out; `None` when nothing pends.
    tx_at: Option<Instant>,
    /// (source address, FCB) of the last SRD/SDA whose response is in `tx`.
    last: Option<(u8, bool)>,
    stats: PassiveStats,
}

impl<R: Responder> PassiveStation<R> {
    /// A passive station with bus parameters `params`.
    pub fn new(app: R, params: BusParams) -> Self {
        Self::with_latency_allowance(app, params, core::time::Duration::ZERO)
    }

    /// A passive station on a transport that adds latency (ptys, USB
    /// adapters): an incomplete telegram is abandoned only when its
    /// missing characters are `allowance` later than the slot time after
    /// they were due.
    pub fn with_latency_allowance(
        app: R,
        params: BusParams,
        allowance: core::time::Duration,
    ) -> Self {
        let mut app = app;
        app.set_baud(params.baud);
        let slack = params.slot_duration() + allowance;
        PassiveStation {
            app,
            params,
            rx: RxPath::new(params.baud, slack),
            tx: [0; consts::MAX_TELEGRAM_LEN],
            tx_len: 0,
            tx_at: None,
            last: None,
            stats: PassiveStats::default(),
        }
    }

    /// The application.
    pub fn app(&self) -> &R {
        &self.app
    }

    /// The application, mutable.
    pub fn app_mut(&mut self) -> &mut R {
        &mut self.app
    }

    /// The application, taking the station apart (e.g. to run it again
    /// at another baud rate).
    pub fn into_app(self) -> R {
        self.app
    }

    /// Bus parameters.
    pub fn params(&self) -> &BusParams {
        &self.params
    }

    /// Counters.
    pub fn stats(&self) -> PassiveStats {
        self.stats
    }

    /// Codec error counters of the receive path.
    pub fn codec_stats(&self) -> crate::codec::CodecStats {
        self.rx.stats()
    }

    fn process(&mut self, now: Instant) {
        while let Some(t) = self.rx.next_telegram() {
            // Asked per telegram: a request may change the address.
            let addr = self.app.address();
            let Telegram::Data(d) = t else { continue };
            let FunctionCode::Request { kind, fcb, fcv } = d.fc else {
                continue;
            };
            if d.da != addr && d.da != consts::BROADCAST {
                continue;
            }
            self.stats.requests += 1;
            let respond_at = now + {
                let bits = self.params.min_tsdr.max(self.app.min_tsdr());
                self.params.bits(bits as u64)
            };
            if d.da == consts::BROADCAST || !kind.expects_reply() {
                // No answer: SDN or broadcast. A stale response is dropped.
                let mut scratch = [0u8; 0];
                self.app.on_request(now, &d, &mut scratch[..]);
                continue;
            }
            if kind == RequestKind::FdlStatus {
                self.stats.fdl_status += 1;
                let t = Telegram::Data(DataTelegram {
                    da: d.sa,
                    sa: addr,
                    fc: FunctionCode::Response {
                        status: ResponseStatus::Ok,
                        station: StationType::Passive,
                    },
                    dsap: None,
                    ssap: None,
                    data: &[],
                    format: None,
                });
                self.tx_len = t.emit(&mut self.tx).unwrap_or(0);
                self.tx_at = Some(respond_at);
                self.last = None;
                continue;
            }
            if !kind.uses_fcb() {
                // Ident, LSAP status: not supported by a DP slave.
                continue;
            }
            if fcv && self.last == Some((d.sa, fcb)) && self.tx_len > 0 {
                self.stats.fcb_repeats += 1;
                self.tx_at = Some(respond_at);
                continue;
            }
            // Build the response into tx: header room first, then data.
            let mut du = [0u8; consts::MAX_DATA_FIELD];
            let reply = self.app.on_request(now, &d, &mut du);
            let emitted = match reply {
                Reply::Silence => None,
                Reply::ShortAck => Telegram::ShortAck.emit(&mut self.tx).ok(),
                Reply::Data {
                    status,
                    dsap,
                    ssap,
                    len,
                } => Telegram::Data(DataTelegram {
                    da: d.sa,
                    sa: addr,
                    fc: FunctionCode::Response {
                        status,
                        station: StationType::Passive,
                    },
                    dsap,
                    ssap,
                    data: &du[..len.min(du.len())],
                    format: None,
                })
                .emit(&mut self.tx)
                .ok(),
            };
            match emitted {
                Some(n) => {
                    self.tx_len = n;
                    self.tx_at = Some(respond_at);
                    self.last = (fcb || fcv).then_some((d.sa, fcb));
                }
                None => {
                    self.tx_len = 0;
                    self.tx_at = None;
                    self.last = None;
                }
            }
        }
    }
}

impl<R: Responder> Station for PassiveStation<R> {
    fn handle_rx(&mut self, now: Instant, bytes: &[u8]) {
        self.rx.push(now, bytes);
        self.process(now);
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.rx.handle_idle(now);
        self.process(now);
        if self.app.poll_timeout().is_some_and(|t| t <= now) {
            self.app.handle_timeout(now);
        }
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<&[u8]> {
        match self.tx_at {
            Some(t) if t <= now && self.tx_len > 0 => {
                self.tx_at = None;
                self.stats.responses += 1;
                Some(&self.tx[..self.tx_len])
            }
            _ => None,
        }
    }

    fn poll_timeout(&self) -> Option<Instant> {
        earliest(
            earliest(self.tx_at, self.rx.idle_deadline()),
            self.app.poll_timeout(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::station::echo::Echo;
    use crate::testing::fdl_status;
    use crate::timing::Baud;

    fn req(da: u8, sa: u8, fcb: bool, fcv: bool, data: &[u8]) -> Vec<u8> {
        let fc = FunctionCode::Request {
            kind: RequestKind::SrdHigh,
            fcb,
            fcv,
        };
        Telegram::Data(DataTelegram::new(da, sa, fc, data))
            .to_vec()
            .unwrap()
    }

    fn station() -> PassiveStation<Echo> {
        PassiveStation::new(Echo::new(8), BusParams::defaults(Baud::B1500000))
    }

    fn exchange(st: &mut PassiveStation<Echo>, now: Instant, bytes: &[u8]) -> Option<Vec<u8>> {
        st.handle_rx(now, bytes);
        let t = st.poll_timeout()?;
        assert!(st.poll_transmit(now).is_none() || t <= now);
        st.handle_timeout(t);
        st.poll_transmit(t).map(|b| b.to_vec())
    }

    #[test]
    fn answers_after_min_tsdr() {
        let mut st = station();
        let t0 = Instant::from_nanos(1_000_000);
        st.handle_rx(t0, &req(8, 2, true, false, &[1, 2]));
        assert!(st.poll_transmit(t0).is_none(), "not before min TSDR");
        let due = st.poll_timeout().unwrap();
        assert_eq!(due, t0 + BusParams::defaults(Baud::B1500000).bits(11));
        let resp = st.poll_transmit(due).unwrap().to_vec();
        let (t, _) = Telegram::parse(&resp).unwrap();
        let d = t.as_data().unwrap();
        assert_eq!((d.da, d.sa, d.data), (2, 8, &[1u8, 2][..]));
    }

    #[test]
    fn fcb_repeat_gets_stored_response_without_reexecution() {
        let mut st = station();
        let t = Instant::ZERO;
        let r1 = exchange(&mut st, t, &req(8, 2, true, false, &[1])).unwrap();
        let r2 = exchange(&mut st, t, &req(8, 2, false, true, &[2])).unwrap();
        // Retry of the second request (same FCB) with different data: the
        // stored response comes back, the request is not executed again.
        let r2b = exchange(&mut st, t, &req(8, 2, false, true, &[3])).unwrap();
        assert_eq!(r2, r2b);
        assert_ne!(r1, r2);
        assert_eq!(st.app().executed, 2);
        assert_eq!(st.stats().fcb_repeats, 1);
        // Toggled FCB: executed.
        let r3 = exchange(&mut st, t, &req(8, 2, true, true, &[4])).unwrap();
        assert_ne!(r3, r2);
        // Same FCB from another master is not a repeat.
        exchange(&mut st, t, &req(8, 3, true, true, &[5])).unwrap();
        assert_eq!(st.app().executed, 4);
    }

    #[test]
    fn fdl_status_and_foreign_addresses() {
        let mut st = station();
        let b = fdl_status(8, 1);
        let r = exchange(&mut st, Instant::ZERO, &b).unwrap();
        assert_eq!(r, vec![0x10, 0x01, 0x08, 0x00, 0x09, 0x16]);
        assert!(exchange(&mut st, Instant::ZERO, &req(9, 2, true, false, &[1])).is_none());
        assert_eq!(st.app().executed, 0);
    }
}
