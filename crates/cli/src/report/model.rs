//! The report's data: a capture replayed through the passive
//! [`Monitor`] (states, restarts, diagnoses, faults, masters) while the
//! samples the plots need are collected on the way (response and cycle
//! times, token rotations).

use profibus_devices::bus::ProfiledBus;
use profibus_dp::config::gsd::Gsd;
use profibus_dp::config::library::GsdLibrary;
use profibus_dp::master::SlaveState;
use profibus_dp::monitor::stats::{Stats, StatsOptions, StatsSet};
use profibus_dp::monitor::{Monitor, MonitorEvent, MonitorOptions, SlaveInfo};
use profibus_dp::pdu::diag::{self, SlaveDiag, StationStatus1};
use profibus_dp::pdu::sap;
use profibus_fdl::capture::pcap::{PcapReader, LINKTYPE_PROFIBUS_DL};
use profibus_fdl::codec::CodecStats;
use profibus_fdl::line::tap::TapEvent;
use profibus_fdl::wire::{FunctionCode, Hex, RequestKind, StationType};
use profibus_fdl::{Baud, Instant, Telegram};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};
use std::io::Read;
use std::time::Duration;

/// What the replay needs besides the capture.
pub struct Options<'a> {
    /// The capture's name, shown in the report.
    pub name: String,
    /// The line's rate, when given.
    pub baud: Option<Baud>,
    /// The segment's bus file.
    pub bus: Option<&'a ProfiledBus>,
    /// GSD files by ident number, for the diagnosis texts.
    pub library: &'a GsdLibrary,
}

/// Why a capture cannot be reported on.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The file does not read as a capture.
    #[error("{0}")]
    Read(#[from] std::io::Error),
    /// A capture of something else than PROFIBUS.
    #[error("link type {0} is not PROFIBUS DL ({LINKTYPE_PROFIBUS_DL})")]
    LinkType(u32),
}

/// Minimum, mean and maximum of a time, in µs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Stat {
    /// Shortest.
    pub min: f64,
    /// Mean.
    pub mean: f64,
    /// Longest.
    pub max: f64,
    /// Samples.
    pub count: u64,
}

impl Stat {
    fn of(samples: &[f64]) -> Option<Stat> {
        if samples.is_empty() {
            return None;
        }
        let (mut min, mut max, mut sum) = (f64::INFINITY, 0f64, 0f64);
        for &s in samples {
            min = min.min(s);
            max = max.max(s);
            sum += s;
        }
        Some(Stat {
            min,
            mean: sum / samples.len() as f64,
            max,
            count: samples.len() as u64,
        })
    }
}

/// The segment as the capture shows it.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Segment {
    /// The line's rate in bit/s.
    pub baud: Option<u32>,
    /// Where the rate comes from: `given`, `bus file`, `guessed` (the
    /// slowest rate at which every telegram fits before the next one
    /// starts) or `unknown`.
    pub baud_source: &'static str,
    /// Masters seen passing the token.
    pub masters: Vec<u8>,
    /// Target rotation time in bit times (from the bus file).
    pub ttr_bits: Option<u32>,
    /// The same in µs (with the rate).
    pub ttr_us: Option<f64>,
    /// Time of the first record (UTC, ISO 8601).
    pub start: String,
    /// From the first record to the last, in seconds.
    pub span_s: f64,
    /// Records in the file.
    pub records: u64,
    /// Valid telegrams.
    pub telegrams: u64,
    /// Token telegrams.
    pub tokens: u64,
    /// Records flagged as corrupt or that do not parse as a telegram.
    pub illegal: u64,
    /// Requests without an answer.
    pub no_answer: u64,
    /// Requests repeated with the same FCB.
    pub retries: u64,
    /// Slaves leaving Data_Exchange for a new start-up.
    pub restarts: u64,
}

