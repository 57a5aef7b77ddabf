//! A passive bus monitor: follows a third-party DP master's traffic and
//! tracks what it does with every slave, without sending a byte.
//!
//! [`Monitor`] is sans-IO. Feed it the telegrams a passive listener
//! frames off the line ([`profibus_fdl::line::tap::Tap`] gives them with the
//! time their first byte arrived) with [`Monitor::observe`], and the
//! bytes the framer had to skip with [`Monitor::observe_skipped`]. It
//! pairs each request with the telegram that follows it (the response,
//! or nothing when the next request or token comes first) and keeps, per
//! slave:
//!
//! - the state the observed master has it in, named like the master's own
//!   [`SlaveState`]: `diag` (start-up seen), `set_prm` (the slave asked
//!   for parameters, Prm_Req), `chk_cfg` (Set_Prm acknowledged),
//!   `check_diag` (Chk_Cfg acknowledged), `data_exchange`, `locked`
//!   (parameterised by another master), `offline` (no reply);
//! - its process data: the outputs of the last Data_Exchange request and
//!   the inputs of its response, split by GSD module when the bus file
//!   names the modules, and decoded into named channels by an
//!   [`ImageDecoder`] (device profiles give one, `profibus_devices`);
//! - its last diagnosis, raw and in words ([`crate::pdu::diag::describe`]);
//! - Data_Exchange cycle times, retries (a request repeated with the same
//!   FCB, IEC 61158-4-3 frame count bit rules), errors (no reply, negative
//!   responses, corrupt telegrams while a reply was due) and restarts.
//!
//! From token telegrams (SD4) it keeps the live list of the masters in
//! the token ring and their token rotation times, and from Global_Control
//! broadcasts each master's operating state (Clear_Data → clear).
//!
//! Changes come out as [`MonitorEvent`]s ([`Monitor::poll_event`]); a
//! [`MonitorStatus`] snapshot ([`Monitor::status`]) is the whole picture
//! for a table or a JSON line. With the `serde` feature both serialise in
//! the shape `dpctl master --json` prints. Nothing here panics on any
//! telegram sequence (property-tested).
//!
//! # Example
//!
//! Master 2 polls slave 8 (one byte out, one byte in) and the monitor,
//! fed the telegrams it overheard, knows the slave's state and data:
//!
//! ```
//! use profibus_dp::master::SlaveState;
//! use profibus_dp::monitor::{Monitor, MonitorEvent, MonitorOptions, SlaveInfo};
//! use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus};
//! use profibus_fdl::{Instant, Telegram};
//!
//! use profibus_dp::config::layout::SlaveLayout;
//! let valve = SlaveLayout { address: 8, name: "valve".into(), ..SlaveLayout::default() };
//! let slaves = vec![SlaveInfo::from(valve)];
//! let mut monitor = Monitor::new(slaves, MonitorOptions::default());
//! let request = FunctionCode::Request { kind: RequestKind::SrdHigh, fcb: true, fcv: true };
//! let response = FunctionCode::slave_response(ResponseStatus::Dl);
//! let data = |da, sa, fc, du| {
//!     Telegram::Data(DataTelegram { da, sa, fc, dsap: None, ssap: None, data: du, format: None })
//! };
//! // Data_Exchange: outputs 0x55 to slave 8, inputs 0x2A back.
//! monitor.observe(Instant::from_nanos(1_000_000), &data(8, 2, request, &[0x55]));
//! monitor.observe(Instant::from_nanos(1_200_000), &data(2, 8, response, &[0x2A]));
//! monitor.observe(Instant::from_nanos(1_300_000), &Telegram::Token { da: 2, sa: 2 });
//!
//! assert_eq!(monitor.slave_state(8), Some(SlaveState::DataExchange));
//! let status = monitor.status();
//! assert_eq!((status.slaves[0].outputs[0], status.slaves[0].inputs[0]), (0x55, 0x2A));
//! assert_eq!(monitor.masters().collect::<Vec<_>>(), [2]);
//! while let Some(event) = monitor.poll_event() {
//!     println!("{event}"); // "slave 8: unseen → data_exchange (master 2)", …
//! }
//! ```

use crate::config::busfile::BusFile;
use crate::config::layout::SlaveLayout;
use crate::master::{AlarmNotice, AlarmReport, OperatingState, SlaveState};
use crate::pdu::alarm::{dpv1_blocks, AlarmBlock, AlarmSpecifier, AlarmType, DiagBlock};
use crate::pdu::control::{ControlCommand, GlobalControl};
use crate::pdu::diag::{self, SlaveDiag, StationStatus1, StationStatus2, NO_MASTER};
use crate::pdu::dpv1::Pdu;
use crate::pdu::sap;
use profibus_fdl::codec::CodecStats;
use profibus_fdl::line::tap::TapEvent;
use profibus_fdl::wire::{
    DataTelegram, FunctionCode, Hex, RequestKind, ResponseStatus, StationType,
};
use profibus_fdl::{Instant, Telegram};
use std::collections::{BTreeMap, VecDeque};
use std::fmt;
use std::time::Duration;

pub mod alert;
pub mod counters;
pub mod fms;
pub mod stats;
#[cfg(test)]
mod tests;
pub mod trigger;

