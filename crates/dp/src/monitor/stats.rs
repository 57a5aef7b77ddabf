//! Statistics per station over time: what a bus analyser's live list and
//! its statistics pages show, computed from what a passive tap overhears.
//!
//! [`Stats`] is sans-IO: feed it the tap's events
//! ([`TapEvent`]: telegrams with the time of their first byte, and the
//! bytes the framer skipped with their codec errors) with [`Stats::hear`],
//! and take a [`StatsReport`] every interval with [`Stats::snapshot`]: the
//! counters of the interval per station, and the totals since the start.
//! [`Stats::live`] gives each station's role, DP state and health for a
//! live list. Alert rules on the reports are in [`super::alert`].
//!
//! Definitions (docs/analyser.md has them for users):
//!
//! - **requests**: telegrams with a request function code addressed to
//!   the station (not broadcasts, and not the FDL status, ident and LSAP
//!   status polls of the GAP and live-list scans, to which absent
//!   stations stay silent by design: a station they find counts from its
//!   answer);
//!   **answers**: responses and short acknowledges it sent.
//! - **retries**: a request repeated with the same FCB. IEC 61158-4-3
//!   frame count bit rules: the initiator toggles FCB after each
//!   acknowledged SRD/SDA with FCV = 1, and repeats with the same FCB when
//!   it got no (valid) answer. The first request after a (re)start carries
//!   FCV = 0, FCB = 1; it is a retry only when the one before it was the
//!   same first request and went unanswered.
//! - **no_answer**: a request that expects a reply followed by silence
//!   until the next request or token (the initiator's slot time ran out).
//!   A reply that arrives corrupted is counted in **illegal** instead.
//! - **illegal**: stretches of bytes that are no valid telegram (bad FCS,
//!   start or end delimiter, length, character framing when the UART
//!   reports it), put on the station whose answer was due, else on the
//!   station holding the token (the only one allowed to send), else on
//!   the line only ([`LineStats`]).
//! - **diag_requests** / **diag_answers** / **ext_diag**: Slave_Diag
//!   requests, their answers, and answers with Ext_Diag set.
//! - **set_prm**, **chk_cfg**: Set_Prm and Chk_Cfg requests;
//!   **restarts**: a slave starting over after it reached Data_Exchange —
//!   the first of a Set_Prm to it, a Slave_Diag answer with
//!   Station_Not_Ready or Prm_Req, or a Data_Exchange refused with RS
//!   (SAP not activated: not parameterised).
//! - **role**: master when it sent a request or passed the token twice (a
//!   token telegram has no FCS: line noise can forge one), slave when it
//!   answered; **dp_state**: as its master has it, `offline` after three
//!   requests in a row without an answer.
//! - **response_time**: from the end of the request (its first byte's
//!   time plus its length at the line's rate, 11 bit per character) to
//!   the first byte of the answer.
//! - **idle_before_request**: on the initiator, from the end of the
//!   telegram before to the first byte of its request.
//! - **token_rotation**: on a master, between two tokens it passed;
//!   **over_ttr**: rotations longer than the target rotation time, when
//!   one is given ([`StatsOptions::ttr`]; TTR is not on the wire).
//! - **cycle**: on a slave, between two Data_Exchange requests to it
//!   (retries not counted); **bus_cycle**: on a master, the same over all
//!   its slaves.
//! - **health**: see [`health`].

use crate::master::SlaveState;
use crate::pdu::diag::{SlaveDiag, StationStatus1, StationStatus2};
use crate::pdu::sap;
use profibus_fdl::codec::CodecStats;
use profibus_fdl::line::tap::TapEvent;
use profibus_fdl::wire::{FunctionCode, RequestKind};
use profibus_fdl::{Baud, Instant, Telegram};
use std::collections::BTreeMap;
use std::fmt;
use std::time::Duration;

/// What a station does on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Role {
    /// Passes the token or sends requests.
    Master,
    /// Answers requests.
    Slave,
    /// Both (a master that answers FDL status, or a class-2 master's
    /// partner).
    Both,
}

impl Role {
    /// Name for people and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Role::Master => "master",
            Role::Slave => "slave",
            Role::Both => "both",
        }
    }
}

/// Minimum, mean and maximum of a duration; serialised in µs as
/// `{"count", "min_us", "mean_us", "max_us"}`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Durations {
    /// How many were measured.
    pub count: u64,
    min_ns: u64,
    max_ns: u64,
    sum_ns: u64,
}

impl Durations {
    /// Adds one measurement.
    pub fn add(&mut self, d: Duration) {
        let ns = d.as_nanos().min(u64::MAX as u128) as u64;
        self.min_ns = if self.count == 0 {
            ns
        } else {
            self.min_ns.min(ns)
        };
        self.max_ns = self.max_ns.max(ns);
        self.sum_ns = self.sum_ns.saturating_add(ns);
        self.count += 1;
    }

    /// Adds `n` measurements of `each`.
    pub fn add_many(&mut self, each: Duration, n: u64) {
        if n == 0 {
            return;
        }
        let ns = each.as_nanos().min(u64::MAX as u128) as u64;
        self.merge(&Durations {
            count: n,
            min_ns: ns,
            max_ns: ns,
            sum_ns: ns.saturating_mul(n),
        });
    }

