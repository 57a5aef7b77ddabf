//! The active station (master side of layer 2): logical token ring,
//! GAP polling, token claiming, collision handling and the requester.
//!
//! States and rules (IEC 61158-4-3 §8 "MAC"; summarised in the Felser
//! PROFIBUS manual's state-machine chapter; where the standard's exact
//! rule was not available the source is named):
//!
//! - **Offline**: does nothing (entered after an address collision).
//! - **Listen_Token**: watches token telegrams and learns the list of
//!   active stations (LAS): one full rotation (the same sender seen twice),
//!   verified by a second identical rotation (profirust's procedure).
//!   Answers FDL Status "not ready" (FC 0x10) until the LAS is valid and
//!   the request comes from its predecessor PS; then "ready for ring"
//!   (0x20) and goes to Active_Idle, where the token will reach it. Two
//!   token telegrams *sent from its own address* mean the address is in
//!   use: the station goes Offline (standard: duplicate address in
//!   Listen_Token).
//! - **Active_Idle**: in the ring; answers FDL Status with 0x30; keeps the
//!   LAS up to date from observed token passes (stations strictly between
//!   sender and receiver are not in the ring); a token addressed to it
//!   starts Use_Token. A frame from another station carrying its own
//!   address as source is an address collision: it leaves the ring and
//!   listens again (profirust leaves the ring; the second time in a row it
//!   goes Offline).
//! - **Claim_Token**: after TTO = 6·TSL + 2·n·TSL of silence (n = own
//!   address, so the lowest address claims first; profirust) the station
//!   sends the token to itself twice and uses it. The LAS learnt so far
//!   stays valid.
//! - **Use_Token**: the token hold time is TTH = TTR − TRR, where TRR is
//!   the real rotation time measured from the previous arrival. While TTH
//!   remains, the application's message cycles run; when the token arrives
//!   late, exactly one high-priority cycle is still allowed. Every cycle
//!   starts after the idle time TID1 (TID2 after an unacknowledged
//!   request).
//! - **Await_Data_Response**: the slot timer runs TSL from the end of the
//!   request. No start of a reply, or a corrupt one, means a retry with the
//!   same FCB, up to the retry limit; then "no response", and the remote
//!   station counts as non-operational: its next request is a first frame
//!   (FCV = 0, FCB = 1) without retries until it answers again
//!   (IEC 61158-4-3).
//! - **GAP update**: with time left after the cycles, one FDL Status
//!   request per token visit to the next address between this station and
//!   its successor NS (wrapping at HSA), not repeated when unanswered (as
//!   profirust does), awaited for TSL plus at most 1 ms of the latency
//!   allowance. A station answering "ready for
//!   ring" or "in ring" becomes the new NS. After a whole sweep the station
//!   waits G rotations (GAP factor) before sweeping again. A master that
//!   answers "not ready" (still in Listen_Token) is polled again on the
//!   next visits, up to G times, before the sweep goes on, so that a
//!   master switched on joins a few rotations after it is ready rather
//!   than a whole sweep later (see `Core::gap_recheck_address`).
//! - **Pass_Token / Check_Token_Pass**: the token telegram `DC NS TS`; NS
//!   must start transmitting within TSL. The pass is repeated up to
//!   `token_retry` times, then NS is removed from the LAS and the next
//!   station in the LAS is tried. A lone master passes the token to itself
//!   (Felser).
//! - **Duplicate token**: a frame from another station arriving while this
//!   station holds the token (other than the awaited reply) means a second
//!   token exists; this station drops its token and goes Active_Idle.
//!
//! Timeouts get an extra `latency_allowance` for transports that add
//! latency (ptys, USB adapters): one allowance on the slot time and the
//! token-pass check, 3 + n on the token-lost timeout of address n (see
//! [`ActiveConfig::token_lost_timeout`]). On the simulator it is zero.
//! A transport that hands a telegram over only once its last character
//! has crossed the wire ([`ActiveConfig::whole_telegrams`]: a paced `dpctl
//! bus`, a serial device server) delays the first character of every
//! answer by the answer's own wire time, which the standard's slot time
//! (measured to the first character) does not contain. The wait for an
//! answer then also allows for the wire time of the longest answer *that
//! request* can get ([`Request::longest_answer`]: 6 characters for FDL
//! Status, the caller's [`Request::max_reply_len`] for an SRD), never for
//! the longest telegram: a station silent at 19.2 kbit/s costs 14 ms per
//! attempt, not 160 ms. A reply that comes after its request's wait (after
//! the retry, or after giving up) is counted
//! ([`ActiveStats::late_replies`], [`MasterApp::on_late_reply`]) and
//! dropped; it never answers a later request of another station or with
//! other SAPs (see `reply_matches`).

use super::{earliest, RxPath, Station};
#[allow(unused_imports)]
use crate::prelude::*;
use crate::time::Instant;
use crate::timing::BusParams;
use crate::wire::{
    consts, DataTelegram, FunctionCode, RequestKind, ResponseStatus, StationType, Telegram,
};
use core::time::Duration;

/// Configuration of an active station.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ActiveConfig {
    /// This station's address TS (0..=125).
    pub address: u8,
    /// Bus parameters.
    pub params: BusParams,
    /// Added to the slot time, token-pass check and token-lost timeout to
    /// cover the latency of the transport (a pty: a few ms; a USB adapter
    /// or a serial device server: 20 ms); zero on the simulator.
    pub latency_allowance: Duration,
    /// The transport hands each telegram over only once its last
    /// character has crossed the wire (a paced `dpctl bus`, a serial
    /// device server), so an answer's first character comes its whole
    /// wire time later than on a line: every wait for a telegram also
    /// allows for the wire time of the longest telegram that can come (per
    /// request: [`Request::longest_answer`]). False on a serial line and on
    /// the simulator, which deliver character by character.
    pub whole_telegrams: bool,
    /// Repetitions of a token pass the successor does not take before it
    /// is removed from the LAS.
    pub token_retry: u8,
}

impl ActiveConfig {
    /// The silence after which this station claims the token: the
    /// standard's TTO = 6·TSL + 2·n·TSL (n = own address) plus 3 + n
    /// latency allowances.
    ///
    /// Three allowances because the line may be silent for a slot time
    /// plus one allowance while any station awaits a reply, and scheduling
    /// jitter on a slow transport must not make a station claim a token
    /// that is not lost. One more per address because the standard's step
    /// of 2·TSL between the timeouts of neighbouring addresses (0.4 ms at
    /// 1.5 Mbit/s) is what lets the claim of the lowest address reach the
    /// next one before that one's own timeout runs out; behind a transport
    /// with latency (a pty, a USB adapter) the claim arrives up to an
    /// allowance later, and without the extra step the next address
    /// claims as well (issue 18: in a 3-master ring on `dpctl bus`, master
    /// 4 claimed next to master 3 in about a third of the runs).
    ///
    /// With [`ActiveConfig::whole_telegrams`] each allowance also holds
    /// the wire time of the longest telegram: while any telegram crosses
    /// such a transport, the other stations see silence.
    pub fn token_lost_timeout(&self) -> Duration {
        let n = self.address.min(125) as u32;
        self.params
            .bits(self.params.token_lost_timeout(n as u8) as u64)
            + (3 + n) * self.telegram_allowance(consts::MAX_TELEGRAM_LEN)
    }

    /// The allowance on a wait for a telegram of up to `chars` characters:
    /// the transport's latency, plus the telegram's wire time when the
    /// transport hands over whole telegrams.
    pub fn telegram_allowance(&self, chars: usize) -> Duration {
        let wire = if self.whole_telegrams {
            self.params.baud.chars_to_duration(chars as u64)
        } else {
            Duration::ZERO
        };
        self.latency_allowance + wire
    }

    /// Configuration with default token retry (1) and no latency allowance.
    pub fn new(address: u8, params: BusParams) -> Self {
        ActiveConfig {
            address,
            params,
            latency_allowance: Duration::ZERO,
            whole_telegrams: false,
            token_retry: 1,
        }
    }
}

/// FDL service of a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Service {
    /// Send and Request Data, high priority.
    SrdHigh,
    /// Send and Request Data, low priority.
    SrdLow,
    /// Send Data with Acknowledge, high priority.
    SdaHigh,
    /// Send Data with Acknowledge, low priority.
    SdaLow,
    /// Send Data with No acknowledge, high priority.
    SdnHigh,
    /// Send Data with No acknowledge, low priority.
    SdnLow,
    /// Request FDL Status.
    FdlStatus,
}

impl Service {
    fn kind(self) -> RequestKind {
        match self {
            Service::SrdHigh => RequestKind::SrdHigh,
            Service::SrdLow => RequestKind::SrdLow,
            Service::SdaHigh => RequestKind::SdaHigh,
            Service::SdaLow => RequestKind::SdaLow,
            Service::SdnHigh => RequestKind::SdnHigh,
            Service::SdnLow => RequestKind::SdnLow,
            Service::FdlStatus => RequestKind::FdlStatus,
        }
    }

    /// Whether the service has high priority.
    pub fn is_high(self) -> bool {
        matches!(self, Service::SrdHigh | Service::SdaHigh | Service::SdnHigh)
    }
}