/// One station of the live list, with its counters.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Station {
    /// Station address.
    pub address: u8,
    /// Name from the bus file.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub name: String,
    /// `master` (passes the token) or `slave`.
    pub role: &'static str,
    /// DP state at the end of the capture (slaves).
    pub state: Option<&'static str>,
    /// The master that talks to it (slaves).
    pub master: Option<u8>,
    /// 0 … 100, `profibus_dp::monitor::stats::health` (docs/analyser.md).
    pub health: u8,
    /// Ident number from its diagnosis (`0x….`).
    pub ident: Option<String>,
    /// The GSD file found for it.
    pub gsd: Option<String>,
    /// Requests to it (retries included).
    pub requests: u64,
    /// Answers from it.
    pub answers: u64,
    /// Requests repeated with the same FCB.
    pub retries: u64,
    /// Requests it left unanswered.
    pub no_answer: u64,
    /// Corrupt records where its answer was due.
    pub illegal: u64,
    /// Slave_Diag requests to it.
    pub diag_requests: u64,
    /// Diagnosis answers with Ext_Diag set.
    pub ext_diag: u64,
    /// Times it left Data_Exchange for a new start-up.
    pub restarts: u64,
    /// Request end to answer start, µs.
    pub response_us: Option<Stat>,
    /// Between its Data_Exchange requests, µs.
    pub cycle_us: Option<Stat>,
    /// Tokens passed (masters).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tokens: Option<u64>,
    /// Token rotation it saw, µs (masters).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotation_us: Option<Stat>,
}

/// A diagnosis a slave gave, in words.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// The slave.
    pub address: u8,
    /// When it was first seen, s from the start.
    pub t_s: f64,
    /// How often this same diagnosis came.
    pub count: u64,
    /// The Slave_Diag data unit.
    pub raw: String,
    /// In words (with the GSD's texts when found).
    pub lines: Vec<String>,
    /// The GSD whose texts were used.
    pub gsd: Option<String>,
}

/// What a timeline mark is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MarkKind {
    /// A slave left Data_Exchange for a new start-up.
    Restart,
    /// A slave's diagnosis changed.
    Diag,
    /// A request failed, or a record was corrupt.
    Error,
    /// A slave changed state, a master joined or left the ring.
    State,
}

impl MarkKind {
    /// Every kind, in the order of the timeline's rows.
    pub const ALL: [MarkKind; 4] = [
        MarkKind::Restart,
        MarkKind::Diag,
        MarkKind::Error,
        MarkKind::State,
    ];

    /// The kind's name.
    pub fn name(self) -> &'static str {
        match self {
            MarkKind::Restart => "restart",
            MarkKind::Diag => "diag",
            MarkKind::Error => "error",
            MarkKind::State => "state",
        }
    }
}

/// One mark on the timeline.
#[derive(Debug, Clone, Serialize)]
pub struct Mark {
    /// s from the start.
    pub t_s: f64,
    /// What happened.
    pub kind: MarkKind,
    /// The station concerned.
    pub address: Option<u8>,
    /// In words.
    pub text: String,
}

/// A histogram of times in µs.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Histogram {
    /// Lower bound of the first bin.
    pub from_us: f64,
    /// Width of a bin.
    pub bin_us: f64,
    /// Samples per bin.
    pub counts: Vec<u64>,
    /// Samples in all.
    pub samples: u64,
}

/// Bins of a histogram.
const BINS: usize = 40;

impl Histogram {
    fn of(samples: &[f64]) -> Histogram {
        let Some(stat) = Stat::of(samples) else {
            return Histogram::default();
        };
        let width = ((stat.max - stat.min) / BINS as f64).max(1.0);
        let mut counts = vec![0u64; BINS];
        for &s in samples {
            let i = (((s - stat.min) / width) as usize).min(BINS - 1);
            counts[i] += 1;
        }
        while counts.last() == Some(&0) {
            counts.pop();
        }
        Histogram {
            from_us: stat.min,
            bin_us: width,
            counts,
            samples: samples.len() as u64,
        }
    }
}

/// One master's token rotation over time.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Rotation {
    /// The master.
    pub master: u8,
    /// (s from the start, rotation in µs): the longest rotation of each
    /// stretch of the capture (at most [`ROTATION_POINTS`] points).
    pub points: Vec<(f64, f64)>,
}