    /// Adds all of `o`'s measurements.
    pub fn merge(&mut self, o: &Durations) {
        if o.count == 0 {
            return;
        }
        self.min_ns = if self.count == 0 {
            o.min_ns
        } else {
            self.min_ns.min(o.min_ns)
        };
        self.max_ns = self.max_ns.max(o.max_ns);
        self.sum_ns = self.sum_ns.saturating_add(o.sum_ns);
        self.count += o.count;
    }

    /// Shortest (`None`: none measured).
    pub fn min(&self) -> Option<Duration> {
        (self.count > 0).then(|| Duration::from_nanos(self.min_ns))
    }

    /// Mean.
    pub fn mean(&self) -> Option<Duration> {
        (self.count > 0).then(|| Duration::from_nanos(self.sum_ns / self.count))
    }

    /// Longest.
    pub fn max(&self) -> Option<Duration> {
        (self.count > 0).then(|| Duration::from_nanos(self.max_ns))
    }
}

fn us(d: Option<Duration>) -> Option<f64> {
    d.map(|d| (d.as_nanos() as f64 / 100.0).round() / 10.0)
}

#[cfg(feature = "serde")]
impl serde::Serialize for Durations {
    fn serialize<S: serde::Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut s = ser.serialize_struct("Durations", 4)?;
        s.serialize_field("count", &self.count)?;
        s.serialize_field("min_us", &us(self.min()))?;
        s.serialize_field("mean_us", &us(self.mean()))?;
        s.serialize_field("max_us", &us(self.max()))?;
        s.end()
    }
}

impl fmt::Display for Durations {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (us(self.min()), us(self.mean()), us(self.max())) {
            (Some(a), Some(b), Some(c)) => write!(f, "{a}/{b}/{c} µs"),
            _ => f.write_str("-"),
        }
    }
}

/// The counters of one station over an interval (or since the start).
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct StationStats {
    /// Master, slave or both (`None`: only addressed, never heard).
    pub role: Option<Role>,
    /// DP state of a slave as its master has it (`None`: not a DP slave
    /// or not seen yet).
    #[cfg_attr(
        feature = "serde",
        serde(serialize_with = "ser::state", skip_serializing_if = "Option::is_none")
    )]
    pub dp_state: Option<SlaveState>,
    /// Health 0 … 100 ([`health`]).
    pub health: u8,
    /// Requests addressed to it.
    pub requests: u64,
    /// Answers (responses and short acknowledges) it sent.
    pub answers: u64,
    /// Requests repeated with the same FCB.
    pub retries: u64,
    /// Requests it left unanswered (silence).
    pub no_answer: u64,
    /// Corrupt stretches put on it.
    pub illegal: u64,
    /// Slave_Diag requests to it.
    pub diag_requests: u64,
    /// Its Slave_Diag answers.
    pub diag_answers: u64,
    /// Its Slave_Diag answers with Ext_Diag set.
    pub ext_diag: u64,
    /// Set_Prm requests to it.
    pub set_prm: u64,
    /// Chk_Cfg requests to it.
    pub chk_cfg: u64,
    /// Start-ups after Data_Exchange (Prm/Cfg cycles).
    pub restarts: u64,
    /// Requests it sent (a master).
    pub requests_sent: u64,
    /// Tokens it passed (a master).
    pub tokens: u64,
    /// Request end to answer start, on the responder.
    pub response_time: Durations,
    /// Idle line before its requests, on the initiator.
    pub idle_before_request: Durations,
    /// Between the tokens it passed (a master).
    pub token_rotation: Durations,
    /// Target rotation time in µs (`--config`), when known (a master).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub ttr_us: Option<f64>,
    /// Rotations longer than the TTR.
    pub over_ttr: u64,
    /// Between Data_Exchange requests to it (a slave).
    pub cycle: Durations,
    /// Between Data_Exchange requests to the same slave, over all its
    /// slaves (a master).
    pub bus_cycle: Durations,
}

#[cfg(feature = "serde")]
mod ser {
    use crate::master::SlaveState;
    pub fn state<S: serde::Serializer>(s: &Option<SlaveState>, ser: S) -> Result<S::Ok, S::Error> {
        match s {
            Some(s) => ser.serialize_str(s.name()),
            None => ser.serialize_none(),
        }
    }
}

/// Health of a station 0 … 100 from its counters (docs/analyser.md):
///
/// `100 − 1000·(no_answer + illegal)/requests − 500·retries/requests
///  − 20·restarts − 10·[ext_diag > 0] − 50·over_ttr/rotations`,
/// clamped to 0 … 100; the ratios are taken over the telegrams the
/// station took part in: requests to it, requests it sent and tokens it
/// passed (at least 1). A slave its master has `offline` is 0.
/// So 1 % lost or corrupt answers cost 10 points, 1 % retries 5, each
/// restart 20, a pending extended diagnosis 10, and a master whose every
/// rotation overran the TTR 50.
pub fn health(s: &StationStats) -> u8 {
    if s.dp_state == Some(SlaveState::Offline) {
        return 0;
    }
    let req = (s.requests + s.requests_sent + s.tokens).max(1) as f64;
    let bad = (s.no_answer + s.illegal) as f64 / req;
    let retries = s.retries as f64 / req;
    let mut h = 100.0 - 1000.0 * bad - 500.0 * retries - 20.0 * s.restarts as f64;
    if s.ext_diag > 0 {
        h -= 10.0;
    }
    if s.token_rotation.count > 0 {
        h -= 50.0 * s.over_ttr as f64 / s.token_rotation.count as f64;
    }
    h.clamp(0.0, 100.0).round() as u8
}