/// A request the application wants sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Request<'a> {
    /// Destination (127 = broadcast, never answered).
    pub da: u8,
    /// FDL service.
    pub service: Service,
    /// Destination SAP (None = default SAP).
    pub dsap: Option<u8>,
    /// Source SAP.
    pub ssap: Option<u8>,
    /// Data unit.
    pub data: &'a [u8],
    /// The longest data unit (bytes after the SAPs) an answer to this SRD
    /// can carry, when the requester knows it (DP: the configured input
    /// length for Data_Exchange, 244 for Slave_Diag); `None` allows for
    /// the longest telegram. Ignored for other services, whose answers
    /// have a fixed length. Sets the wait for the answer on a transport
    /// with [`ActiveConfig::whole_telegrams`]; an answer that is longer
    /// is still taken when it comes in time.
    pub max_reply_len: Option<u8>,
}

impl Request<'_> {
    /// Characters of the longest telegram that can answer this request:
    /// 0 for SDN (no answer), 6 for FDL Status and SDA (an SD1 reply; a
    /// short acknowledge is 1), for SRD an SD2 telegram with the request's
    /// SAPs swapped and [`Request::max_reply_len`] bytes of data (at least
    /// the 6 of an SD1 "no data" reply; the longest telegram, 255, when
    /// unknown).
    pub fn longest_answer(&self) -> usize {
        const SD1_LEN: usize = 6;
        match self.service {
            Service::SdnHigh | Service::SdnLow => 0,
            Service::FdlStatus | Service::SdaHigh | Service::SdaLow => SD1_LEN,
            Service::SrdHigh | Service::SrdLow => match self.max_reply_len {
                None => consts::MAX_TELEGRAM_LEN,
                Some(n) => {
                    let saps = self.dsap.is_some() as usize + self.ssap.is_some() as usize;
                    match saps + n as usize {
                        0 => SD1_LEN,
                        // SD2: SD LE LEr SD DA SA FC, the field, FCS ED.
                        field => (9 + field).min(consts::MAX_TELEGRAM_LEN),
                    }
                }
            },
        }
    }
}

/// How a message cycle ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome<'a> {
    /// A response telegram.
    Response {
        /// Response status (DL, DH, RS, UE, …).
        status: ResponseStatus,
        /// Responder's station type.
        station: StationType,
        /// DSAP of the response.
        dsap: Option<u8>,
        /// SSAP of the response.
        ssap: Option<u8>,
        /// Data unit, borrowed from the receive buffer.
        data: &'a [u8],
    },
    /// A short acknowledge (SC).
    ShortAck,
    /// An unacknowledged request (SDN, broadcast) went out.
    Sent,
    /// No valid reply after all retries.
    NoResponse,
}

/// Result of one message cycle, handed to [`MasterApp::on_result`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CycleResult<'a> {
    /// The destination of the request.
    pub da: u8,
    /// The service requested.
    pub service: Service,
    /// How it ended.
    pub outcome: Outcome<'a>,
    /// Retries it took.
    pub retries: u8,
}

/// What the station tells its application about the ring.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize),
    serde(rename_all = "snake_case")
)]
pub enum FdlEvent {
    /// The station took part in the ring for the first time (or again).
    EnteredRing,
    /// The station left the ring (collision, duplicate token).
    LeftRing,
    /// The station claimed a lost token.
    TokenClaimed,
    /// A master joined after a GAP poll; it is the new successor.
    StationJoined(u8),
    /// The successor did not take the token and was removed from the LAS.
    StationRemoved(u8),
    /// Another station uses this station's address; the station is now
    /// Offline.
    AddressInUse,
    /// A frame from another station with this station's source address.
    AddressCollision,
    /// A second token was detected; this station dropped its own.
    DuplicateToken,
    /// Answers from this address keep arriving garbled (codec errors while
    /// its reply was due, [`DUPLICATE_GARBLED`] attempts in a row) or twice
    /// to one request ([`DUPLICATE_TWICE`] times): most likely two
    /// stations answer at this address. Reported once per address.
    DuplicateAddress(u8),
    /// Answer to a GAP poll (`None`: nobody answered).
    GapStatus {
        /// Address polled.
        address: u8,
        /// Station type of the answer.
        station: Option<StationType>,
    },
}

impl core::fmt::Display for FdlEvent {
    /// The event in words, as `dpctl` prints it.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            FdlEvent::GapStatus {
                address,
                station: None,
            } => write!(f, "station {address} no longer answers"),
            FdlEvent::GapStatus {
                address,
                station: Some(t),
            } => write!(f, "station {address} found: {}", t.describe()),
            FdlEvent::EnteredRing => f.write_str("in the token ring"),
            FdlEvent::LeftRing => f.write_str("left the token ring"),
            FdlEvent::TokenClaimed => f.write_str("claimed the token"),
            FdlEvent::StationJoined(a) => write!(f, "master {a} joined the ring"),
            FdlEvent::StationRemoved(a) => write!(f, "master {a} left the ring"),
            FdlEvent::AddressInUse => f.write_str("another station uses this address: offline"),
            FdlEvent::AddressCollision => f.write_str("address collision"),
            FdlEvent::DuplicateToken => f.write_str("duplicate token dropped"),
            FdlEvent::DuplicateAddress(a) => write!(
                f,
                "possible duplicate address {a}: its answers arrive garbled or twice"
            ),
        }
    }
}

/// What the application may do with the token at the moment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TokenContext {
    /// Now.
    pub now: Instant,
    /// The token came late: only one high-priority cycle is allowed.
    pub high_only: bool,
    /// End of the token hold time.
    pub hold_until: Instant,
    /// Cycles already done in this token visit.
    pub cycles: u32,
    /// No other master is in the ring (the next station NS is this
    /// station): the token only ever comes back here, so the application
    /// may start further cycles while the token hold time lasts instead
    /// of passing the token to itself after each of its polls.
    pub alone: bool,
}

/// The application behind an active station (the DP master core, a live
/// list scanner, …).
pub trait MasterApp {
    /// The station holds the token and may start a message cycle. Return
    /// the next request, or `None` to end this token visit.
    fn poll_request(&mut self, ctx: &TokenContext) -> Option<Request<'_>>;

    /// Asked when [`MasterApp::poll_request`] returned `None` while the
    /// station is alone in the ring ([`TokenContext::alone`]) with token
    /// hold time left: when the application will have its next request
    /// (e.g. once a slave's Min_Slave_Interval has run out). When that is
    /// within one slot time TSL and the token hold time, the station keeps
    /// the token and the line idle until then and asks again, instead of
    /// passing the token to itself (token telegram, TID1, and its GAP
    /// poll). An idle line shorter than TSL is far from any station's
    /// token-loss timeout (TTO ≥ 6 TSL, IEC 61158-4-3). `None` (the
    /// default): pass the token.
    fn next_request_at(&self, _ctx: &TokenContext) -> Option<Instant> {
        None
    }

    /// A message cycle ended.
    fn on_result(&mut self, now: Instant, result: &CycleResult<'_>);

    /// Something happened to the ring.
    fn on_event(&mut self, _now: Instant, _event: FdlEvent) {}

    /// A reply addressed to this station came when no request awaited it
    /// (after its request's wait ran out: the retry went out, or the
    /// request got no response) or did not fit the pending request; it
    /// was dropped and counted in [`ActiveStats::late_replies`]. `from`
    /// is the sender (`None` for a short acknowledge, which names none).
    fn on_late_reply(&mut self, _now: Instant, _from: Option<u8>) {}
}

/// Externally visible state of the station.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RingState {
    /// Not taking part.
    Offline,
    /// Learning the LAS.
    ListenToken,
    /// In the ring, waiting for the token.
    ActiveIdle,
    /// Holding the token.
    UseToken,
    /// Claiming a lost token.
    ClaimToken,
    /// Checking that the successor took the token.
    CheckTokenPass,
}

/// Garbled replies in a row from one address after which it is reported
/// as a possible duplicate ([`FdlEvent::DuplicateAddress`]). Two stations
/// answering at once garble every reply; line noise rarely garbles this
/// many in a row.
pub const DUPLICATE_GARBLED: u8 = 6;
/// Second replies to one request from one address after which it is
/// reported as a possible duplicate. Replies to retried requests do not
/// count (the first answer may just have been late).
pub const DUPLICATE_TWICE: u8 = 3;

/// Counters of an active station.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ActiveStats {
    /// Tokens received (including passes to itself).
    pub tokens: u64,
    /// Token passes sent (including repeats).
    pub token_passes: u64,
    /// Message cycles completed (any outcome).
    pub cycles: u64,
    /// Request repetitions.
    pub retries: u64,
    /// Cycles that ended without response.
    pub no_response: u64,
    /// GAP polls sent.
    pub gap_polls: u64,
    /// Tokens claimed.
    pub claims: u64,
    /// Address collisions detected.
    pub collisions: u64,
    /// Duplicate tokens detected.
    pub duplicate_tokens: u64,
    /// Replies addressed to this station that came after their request's
    /// wait ran out (or did not fit the pending request) and were dropped.
    pub late_replies: u64,
    /// Signs of two stations at one address: attempts whose reply was
    /// garbled, and second replies to one request.
    pub duplicate_address_signs: u64,
    /// Shortest real rotation time (ns).
    pub rotation_min_ns: u64,
    /// Longest real rotation time (ns).
    pub rotation_max_ns: u64,
    /// Sum of real rotation times (ns), for the average.
    pub rotation_sum_ns: u64,
    /// Rotations measured.
    pub rotations: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Offline,
    ListenToken,
    ActiveIdle,
    UseToken { wake: Instant },
    AwaitResponse { deadline: Instant },
    AwaitStatus { address: u8, deadline: Instant },
    CheckTokenPass { attempts: u8, deadline: Instant },
    ClaimToken { sent: u8, wake: Instant },
}