/// Points of a rotation series at most.
pub const ROTATION_POINTS: usize = 600;
/// Timeline marks kept at most (the first ones).
pub const MAX_MARKS: usize = 5000;

/// The whole report.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Report {
    /// The capture file.
    pub capture: String,
    /// The segment's parameters and totals.
    pub segment: Segment,
    /// Every station seen (and every slave of the bus file), by address.
    pub stations: Vec<Station>,
    /// Diagnoses in words, in the order they came.
    pub diagnoses: Vec<Diagnosis>,
    /// Restarts, diagnoses, errors and state changes over time.
    pub timeline: Vec<Mark>,
    /// Marks left out beyond [`MAX_MARKS`].
    pub timeline_dropped: u64,
    /// Data_Exchange cycle times of all slaves.
    pub cycle_histogram: Histogram,
    /// Response times of all stations.
    pub response_histogram: Histogram,
    /// Token rotation over time, per master.
    pub rotation: Vec<Rotation>,
}

/// What the replay collects from the monitor's events.
#[derive(Default)]
struct Collect {
    /// Diagnoses by slave and data unit.
    diags: Vec<(u8, Vec<u8>, Diagnosis)>,
    /// Slaves seen in Data_Exchange since their last start-up.
    been_dx: BTreeSet<u8>,
    /// Restarts per slave.
    restarts: BTreeMap<u8, u64>,
}

/// A request waiting for its answer.
#[derive(Debug, Clone, Copy)]
struct Pending {
    slave: u8,
    /// Its last byte's end (its start without a rate).
    end: Instant,
    /// An FDL status request (unanswered ones are gap polls, not errors).
    fdl_status: bool,
    /// Slave_Diag request.
    diag: bool,
}

#[derive(Debug, Default)]
struct Track {
    requests: u64,
    answers: u64,
    no_answer: u64,
    illegal: u64,
    diag_requests: u64,
    ext_diag: u64,
    response: Vec<f64>,
    cycle: Vec<f64>,
    last_dx: Option<Instant>,
    ident: Option<u16>,
    station_type: Option<StationType>,
    tokens: u64,
    last_token: Option<Instant>,
    rotation: Vec<(f64, f64)>,
}

/// The samples collected on the way.
#[derive(Default)]
struct Sampler {
    baud: Option<Baud>,
    tracks: BTreeMap<u8, Track>,
    pending: Option<Pending>,
    /// Lower bounds of the rate (bit/s) from consecutive telegrams.
    rate_bounds: Vec<f64>,
    /// The previous record: start and length.
    prev: Option<(Instant, usize)>,
    illegal: u64,
    no_answer: u64,
}

fn us(d: Duration) -> f64 {
    d.as_nanos() as f64 / 1000.0
}

fn secs(at: Instant) -> f64 {
    at.as_nanos() as f64 / 1e9
}

impl Sampler {
    fn end_of(&self, at: Instant, len: usize) -> Instant {
        match self.baud {
            Some(b) => Instant::from_nanos(
                at.as_nanos() + b.chars_to_duration(len as u64).as_nanos() as u64,
            ),
            None => at,
        }
    }

    /// Whatever comes while an answer is due and is no answer.
    fn unanswered(&mut self) {
        if let Some(p) = self.pending.take() {
            if !p.fdl_status {
                self.tracks.entry(p.slave).or_default().no_answer += 1;
                self.no_answer += 1;
            }
        }
    }

    fn record(&mut self, at: Instant, len: usize) {
        if let Some((t, n)) = self.prev {
            let gap = at.saturating_duration_since(t).as_secs_f64();
            if gap > 0.0 {
                self.rate_bounds.push(11.0 * n as f64 / gap);
            }
        }
        self.prev = Some((at, len));
    }

    fn corrupt(&mut self, at: Instant, len: usize) {
        self.record(at, len);
        self.illegal += 1;
        if let Some(p) = self.pending.take() {
            self.tracks.entry(p.slave).or_default().illegal += 1;
        }
    }