/// Which process image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Image {
    /// Slave → master (the Data_Exchange response).
    Inputs,
    /// Master → slave (the Data_Exchange request).
    Outputs,
}

/// A decoded value of a named channel.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(feature = "serde", serde(untagged))]
pub enum ReadingValue {
    /// A bit.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A number with a fraction (scaled or floating point channels).
    Float(f64),
}

impl fmt::Display for ReadingValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReadingValue::Bool(b) => write!(f, "{}", *b as u8),
            ReadingValue::Int(i) => write!(f, "{i}"),
            ReadingValue::Float(x) => write!(f, "{x}"),
        }
    }
}

/// One named value of a process image.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Reading {
    /// Channel name.
    pub name: String,
    /// Its value.
    pub value: ReadingValue,
    /// Engineering unit, if the channel has one.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub unit: Option<String>,
}

impl fmt::Display for Reading {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.unit {
            Some(u) => write!(f, "{}={} {u}", self.name, self.value),
            None => write!(f, "{}={}", self.name, self.value),
        }
    }
}

/// Decodes a slave's process images into named values: what a device
/// profile knows about its data (implemented for
/// `profibus_devices::channels::ChannelMap`).
pub trait ImageDecoder: Send + fmt::Debug {
    /// The named values in `bytes`, an image of kind `image`.
    fn decode(&self, image: Image, bytes: &[u8]) -> Vec<Reading>;
}

/// What the monitor knows of a slave before seeing any traffic: its
/// layout from a bus file, and a decoder for its images.
#[derive(Debug, Default)]
pub struct SlaveInfo {
    /// Address, name, GSD (for diagnosis texts), DP-V1 (reads its
    /// diagnosis blocks as alarms) and GSD modules with their spans.
    pub layout: SlaveLayout,
    /// Named channels of its images (a slave given as a device profile).
    pub decoder: Option<Box<dyn ImageDecoder>>,
}

impl From<SlaveLayout> for SlaveInfo {
    fn from(layout: SlaveLayout) -> SlaveInfo {
        SlaveInfo {
            layout,
            decoder: None,
        }
    }
}

impl SlaveInfo {
    /// The slaves of a bus file, with their GSD modules' spans.
    pub fn from_bus(bus: &BusFile) -> Vec<SlaveInfo> {
        (SlaveLayout::of_bus(bus).into_iter())
            .map(SlaveInfo::from)
            .collect()
    }
}

/// Why a slave counted an error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// A request that needs a reply got none before the next telegram.
    NoReply,
    /// The reply was corrupt (bytes the framer skipped while it was due).
    Corrupt,
    /// A negative response (UE, RR, RS, RDL, RDH …).
    Negative(ResponseStatus),
}

impl fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ErrorKind::NoReply => f.write_str("no reply"),
            ErrorKind::Corrupt => f.write_str("corrupt reply"),
            ErrorKind::Negative(s) => write!(f, "negative response {}", s.mnemonic()),
        }
    }
}

/// A DP service as the monitor names it.
fn service_name(dsap: Option<u8>) -> &'static str {
    match dsap {
        None => "Data_Exchange",
        Some(s) => sap::name(s).unwrap_or("unknown SAP"),
    }
}

/// A change the monitor saw.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(
    feature = "serde",
    serde(
        tag = "event",
        rename_all = "snake_case",
        rename_all_fields = "snake_case"
    )
)]
pub enum MonitorEvent {
    /// A slave changed state.
    #[cfg_attr(feature = "serde", serde(rename = "state"))]
    SlaveState {
        /// The slave.
        #[cfg_attr(feature = "serde", serde(rename = "slave"))]
        address: u8,
        /// The master talking to it.
        master: u8,
        /// The state before (`None`: not seen before).
        from: Option<SlaveState>,
        /// The new state.
        to: SlaveState,
    },
    /// A slave's diagnosis changed.
    Diag {
        /// The slave.
        #[cfg_attr(feature = "serde", serde(rename = "slave"))]
        address: u8,
        /// The Slave_Diag data unit.
        #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
        raw: Vec<u8>,
        /// In words.
        words: Vec<String>,
    },
    /// A request to a slave failed.
    Fault {
        /// The slave.
        #[cfg_attr(feature = "serde", serde(rename = "slave"))]
        address: u8,
        /// The service asked for (`Data_Exchange`, `Set_Prm` …).
        service: &'static str,
        /// What went wrong.
        #[cfg_attr(
            feature = "serde",
            serde(serialize_with = "profibus_fdl::ser::display")
        )]
        reason: ErrorKind,
    },
    /// A DP-V1 alarm: seen in a diagnosis (`acknowledged` false), then
    /// again when the master's Alarm_Ack (SAP 50) was confirmed by the
    /// slave (`acknowledged` true). The fields are those of `dpctl
    /// master`'s alarm event.
    #[cfg_attr(feature = "serde", serde(rename = "alarm"))]
    Alarm(AlarmReport),
    /// A master's Global_Control announced an operating state.
    Operating {
        /// The master.
        master: u8,
        /// Clear (Clear_Data set) or operate.
        state: OperatingState,
    },
    /// A station appeared in the token ring.
    MasterJoined {
        /// Its address.
        master: u8,
    },
    /// A station has not held the token for a while.
    MasterLeft {
        /// Its address.
        master: u8,
    },
    /// An FMS service confirmed (request and response paired by
    /// connection and invoke ID), or an FMS connection event (Initiate,
    /// Abort, Information-Report): [`fms::FmsEvent`].
    #[cfg_attr(feature = "serde", serde(rename = "fms"))]
    Fms(fms::FmsEvent),
}