#[derive(Debug, Clone, Copy)]
struct Remote {
    /// FCB to send next.
    fcb: bool,
    /// Whether FCV is set (false: the next request is a first frame).
    fcv: bool,
    /// Whether the station answered its last request (retries allowed).
    operational: bool,
}

const REMOTE_INIT: Remote = Remote {
    fcb: true,
    fcv: false,
    operational: true,
};

#[derive(Debug, Clone, Copy)]
struct Pending {
    da: u8,
    service: Service,
    attempts: u8,
    max_retries: u8,
    len: usize,
    /// How long after the end of the request its answer is awaited.
    wait: Duration,
    /// SAPs of the request; a reply carries them swapped.
    dsap: Option<u8>,
    ssap: Option<u8>,
}

impl Pending {
    /// The result of a request that got no answer.
    fn no_response(&self) -> CycleResult<'static> {
        CycleResult {
            da: self.da,
            service: self.service,
            outcome: Outcome::NoResponse,
            retries: self.attempts,
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Listen {
    first_sa: Option<u8>,
    seen: [bool; 128],
    candidate: Option<[bool; 128]>,
    own_tokens: u8,
}

impl Default for Listen {
    fn default() -> Self {
        Listen {
            first_sa: None,
            seen: [false; 128],
            candidate: None,
            own_tokens: 0,
        }
    }
}

#[derive(Debug)]
struct Core {
    cfg: ActiveConfig,
    state: State,
    las: [bool; 128],
    las_valid: bool,
    ns: u8,
    ps: u8,
    listen: Listen,
    tx: [u8; consts::MAX_TELEGRAM_LEN],
    tx_len: usize,
    tx_at: Option<Instant>,
    req: [u8; consts::MAX_TELEGRAM_LEN],
    pending: Option<Pending>,
    remote: [Remote; 128],
    line_free_at: Instant,
    last_activity: Instant,
    last_token: Option<Instant>,
    hold_until: Instant,
    cycles_this_visit: u32,
    gap_polled_this_visit: bool,
    gap_next: u8,
    gap_wait: u8,
    /// A master that answered the GAP poll "not ready" (still in
    /// Listen_Token) and how many more visits it is polled again before
    /// the sweep goes on.
    gap_recheck: Option<(u8, u8)>,
    collisions_in_row: u8,
    was_in_ring: bool,
    stats: ActiveStats,
    /// Per address: garbled replies in a row, second replies seen, and
    /// whether it was reported as a possible duplicate.
    duplicate: [DuplicateSigns; 128],
    /// The station whose reply completed the last cycle at the first
    /// attempt: a second reply from it means two stations answered.
    last_answered: Option<u8>,
}

/// Signs of two stations at one address.
#[derive(Debug, Clone, Copy, Default)]
struct DuplicateSigns {
    garbled_in_row: u8,
    twice: u8,
    reported: bool,
}

/// An active FDL station driving a [`MasterApp`]; see the module docs.
#[derive(Debug)]
pub struct ActiveStation<A> {
    rx: RxPath,
    core: Core,
    app: A,
}

impl<A: MasterApp> ActiveStation<A> {
    /// A station that starts listening for the token at time zero.
    pub fn new(cfg: ActiveConfig, app: A) -> Self {
        let slack = cfg.params.slot_duration() + cfg.telegram_allowance(consts::MAX_TELEGRAM_LEN);
        let ts = cfg.address.min(125);
        ActiveStation {
            rx: RxPath::new(cfg.params.baud, slack),
            core: Core {
                cfg: ActiveConfig { address: ts, ..cfg },
                state: State::ListenToken,
                las: [false; 128],
                las_valid: false,
                ns: ts,
                ps: ts,
                listen: Listen::default(),
                tx: [0; consts::MAX_TELEGRAM_LEN],
                tx_len: 0,
                tx_at: None,
                req: [0; consts::MAX_TELEGRAM_LEN],
                pending: None,
                remote: [REMOTE_INIT; 128],
                line_free_at: Instant::ZERO,
                last_activity: Instant::ZERO,
                last_token: None,
                hold_until: Instant::ZERO,
                cycles_this_visit: 0,
                gap_polled_this_visit: false,
                gap_next: next_addr(ts, cfg.params.hsa),
                gap_wait: 0,
                gap_recheck: None,
                collisions_in_row: 0,
                was_in_ring: false,
                stats: ActiveStats::default(),
                duplicate: [DuplicateSigns::default(); 128],
                last_answered: None,
            },
            app,
        }
    }

    /// Restart listening for the token at `now` (e.g. after Offline).
    pub fn restart(&mut self, now: Instant) {
        let c = &mut self.core;
        c.state = State::ListenToken;
        c.listen = Listen::default();
        c.las = [false; 128];
        c.las_valid = false;
        c.gap_recheck = None;
        c.last_activity = now;
        c.pending = None;
        c.tx_at = None;
    }

    /// The application.
    pub fn app(&self) -> &A {
        &self.app
    }

    /// The application, mutable.
    pub fn app_mut(&mut self) -> &mut A {
        &mut self.app
    }

    /// The configuration.
    pub fn config(&self) -> &ActiveConfig {
        &self.core.cfg
    }

    /// Where the station is in the ring.
    pub fn ring_state(&self) -> RingState {
        match self.core.state {
            State::Offline => RingState::Offline,
            State::ListenToken => RingState::ListenToken,
            State::ActiveIdle => RingState::ActiveIdle,
            State::UseToken { .. } | State::AwaitResponse { .. } | State::AwaitStatus { .. } => {
                RingState::UseToken
            }
            State::CheckTokenPass { .. } => RingState::CheckTokenPass,
            State::ClaimToken { .. } => RingState::ClaimToken,
        }
    }

    /// The list of active stations as this station knows it.
    pub fn las(&self) -> impl Iterator<Item = u8> + '_ {
        (0..=126u8).filter(|&a| self.core.las[a as usize])
    }

    /// The successor NS.
    pub fn next_station(&self) -> u8 {
        self.core.ns
    }

    /// The predecessor PS.
    pub fn previous_station(&self) -> u8 {
        self.core.ps
    }

    /// Counters.
    pub fn stats(&self) -> ActiveStats {
        self.core.stats
    }

    /// Codec error counters of the receive path.
    pub fn codec_stats(&self) -> crate::codec::CodecStats {
        self.rx.stats()
    }

    fn process(&mut self, now: Instant) {
        loop {
            // Codec errors while a reply is due: that reply was garbled.
            let awaiting = self.core.awaiting();
            let errors = self.rx.stats().errors();
            let got = match self.rx.next_telegram() {
                Some(t) => {
                    self.core.on_telegram(now, &t, &mut self.app);
                    true
                }
                None => false,
            };
            if let Some(da) = awaiting.filter(|_| self.rx.stats().errors() > errors) {
                self.core.garbled_reply(now, da, &mut self.app);
            }
            if !got {
                return;
            }
        }
    }
}

impl<A: MasterApp> Station for ActiveStation<A> {
    fn handle_rx(&mut self, now: Instant, bytes: &[u8]) {
        if matches!(self.core.state, State::Offline) {
            return;
        }
        self.core.last_activity = self.core.last_activity.max(now);
        self.rx.push(now, bytes);
        self.process(now);
    }

    fn handle_timeout(&mut self, now: Instant) {
        let awaiting = self.core.awaiting();
        let errors = self.rx.stats().errors();
        self.rx.handle_idle(now);
        if let Some(da) = awaiting.filter(|_| self.rx.stats().errors() > errors) {
            self.core.garbled_reply(now, da, &mut self.app);
        }
        self.process(now);
        let receiving = self.rx.receiving();
        self.core.on_timeout(now, receiving, &mut self.app);
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<&[u8]> {
        let c = &mut self.core;
        match c.tx_at {
            Some(t) if t <= now && c.tx_len > 0 => {
                c.tx_at = None;
                // Sent late (the driver woke after `t`): everything timed
                // from this telegram's end moves with it, so that the next
                // telegram still keeps its idle time (TID1 ≥ TSYN) after it.
                c.delay_timers(now - t);
                Some(&c.tx[..c.tx_len])
            }
            _ => None,
        }
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let c = &self.core;
        if self.rx.receiving() {
            // Every state timer waits for the line to be quiet; the receive
            // path's idle deadline comes first.
            return earliest(c.tx_at, self.rx.idle_deadline());
        }
        let state = match c.state {
            State::Offline => None,
            State::ListenToken | State::ActiveIdle => {
                Some(c.last_activity + c.token_lost_timeout())
            }
            State::UseToken { wake } | State::ClaimToken { wake, .. } => Some(wake),
            State::AwaitResponse { deadline }
            | State::AwaitStatus { deadline, .. }
            | State::CheckTokenPass { deadline, .. } => Some(deadline),
        };
        earliest(c.tx_at, state)
    }

    fn awaits_answer(&self) -> bool {
        matches!(
            self.core.state,
            State::AwaitResponse { .. } | State::AwaitStatus { .. } | State::CheckTokenPass { .. }
        )
    }
}

/// The address after `a`, wrapping after HSA to 0.
/// Whether a reply (already known to come from the station asked and to be
/// addressed to us) answers the pending request as far as SAPs go.
///
/// A reply carries the request's SAPs swapped; a request without SAPs (the
/// default SAP, e.g. Data_Exchange) is answered without SAPs. The only
/// exception: a negative acknowledge without data (UE, RR, RS, NR, RDL,
/// RDH) may omit the SAPs of a request that had them, as slave ASICs do
/// for a SAP that is not activated. A data reply without the SAPs, such as
/// a late Data_Exchange answer arriving while a Slave_Diag is pending, is
/// not an answer to this request.
///
/// The status must fit the service, too: an SRD is answered with data
/// (DL, DH, RDL, RDH), "no data" (NR) or a negative acknowledge, never with
/// the plain "OK" of an FDL Status reply or an SDA acknowledge (a late
/// answer to a GAP poll looks exactly like that); an SDA is answered with
/// OK or a negative acknowledge, never with data; an FDL Status with OK.
fn reply_matches(p: &Pending, d: &DataTelegram<'_>) -> bool {
    let FunctionCode::Response { status, .. } = d.fc else {
        return false;
    };
    let fits = match p.service {
        Service::SrdHigh | Service::SrdLow => status != ResponseStatus::Ok,
        Service::SdaHigh | Service::SdaLow => status == ResponseStatus::Ok || status.is_negative(),
        Service::FdlStatus => status == ResponseStatus::Ok,
        Service::SdnHigh | Service::SdnLow => false,
    };
    if !fits {
        return false;
    }
    if (d.dsap, d.ssap) == (p.ssap, p.dsap) {
        return true;
    }
    d.dsap.is_none()
        && d.ssap.is_none()
        && d.data.is_empty()
        && (status.is_negative() || status == ResponseStatus::Nr)
}

/// Whether `t` is a reply addressed to station `ts` (a response telegram
/// to it, or a short acknowledge, which names no one: only while `ts`
/// holds the token is it surely `ts`'s).
fn is_reply_to(t: &Telegram<'_>, ts: u8) -> bool {
    matches!(t, Telegram::ShortAck) || is_response_to(t, ts)
}

/// Whether `t` is a response telegram addressed to station `ts`.
fn is_response_to(t: &Telegram<'_>, ts: u8) -> bool {
    matches!(t, Telegram::Data(d) if !d.fc.is_request() && d.da == ts)
}

fn next_addr(a: u8, hsa: u8) -> u8 {
    if a >= hsa {
        0
    } else {
        a + 1
    }
}

impl Core {
    fn ts(&self) -> u8 {
        self.cfg.address
    }