    fn telegram(&mut self, at: Instant, bytes: &[u8], t: &Telegram<'_>) {
        self.record(at, bytes.len());
        match t {
            Telegram::Token { sa, .. } => {
                self.unanswered();
                let tr = self.tracks.entry(*sa).or_default();
                tr.tokens += 1;
                if let Some(last) = tr.last_token.replace(at) {
                    tr.rotation.push((secs(at), us(at - last)));
                }
            }
            Telegram::Data(d) => match d.fc {
                FunctionCode::Request { kind, .. } => {
                    self.unanswered();
                    if !kind.expects_reply() || d.da == 127 {
                        return;
                    }
                    let diag = d.dsap == Some(sap::SLAVE_DIAG);
                    let fdl_status = kind == RequestKind::FdlStatus;
                    if !fdl_status {
                        let tr = self.tracks.entry(d.da).or_default();
                        tr.requests += 1;
                        tr.diag_requests += diag as u64;
                        if d.dsap.is_none() && d.ssap.is_none() {
                            if let Some(last) = tr.last_dx.replace(at) {
                                tr.cycle.push(us(at - last));
                            }
                        }
                    }
                    self.pending = Some(Pending {
                        slave: d.da,
                        end: self.end_of(at, bytes.len()),
                        fdl_status,
                        diag,
                    });
                }
                FunctionCode::Response { station, .. } => {
                    let Some(p) = self.pending.take() else {
                        return;
                    };
                    let tr = self.tracks.entry(p.slave).or_default();
                    tr.station_type.get_or_insert(station);
                    if p.fdl_status {
                        return;
                    }
                    tr.answers += 1;
                    tr.response.push(us(at.saturating_duration_since(p.end)));
                    if p.diag {
                        if let Ok(sd) = SlaveDiag::parse(d.data) {
                            tr.ident = Some(sd.ident_number);
                            if sd.status1.contains(StationStatus1::EXT_DIAG) {
                                tr.ext_diag += 1;
                            }
                        }
                    }
                }
            },
            Telegram::ShortAck => {
                if let Some(p) = self.pending.take() {
                    let tr = self.tracks.entry(p.slave).or_default();
                    if !p.fdl_status {
                        tr.answers += 1;
                        tr.response.push(us(at.saturating_duration_since(p.end)));
                    }
                }
            }
        }
    }

    /// The slowest rate at which each telegram ends before the next one
    /// starts (ignoring the fastest 0.1 % of the gaps: time-stamp
    /// jitter).
    fn guess_baud(&self) -> Option<Baud> {
        let mut b = self.rate_bounds.clone();
        if b.len() < 10 {
            return None;
        }
        b.sort_by(f64::total_cmp);
        let bound = b[b.len() - 1 - b.len() / 1000];
        Baud::ALL.into_iter().find(|r| r.bps() as f64 >= bound)
    }
}

/// Civil date of days since 1970-01-01 (proleptic Gregorian).
fn civil(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + (m <= 2) as i64, m, d)
}

/// `ts` (since the Unix epoch) as ISO 8601 UTC with milliseconds.
pub fn utc(ts: Duration) -> String {
    let s = ts.as_secs() as i64;
    let (y, m, d) = civil(s.div_euclid(86_400));
    let r = s.rem_euclid(86_400);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{:03}Z",
        r / 3600,
        r / 60 % 60,
        r % 60,
        ts.subsec_millis()
    )
}

/// At most `n` points: the largest value of each stretch.
fn thin(points: &[(f64, f64)], n: usize) -> Vec<(f64, f64)> {
    if points.len() <= n {
        return points.to_vec();
    }
    points
        .chunks(points.len().div_ceil(n))
        .filter_map(|c| c.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1)))
        .collect()
}