/// Counters of the whole line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct LineStats {
    /// Valid telegrams.
    pub telegrams: u64,
    /// Token telegrams.
    pub tokens: u64,
    /// Stretches of bytes that were no valid telegram.
    pub illegal: u64,
    /// Of those, the ones no station could be blamed for.
    pub unattributed: u64,
    /// The codec's counters of the skipped bytes (bad FCS, delimiters,
    /// length, garbage bytes, …).
    pub errors: CodecStats,
}

/// One set of counters: per station and for the line.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct StatsSet {
    /// Per station, by address (JSON keys: the decimal address).
    #[cfg_attr(feature = "serde", serde(serialize_with = "ser_keys::stations"))]
    pub stations: BTreeMap<u8, StationStats>,
    /// The line.
    pub line: LineStats,
}

#[cfg(feature = "serde")]
mod ser_keys {
    use super::StationStats;
    use serde::ser::SerializeMap;
    use std::collections::BTreeMap;
    pub fn stations<S: serde::Serializer>(
        m: &BTreeMap<u8, StationStats>,
        ser: S,
    ) -> Result<S::Ok, S::Error> {
        let mut map = ser.serialize_map(Some(m.len()))?;
        for (a, s) in m {
            map.serialize_entry(&a.to_string(), s)?;
        }
        map.end()
    }
}

/// The statistics of one interval and the totals since the start: the
/// JSON line `{"event": "stats", "interval_s", "t_s", "stations":
/// {"ADDR": {…}}, "line", "totals": {"stations", "line"}}`.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct StatsReport {
    /// Always `"stats"`.
    pub event: &'static str,
    /// Length of the interval in seconds.
    pub interval_s: f64,
    /// End of the interval, seconds on the telegram clock.
    pub t_s: f64,
    /// The interval's counters.
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub interval: StatsSet,
    /// Since the start.
    pub totals: StatsSet,
}

impl fmt::Display for StatsReport {
    /// Plain lines: a summary line, then one line per station.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let l = &self.interval.line;
        write!(
            f,
            "stats t={:.1} s over {:.1} s: telegrams {}, tokens {}, illegal {}",
            self.t_s, self.interval_s, l.telegrams, l.tokens, l.illegal
        )?;
        for (a, s) in &self.interval.stations {
            write!(
                f,
                "\n  {a:3} {:<6} {:<13} health {:3}  req {} ans {} retry {} no_answer {} illegal {} diag {}/{} ext {} restarts {}  resp {}",
                s.role.map_or("-", Role::name),
                s.dp_state.map_or("-", SlaveState::name),
                s.health,
                s.requests,
                s.answers,
                s.retries,
                s.no_answer,
                s.illegal,
                s.diag_requests,
                s.diag_answers,
                s.ext_diag,
                s.restarts,
                s.response_time,
            )?;
            if s.token_rotation.count > 0 {
                write!(f, "  rotation {}", s.token_rotation)?;
                if s.over_ttr > 0 {
                    write!(f, " ({} over TTR)", s.over_ttr)?;
                }
            }
            if s.bus_cycle.count > 0 {
                write!(f, "  bus cycle {}", s.bus_cycle)?;
            }
            if s.cycle.count > 0 {
                write!(f, "  cycle {}", s.cycle)?;
            }
        }
        Ok(())
    }
}

/// A station in the live list.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LiveStation {
    /// Its address.
    pub address: u8,
    /// Master, slave or both.
    pub role: Option<Role>,
    /// Its DP state (slaves).
    pub dp_state: Option<SlaveState>,
    /// Health 0 … 100 over the totals.
    pub health: u8,
}

/// Settings of a [`Stats`].
#[derive(Debug, Clone, Copy, Default)]
pub struct StatsOptions {
    /// The line's rate: request ends and idle times are computed from
    /// telegram lengths at this rate (`None`: lengths are ignored, as on
    /// a pty where bytes come at once).
    pub baud: Option<Baud>,
    /// Target rotation time (from a bus file's master parameters).
    pub ttr: Option<Duration>,
}

/// A request waiting for its answer.
#[derive(Debug, Clone, Copy)]
struct Pending {
    initiator: u8,
    responder: u8,
    dsap: Option<u8>,
    end: Instant,
    expects_reply: bool,
    /// An SRD without SAPs: Data_Exchange (not an FDL status request).
    data_exchange: bool,
}

#[derive(Debug, Clone, Copy)]
struct LastRequest {
    master: u8,
    dsap: Option<u8>,
    fcb: bool,
    fcv: bool,
    answered: bool,
}

/// What the core remembers of a station between telegrams.
#[derive(Debug, Default, Clone)]
struct Track {
    sends_as_master: bool,
    answers: bool,
    dp_state: Option<SlaveState>,
    /// Reached Data_Exchange since its last start-up.
    in_dx: bool,
    /// Requests in a row without an answer.
    failures: u32,
    tokens: u64,
    last: Option<LastRequest>,
    last_token: Option<Instant>,
    last_dx: Option<Instant>,
}

/// Requests in a row without an answer after which a slave is `offline`.
const OFFLINE_AFTER: u32 = 3;