    fn p(&self) -> &BusParams {
        &self.cfg.params
    }

    fn bits(&self, n: u32) -> Duration {
        self.cfg.params.bits(n as u64)
    }

    /// The wait for the first telegram of the successor after a token
    /// pass: the slot time plus the allowance for the longest telegram
    /// (the successor may start with any request).
    fn token_pass_slot(&self) -> Duration {
        self.bits(self.p().slot_time) + self.cfg.telegram_allowance(consts::MAX_TELEGRAM_LEN)
    }

    /// The wait for the answer to a request whose longest answer is
    /// `chars` characters: the slot time plus the allowance for it.
    fn answer_slot(&self, chars: usize) -> Duration {
        self.bits(self.p().slot_time) + self.cfg.telegram_allowance(chars)
    }

    /// The wait for the answer to a GAP poll: the slot time plus at most
    /// 1 ms of the latency allowance (plus the 6 characters of the FDL
    /// Status answer on a transport of whole telegrams). Most GAP
    /// addresses are empty, so this wait is paid on almost every poll; an
    /// answer that comes later only delays finding a new master to the
    /// next sweep (it is ignored as a late reply meanwhile).
    fn gap_slot(&self) -> Duration {
        let latency = self.cfg.latency_allowance.min(Duration::from_millis(1));
        let cfg = ActiveConfig {
            latency_allowance: latency,
            ..self.cfg
        };
        self.bits(self.p().slot_time) + cfg.telegram_allowance(6)
    }

    fn token_lost_timeout(&self) -> Duration {
        self.cfg.token_lost_timeout()
    }

    /// Distance from `from` to `to` going up and wrapping after HSA. An
    /// address above HSA (a foreign token pass, a station outside this
    /// ring's range) counts as HSA.
    fn dist(&self, from: u8, to: u8) -> u32 {
        let m = self.p().hsa.max(self.ts()) as u32 + 1;
        let (from, to) = ((from as u32).min(m - 1), (to as u32).min(m - 1));
        (to + m - from) % m
    }

    fn next_in_las(&self, from: u8) -> u8 {
        let mut a = next_addr(from, self.p().hsa.max(self.ts()));
        while a != self.ts() {
            if self.las[a as usize] {
                return a;
            }
            if a == from {
                break;
            }
            a = next_addr(a, self.p().hsa.max(self.ts()));
        }
        self.ts()
    }

    fn prev_in_las(&self) -> u8 {
        let mut best = self.ts();
        let mut best_d = 0;
        for a in 0..=126u8 {
            if self.las[a as usize] && a != self.ts() {
                let d = self.dist(a, self.ts());
                if best == self.ts() || d < best_d {
                    best = a;
                    best_d = d;
                }
            }
        }
        best
    }

    /// The telegram queued for `tx_at` leaves `late` after it: move the
    /// timers that were computed from its end.
    fn delay_timers(&mut self, late: Duration) {
        if late.is_zero() {
            return;
        }
        self.line_free_at += late;
        self.last_activity += late;
        match &mut self.state {
            State::UseToken { wake } | State::ClaimToken { wake, .. } => *wake += late,
            State::AwaitResponse { deadline }
            | State::AwaitStatus { deadline, .. }
            | State::CheckTokenPass { deadline, .. } => *deadline += late,
            State::Offline | State::ListenToken | State::ActiveIdle => {}
        }
    }

    /// Queue a telegram for transmission at `at`; returns when its last
    /// character will have left.
    fn send(&mut self, at: Instant, t: Telegram<'_>) -> Instant {
        self.tx_len = t.emit(&mut self.tx).unwrap_or(0);
        self.tx_at = Some(at);
        let end = at + self.p().baud.chars_to_duration(self.tx_len as u64);
        self.last_activity = self.last_activity.max(end);
        end
    }

    fn send_req_buffer(&mut self, at: Instant, len: usize) -> Instant {
        self.tx[..len].copy_from_slice(&self.req[..len]);
        self.tx_len = len;
        self.tx_at = Some(at);
        let end = at + self.p().baud.chars_to_duration(len as u64);
        self.last_activity = self.last_activity.max(end);
        end
    }

    fn fdl_status_reply_type(&self, sa: u8) -> Option<StationType> {
        match self.state {
            State::Offline => None,
            State::ListenToken => Some(if self.las_valid && sa == self.ps {
                StationType::ActiveReady
            } else {
                StationType::ActiveNotReady
            }),
            _ => Some(StationType::ActiveInRing),
        }
    }

    fn on_telegram<A: MasterApp>(&mut self, now: Instant, t: &Telegram<'_>, app: &mut A) {
        self.last_activity = self.last_activity.max(now);
        let ts = self.ts();
        let sa = match t {
            Telegram::Data(d) => Some(d.sa),
            Telegram::Token { sa, .. } => Some(*sa),
            Telegram::ShortAck => None,
        };
        // Our own address as the source of a frame we did not send.
        if sa == Some(ts) {
            match self.state {
                State::Offline => {}
                State::ListenToken => {
                    if matches!(t, Telegram::Token { .. }) {
                        self.listen.own_tokens += 1;
                        if self.listen.own_tokens >= 2 {
                            tracing::warn!(address = ts, "address in use, going offline");
                            self.state = State::Offline;
                            self.stats.collisions += 1;
                            app.on_event(now, FdlEvent::AddressInUse);
                        }
                    }
                }
                _ => {
                    self.stats.collisions += 1;
                    self.collisions_in_row += 1;
                    app.on_event(now, FdlEvent::AddressCollision);
                    self.drop_pending(now, app);
                    if self.collisions_in_row >= 2 {
                        self.state = State::Offline;
                        app.on_event(now, FdlEvent::AddressInUse);
                    } else {
                        self.state = State::ListenToken;
                        self.listen = Listen::default();
                        self.las_valid = false;
                        app.on_event(now, FdlEvent::LeftRing);
                    }
                }
            }
            return;
        }
        match self.state {
            State::Offline => {}
            State::ListenToken => self.listen_token(now, t, app),
            State::ActiveIdle => self.active_idle(now, t, app),
            State::ClaimToken { .. } => {
                // Someone else is active: give up the claim.
                self.state = State::ActiveIdle;
                self.active_idle(now, t, app);
            }
            State::CheckTokenPass { .. } if is_response_to(t, ts) => {
                // A late reply to one of our requests, not the successor
                // (which starts with a request or a token). A short
                // acknowledge names no one: it may answer the successor's
                // first request, so it ends the check as before.
                self.late_reply(now, t, app);
            }
            State::CheckTokenPass { .. } => {
                // The successor (or someone) started transmitting.
                self.state = State::ActiveIdle;
                self.active_idle(now, t, app);
            }
            State::AwaitResponse { .. } => {
                let p = self.pending.expect("pending request while awaiting");
                let outcome = match t {
                    Telegram::ShortAck => Some(Outcome::ShortAck),
                    // A reply to this request: from the station asked, to
                    // us, and matching the request's SAPs (see
                    // `reply_matches`). Anything else is a late or stray
                    // reply, counted and ignored.
                    Telegram::Data(d)
                        if !d.fc.is_request()
                            && d.da == ts
                            && d.sa == p.da
                            && reply_matches(&p, d) =>
                    {
                        let FunctionCode::Response { status, station } = d.fc else {
                            unreachable!()
                        };
                        Some(Outcome::Response {
                            status,
                            station,
                            dsap: d.dsap,
                            ssap: d.ssap,
                            data: d.data,
                        })
                    }
                    _ => None,
                };
                match outcome {
                    Some(o) => self.complete(now, o, app),
                    None => self.duplicate_token(now, t, app),
                }
            }
            State::AwaitStatus { address, .. } => match t {
                Telegram::Data(d) if !d.fc.is_request() && d.da == ts && d.sa == address => {
                    let FunctionCode::Response { station, .. } = d.fc else {
                        unreachable!()
                    };
                    app.on_event(
                        now,
                        FdlEvent::GapStatus {
                            address,
                            station: Some(station),
                        },
                    );
                    self.gap_recheck = match station {
                        StationType::ActiveNotReady => {
                            let left = match self.gap_recheck {
                                Some((a, n)) if a == address => n.saturating_sub(1),
                                _ => self.p().gap_factor,
                            };
                            (left > 0).then_some((address, left))
                        }
                        _ => None,
                    };
                    if matches!(
                        station,
                        StationType::ActiveReady | StationType::ActiveInRing
                    ) {
                        self.las[address as usize] = true;
                        self.ns = address;
                        app.on_event(now, FdlEvent::StationJoined(address));
                    }
                    self.line_free_at = now + self.bits(self.p().tid1());
                    self.state = State::UseToken {
                        wake: self.line_free_at,
                    };
                }
                _ => self.duplicate_token(now, t, app),
            },
            State::UseToken { .. } => self.duplicate_token(now, t, app),
        }
    }