impl Report {
    /// Replay the capture `source`.
    pub fn from_capture(source: impl Read, o: &Options<'_>) -> Result<Report, ReportError> {
        let reader = PcapReader::new(source)?;
        if reader.linktype() != LINKTYPE_PROFIBUS_DL {
            return Err(ReportError::LinkType(reader.linktype()));
        }
        let slaves = match o.bus {
            Some(b) => b.layouts().into_iter().map(SlaveInfo::from).collect(),
            None => vec![],
        };
        let mut monitor = Monitor::new(slaves, MonitorOptions::default());
        let bus_baud = o.bus.map(|b| b.file.master.params.baud);
        let mut sampler = Sampler {
            baud: o.baud.or(bus_baud),
            ..Sampler::default()
        };
        let mut r = Report {
            capture: o.name.clone(),
            ..Report::default()
        };
        let mut first: Option<Duration> = None;
        let mut last = Instant::ZERO;
        let mut c = Collect::default();
        // Records are replayed twice when no rate is known: first to
        // guess it (response times start at a request's end).
        let mut records = vec![];
        for p in reader {
            let p = p?;
            let t0 = *first.get_or_insert(p.ts);
            let at = Instant::from_nanos(p.ts.saturating_sub(t0).as_nanos() as u64);
            records.push((at, p.is_corrupt(), p.data));
        }
        let given = sampler.baud.is_some();
        if !given {
            let mut probe = Sampler::default();
            for (at, corrupt, data) in &records {
                match (corrupt, Telegram::parse(data)) {
                    (false, Ok((t, _))) => probe.telegram(*at, data, &t),
                    _ => probe.corrupt(*at, data.len()),
                }
            }
            sampler.baud = probe.guess_baud();
        }
        // The per-station counters and health come from the analyser's
        // statistics core, as in `dpctl sniff --stats`; the sampler keeps
        // only what the plots need.
        let ttr = o
            .bus
            .zip(sampler.baud)
            .map(|(b, baud)| baud.bits_to_duration(b.file.master.params.ttr as u64));
        let mut stats = Stats::new(StatsOptions {
            baud: sampler.baud,
            ttr,
        });
        for (at, corrupt, data) in records {
            last = at;
            r.segment.records += 1;
            let parsed = if corrupt {
                None
            } else {
                Telegram::parse(&data).ok().map(|(t, _)| t)
            };
            let ev = match parsed {
                Some(t) => {
                    r.segment.telegrams += 1;
                    if matches!(t, Telegram::Token { .. }) {
                        r.segment.tokens += 1;
                    }
                    sampler.telegram(at, &data, &t);
                    TapEvent::Telegram {
                        at,
                        bytes: data.clone(),
                    }
                }
                None => {
                    sampler.corrupt(at, data.len());
                    r.mark(
                        at,
                        MarkKind::Error,
                        None,
                        format!("illegal telegram: {} bytes {}", data.len(), Hex(&data)),
                    );
                    TapEvent::Skipped {
                        at,
                        bytes: data.clone(),
                        errors: CodecStats::default(),
                    }
                }
            };
            monitor.hear(&ev);
            stats.hear(&ev);
            while let Some(e) = monitor.poll_event() {
                r.event(at, e, o, &mut c);
            }
        }
        monitor.tick(last);
        while let Some(e) = monitor.poll_event() {
            r.event(last, e, o, &mut c);
        }
        r.diagnoses = c.diags.into_iter().map(|(_, _, d)| d).collect();
        r.finish(
            &monitor,
            &stats.totals(),
            sampler,
            o,
            (first.unwrap_or_default(), last),
            given,
        );
        Ok(r)
    }

    fn mark(&mut self, at: Instant, kind: MarkKind, address: Option<u8>, text: String) {
        if self.timeline.len() >= MAX_MARKS {
            self.timeline_dropped += 1;
            return;
        }
        self.timeline.push(Mark {
            t_s: secs(at),
            kind,
            address,
            text,
        });
    }