/// The statistics core; see the module docs.
#[derive(Debug, Default)]
pub struct Stats {
    options: StatsOptions,
    tracks: BTreeMap<u8, Track>,
    interval: StatsSet,
    total: StatsSet,
    pending: Option<Pending>,
    /// The station the last token went to (the only one allowed to send).
    token_holder: Option<u8>,
    /// End of the last telegram.
    line_free: Option<Instant>,
    interval_start: Option<Instant>,
    now: Instant,
}

impl Stats {
    /// An empty core.
    pub fn new(options: StatsOptions) -> Stats {
        Stats {
            options,
            ..Stats::default()
        }
    }

    /// The time of the latest event seen.
    pub fn now(&self) -> Instant {
        self.now
    }

    fn wire_time(&self, len: usize) -> Duration {
        self.options
            .baud
            .map_or(Duration::ZERO, |b| b.chars_to_duration(len as u64))
    }

    fn both(&mut self, address: u8, f: impl Fn(&mut StationStats)) {
        f(self.interval.stations.entry(address).or_default());
        f(self.total.stations.entry(address).or_default());
    }

    fn line(&mut self, f: impl Fn(&mut LineStats)) {
        f(&mut self.interval.line);
        f(&mut self.total.line);
    }

    fn track(&mut self, address: u8) -> &mut Track {
        self.tracks.entry(address).or_default()
    }

    fn at(&mut self, at: Instant) {
        self.now = self.now.max(at);
        if self.interval_start.is_none() {
            self.interval_start = Some(at);
        }
    }

    /// One event of a passive tap.
    pub fn hear(&mut self, e: &TapEvent) {
        match e {
            TapEvent::Telegram { at, bytes } => match Telegram::parse(bytes) {
                Ok((t, _)) => self.observe(*at, &t, bytes.len()),
                Err(_) => self.observe_skipped(*at, bytes.len(), &CodecStats::default()),
            },
            TapEvent::Skipped { at, bytes, errors } => {
                self.observe_skipped(*at, bytes.len(), errors)
            }
        }
    }

    /// `len` bytes that were no valid telegram, the first at `at`, with
    /// the codec errors they raised.
    pub fn observe_skipped(&mut self, at: Instant, len: usize, errors: &CodecStats) {
        self.at(at);
        let errors = *errors;
        self.line(|l| {
            l.illegal += 1;
            add_codec(&mut l.errors, &errors);
        });
        let blame = match self.pending.take() {
            Some(p) if p.expects_reply => Some(p.responder),
            _ => self.token_holder,
        };
        match blame {
            Some(a) => self.both(a, |s| s.illegal += 1),
            None => self.line(|l| l.unattributed += 1),
        }
        let end = at + self.wire_time(len);
        self.line_free = Some(self.line_free.map_or(end, |f| f.max(end)));
    }

    /// A telegram, its first byte at `at`, `len` bytes long.
    pub fn observe(&mut self, at: Instant, t: &Telegram<'_>, len: usize) {
        self.at(at);
        self.line(|l| l.telegrams += 1);
        let idle = self.line_free.map(|f| at.saturating_duration_since(f));
        let end = at + self.wire_time(len);
        self.line_free = Some(end);
        match t {
            Telegram::Token { da, sa } => {
                self.unanswered();
                self.line(|l| l.tokens += 1);
                self.token(at, *sa, *da);
            }
            Telegram::ShortAck => self.answer(at, None),
            Telegram::Data(d) => match d.fc {
                FunctionCode::Request { kind, fcb, fcv } => {
                    self.unanswered();
                    self.request(at, end, idle, d, kind, fcb, fcv);
                }
                FunctionCode::Response { .. } => self.answer(at, Some(d)),
            },
        }
    }

    fn token(&mut self, at: Instant, sa: u8, da: u8) {
        if sa <= 126 {
            self.token_holder = Some(da);
            let ttr = self.options.ttr;
            let last = {
                let t = self.track(sa);
                // A token telegram has no FCS: a corrupt telegram can
                // look like one. A master passes the token again.
                t.tokens += 1;
                t.sends_as_master |= t.tokens >= 2;
                t.last_token.replace(at)
            };
            let rotation = last.filter(|&l| at > l).map(|l| at - l);
            self.both(sa, |s| {
                s.tokens += 1;
                if let Some(r) = rotation {
                    s.token_rotation.add(r);
                    if ttr.is_some_and(|ttr| r > ttr) {
                        s.over_ttr += 1;
                    }
                }
            });
        }
    }