    /// A frame arrived that is not the awaited reply while this station
    /// holds the token. A late reply addressed to this station (after its
    /// slot time ran out, e.g. on a slow transport) or a stray short
    /// acknowledge is ignored and counted; a token or a request from
    /// another station, or a reply to another master, means a second
    /// token exists.
    fn duplicate_token<A: MasterApp>(&mut self, now: Instant, t: &Telegram<'_>, app: &mut A) {
        if is_reply_to(t, self.ts()) {
            self.late_reply(now, t, app);
            return;
        }
        tracing::warn!(address = self.ts(), "duplicate token: dropping ours");
        self.stats.duplicate_tokens += 1;
        app.on_event(now, FdlEvent::DuplicateToken);
        self.drop_pending(now, app);
        self.state = State::ActiveIdle;
        self.active_idle(now, t, app);
    }

    /// Count and drop a reply addressed to this station that no request
    /// awaits (see [`is_reply_to`]).
    fn late_reply<A: MasterApp>(&mut self, now: Instant, t: &Telegram<'_>, app: &mut A) {
        let from = match t {
            Telegram::Data(d) => Some(d.sa),
            _ => None,
        };
        if let Some(sa) = from.filter(|&sa| self.last_answered == Some(sa)) {
            self.last_answered = None;
            self.second_reply(now, sa, app);
        }
        self.stats.late_replies += 1;
        tracing::debug!(address = self.ts(), from, "late reply dropped");
        app.on_late_reply(now, from);
    }

    /// The station asked for a reply is `da`, if one is due now.
    fn awaiting(&self) -> Option<u8> {
        match self.state {
            State::AwaitResponse { .. } => self.pending.map(|p| p.da),
            _ => None,
        }
    }

    /// The reply due from `da` arrived garbled (bad FCS, length or
    /// delimiter).
    fn garbled_reply<A: MasterApp>(&mut self, now: Instant, da: u8, app: &mut A) {
        self.stats.duplicate_address_signs += 1;
        let d = &mut self.duplicate[da as usize & 0x7F];
        d.garbled_in_row = d.garbled_in_row.saturating_add(1);
        if d.garbled_in_row >= DUPLICATE_GARBLED {
            self.report_duplicate(now, da, app);
        }
    }

    /// A second reply from `da` to a request it already answered.
    fn second_reply<A: MasterApp>(&mut self, now: Instant, da: u8, app: &mut A) {
        self.stats.duplicate_address_signs += 1;
        let d = &mut self.duplicate[da as usize & 0x7F];
        d.twice = d.twice.saturating_add(1);
        if d.twice >= DUPLICATE_TWICE {
            self.report_duplicate(now, da, app);
        }
    }

    fn report_duplicate<A: MasterApp>(&mut self, now: Instant, da: u8, app: &mut A) {
        let d = &mut self.duplicate[da as usize & 0x7F];
        if !d.reported {
            d.reported = true;
            tracing::warn!(address = da, "possible duplicate address");
            app.on_event(now, FdlEvent::DuplicateAddress(da));
        }
    }

    fn drop_pending<A: MasterApp>(&mut self, now: Instant, app: &mut A) {
        if let Some(p) = self.pending.take() {
            self.stats.cycles += 1;
            self.stats.no_response += 1;
            app.on_result(now, &p.no_response());
        }
        self.tx_at = None;
    }

    /// Answer an FDL Status request (or refuse other services) addressed
    /// to this station. Returns whether the telegram was such a request.
    fn answer_request(&mut self, now: Instant, d: &DataTelegram<'_>) -> Option<StationType> {
        let FunctionCode::Request { kind, .. } = d.fc else {
            return None;
        };
        if d.da != self.ts() || !kind.expects_reply() {
            return None;
        }
        let station = self.fdl_status_reply_type(d.sa)?;
        let status = if kind == RequestKind::FdlStatus {
            ResponseStatus::Ok
        } else {
            ResponseStatus::Rs
        };
        let at = now + self.bits(self.p().min_tsdr);
        self.send(
            at,
            Telegram::Data(DataTelegram {
                da: d.sa,
                sa: self.ts(),
                fc: FunctionCode::Response { status, station },
                dsap: d.ssap,
                ssap: d.dsap,
                data: &[],
                format: None,
            }),
        );
        (kind == RequestKind::FdlStatus).then_some(station)
    }

    fn listen_token<A: MasterApp>(&mut self, now: Instant, t: &Telegram<'_>, _app: &mut A) {
        match *t {
            Telegram::Token { da, sa } => {
                // A token for our address while we listen is not ours to
                // take: we enter the ring only through the predecessor's
                // FDL Status invitation (it may also belong to another
                // station with our address, which we are about to detect).
                self.observe_pass(sa, da);
                let l = &mut self.listen;
                match l.first_sa {
                    None => {
                        l.first_sa = Some(sa);
                        l.seen = [false; 128];
                        l.seen[sa as usize] = true;
                    }
                    Some(first) if first == sa => {
                        // One rotation complete.
                        let seen = l.seen;
                        if l.candidate == Some(seen) {
                            self.las = seen;
                            self.las_valid = true;
                            self.ps = self.prev_in_las();
                            self.ns = self.next_in_las(self.ts());
                        } else {
                            l.candidate = Some(seen);
                        }
                        let l = &mut self.listen;
                        l.seen = [false; 128];
                        l.seen[sa as usize] = true;
                    }
                    Some(_) => l.seen[sa as usize] = true,
                }
                if self.las_valid {
                    self.las[sa as usize] = true;
                    self.las[da as usize] = true;
                    self.ps = self.prev_in_las();
                }
            }
            Telegram::Data(ref d) => {
                if let Some(StationType::ActiveReady) = self.answer_request(now, d) {
                    // Ready for the ring: the predecessor passes the token next.
                    self.state = State::ActiveIdle;
                }
            }
            Telegram::ShortAck => {}
        }
    }

    /// A token passed from `sa` to `da` by other stations: both are in the
    /// ring, stations strictly between them are not.
    fn observe_pass(&mut self, sa: u8, da: u8) {
        if !self.las_valid {
            return;
        }
        self.las[sa as usize] = true;
        self.las[da as usize] = true;
        let span = self.dist(sa, da);
        let mut a = sa;
        for _ in 1..span {
            a = next_addr(a, self.p().hsa.max(self.ts()));
            if a != self.ts() {
                self.las[a as usize] = false;
            }
        }
    }

    fn active_idle<A: MasterApp>(&mut self, now: Instant, t: &Telegram<'_>, app: &mut A) {
        if is_response_to(t, self.ts()) {
            // An answer to one of our requests after the token went on
            // (a short acknowledge here is another master's).
            self.late_reply(now, t, app);
            return;
        }
        match *t {
            Telegram::Token { da, sa } => {
                if da == self.ts() {
                    self.las[sa as usize] = true;
                    self.token_received(now, sa);
                } else {
                    self.observe_pass(sa, da);
                }
            }
            Telegram::Data(ref d) => {
                self.answer_request(now, d);
            }
            Telegram::ShortAck => {}
        }
    }

    fn token_received(&mut self, now: Instant, from: u8) {
        self.ps = from;
        self.las[self.ts() as usize] = true;
        if !self.las[self.ns as usize] || self.ns == self.ts() {
            self.ns = self.next_in_las(self.ts());
        }
        self.begin_token_use(now);
    }

    fn begin_token_use(&mut self, now: Instant) {
        self.stats.tokens += 1;
        self.collisions_in_row = 0;
        let ttr = self.bits(self.p().ttr);
        if let Some(prev) = self.last_token {
            let trr = (now - prev).as_nanos() as u64;
            let s = &mut self.stats;
            s.rotation_min_ns = if s.rotations == 0 {
                trr
            } else {
                s.rotation_min_ns.min(trr)
            };
            s.rotation_max_ns = s.rotation_max_ns.max(trr);
            s.rotation_sum_ns += trr;
            s.rotations += 1;
            self.hold_until = prev + ttr;
        } else {
            self.hold_until = now + ttr;
        }
        self.last_token = Some(now);
        self.cycles_this_visit = 0;
        self.gap_polled_this_visit = false;
        self.line_free_at = now + self.bits(self.p().tid1());
        self.state = State::UseToken {
            wake: self.line_free_at,
        };
    }