impl fmt::Display for MonitorEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MonitorEvent::SlaveState {
                address,
                master,
                from,
                to,
            } => write!(
                f,
                "slave {address}: {} → {} (master {master})",
                from.map_or("unseen", |s| s.name()),
                to.name()
            ),
            MonitorEvent::Diag { address, words, .. } => {
                write!(f, "slave {address} diagnosis: {}", words.join("; "))
            }
            MonitorEvent::Fault {
                address,
                service,
                reason,
            } => write!(f, "slave {address} fault: {service}: {reason}"),
            MonitorEvent::Alarm(a) => a.fmt(f),
            MonitorEvent::Operating { master, state } => {
                write!(f, "master {master}: operating state {}", state.as_str())
            }
            MonitorEvent::MasterJoined { master } => write!(f, "master {master} in the token ring"),
            MonitorEvent::MasterLeft { master } => write!(f, "master {master} left the token ring"),
            MonitorEvent::Fms(e) => e.fmt(f),
        }
    }
}

/// Minimum, average and maximum of a time interval, in µs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Interval {
    /// Shortest.
    pub min: u64,
    /// Mean.
    pub avg: u64,
    /// Longest.
    pub max: u64,
    /// The last one.
    pub last: u64,
    /// How many were measured.
    #[cfg_attr(feature = "serde", serde(skip))]
    pub count: u64,
    #[cfg_attr(feature = "serde", serde(skip))]
    sum: u64,
}

impl Interval {
    fn add(&mut self, d: Duration) {
        let us = d.as_micros().min(u64::MAX as u128) as u64;
        self.min = if self.count == 0 {
            us
        } else {
            self.min.min(us)
        };
        self.max = self.max.max(us);
        self.last = us;
        self.count += 1;
        self.sum = self.sum.saturating_add(us);
        self.avg = self.sum / self.count;
    }

    fn merge(&mut self, o: &Interval) {
        if o.count == 0 {
            return;
        }
        self.min = if self.count == 0 {
            o.min
        } else {
            self.min.min(o.min)
        };
        self.max = self.max.max(o.max);
        self.last = o.last;
        self.count += o.count;
        self.sum = self.sum.saturating_add(o.sum);
        self.avg = self.sum / self.count;
    }
}

/// Counters of one slave.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SlaveCounters {
    /// Requests addressed to it (retries included).
    pub requests: u64,
    /// Data_Exchange cycles answered.
    pub data_exchanges: u64,
    /// Requests repeated with the same FCB.
    pub retries: u64,
    /// Requests without a valid positive reply.
    pub errors: u64,
    /// Times it left Data_Exchange for a new start-up.
    pub restarts: u64,
    /// Warnings: Slave_Diag answers with the always-1 bit (bit 2 of
    /// Station_Status_2) clear, taken as diagnoses all the same.
    pub always_one_clear: u64,
}

/// A GSD module's part of the process images.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct ModuleData {
    /// Module name from the GSD.
    pub name: String,
    /// Its input bytes.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub inputs: Vec<u8>,
    /// Its output bytes.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub outputs: Vec<u8>,
}

/// Named channel values of both images.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Channels {
    /// Input channels.
    #[cfg_attr(feature = "serde", serde(serialize_with = "ser::readings"))]
    pub inputs: Vec<Reading>,
    /// Output channels.
    #[cfg_attr(feature = "serde", serde(serialize_with = "ser::readings"))]
    pub outputs: Vec<Reading>,
}

/// One slave as the monitor sees it.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SlaveStatus {
    /// Station address.
    pub address: u8,
    /// Name from the bus file (empty for slaves not in it).
    pub name: String,
    /// State (`None`: no traffic seen yet).
    pub state: Option<SlaveState>,
    /// The master that talks to it.
    pub master: Option<u8>,
    /// Inputs of the last Data_Exchange.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub inputs: Vec<u8>,
    /// Outputs of the last Data_Exchange.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub outputs: Vec<u8>,
    /// Counters.
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub counters: SlaveCounters,
    /// Time between its Data_Exchange requests.
    pub cycle_us: Interval,
    /// The last diagnosis in words (empty: none seen).
    pub diag: Vec<String>,
    /// Its images by GSD module (when the bus file names the modules).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Vec::is_empty"))]
    pub modules: Vec<ModuleData>,
    /// Named channels (a device profile's decoding).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub channels: Option<Channels>,
    /// Its FMS connections as a server (`dpctl monitor` saw FMS
    /// traffic to it; left out of the JSON when none).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Vec::is_empty"))]
    pub fms: Vec<fms::FmsConnectionStatus>,
}

/// A master in the token ring.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MasterStatus {
    /// Station address.
    pub address: u8,
    /// Tokens it passed.
    pub tokens: u64,
    /// Time between the tokens it passed (the token rotation it sees).
    pub rotation_us: Interval,
    /// Operating state from its Global_Control (`None`: none seen).
    pub operating: Option<OperatingState>,
    /// Still passing the token.
    pub in_ring: bool,
}