    /// The request before got no answer before the next request or token.
    fn unanswered(&mut self) {
        if let Some(p) = self.pending.take() {
            if p.expects_reply {
                self.both(p.responder, |s| s.no_answer += 1);
                let t = self.track(p.responder);
                t.failures = t.failures.saturating_add(1);
                if t.failures >= OFFLINE_AFTER && t.dp_state.is_some() {
                    t.dp_state = Some(SlaveState::Offline);
                }
            }
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn request(
        &mut self,
        at: Instant,
        end: Instant,
        idle: Option<Duration>,
        d: &profibus_fdl::wire::DataTelegram<'_>,
        kind: RequestKind,
        fcb: bool,
        fcv: bool,
    ) {
        let master = d.sa;
        self.track(master).sends_as_master = true;
        self.both(master, |s| {
            s.requests_sent += 1;
            if let Some(i) = idle {
                s.idle_before_request.add(i);
            }
        });
        if d.is_broadcast() || d.da > 126 {
            return;
        }
        let slave = d.da;
        let dsap = d.dsap.map(|s| s & 0x3F);
        if matches!(
            kind,
            RequestKind::FdlStatus | RequestKind::Ident | RequestKind::LsapStatus
        ) {
            // GAP polling and live lists: absent stations are normal; a
            // station counts from its answer.
            self.pending = Some(Pending {
                initiator: master,
                responder: slave,
                dsap,
                end,
                expects_reply: false,
                data_exchange: false,
            });
            return;
        }
        let expects_reply = kind.expects_reply();
        let data_exchange = dsap.is_none()
            && d.ssap.is_none()
            && matches!(kind, RequestKind::SrdLow | RequestKind::SrdHigh);
        self.pending = Some(Pending {
            initiator: master,
            responder: slave,
            dsap,
            end,
            expects_reply,
            data_exchange,
        });
        let retry = {
            let t = self.track(slave);
            let retry = kind.uses_fcb()
                && t.last.is_some_and(|l| {
                    l.master == master
                        && l.dsap == dsap
                        && l.fcb == fcb
                        && l.fcv == fcv
                        && (fcv || !l.answered)
                });
            if kind.uses_fcb() {
                t.last = Some(LastRequest {
                    master,
                    dsap,
                    fcb,
                    fcv,
                    answered: false,
                });
            }
            retry
        };
        let dp = d.ssap.is_none() || (d.ssap.map(|s| s & 0x3F) == Some(sap::MASTER));
        let (diag, set_prm, chk_cfg) = match (dp, dsap) {
            (true, Some(sap::SLAVE_DIAG)) => (1, 0, 0),
            (true, Some(sap::SET_PRM)) => (0, 1, 0),
            (true, Some(sap::CHK_CFG)) => (0, 0, 1),
            _ => (0, 0, 0),
        };
        let mut cycle = None;
        let mut restart = false;
        {
            let t = self.track(slave);
            if data_exchange && !retry {
                cycle = t.last_dx.filter(|&p| at > p).map(|p| at - p);
                t.last_dx = Some(at);
            }
            if set_prm == 1 && !retry {
                restart = std::mem::take(&mut t.in_dx);
                t.dp_state = Some(SlaveState::ChkCfg);
                t.last_dx = None;
            }
            if chk_cfg == 1 && !retry {
                t.dp_state = Some(SlaveState::CheckDiag);
            }
        }
        self.both(slave, |s| {
            s.requests += 1;
            s.retries += retry as u64;
            s.diag_requests += diag;
            s.set_prm += set_prm;
            s.chk_cfg += chk_cfg;
            s.restarts += restart as u64;
            if let Some(c) = cycle {
                s.cycle.add(c);
            }
        });
        if let Some(c) = cycle {
            self.both(master, |s| s.bus_cycle.add(c));
        }
    }

    fn answer(&mut self, at: Instant, d: Option<&profibus_fdl::wire::DataTelegram<'_>>) {
        let Some(p) = self.pending.take() else {
            if let Some(d) = d {
                // An answer nobody asked for (or whose request was lost).
                self.track(d.sa).answers = true;
                self.both(d.sa, |s| s.answers += 1);
            }
            return;
        };
        if let Some(d) = d {
            if d.sa != p.responder || d.da != p.initiator {
                self.pending = Some(p);
                self.unanswered();
                self.track(d.sa).answers = true;
                self.both(d.sa, |s| s.answers += 1);
                return;
            }
        }
        let response = at.saturating_duration_since(p.end);
        let status = match d.map(|d| d.fc) {
            Some(FunctionCode::Response { status, .. }) => Some(status),
            _ => None,
        };
        let negative = status.is_some_and(|s| s.is_negative());
        let (diag_answer, ext_diag, not_ready) = match (p.dsap, d) {
            (Some(sap::SLAVE_DIAG), Some(d)) if !negative => match SlaveDiag::parse(d.data) {
                Ok(diag) => (
                    1,
                    diag.status1.contains(StationStatus1::EXT_DIAG) as u64,
                    diag.status1.contains(StationStatus1::STATION_NOT_READY)
                        || diag.status2.contains(StationStatus2::PRM_REQ),
                ),
                Err(_) => (1, 0, false),
            },
            _ => (0, 0, false),
        };
        let mut restart = false;
        {
            let t = self.track(p.responder);
            t.answers = true;
            t.failures = 0;
            if let Some(l) = t.last.as_mut() {
                l.answered = true;
            }
            if p.data_exchange && !negative {
                t.dp_state = Some(SlaveState::DataExchange);
                t.in_dx = true;
            } else if p.data_exchange && status == Some(profibus_fdl::wire::ResponseStatus::Rs) {
                // Data_Exchange refused: the slave is not parameterised
                // (it restarted).
                restart = std::mem::take(&mut t.in_dx);
                t.dp_state = Some(SlaveState::Diag);
            }
            if diag_answer == 1 && not_ready {
                restart |= std::mem::take(&mut t.in_dx);
                t.dp_state = Some(SlaveState::SetPrm);
                t.last_dx = None;
            } else if diag_answer == 1 && t.dp_state.is_none() {
                t.dp_state = Some(SlaveState::Diag);
            }
        }
        self.both(p.responder, |s| {
            s.answers += 1;
            s.response_time.add(response);
            s.diag_answers += diag_answer;
            s.ext_diag += ext_diag;
            s.restarts += restart as u64;
        });
    }

    /// Role of a station from what it was heard doing.
    fn role(t: &Track) -> Option<Role> {
        match (t.sends_as_master, t.answers) {
            (true, true) => Some(Role::Both),
            (true, false) => Some(Role::Master),
            (false, true) => Some(Role::Slave),
            (false, false) => None,
        }
    }

    fn finish(&self, set: &mut StatsSet) {
        let ttr_us = self.options.ttr.map(|t| t.as_secs_f64() * 1e6);
        for (a, s) in set.stations.iter_mut() {
            if let Some(t) = self.tracks.get(a) {
                s.role = Stats::role(t);
                s.dp_state = t.dp_state;
                if t.sends_as_master {
                    s.ttr_us = ttr_us;
                }
            }
            s.health = health(s);
        }
    }

    /// The totals since the start, as of now.
    pub fn totals(&self) -> StatsSet {
        let mut t = self.total.clone();
        self.finish(&mut t);
        t
    }

    /// The report of the interval ending at `now` (the statistics since
    /// the last snapshot, and the totals), and a new interval begins.
    pub fn snapshot(&mut self, now: Instant) -> StatsReport {
        self.now = self.now.max(now);
        let start = self.interval_start.unwrap_or(now);
        let mut interval = std::mem::take(&mut self.interval);
        self.finish(&mut interval);
        self.interval_start = Some(now);
        StatsReport {
            event: "stats",
            interval_s: now.saturating_duration_since(start).as_secs_f64(),
            t_s: now.as_nanos() as f64 / 1e9,
            interval,
            totals: self.totals(),
        }
    }

    /// Every station heard of, with role, DP state and health (over the
    /// totals), by address.
    pub fn live(&self) -> Vec<LiveStation> {
        self.totals()
            .stations
            .into_iter()
            .map(|(address, s)| LiveStation {
                address,
                role: s.role,
                dp_state: s.dp_state,
                health: s.health,
            })
            .collect()
    }
}

fn add_codec(a: &mut CodecStats, b: &CodecStats) {
    a.telegrams += b.telegrams;
    a.garbage_bytes += b.garbage_bytes;
    a.bad_fcs += b.bad_fcs;
    a.bad_length += b.bad_length;
    a.bad_end_delimiter += b.bad_end_delimiter;
    a.bad_format += b.bad_format;
    a.truncated += b.truncated;
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_fdl::wire::{DataTelegram, ResponseStatus};

    const M: u8 = 2;
    const S: u8 = 8;

    /// A telegram sequence on a 1.5 Mbit/s line, time in µs.
    struct Line {
        stats: Stats,
    }

    fn req(fcb: bool, fcv: bool) -> FunctionCode {
        FunctionCode::Request {
            kind: RequestKind::SrdHigh,
            fcb,
            fcv,
        }
    }

    fn resp() -> FunctionCode {
        FunctionCode::slave_response(ResponseStatus::Dl)
    }

    impl Line {
        fn new() -> Line {
            Line {
                stats: Stats::new(StatsOptions {
                    baud: Some(Baud::B1500000),
                    ttr: Some(Duration::from_micros(1000)),
                }),
            }
        }
        fn send(&mut self, us: u64, t: Telegram<'_>) {
            let bytes = t.to_vec().unwrap();
            self.stats.hear(&TapEvent::Telegram {
                at: Instant::from_nanos(us * 1000),
                bytes,
            });
        }
        fn data(&mut self, us: u64, da: u8, sa: u8, fc: FunctionCode, dsap: Option<u8>, du: &[u8]) {
            let ssap = dsap.map(|_| sap::MASTER);
            let (dsap, ssap) = match fc {
                FunctionCode::Request { .. } => (dsap, ssap),
                _ => (ssap, dsap),
            };
            self.send(
                us,
                Telegram::Data(DataTelegram::new(da, sa, fc, du).with_saps(dsap, ssap)),
            );
        }
        /// Data_Exchange: request at `us`, answer 100 µs later.
        fn dx(&mut self, us: u64, fcb: bool) {
            self.data(us, S, M, req(fcb, true), None, &[0x55]);
            self.data(us + 100, M, S, resp(), None, &[0x2A]);
        }
        fn diag(&mut self, us: u64, fcb: bool, status1: u8, status2: u8) {
            self.data(us, S, M, req(fcb, true), Some(sap::SLAVE_DIAG), &[]);
            let du = [status1, status2 | 0x04, 0, 0, 0x0D, 0xCE];
            self.data(us + 100, M, S, resp(), Some(sap::SLAVE_DIAG), &du);
        }
        fn station(&self, a: u8) -> StationStats {
            self.stats.totals().stations[&a].clone()
        }
    }

    #[test]
    fn requests_answers_and_response_time_from_the_request_end() {
        let mut l = Line::new();
        l.dx(0, true);
        l.dx(1000, false);
        l.dx(2500, true);
        let s = l.station(S);
        assert_eq!(
            (s.requests, s.answers, s.retries, s.no_answer),
            (3, 3, 0, 0)
        );
        assert_eq!(s.role, Some(Role::Slave));
        assert_eq!(s.dp_state, Some(SlaveState::DataExchange));
        // The request is 10 characters (SD2 with one data byte): 110 bit
        // at 1.5 Mbit/s = 73.3 µs; the answer starts 100 µs after its
        // first byte.
        let r = s.response_time;
        assert_eq!(r.count, 3);
        assert_eq!(r.max().unwrap().as_nanos(), 100_000 - 73_334);
        assert_eq!(s.cycle.min(), Some(Duration::from_micros(1000)));
        assert_eq!(s.cycle.max(), Some(Duration::from_micros(1500)));
        let m = l.station(M);
        assert_eq!(m.role, Some(Role::Master));
        assert_eq!((m.requests_sent, m.bus_cycle.count), (3, 2));
        // Idle before the second request: from the answer's end (first
        // byte at 100 µs, 10 characters) to 1000 µs.
        assert_eq!(
            m.idle_before_request.min(),
            Some(Duration::from_nanos(1_000_000 - 100_000 - 73_334))
        );
        assert_eq!(health(&s), 100);
    }

    #[test]
    fn a_repetition_with_the_same_fcb_is_a_retry() {
        let mut l = Line::new();
        l.dx(0, true);
        // FCB toggled: a new request. Not answered …
        l.data(1000, S, M, req(false, true), None, &[0x55]);
        // … repeated with the same FCB: a retry, and the cycle is
        // measured from the original request.
        l.dx(1300, false);
        l.dx(2000, true);
        let s = l.station(S);
        assert_eq!(
            (s.requests, s.retries, s.no_answer, s.answers),
            (4, 1, 1, 3)
        );
        assert_eq!(s.cycle.count, 2);
        assert_eq!(s.cycle.max(), Some(Duration::from_micros(1000)));
        // 1 lost answer of 4 requests (25 %) and a retry: 0.
        assert_eq!(s.health, 0);
    }

    #[test]
    fn first_requests_after_a_restart_are_not_retries() {
        let mut l = Line::new();
        // FCV = 0, FCB = 1 opens the exchange; answered.
        l.data(0, S, M, req(true, false), Some(sap::SLAVE_DIAG), &[]);
        l.data(
            100,
            M,
            S,
            resp(),
            Some(sap::SLAVE_DIAG),
            &[0x02, 0x05, 0, 0xFF, 0x0D, 0xCE],
        );
        // The master restarted: the same first request again is no retry.
        l.data(5000, S, M, req(true, false), Some(sap::SLAVE_DIAG), &[]);
        // Unanswered, then repeated: a retry.
        l.data(6000, S, M, req(true, false), Some(sap::SLAVE_DIAG), &[]);
        let s = l.station(S);
        assert_eq!((s.requests, s.retries, s.no_answer), (3, 1, 1));
        assert_eq!((s.diag_requests, s.diag_answers), (3, 1));
        assert_eq!(s.dp_state, Some(SlaveState::SetPrm));
        // A Set_Prm request in a different service is never a retry of
        // the Slave_Diag.
        l.data(7000, S, M, req(true, true), Some(sap::SET_PRM), &[0x88]);
        assert_eq!(l.station(S).retries, 1);
    }

    #[test]
    fn an_answered_fdl_status_request_is_no_data_exchange() {
        let mut l = Line::new();
        // A live-list poll (FDL_Status) answered: the station answers,
        // but no master has it in Data_Exchange.
        l.data(
            0,
            S,
            M,
            FunctionCode::request(RequestKind::FdlStatus),
            None,
            &[],
        );
        l.send(100, Telegram::Data(DataTelegram::new(M, S, resp(), &[])));
        let s = l.station(S);
        assert_eq!((s.role, s.dp_state), (Some(Role::Slave), None));
        // Data_Exchange is.
        l.dx(1000, true);
        assert_eq!(l.station(S).dp_state, Some(SlaveState::DataExchange));
    }

    #[test]
    fn restarts_from_set_prm_or_diagnosis_after_data_exchange() {
        let mut l = Line::new();
        // Start-up: diagnosis, Set_Prm, Chk_Cfg: no restart yet.
        l.diag(0, true, 0x02, 0x01);
        l.data(
            1000,
            S,
            M,
            req(false, true),
            Some(sap::SET_PRM),
            &[0x88, 0, 0, 0x0B, 0x0D, 0xCE, 0],
        );
        l.send(1100, Telegram::ShortAck);
        l.data(2000, S, M, req(true, true), Some(sap::CHK_CFG), &[0x71]);
        l.send(2100, Telegram::ShortAck);
        l.dx(3000, false);
        assert_eq!(l.station(S).restarts, 0);
        // The slave reports Prm_Req after Data_Exchange: it restarted.
        l.diag(4000, true, 0x00, 0x01);
        assert_eq!(l.station(S).restarts, 1);
        assert_eq!(l.station(S).dp_state, Some(SlaveState::SetPrm));
        // Back to Data_Exchange, then a Set_Prm: a second restart.
        l.dx(5000, false);
        l.data(
            6000,
            S,
            M,
            req(true, true),
            Some(sap::SET_PRM),
            &[0x88, 0, 0, 0x0B, 0x0D, 0xCE, 0],
        );
        let s = l.station(S);
        assert_eq!((s.restarts, s.set_prm, s.chk_cfg), (2, 2, 1));
        assert_eq!(s.health, 60);
    }

    #[test]
    fn a_killed_slave_goes_offline_and_restarts_once_when_refusing_data_exchange() {
        let mut l = Line::new();
        l.dx(0, true);
        // The slave is gone: three Data_Exchange requests unanswered.
        for (i, at) in [1000, 2000, 3000, 4000].into_iter().enumerate() {
            l.data(at, S, M, req(i % 2 == 1, true), None, &[0x55]);
        }
        l.send(4500, Telegram::Token { da: M, sa: M });
        let s = l.station(S);
        assert_eq!((s.no_answer, s.dp_state), (4, Some(SlaveState::Offline)));
        assert_eq!(s.health, 0);
        // Back, not parameterised: Data_Exchange refused (RS), then the
        // master's start-up (Slave_Diag with Prm_Req, Set_Prm): one
        // restart, not three.
        l.data(5000, S, M, req(false, true), None, &[0x55]);
        let rs = FunctionCode::slave_response(ResponseStatus::Rs);
        l.send(5100, Telegram::Data(DataTelegram::new(M, S, rs, &[])));
        l.diag(6000, true, 0x02, 0x01);
        l.data(7000, S, M, req(false, true), Some(sap::SET_PRM), &[0x88]);
        let s = l.station(S);
        assert_eq!(s.restarts, 1);
        assert_eq!(s.dp_state, Some(SlaveState::ChkCfg));
        // A single token telegram (no FCS: noise can forge one) makes no
        // master; master 2 passed it once only, but sent requests.
        assert_eq!(l.station(M).role, Some(Role::Master));
    }

    #[test]
    fn ext_diag_answers_and_illegal_telegrams() {
        let mut l = Line::new();
        l.diag(0, true, 0x08, 0x00);
        // A corrupt answer: blamed on the slave whose answer was due.
        l.data(1000, S, M, req(false, true), None, &[0x55]);
        let errors = CodecStats {
            bad_fcs: 1,
            ..CodecStats::default()
        };
        l.stats.hear(&TapEvent::Skipped {
            at: Instant::from_nanos(1_100_000),
            bytes: vec![0x68, 0x05],
            errors,
        });
        // Garbage with no answer due and no token seen: the line's.
        l.stats.hear(&TapEvent::Skipped {
            at: Instant::from_nanos(3_000_000),
            bytes: vec![0xFF],
            errors: CodecStats {
                garbage_bytes: 1,
                ..CodecStats::default()
            },
        });
        let t = l.stats.totals();
        let s = &t.stations[&S];
        assert_eq!(
            (s.ext_diag, s.diag_answers, s.illegal, s.no_answer),
            (1, 1, 1, 0)
        );
        assert_eq!((t.line.illegal, t.line.unattributed), (2, 1));
        assert_eq!((t.line.errors.bad_fcs, t.line.errors.garbage_bytes), (1, 1));
    }

    #[test]
    fn token_rotation_against_ttr_and_roles() {
        let mut l = Line::new();
        for (i, at) in [0u64, 800, 2000, 2700].into_iter().enumerate() {
            l.send(at, Telegram::Token { da: 3, sa: M });
            l.send(at + 300, Telegram::Token { da: M, sa: 3 });
            if i == 0 {
                // Master 2 answers an FDL status request of master 3.
                let fc = FunctionCode::Request {
                    kind: RequestKind::FdlStatus,
                    fcb: false,
                    fcv: false,
                };
                l.data(at + 400, M, 3, fc, None, &[]);
                let fc = FunctionCode::Response {
                    status: ResponseStatus::Ok,
                    station: profibus_fdl::wire::StationType::ActiveInRing,
                };
                l.data(at + 450, 3, M, fc, None, &[]);
            }
        }
        let m = l.station(M);
        assert_eq!(m.role, Some(Role::Both));
        assert_eq!(m.tokens, 4);
        assert_eq!(m.token_rotation.count, 3);
        assert_eq!(m.token_rotation.max(), Some(Duration::from_micros(1200)));
        assert_eq!(m.over_ttr, 1);
        assert_eq!(m.ttr_us, Some(1000.0));
        // 1 of 3 rotations over the TTR: −17; one FDL status request to
        // it, answered.
        assert_eq!(m.health, 83);
        assert_eq!(l.station(3).role, Some(Role::Master));
    }

    #[test]
    fn snapshots_split_intervals_and_keep_totals() {
        let mut l = Line::new();
        l.dx(0, true);
        l.dx(1000, false);
        let first = l.stats.snapshot(Instant::from_nanos(2_000_000));
        assert_eq!(first.interval.stations[&S].requests, 2);
        l.dx(2500, true);
        let second = l.stats.snapshot(Instant::from_nanos(4_000_000));
        assert_eq!(second.interval.stations[&S].requests, 1);
        assert_eq!(second.totals.stations[&S].requests, 3);
        assert!((second.interval_s - 0.002).abs() < 1e-9);
        #[cfg(feature = "serde")]
        {
            let v = serde_json::to_value(&second).unwrap();
            assert_eq!(v["event"], "stats");
            assert_eq!(v["stations"]["8"]["requests"], 1);
            assert_eq!(v["stations"]["8"]["dp_state"], "data_exchange");
            assert_eq!(v["stations"]["2"]["role"], "master");
            assert_eq!(v["totals"]["stations"]["8"]["requests"], 3);
            assert!(v["stations"]["8"]["response_time"]["max_us"].is_number());
        }
        let live = l.stats.live();
        assert_eq!(live.len(), 2);
        assert_eq!(live[1].health, 100);
    }
}