    fn on_timeout<A: MasterApp>(&mut self, now: Instant, receiving: bool, app: &mut A) {
        match self.state {
            State::Offline => {}
            State::ListenToken | State::ActiveIdle => {
                if !receiving && now >= self.last_activity + self.token_lost_timeout() {
                    tracing::debug!(address = self.ts(), "token lost, claiming");
                    if !self.las_valid {
                        self.las = [false; 128];
                        self.las_valid = true;
                    }
                    self.state = State::ClaimToken { sent: 0, wake: now };
                    self.on_timeout(now, receiving, app);
                }
            }
            State::ClaimToken { sent, wake } => {
                if now < wake {
                    return;
                }
                let ts = self.ts();
                let end = self.send(now, Telegram::Token { da: ts, sa: ts });
                if sent == 0 {
                    self.state = State::ClaimToken {
                        sent: 1,
                        wake: end + self.bits(self.p().tid1()),
                    };
                } else {
                    self.stats.claims += 1;
                    self.las[ts as usize] = true;
                    self.ns = self.next_in_las(ts);
                    app.on_event(now, FdlEvent::TokenClaimed);
                    self.begin_token_use(end);
                }
            }
            State::UseToken { wake } => {
                if now >= wake {
                    if !self.was_in_ring {
                        self.was_in_ring = true;
                        app.on_event(now, FdlEvent::EnteredRing);
                    }
                    self.next_action(now, app);
                }
            }
            State::AwaitResponse { deadline } => {
                if now >= deadline && !receiving {
                    self.attempt_failed(now, app);
                }
            }
            State::AwaitStatus { address, deadline } => {
                if now >= deadline && !receiving {
                    if self.gap_recheck.is_some_and(|(a, _)| a == address) {
                        self.gap_recheck = None;
                    }
                    app.on_event(
                        now,
                        FdlEvent::GapStatus {
                            address,
                            station: None,
                        },
                    );
                    self.state = State::UseToken { wake: now };
                    self.next_action(now, app);
                }
            }
            State::CheckTokenPass { attempts, deadline } => {
                if now >= deadline && !receiving {
                    if attempts < self.cfg.token_retry {
                        self.pass_token(now, attempts + 1);
                    } else {
                        let dead = self.ns;
                        tracing::info!(
                            address = self.ts(),
                            dead,
                            "successor does not take the token"
                        );
                        self.las[dead as usize] = false;
                        app.on_event(now, FdlEvent::StationRemoved(dead));
                        self.ns = self.next_in_las(dead);
                        self.pass_token(now, 0);
                    }
                }
            }
        }
    }

    fn next_action<A: MasterApp>(&mut self, now: Instant, app: &mut A) {
        let time_left = now < self.hold_until;
        let high_only = !time_left && self.cycles_this_visit == 0;
        let alone = self.ns == self.ts();
        if time_left || high_only {
            let ctx = TokenContext {
                now,
                high_only,
                hold_until: self.hold_until,
                cycles: self.cycles_this_visit,
                alone,
            };
            let sent = app
                .poll_request(&ctx)
                .map(|req| self.start_request(now, req));
            if let Some(sent) = sent {
                if let Some(result) = sent {
                    app.on_result(now, &result);
                }
                return;
            }
            if alone && time_left {
                // Alone, a request due shortly: hold the token, idle,
                // rather than pass it to itself.
                let limit = (now + self.bits(self.p().slot_time)).min(self.hold_until);
                if let Some(t) = app.next_request_at(&ctx).filter(|&t| t > now && t <= limit) {
                    self.state = State::UseToken { wake: t };
                    return;
                }
            }
        }
        if !self.gap_polled_this_visit {
            let waiting = self.gap_wait > 0;
            if time_left && self.try_gap_poll(now) {
                return;
            }
            if waiting {
                self.gap_wait -= 1;
            }
        }
        self.pass_token(now, 0);
    }

    /// Send this visit's GAP poll (FDL_Status to the next address of the
    /// GAP), if one is due: at most one per token visit, none while the
    /// GAP factor is counting, except to a master that answered "not
    /// ready" on one of the last visits ([`Core::gap_recheck_address`]).
    /// Returns whether it was sent.
    fn try_gap_poll(&mut self, now: Instant) -> bool {
        if self.gap_polled_this_visit {
            return false;
        }
        let address = match self.gap_recheck_address() {
            Some(a) => a,
            None if self.gap_wait > 0 => return false,
            None => match self.next_gap_address() {
                Some(a) => a,
                None => return false,
            },
        };
        self.gap_polled_this_visit = true;
        self.stats.gap_polls += 1;
        let ts = self.ts();
        let end = self.send(
            now,
            Telegram::Data(DataTelegram {
                da: address,
                sa: ts,
                fc: FunctionCode::request(RequestKind::FdlStatus),
                dsap: None,
                ssap: None,
                data: &[],
                format: None,
            }),
        );
        self.state = State::AwaitStatus {
            address,
            deadline: end + self.gap_slot(),
        };
        true
    }

    /// A master in this station's GAP that answered "not ready" (it is
    /// still learning the ring in Listen_Token) is polled again on the
    /// next visits, up to G (GAP factor) times, before the sweep goes on.
    ///
    /// The standard examines one GAP address per token receipt and marks
    /// a "not ready" answer in the GAP list before checking the next
    /// address (PROFIBUS Specification, EN 50170 Vol. 2, Part 4 §4.4
    /// "GAP maintenance", p. 102); it does not forbid asking that station
    /// again. A master switched on is polled by its predecessor before it
    /// has listened to two rotations; without the second look it joins
    /// only after the rest of the sweep and the GAP update time, and a
    /// lone master that holds the token for several poll cycles per visit
    /// (one GAP address per visit) makes that a second or more. With it
    /// the new master joins a few rotations after it is ready. A station
    /// that stays "not ready" (a master that does not want the token)
    /// costs G extra polls per sweep.
    fn gap_recheck_address(&mut self) -> Option<u8> {
        let (a, _) = self.gap_recheck?;
        let hsa = self.p().hsa.max(self.ts());
        let gap = if self.ns == self.ts() {
            hsa as u32 + 1
        } else {
            self.dist(self.ts(), self.ns)
        };
        let d = self.dist(self.ts(), a);
        if d == 0 || d >= gap {
            self.gap_recheck = None;
            return None;
        }
        Some(a)
    }

    /// The next address of the GAP sweep, or `None` when the sweep ended
    /// (then the GAP factor starts counting).
    fn next_gap_address(&mut self) -> Option<u8> {
        let hsa = self.p().hsa.max(self.ts());
        let gap = if self.ns == self.ts() {
            hsa as u32 + 1
        } else {
            self.dist(self.ts(), self.ns)
        };
        let d = self.dist(self.ts(), self.gap_next);
        if d == 0 || d >= gap {
            self.gap_next = next_addr(self.ts(), hsa);
            self.gap_wait = self.p().gap_factor;
            return None;
        }
        let a = self.gap_next;
        self.gap_next = next_addr(a, hsa);
        Some(a)
    }