/// Counters of the whole line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct BusCounters {
    /// Telegrams observed.
    pub telegrams: u64,
    /// Token telegrams.
    pub tokens: u64,
    /// Stretches of bytes that were no valid telegram.
    pub corrupt: u64,
    /// Requests without the reply they needed.
    pub no_reply: u64,
}

/// The whole picture at one moment.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MonitorStatus {
    /// Time of the snapshot in seconds (the telegram clock).
    pub t: f64,
    /// Data_Exchange cycles: the most any slave has done.
    pub cycles: u64,
    /// Data_Exchange intervals over all slaves.
    pub cycle_us: Interval,
    /// Operating state of the (first) master seen sending Global_Control.
    pub operating: Option<OperatingState>,
    /// Masters seen in the token ring, by address.
    pub masters: Vec<MasterStatus>,
    /// Slaves of the bus file and any other slave seen, by address.
    pub slaves: Vec<SlaveStatus>,
    /// Line counters.
    pub bus: BusCounters,
}

/// Tuning of a [`Monitor`].
#[derive(Debug, Clone, Copy)]
pub struct MonitorOptions {
    /// A master that has not passed the token for this long, and for five
    /// of its longest rotations, has left the ring; a slave in
    /// Data_Exchange not polled for this long, and for five of its longest
    /// cycles, is `offline`.
    pub master_timeout: Duration,
    /// Consecutive failed requests after which a slave is `offline`.
    pub offline_after: u32,
}

impl Default for MonitorOptions {
    fn default() -> Self {
        MonitorOptions {
            master_timeout: Duration::from_secs(1),
            offline_after: 2,
        }
    }
}

/// The last request to a slave, to recognise a repetition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct LastRequest {
    master: u8,
    dsap: Option<u8>,
    fcb: bool,
    fcv: bool,
    answered: bool,
}

#[derive(Debug)]
struct SlaveTrack {
    info: SlaveInfo,
    state: Option<SlaveState>,
    master: Option<u8>,
    inputs: Vec<u8>,
    outputs: Vec<u8>,
    counters: SlaveCounters,
    cycle: Interval,
    last_dx: Option<Instant>,
    diag_raw: Vec<u8>,
    diag_words: Vec<String>,
    last: Option<LastRequest>,
    /// When its master last addressed it.
    last_polled: Option<Instant>,
    failures: u32,
    /// DP-V1 alarms seen in its diagnosis, and whether the master's
    /// Alarm_Ack was confirmed.
    alarms: Vec<(AlarmNotice, bool)>,
}