    fn event(&mut self, at: Instant, e: MonitorEvent, o: &Options<'_>, c: &mut Collect) {
        let text = e.to_string();
        match e {
            MonitorEvent::SlaveState { address, to, .. } => {
                // A restart: a slave that was in Data_Exchange starts up
                // anew (asks for parameters), whether it went offline
                // first (power cycle) or not (watchdog, a new Set_Prm).
                let kind = if to == SlaveState::DataExchange {
                    c.been_dx.insert(address);
                    MarkKind::State
                } else if to == SlaveState::SetPrm && c.been_dx.remove(&address) {
                    *c.restarts.entry(address).or_default() += 1;
                    MarkKind::Restart
                } else {
                    MarkKind::State
                };
                let text = if kind == MarkKind::Restart {
                    format!("slave {address} restarts: {text}")
                } else {
                    text
                };
                self.mark(at, kind, Some(address), text);
            }
            MonitorEvent::Diag { address, raw, .. } => {
                self.mark(at, MarkKind::Diag, Some(address), text);
                if let Some((_, _, d)) = c
                    .diags
                    .iter_mut()
                    .find(|(a, r, _)| *a == address && *r == raw)
                {
                    d.count += 1;
                    return;
                }
                let gsd = gsd_for(o, address, &raw);
                let dpv1 = gsd.as_ref().is_some_and(|(_, g)| g.dpv1_slave);
                let lines = diag::describe(&raw, gsd.as_ref().map(|(_, g)| g), dpv1);
                c.diags.push((
                    address,
                    raw.clone(),
                    Diagnosis {
                        address,
                        t_s: secs(at),
                        count: 1,
                        raw: Hex(&raw).to_string(),
                        lines,
                        gsd: gsd.map(|(n, _)| n),
                    },
                ));
            }
            MonitorEvent::Fault { address, .. } => {
                self.mark(at, MarkKind::Error, Some(address), text)
            }
            MonitorEvent::MasterJoined { master } | MonitorEvent::MasterLeft { master } => {
                self.mark(at, MarkKind::State, Some(master), text)
            }
            MonitorEvent::Alarm(_) | MonitorEvent::Operating { .. } => {
                self.mark(at, MarkKind::State, None, text)
            }
            // FMS services are no DP events: not in the timeline.
            MonitorEvent::Fms(_) => {}
        }
    }

    fn finish(
        &mut self,
        m: &Monitor,
        totals: &StatsSet,
        s: Sampler,
        o: &Options<'_>,
        (first, last): (Duration, Instant),
        given: bool,
    ) {
        let status = m.status();
        let seg = &mut self.segment;
        seg.baud = s.baud.map(|b| b.bps());
        seg.baud_source = match (s.baud, o.baud, given) {
            (None, _, _) => "unknown",
            (Some(_), Some(_), _) => "given",
            (Some(_), None, true) => "bus file",
            (Some(_), None, false) => "guessed",
        };
        seg.masters = status.masters.iter().map(|m| m.address).collect();
        if let Some(b) = o.bus {
            let ttr = b.file.master.params.ttr;
            seg.ttr_bits = Some(ttr);
            seg.ttr_us = s.baud.map(|b| us(b.bits_to_duration(ttr as u64)));
        }
        seg.start = utc(first);
        seg.span_s = secs(last);
        seg.illegal = s.illegal;
        seg.no_answer = s.no_answer;
        let mut cycles = vec![];
        let mut responses = vec![];
        let mut stations: BTreeMap<u8, Station> = BTreeMap::new();
        for sl in &status.slaves {
            let st = stations.entry(sl.address).or_default();
            st.address = sl.address;
            st.name = sl.name.clone();
            st.role = "slave";
            st.state = sl.state.map(|s| s.name());
            st.master = sl.master;
            st.retries = sl.counters.retries;
        }
        for (addr, tr) in &s.tracks {
            let is_master = tr.tokens > 0
                || matches!(
                    tr.station_type,
                    Some(StationType::ActiveReady | StationType::ActiveInRing)
                );
            if !is_master && tr.requests == 0 && tr.answers == 0 && !stations.contains_key(addr) {
                // Only ever asked for its FDL status without answer: a gap.
                if tr.station_type.is_none() {
                    continue;
                }
            }
            let st = stations.entry(*addr).or_default();
            st.address = *addr;
            st.role = if is_master { "master" } else { "slave" };
            st.requests = tr.requests;
            st.answers = tr.answers;
            st.no_answer = tr.no_answer;
            st.illegal = tr.illegal;
            st.diag_requests = tr.diag_requests;
            st.ext_diag = tr.ext_diag;
            st.response_us = Stat::of(&tr.response);
            st.cycle_us = Stat::of(&tr.cycle);
            if is_master {
                st.tokens = Some(tr.tokens);
                let r: Vec<f64> = tr.rotation.iter().map(|p| p.1).collect();
                st.rotation_us = Stat::of(&r);
                if !tr.rotation.is_empty() {
                    self.rotation.push(Rotation {
                        master: *addr,
                        points: thin(&tr.rotation, ROTATION_POINTS),
                    });
                }
            }
            if let Some(id) = tr.ident {
                st.ident = Some(format!("0x{id:04X}"));
                st.gsd = gsd_by_ident(o, *addr, id).map(|(n, _)| n);
            }
            cycles.extend_from_slice(&tr.cycle);
            responses.extend_from_slice(&tr.response);
        }
        for (addr, t) in &totals.stations {
            let Some(st) = stations.get_mut(addr) else {
                continue;
            };
            if let Some(role) = t.role {
                st.role = role.name();
            }
            st.requests = t.requests;
            st.answers = t.answers;
            st.retries = t.retries;
            st.no_answer = t.no_answer;
            st.illegal = t.illegal;
            st.diag_requests = t.diag_requests;
            st.ext_diag = t.ext_diag;
            st.restarts = t.restarts;
            st.health = t.health;
            seg.retries += t.retries;
            seg.restarts += t.restarts;
        }
        self.stations = stations.into_values().collect();
        self.cycle_histogram = Histogram::of(&cycles);
        self.response_histogram = Histogram::of(&responses);
    }
}