    /// Send a request; returns the result at once for a request without
    /// reply.
    fn start_request(&mut self, now: Instant, req: Request<'_>) -> Option<CycleResult<'static>> {
        let kind = req.service.kind();
        let reply = kind.expects_reply() && req.da != consts::BROADCAST;
        let r = self.remote[req.da as usize & 0x7F];
        let fc = if kind.uses_fcb() && reply {
            FunctionCode::Request {
                kind,
                fcb: r.fcb,
                fcv: r.fcv,
            }
        } else {
            FunctionCode::request(kind)
        };
        let t = Telegram::Data(DataTelegram {
            da: req.da,
            sa: self.ts(),
            fc,
            dsap: req.dsap,
            ssap: req.ssap,
            data: req.data,
            format: None,
        });
        let len = match t.emit(&mut self.req) {
            Ok(n) => n,
            Err(e) => {
                tracing::warn!("request not sent: {e}");
                self.state = State::UseToken { wake: now };
                return None;
            }
        };
        let (service, da, dsap, ssap) = (req.service, req.da, req.dsap, req.ssap);
        let wait = self.answer_slot(req.longest_answer());
        let end = self.send_req_buffer(now, len);
        if reply {
            self.pending = Some(Pending {
                da,
                service,
                attempts: 0,
                max_retries: if r.operational { self.p().max_retry } else { 0 },
                len,
                wait,
                dsap,
                ssap,
            });
            self.state = State::AwaitResponse {
                deadline: end + wait,
            };
            None
        } else {
            self.stats.cycles += 1;
            self.cycles_this_visit += 1;
            self.line_free_at = end + self.bits(self.p().tid2());
            self.state = State::UseToken {
                wake: self.line_free_at,
            };
            Some(CycleResult {
                da,
                service,
                outcome: Outcome::Sent,
                retries: 0,
            })
        }
    }

    fn complete<A: MasterApp>(&mut self, now: Instant, outcome: Outcome<'_>, app: &mut A) {
        let p = self.pending.take().expect("pending");
        let data_reply = matches!(outcome, Outcome::Response { .. });
        if data_reply {
            self.duplicate[p.da as usize & 0x7F].garbled_in_row = 0;
        }
        self.last_answered = (data_reply && p.attempts == 0).then_some(p.da);
        let r = &mut self.remote[p.da as usize & 0x7F];
        if p.service.kind().uses_fcb() {
            r.fcb = !r.fcb;
            r.fcv = true;
        }
        r.operational = true;
        self.stats.cycles += 1;
        self.cycles_this_visit += 1;
        self.line_free_at = now + self.bits(self.p().tid1());
        self.state = State::UseToken {
            wake: self.line_free_at,
        };
        app.on_result(
            now,
            &CycleResult {
                da: p.da,
                service: p.service,
                outcome,
                retries: p.attempts,
            },
        );
    }

    fn attempt_failed<A: MasterApp>(&mut self, now: Instant, app: &mut A) {
        let Some(mut p) = self.pending else {
            self.state = State::UseToken { wake: now };
            return;
        };
        if p.attempts < p.max_retries {
            p.attempts += 1;
            self.stats.retries += 1;
            self.pending = Some(p);
            let end = self.send_req_buffer(now, p.len);
            self.state = State::AwaitResponse {
                deadline: end + p.wait,
            };
            return;
        }
        self.pending = None;
        self.remote[p.da as usize & 0x7F] = Remote {
            operational: false,
            ..REMOTE_INIT
        };
        self.stats.cycles += 1;
        self.stats.no_response += 1;
        self.cycles_this_visit += 1;
        self.line_free_at = now;
        self.state = State::UseToken { wake: now };
        app.on_result(now, &p.no_response());
    }

    fn pass_token(&mut self, now: Instant, attempts: u8) {
        let ts = self.ts();
        let ns = self.ns;
        self.stats.token_passes += 1;
        let end = self.send(now, Telegram::Token { da: ns, sa: ts });
        if ns == ts {
            self.begin_token_use(end);
        } else {
            self.state = State::CheckTokenPass {
                attempts,
                deadline: end + self.token_pass_slot(),
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::fdl_status;
    use crate::timing::Baud;

    #[derive(Default)]
    struct Recorder {
        events: Vec<FdlEvent>,
        results: Vec<(u8, &'static str, u8)>,
        queue: Vec<(u8, Service)>,
        /// (DSAP, SSAP) of every request, if any.
        saps: Option<(u8, u8)>,
        /// [`Request::max_reply_len`] of every request.
        max_reply: Option<u8>,
        /// Senders of late replies ([`MasterApp::on_late_reply`]).
        late: Vec<Option<u8>>,
    }

    impl MasterApp for Recorder {
        fn poll_request(&mut self, _ctx: &TokenContext) -> Option<Request<'_>> {
            let (da, service) = self.queue.first().copied()?;
            self.queue.remove(0);
            Some(Request {
                da,
                service,
                dsap: self.saps.map(|s| s.0),
                ssap: self.saps.map(|s| s.1),
                data: &[],
                max_reply_len: self.max_reply,
            })
        }
        fn on_result(&mut self, _now: Instant, r: &CycleResult<'_>) {
            let o = match r.outcome {
                Outcome::Response { .. } => "response",
                Outcome::ShortAck => "ack",
                Outcome::Sent => "sent",
                Outcome::NoResponse => "none",
            };
            self.results.push((r.da, o, r.retries));
        }
        fn on_event(&mut self, _now: Instant, e: FdlEvent) {
            self.events.push(e);
        }
        fn on_late_reply(&mut self, _now: Instant, from: Option<u8>) {
            self.late.push(from);
        }
    }

    fn step(st: &mut ActiveStation<Recorder>) -> (Instant, Option<Vec<u8>>) {
        let t = st.poll_timeout().unwrap();
        st.handle_timeout(t);
        (t, st.poll_transmit(t).map(|b| b.to_vec()))
    }

    /// Master 3 alone at 19.2 kbit/s after its first request, an SRD to
    /// station 8 with `saps`: the station, when it sent it, the bytes.
    fn srd_to_8(saps: Option<(u8, u8)>) -> (ActiveStation<Recorder>, Instant, Vec<u8>) {
        let params = BusParams::defaults(Baud::B19200);
        let mut st = ActiveStation::new(ActiveConfig::new(3, params), Recorder::default());
        st.app_mut().saps = saps;
        st.app_mut().queue.push((8, Service::SrdHigh));
        step(&mut st);
        step(&mut st);
        let (t, tx) = step(&mut st);
        (st, t, tx.unwrap())
    }

    /// Found by the `master_response` fuzz target: a token passed by a
    /// station above HSA made the ring-distance arithmetic underflow.
    #[test]
    fn token_pass_from_above_hsa_is_no_panic() {
        let mut params = BusParams::defaults(Baud::B1500000);
        params.hsa = 4;
        let mut st = ActiveStation::new(ActiveConfig::new(2, params), Recorder::default());
        st.app_mut().queue.push((8, Service::SrdHigh));
        step(&mut st);
        step(&mut st);
        // The fuzzer's bytes: garbage, then SD4 DA=0 SA=0x65 (101).
        let (t, _) = step(&mut st);
        st.handle_rx(t, &[0x00, 0xDC, 0x00, 0xE5]);
        for (da, sa) in [(0, 101), (101, 3), (120, 110), (3, 126)] {
            st.handle_rx(t, &[0xDC, da, sa]);
        }
        for _ in 0..20 {
            step(&mut st);
        }
        assert!(st.poll_timeout().is_some());
    }

    #[test]
    fn lone_master_claims_and_retries_with_same_fcb() {
        let params = BusParams::defaults(Baud::B19200);
        let mut st = ActiveStation::new(ActiveConfig::new(3, params), Recorder::default());
        st.app_mut().queue.push((8, Service::SrdHigh));
        // Silence for TTO = 6·100 + 2·3·100 = 1200 bit: claim, token to self twice.
        let (t, tx) = step(&mut st);
        assert_eq!(t, Instant::ZERO + params.bits(1200));
        assert_eq!(tx.unwrap(), vec![0xDC, 3, 3]);
        let (_, tx) = step(&mut st);
        assert_eq!(tx.unwrap(), vec![0xDC, 3, 3]);
        assert!(st.app().events.contains(&FdlEvent::TokenClaimed));
        // Use token: the request as a first frame (FCB=1, FCV=0): 0x6D.
        let (_, tx) = step(&mut st);
        let first = tx.unwrap();
        assert_eq!(first[..4], [0x10, 8, 3, 0x6D]);
        // No answer within TSL: the same telegram again (same FCB).
        let (t1, tx) = step(&mut st);
        assert_eq!(tx.unwrap(), first);
        // No answer again: no response, station non-operational.
        let (t2, _) = step(&mut st);
        assert_eq!(t2 - t1, params.bits(6 * 11 + 100));
        assert_eq!(st.app().results, vec![(8, "none", 1)]);
        assert_eq!(st.stats().retries, 1);
    }

    /// A response from `sa` to `da` with the given status, SAPs and data.
    fn reply(
        da: u8,
        sa: u8,
        status: ResponseStatus,
        saps: Option<(u8, u8)>,
        data: &[u8],
    ) -> Vec<u8> {
        let fc = FunctionCode::Response {
            status,
            station: StationType::Passive,
        };
        let t = DataTelegram::new(da, sa, fc, data).with_saps(saps.map(|s| s.0), saps.map(|s| s.1));
        Telegram::Data(t).to_vec().unwrap()
    }

    #[test]
    fn only_a_reply_with_the_requests_saps_swapped_answers_it() {
        let params = BusParams::defaults(Baud::B19200);
        // Slave_Diag: DSAP 60, SSAP 62.
        let (mut st, t, tx) = srd_to_8(Some((60, 62)));
        assert_eq!(tx[..4], [0x68, 5, 5, 0x68]);
        let at = t + params.bits(11);
        // A late Data_Exchange answer (20 bytes of inputs, no SAPs) is not
        // the diagnosis: counted and ignored.
        st.handle_rx(at, &reply(3, 8, ResponseStatus::Dl, None, &[0x55; 20]));
        // Nor is a reply with other SAPs, or one from another station.
        st.handle_rx(
            at,
            &reply(3, 8, ResponseStatus::Dl, Some((62, 59)), &[1, 2]),
        );
        st.handle_rx(
            at,
            &reply(3, 9, ResponseStatus::Dl, Some((62, 60)), &[0; 6]),
        );
        assert!(st.app().results.is_empty());
        assert_eq!(st.stats().late_replies, 3);
        assert_eq!(st.stats().duplicate_tokens, 0);
        // The real answer.
        let diag = [0, 0x0C, 0, 3, 0x80, 0x6A];
        st.handle_rx(at, &reply(3, 8, ResponseStatus::Dl, Some((62, 60)), &diag));
        assert_eq!(st.app().results, vec![(8, "response", 0)]);
    }

    #[test]
    fn a_negative_acknowledge_without_saps_answers_a_request_with_saps() {
        let params = BusParams::defaults(Baud::B19200);
        for (status, data, accepted) in [
            (ResponseStatus::Rs, &[][..], true),
            (ResponseStatus::Ue, &[][..], true),
            (ResponseStatus::Rr, &[][..], true),
            (ResponseStatus::Nr, &[][..], true),
            // Data without SAPs cannot answer a request with SAPs.
            (ResponseStatus::Dl, &[1, 2, 3][..], false),
            (ResponseStatus::Rs, &[1][..], false),
        ] {
            let (mut st, t, _) = srd_to_8(Some((61, 62)));
            st.handle_rx(t + params.bits(11), &reply(3, 8, status, None, data));
            assert_eq!(st.app().results.len(), accepted as usize, "{status:?}");
            assert_eq!(st.stats().late_replies, !accepted as u64, "{status:?}");
        }
    }

    #[test]
    fn a_late_fdl_status_answer_does_not_answer_a_data_exchange() {
        // The answer to a GAP poll (FDL Status, "OK" from a passive
        // station) arrives after the GAP wait, while a Data_Exchange to the
        // same station is pending: not its answer.
        let params = BusParams::defaults(Baud::B19200);
        let (mut st, t, _) = srd_to_8(None);
        st.handle_rx(t + params.bits(11), &[0x10, 3, 8, 0x00, 0x0B, 0x16]);
        assert!(st.app().results.is_empty());
        assert_eq!(st.stats().late_replies, 1);
        st.handle_rx(
            t + params.bits(11),
            &reply(3, 8, ResponseStatus::Dl, None, &[1, 2]),
        );
        assert_eq!(st.app().results, vec![(8, "response", 0)]);
    }

    #[test]
    fn a_reply_with_saps_does_not_answer_a_request_without() {
        let params = BusParams::defaults(Baud::B19200);
        let (mut st, t, _) = srd_to_8(None);
        let late_diag = reply(
            3,
            8,
            ResponseStatus::Dl,
            Some((62, 60)),
            &[0, 0x0C, 0, 3, 0x80, 0x6A],
        );
        st.handle_rx(t + params.bits(11), &late_diag);
        assert!(st.app().results.is_empty());
        st.handle_rx(
            t + params.bits(11),
            &reply(3, 8, ResponseStatus::Dl, None, &[7; 4]),
        );
        assert_eq!(st.app().results, vec![(8, "response", 0)]);
        assert_eq!(st.stats().late_replies, 1);
    }

    #[test]
    fn longest_answer_of_each_service() {
        let req = |service, saps: Option<(u8, u8)>, max| Request {
            da: 8,
            service,
            dsap: saps.map(|s| s.0),
            ssap: saps.map(|s| s.1),
            data: &[1, 2, 3],
            max_reply_len: max,
        };
        let diag = Some((60, 62));
        for (r, chars) in [
            (req(Service::FdlStatus, None, None), 6),
            (req(Service::SdaLow, diag, Some(200)), 6),
            (req(Service::SdnHigh, None, None), 0),
            (req(Service::SrdHigh, None, None), 255),
            // Data_Exchange with 2 bytes of inputs: SD2 of 9 + 2.
            (req(Service::SrdHigh, None, Some(2)), 11),
            // No data, no SAPs: the 6 characters of an SD1 "no data".
            (req(Service::SrdHigh, None, Some(0)), 6),
            // Set_Prm: a short acknowledge, or a reply with the SAPs.
            (req(Service::SrdHigh, diag, Some(0)), 11),
            (req(Service::SrdLow, diag, Some(244)), 255),
            (req(Service::SrdLow, None, Some(255)), 255),
        ] {
            assert_eq!(r.longest_answer(), chars, "{r:?}");
        }
    }

    /// Issue 26: on a transport of whole telegrams each request waits for
    /// the slot time, the latency and the wire time of *its* longest
    /// answer; a silent station costs 14 ms per FDL Status at 19.2 kbit/s,
    /// not the 160 ms of an allowance for the longest telegram.
    #[test]
    fn the_wait_for_an_answer_allows_for_that_requests_longest_answer() {
        let params = BusParams::defaults(Baud::B19200);
        let mut cfg = ActiveConfig::new(3, params);
        cfg.latency_allowance = Duration::from_millis(5);
        cfg.whole_telegrams = true;
        let wire = |n: usize| params.baud.chars_to_duration(n as u64);
        let tsl = params.bits(params.slot_time as u64);
        for (service, saps, max, answer) in [
            (Service::FdlStatus, None, None, 6),
            (Service::SrdHigh, None, Some(2), 11),
            (Service::SrdHigh, Some((60, 62)), Some(244), 255),
            (Service::SrdHigh, None, None, 255),
        ] {
            let mut st = ActiveStation::new(cfg, Recorder::default());
            st.app_mut().saps = saps;
            st.app_mut().max_reply = max;
            st.app_mut().queue.push((8, service));
            step(&mut st);
            step(&mut st);
            let (t, tx) = step(&mut st);
            let sent = tx.unwrap().len();
            // No answer: the retry goes out when the wait ran out.
            let (t1, retry) = step(&mut st);
            assert_eq!(retry.unwrap().len(), sent);
            assert_eq!(
                t1 - t,
                wire(sent) + tsl + Duration::from_millis(5) + wire(answer),
                "{service:?} {max:?}"
            );
        }
        // On a line that delivers character by character the first
        // character is awaited: the slot time and the latency only.
        cfg.whole_telegrams = false;
        let mut st = ActiveStation::new(cfg, Recorder::default());
        st.app_mut().queue.push((8, Service::SrdHigh));
        step(&mut st);
        step(&mut st);
        let (t, tx) = step(&mut st);
        let (t1, _) = step(&mut st);
        let sent = tx.unwrap().len();
        assert_eq!(t1 - t, wire(sent) + tsl + Duration::from_millis(5));
        // The token-lost timeout still allows for the longest telegram per
        // allowance: any telegram is silence to the others while it
        // crosses a transport of whole telegrams.
        cfg.whole_telegrams = true;
        assert_eq!(
            cfg.token_lost_timeout(),
            params.bits(params.token_lost_timeout(3) as u64)
                + 6 * (Duration::from_millis(5) + wire(255))
        );
    }

    /// The answer to a request whose wait ran out comes after the retry
    /// was answered, and after that while the token is checked at the
    /// successor: counted and dropped, and the token pass still waits for
    /// the successor.
    #[test]
    fn a_reply_after_its_wait_is_counted_and_dropped() {
        let params = BusParams::defaults(Baud::B19200);
        let (mut st, t, _) = srd_to_8(None);
        let answer = reply(3, 8, ResponseStatus::Dl, None, &[1, 2]);
        // No answer in time: the retry; its answer comes.
        let (t1, retry) = step(&mut st);
        assert!(retry.is_some());
        st.handle_rx(t1 + params.bits(200), &answer);
        assert_eq!(st.app().results, vec![(8, "response", 1)]);
        // The answer to the first attempt, late: not taken for anything.
        st.handle_rx(t1 + params.bits(300), &answer);
        assert_eq!(st.stats().late_replies, 1);
        assert_eq!(st.app().late, vec![Some(8)]);
        assert_eq!(st.app().results.len(), 1);
        assert!(t1 > t);
        // Another master in the ring: the token goes to it, and a late
        // reply during the check is not the successor taking it.
        st.core.las[5] = true;
        st.core.ns = 5;
        let (t2, token) = loop {
            let (t2, tx) = step(&mut st);
            if let Some(tx) = tx.filter(|b| b[0] == consts::SD4) {
                break (t2, tx);
            }
        };
        assert_eq!(token, vec![0xDC, 5, 3]);
        assert_eq!(st.ring_state(), RingState::CheckTokenPass);
        st.handle_rx(t2 + params.bits(50), &answer);
        assert_eq!(st.ring_state(), RingState::CheckTokenPass);
        assert_eq!(st.stats().late_replies, 2);
        assert_eq!(st.app().late, vec![Some(8), Some(8)]);
        // The successor's first telegram ends the check.
        st.handle_rx(t2 + params.bits(60), &[0xDC, 7, 5]);
        assert_eq!(st.ring_state(), RingState::ActiveIdle);
        // Waiting for the token: a short acknowledge is another master's
        // business; a response addressed to this station is late.
        st.handle_rx(t2 + params.bits(90), &[0xE5]);
        assert_eq!(st.stats().late_replies, 2);
        st.handle_rx(t2 + params.bits(120), &answer);
        assert_eq!(st.stats().late_replies, 3);
        assert_eq!(st.ring_state(), RingState::ActiveIdle);
    }

    #[test]
    fn fcb_alternates_after_answers() {
        let params = BusParams::defaults(Baud::B19200);
        let mut st = ActiveStation::new(ActiveConfig::new(3, params), Recorder::default());
        for _ in 0..3 {
            st.app_mut().queue.push((8, Service::SrdHigh));
        }
        step(&mut st);
        step(&mut st);
        let mut fcs = vec![];
        for _ in 0..3 {
            let (t, tx) = step(&mut st);
            let tx = tx.unwrap();
            fcs.push(tx[3]);
            // Slave answers with SC after TSDR.
            st.handle_rx(t + params.bits(6 * 11 + 11), &[0xE5]);
        }
        assert_eq!(fcs, vec![0x6D, 0x5D, 0x7D]);
        assert_eq!(st.app().results.len(), 3);
        assert!(st.app().results.iter().all(|r| r.1 == "ack"));
    }

    #[test]
    fn listener_answers_not_ready_then_goes_offline_on_own_address() {
        let params = BusParams::defaults(Baud::B19200);
        let mut st = ActiveStation::new(ActiveConfig::new(5, params), Recorder::default());
        st.handle_rx(Instant::ZERO, &fdl_status(5, 2));
        let (t, _) = (st.poll_timeout().unwrap(), ());
        let tx = st.poll_transmit(t).unwrap().to_vec();
        assert_eq!(tx[3], 0x10, "not ready while the LAS is unknown");
        st.handle_rx(t, &[0xDC, 7, 5]);
        st.handle_rx(t, &[0xDC, 7, 5]);
        assert_eq!(st.ring_state(), RingState::Offline);
        assert!(st.app().events.contains(&FdlEvent::AddressInUse));
    }
}