impl SlaveTrack {
    fn new(info: SlaveInfo) -> SlaveTrack {
        SlaveTrack {
            info,
            state: None,
            master: None,
            inputs: vec![],
            outputs: vec![],
            counters: SlaveCounters::default(),
            cycle: Interval::default(),
            last_dx: None,
            diag_raw: vec![],
            diag_words: vec![],
            last: None,
            last_polled: None,
            failures: 0,
            alarms: vec![],
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct MasterTrack {
    tokens: u64,
    last_token: Option<Instant>,
    last_seen: Instant,
    rotation: Interval,
    operating: Option<OperatingState>,
    in_ring: bool,
}

/// A request waiting for its reply.
#[derive(Debug, Clone)]
struct Pending {
    master: u8,
    slave: u8,
    dsap: Option<u8>,
    data: Vec<u8>,
    expects_reply: bool,
}

/// The passive observer; see the module docs.
#[derive(Debug)]
pub struct Monitor {
    options: MonitorOptions,
    slaves: BTreeMap<u8, SlaveTrack>,
    masters: BTreeMap<u8, MasterTrack>,
    pending: Option<Pending>,
    /// FMS connections on the line.
    fms: fms::FmsWatch,
    events: VecDeque<MonitorEvent>,
    bus: BusCounters,
    now: Instant,
}

/// Events kept at most; the oldest are dropped when nobody polls.
const MAX_EVENTS: usize = 4096;

impl Monitor {
    /// A monitor that knows `slaves` (from a bus file; others are added
    /// as they are seen).
    pub fn new(slaves: Vec<SlaveInfo>, options: MonitorOptions) -> Monitor {
        Monitor {
            options,
            slaves: slaves
                .into_iter()
                .map(|s| (s.layout.address, SlaveTrack::new(s)))
                .collect(),
            masters: BTreeMap::new(),
            pending: None,
            fms: fms::FmsWatch::default(),
            events: VecDeque::new(),
            bus: BusCounters::default(),
            now: Instant::ZERO,
        }
    }

    /// A monitor for the slaves of a bus file.
    pub fn from_bus(bus: &BusFile) -> Monitor {
        Monitor::new(SlaveInfo::from_bus(bus), MonitorOptions::default())
    }

    /// Give the slave at `address` a decoder for its process images.
    pub fn set_decoder(&mut self, address: u8, decoder: Box<dyn ImageDecoder>) {
        self.slave(address).info.decoder = Some(decoder);
    }

    /// The next event, oldest first.
    pub fn poll_event(&mut self) -> Option<MonitorEvent> {
        self.events.pop_front()
    }

    /// The state of the slave at `address` (`None`: not seen).
    pub fn slave_state(&self, address: u8) -> Option<SlaveState> {
        self.slaves.get(&address).and_then(|s| s.state)
    }

    /// Counters of the slave at `address`.
    pub fn slave_counters(&self, address: u8) -> Option<SlaveCounters> {
        self.slaves.get(&address).map(|s| s.counters)
    }

    /// Addresses of the masters in the token ring now.
    pub fn masters(&self) -> impl Iterator<Item = u8> + '_ {
        self.masters
            .iter()
            .filter(|(_, m)| m.in_ring)
            .map(|(a, _)| *a)
    }

    /// Line counters.
    pub fn bus_counters(&self) -> BusCounters {
        self.bus
    }

    fn push(&mut self, e: MonitorEvent) {
        if self.events.len() >= MAX_EVENTS {
            self.events.pop_front();
        }
        tracing::debug!(event = %e, "monitor");
        self.events.push_back(e);
    }

    fn slave(&mut self, address: u8) -> &mut SlaveTrack {
        self.slaves.entry(address).or_insert_with(|| {
            SlaveTrack::new(SlaveInfo::from(SlaveLayout {
                address,
                ..SlaveLayout::default()
            }))
        })
    }

    /// Time passes without telegrams: masters that stopped passing the
    /// token leave the live list, and slaves in Data_Exchange that their
    /// master has not addressed for [`MonitorOptions::master_timeout`]
    /// (and five of their longest cycles) go `offline`.
    pub fn tick(&mut self, now: Instant) {
        self.now = self.now.max(now);
        let base = self.options.master_timeout;
        let mut left = vec![];
        for (a, m) in self.masters.iter_mut() {
            let limit = base.max(Duration::from_micros(m.rotation.max.saturating_mul(5)));
            if m.in_ring && self.now - m.last_seen > limit {
                m.in_ring = false;
                left.push(*a);
            }
        }
        for master in left {
            self.push(MonitorEvent::MasterLeft { master });
        }
        // A slave in Data_Exchange is polled every cycle. When its master
        // stops polling it (the master stopped, or dropped it), it is no
        // longer exchanging data: its watchdog (IEC 61158-6-3, Set_Prm
        // WD_Fact) ends Data_Exchange on the slave side too. The monitor
        // cannot see the slave's own state, so it is `offline` for the
        // master.
        let mut silent = vec![];
        for (a, s) in self.slaves.iter() {
            let (Some(SlaveState::DataExchange), Some(master), Some(t)) =
                (s.state, s.master, s.last_polled)
            else {
                continue;
            };
            let limit = base.max(Duration::from_micros(s.cycle.max.saturating_mul(5)));
            if self.now - t > limit {
                silent.push((*a, master));
            }
        }
        for (address, master) in silent {
            self.set_state(address, master, SlaveState::Offline);
        }
    }

    /// Bytes that were no valid telegram arrived at `at`: a reply being
    /// waited for is corrupt.
    pub fn observe_skipped(&mut self, at: Instant, _errors: &CodecStats) {
        self.tick(at);
        self.bus.corrupt += 1;
        if let Some(p) = self.pending.take() {
            if p.expects_reply {
                self.failed(p, ErrorKind::Corrupt);
            }
        }
    }

    /// What a passive tap framed off the line: a telegram (bytes that
    /// do not parse count as corrupt) or skipped bytes. Returns its time.
    pub fn hear(&mut self, e: &TapEvent) -> Instant {
        match e {
            TapEvent::Telegram { at, bytes } => {
                match Telegram::parse(bytes) {
                    Ok((t, _)) => self.observe(*at, &t),
                    Err(_) => self.observe_skipped(*at, &CodecStats::default()),
                }
                *at
            }
            TapEvent::Skipped { at, errors, .. } => {
                self.observe_skipped(*at, errors);
                *at
            }
        }
    }

    /// A telegram the line carried, its first byte at `at`.
    pub fn observe(&mut self, at: Instant, telegram: &Telegram<'_>) {
        self.tick(at);
        self.bus.telegrams += 1;
        for e in self.fms.observe(at, telegram) {
            self.slave(e.station);
            self.push(MonitorEvent::Fms(e));
        }
        match telegram {
            Telegram::Token { da, sa } => {
                self.unanswered();
                self.token(at, *sa, *da);
            }
            Telegram::ShortAck => self.reply(None),
            Telegram::Data(d) => match d.fc {
                FunctionCode::Request { kind, fcb, fcv } => {
                    self.unanswered();
                    self.request(at, d, kind, fcb, fcv);
                }
                FunctionCode::Response { status, station } => {
                    if station != StationType::Passive {
                        // A master answering FDL status: it is a master.
                        self.seen_master(d.sa, at, false);
                    }
                    self.reply(Some((d, status)));
                }
            },
        }
    }

    /// The request before the current telegram got no reply.
    fn unanswered(&mut self) {
        if let Some(p) = self.pending.take() {
            if p.expects_reply {
                self.bus.no_reply += 1;
                self.failed(p, ErrorKind::NoReply);
            }
        }
    }

    fn seen_master(&mut self, address: u8, at: Instant, token: bool) {
        if address > 126 {
            return;
        }
        let m = self.masters.entry(address).or_insert(MasterTrack {
            tokens: 0,
            last_token: None,
            last_seen: at,
            rotation: Interval::default(),
            operating: None,
            in_ring: false,
        });
        m.last_seen = m.last_seen.max(at);
        if token {
            m.tokens += 1;
            if let Some(t) = m.last_token {
                if at > t {
                    m.rotation.add(at - t);
                }
            }
            m.last_token = Some(at);
        }
        if token && !m.in_ring {
            m.in_ring = true;
            self.push(MonitorEvent::MasterJoined { master: address });
        }
    }

    fn token(&mut self, at: Instant, sa: u8, da: u8) {
        self.bus.tokens += 1;
        self.seen_master(sa, at, true);
        if da != sa && da <= 126 {
            // The receiver is in the ring too; its own token pass counts
            // its rotation.
            let known = self.masters.get(&da).is_some_and(|m| m.in_ring);
            if !known {
                self.seen_master(da, at, false);
                if let Some(m) = self.masters.get_mut(&da) {
                    m.in_ring = true;
                }
                self.push(MonitorEvent::MasterJoined { master: da });
            }
        }
    }

    fn request(
        &mut self,
        at: Instant,
        d: &DataTelegram<'_>,
        kind: RequestKind,
        fcb: bool,
        fcv: bool,
    ) {
        if d.is_broadcast() {
            if d.dsap == Some(sap::GLOBAL_CONTROL) {
                if let Ok(gc) = GlobalControl::parse(d.data) {
                    self.global_control(at, d.sa, gc);
                }
            }
            return;
        }
        if matches!(
            kind,
            RequestKind::FdlStatus | RequestKind::Ident | RequestKind::LsapStatus
        ) || d.da > 126
        {
            // GAP polling and live lists: absent stations are normal.
            return;
        }
        // Only DP traffic (Data_Exchange or a DP SAP from the master SAP)
        // makes a station a slave worth following.
        let dp = match d.dsap {
            None => d.ssap.is_none(),
            Some(s) => {
                (sap::MSAC_C1..=sap::CHK_CFG).contains(&(s & 0x3F))
                    || s == sap::ALARM_ACK
                    || s == sap::MSAC_C2_INITIATE
            }
        };
        if !dp {
            return;
        }
        let dsap = d.dsap.map(|s| s & 0x3F);
        let expects_reply = kind.expects_reply();
        let s = self.slave(d.da);
        s.counters.requests += 1;
        s.last_polled = Some(at);
        let retry = kind.uses_fcb()
            && s.last.is_some_and(|l| {
                l.master == d.sa
                    && l.dsap == dsap
                    && l.fcb == fcb
                    && l.fcv == fcv
                    && (fcv || !l.answered)
            });
        if retry {
            s.counters.retries += 1;
        }
        s.last = Some(LastRequest {
            master: d.sa,
            dsap,
            fcb,
            fcv,
            answered: false,
        });
        if dsap.is_none() && !retry {
            if let Some(prev) = s.last_dx {
                if at > prev {
                    s.cycle.add(at - prev);
                }
            }
            s.last_dx = Some(at);
        }
        self.pending = Some(Pending {
            master: d.sa,
            slave: d.da,
            dsap,
            data: d.data.to_vec(),
            expects_reply,
        });
        if !expects_reply {
            self.pending = None;
        }
    }

    fn global_control(&mut self, at: Instant, master: u8, gc: GlobalControl) {
        let state = if gc.command.contains(ControlCommand::CLEAR_DATA) {
            OperatingState::Clear
        } else {
            OperatingState::Operate
        };
        self.seen_master(master, at, false);
        let Some(m) = self.masters.get_mut(&master) else {
            return;
        };
        if m.operating != Some(state) {
            m.operating = Some(state);
            self.push(MonitorEvent::Operating { master, state });
        }
    }

    fn set_state(&mut self, address: u8, master: u8, to: SlaveState) {
        let s = self.slave(address);
        s.master = Some(master);
        let from = s.state;
        if from == Some(to) {
            return;
        }
        if from == Some(SlaveState::DataExchange) && to != SlaveState::Offline {
            s.counters.restarts += 1;
        }
        if to != SlaveState::DataExchange {
            s.last_dx = None;
        }
        s.state = Some(to);
        self.push(MonitorEvent::SlaveState {
            address,
            master,
            from,
            to,
        });
    }

    fn failed(&mut self, p: Pending, reason: ErrorKind) {
        let limit = self.options.offline_after.max(1);
        let s = self.slave(p.slave);
        s.counters.errors += 1;
        s.failures = s.failures.saturating_add(1);
        let offline = s.failures >= limit;
        self.push(MonitorEvent::Fault {
            address: p.slave,
            service: service_name(p.dsap),
            reason,
        });
        if offline {
            self.set_state(p.slave, p.master, SlaveState::Offline);
        }
    }

    /// A response (`None`: short acknowledge) to the pending request.
    fn reply(&mut self, response: Option<(&DataTelegram<'_>, ResponseStatus)>) {
        let Some(p) = self.pending.take() else {
            return;
        };
        if let Some((d, _)) = response {
            if d.sa != p.slave || d.da != p.master {
                // Not the answer to this request.
                self.unanswered_with(p);
                return;
            }
        }
        let status = response.map_or(ResponseStatus::Ok, |(_, s)| s);
        let data = response.map_or(&[][..], |(d, _)| d.data);
        if status.is_negative() {
            let kind = ErrorKind::Negative(status);
            let sap_off = matches!(status, ResponseStatus::Rs);
            self.failed(p.clone(), kind);
            if sap_off && p.dsap.is_none() {
                // Data_Exchange refused: the slave is not parameterised.
                self.set_state(p.slave, p.master, SlaveState::Diag);
            }
            return;
        }
        {
            let s = self.slave(p.slave);
            s.failures = 0;
            if let Some(l) = s.last.as_mut() {
                l.answered = true;
            }
        }
        match p.dsap {
            None => {
                let s = self.slave(p.slave);
                s.counters.data_exchanges += 1;
                s.outputs.clone_from(&p.data);
                if response.is_some() {
                    s.inputs.clear();
                    s.inputs.extend_from_slice(data);
                }
                self.set_state(p.slave, p.master, SlaveState::DataExchange);
            }
            Some(sap::SLAVE_DIAG) if response.is_some() => self.diag(p.slave, p.master, data),
            Some(sap::ALARM_ACK) if response.is_some() => self.alarm_ack(p.slave, data),
            Some(sap::SET_PRM) => self.set_state(p.slave, p.master, SlaveState::ChkCfg),
            Some(sap::CHK_CFG) => self.set_state(p.slave, p.master, SlaveState::CheckDiag),
            _ => {}
        }
    }

    fn unanswered_with(&mut self, p: Pending) {
        if p.expects_reply {
            self.bus.no_reply += 1;
            self.failed(p, ErrorKind::NoReply);
        }
    }

    fn diag(&mut self, address: u8, master: u8, data: &[u8]) {
        let s = self.slave(address);
        if s.diag_raw != data {
            s.diag_raw = data.to_vec();
            s.diag_words = diag::describe(data, s.info.layout.gsd.as_ref(), s.info.layout.dpv1);
            let e = MonitorEvent::Diag {
                address,
                raw: s.diag_raw.clone(),
                words: s.diag_words.clone(),
            };
            self.push(e);
        }
        let Ok(d) = SlaveDiag::parse(data) else {
            return;
        };
        if !d.is_valid() {
            self.slave(address).counters.always_one_clear += 1;
        }
        if self.slave(address).info.layout.dpv1 {
            self.alarms_in(address, &d);
        }
        let state = self.slave(address).state;
        let other = d.master_address != NO_MASTER && d.master_address != master;
        let to = if other && d.status1.contains(StationStatus1::MASTER_LOCK) {
            SlaveState::Locked
        } else if d.status2.contains(StationStatus2::PRM_REQ)
            || d.status1.contains(StationStatus1::PRM_FAULT)
        {
            SlaveState::SetPrm
        } else if d.ready_for(master) {
            match state {
                // Ready: stays where the start-up left it, until the
                // next Data_Exchange.
                Some(SlaveState::DataExchange) => SlaveState::DataExchange,
                _ => SlaveState::CheckDiag,
            }
        } else {
            match state {
                None | Some(SlaveState::Offline) | Some(SlaveState::Locked) => SlaveState::Diag,
                Some(s) => s,
            }
        };
        self.set_state(address, master, to);
    }

    /// The alarm blocks of a DP-V1 slave's diagnosis: new ones are
    /// reported; acknowledged ones the slave no longer shows are
    /// forgotten.
    fn alarms_in(&mut self, address: u8, d: &SlaveDiag<'_>) {
        let s = self.slave(address);
        let blocks: Vec<_> = dpv1_blocks(d.ext_diag)
            .filter_map(|b| match b {
                DiagBlock::Alarm(a) => Some(a),
                DiagBlock::Status(_) => None,
            })
            .collect();
        s.alarms
            .retain(|(a, acked)| !acked || blocks.iter().any(|b| a.same(b)));
        let mut new = vec![];
        for b in &blocks {
            if !s.alarms.iter().any(|(a, _)| a.same(b)) && s.alarms.len() < 32 {
                let a = AlarmNotice::new(b);
                new.push(AlarmReport::new(address, &a, s.info.layout.gsd.as_ref()));
                s.alarms.push((a, false));
            }
        }
        for r in new {
            self.push(MonitorEvent::Alarm(r));
        }
    }

    /// A positive answer to an Alarm_Ack (the slave's echo `5C slot
    /// type specifier`).
    fn alarm_ack(&mut self, address: u8, data: &[u8]) {
        let Ok(Pdu::AlarmAck {
            slot,
            alarm_type,
            specifier,
        }) = Pdu::parse_response(data)
        else {
            return;
        };
        let b = AlarmBlock {
            alarm_type: AlarmType::from_code(alarm_type),
            slot,
            specifier: AlarmSpecifier::from_byte(specifier),
            data: &[],
        };
        let s = self.slave(address);
        let i = match s.alarms.iter().position(|(a, _)| a.same(&b)) {
            Some(i) => i,
            None => {
                // Acknowledged before the monitor saw the diagnosis.
                s.alarms.push((AlarmNotice::new(&b), false));
                s.alarms.len() - 1
            }
        };
        let (a, acked) = &mut s.alarms[i];
        if std::mem::replace(acked, true) {
            return;
        }
        let a = AlarmNotice {
            acknowledged: true,
            ..a.clone()
        };
        let r = AlarmReport::new(address, &a, s.info.layout.gsd.as_ref());
        self.push(MonitorEvent::Alarm(r));
    }

    /// The whole picture now.
    pub fn status(&self) -> MonitorStatus {
        let mut cycle = Interval::default();
        let mut cycles = 0;
        let slaves: Vec<SlaveStatus> = self
            .slaves
            .values()
            .map(|s| {
                cycle.merge(&s.cycle);
                cycles = cycles.max(s.counters.data_exchanges);
                let mut st = slave_status(s);
                st.fms = self.fms.connections_of(st.address);
                st
            })
            .collect();
        MonitorStatus {
            t: self.now.as_nanos() as f64 / 1e9,
            cycles,
            cycle_us: cycle,
            operating: self.masters.values().find_map(|m| m.operating),
            masters: self
                .masters
                .iter()
                .map(|(a, m)| MasterStatus {
                    address: *a,
                    tokens: m.tokens,
                    rotation_us: m.rotation,
                    operating: m.operating,
                    in_ring: m.in_ring,
                })
                .collect(),
            slaves,
            bus: self.bus,
        }
    }
}

/// The text lines `dpctl monitor` prints: a summary line, then per slave
/// a line with state, data and counters, its module or channel values,
/// and its diagnosis.
impl fmt::Display for MonitorStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let masters: Vec<String> = self
            .masters
            .iter()
            .filter(|m| m.in_ring)
            .map(|m| match m.operating {
                Some(o) => format!("{} ({})", m.address, o.as_str()),
                None => m.address.to_string(),
            })
            .collect();
        let c = &self.cycle_us;
        write!(
            f,
            "status t={:.1} s  masters in ring: [{}]  cycles {}  cycle min/avg/max {}/{}/{} µs  telegrams {}  corrupt {}  no reply {}",
            self.t,
            masters.join(", "),
            self.cycles,
            c.min,
            c.avg,
            c.max,
            self.bus.telegrams,
            self.bus.corrupt,
            self.bus.no_reply
        )?;
        for s in &self.slaves {
            write!(f, "\n  {s}")?;
        }
        Ok(())
    }
}

impl fmt::Display for SlaveStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.counters;
        write!(
            f,
            "{:3} {:<20} {:<13} in: {}  out: {}  (cycle {} µs, errors {}, retries {}, restarts {})",
            self.address,
            self.name,
            self.state.map_or("unseen", |x| x.name()),
            Hex(&self.inputs),
            Hex(&self.outputs),
            self.cycle_us.last,
            c.errors,
            c.retries,
            c.restarts,
        )?;
        let words = |r: &[Reading]| {
            r.iter()
                .map(|x| x.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        };
        if let Some(ch) = &self.channels {
            write!(
                f,
                "\n      in: {}  out: {}",
                words(&ch.inputs),
                words(&ch.outputs)
            )?;
        } else if !self.modules.is_empty() {
            let parts: Vec<String> = self
                .modules
                .iter()
                .map(|m| match (m.inputs.is_empty(), m.outputs.is_empty()) {
                    (false, true) => format!("{}: in {}", m.name, Hex(&m.inputs)),
                    (true, false) => format!("{}: out {}", m.name, Hex(&m.outputs)),
                    _ => format!("{}: in {} out {}", m.name, Hex(&m.inputs), Hex(&m.outputs)),
                })
                .collect();
            write!(f, "\n      {}", parts.join("; "))?;
        }
        if !self.diag.is_empty() {
            write!(f, "\n      diagnosis: {}", self.diag.join("; "))?;
        }
        for c in &self.fms {
            write!(f, "\n      {c}")?;
        }
        Ok(())
    }
}