/// The GSD of a slave: the bus file's, else the library's by the ident
/// number in `raw` (a Slave_Diag data unit).
fn gsd_for(o: &Options<'_>, address: u8, raw: &[u8]) -> Option<(String, Gsd)> {
    let ident = SlaveDiag::parse(raw).ok()?.ident_number;
    gsd_by_ident(o, address, ident)
}

fn gsd_by_ident(o: &Options<'_>, address: u8, ident: u16) -> Option<(String, Gsd)> {
    if let Some(s) = o
        .bus
        .and_then(|b| b.file.slaves.iter().find(|s| s.params.address == address))
    {
        if s.gsd.ident_number == ident {
            return Some((s.gsd_path.display().to_string(), s.gsd.clone()));
        }
    }
    let e = o.library.find(ident).into_iter().next()?;
    Some((e.source.to_string(), e.gsd.clone()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates() {
        assert_eq!(utc(Duration::ZERO), "1970-01-01T00:00:00.000Z");
        assert_eq!(
            utc(Duration::new(1_700_000_000, 250_000_000)),
            "2023-11-14T22:13:20.250Z"
        );
        assert_eq!(
            utc(Duration::from_secs(951_782_400)),
            "2000-02-29T00:00:00.000Z"
        );
    }

    #[test]
    fn histogram_bins_every_sample() {
        let h = Histogram::of(&[10.0, 10.0, 50.0, 410.0]);
        assert_eq!(h.samples, 4);
        assert_eq!(h.counts.iter().sum::<u64>(), 4);
        assert_eq!(h.counts[0], 2);
        assert_eq!(*h.counts.last().unwrap(), 1);
        assert_eq!(h.from_us, 10.0);
        assert!(Histogram::of(&[]).counts.is_empty());
    }

    #[test]
    fn thin_keeps_the_peaks() {
        let pts: Vec<(f64, f64)> = (0..1000).map(|i| (i as f64, (i % 7) as f64)).collect();
        let t = thin(&pts, 100);
        assert!(t.len() <= 100);
        assert!(t.iter().all(|p| p.1 == 6.0));
    }
}