fn slave_status(s: &SlaveTrack) -> SlaveStatus {
    let modules = (s.info.layout.modules.iter())
        .map(|m| ModuleData {
            name: m.name.clone(),
            inputs: m.inputs.of(&s.inputs).to_vec(),
            outputs: m.outputs.of(&s.outputs).to_vec(),
        })
        .collect();
    let channels = s.info.decoder.as_ref().map(|d| Channels {
        inputs: d.decode(Image::Inputs, &s.inputs),
        outputs: d.decode(Image::Outputs, &s.outputs),
    });
    SlaveStatus {
        address: s.info.layout.address,
        name: s.info.layout.name.clone(),
        state: s.state,
        master: s.master,
        inputs: s.inputs.clone(),
        outputs: s.outputs.clone(),
        counters: s.counters,
        cycle_us: s.cycle,
        diag: s.diag_words.clone(),
        modules,
        channels,
        fms: vec![],
    }
}

#[cfg(feature = "serde")]
pub(crate) mod ser {
    //! Channels as a `name: value` object.
    use super::Reading;
    use serde::ser::SerializeMap;
    use serde::Serializer;

    pub fn readings<S: Serializer>(r: &[Reading], ser: S) -> Result<S::Ok, S::Error> {
        let mut m = ser.serialize_map(Some(r.len()))?;
        for x in r {
            m.serialize_entry(&x.name, &x.value)?;
        }
        m.end()
    }
}
