//! What a master tells people: its events resolved to the data they
//! point to ([`MasterReport`]) and snapshots of its state
//! ([`MasterStatus`], [`SlaveStatus`]). `Display` gives the text lines
//! `dpctl master` prints; with the feature `serde` they serialise to its
//! JSON lines.

use super::{
    AlarmNotice, CycleStats, DpMaster, FaultReason, JobResult, MasterEvent, OperatingState,
    SlaveState, SlaveStats,
};
use crate::config::gsd::Gsd;
use profibus_fdl::station::active::FdlEvent;
use profibus_fdl::wire::Hex;
use profibus_fdl::{Baud, Instant};
use std::fmt;

/// A [`MasterEvent`] together with what it refers to: the diagnosis in
/// words, a job's result. Built with [`MasterReport::new`] right after
/// [`DpMaster::poll_event`]. Serialises with an `"event"` field (`state`,
/// `diag`, `fault`, `fault_ended`, `cfg_mismatch`, `alarm`, `job`,
/// `ring`, `duplicate_address`) and the slave's address as `slave`.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize),
    serde(tag = "event", rename_all = "snake_case")
)]
pub enum MasterReport {
    /// A slave changed state.
    State {
        /// Station address.
        slave: u8,
        /// Previous state.
        from: SlaveState,
        /// New state.
        to: SlaveState,
    },
    /// A slave's diagnosis changed.
    Diag {
        /// Station address.
        slave: u8,
        /// The Slave_Diag data unit.
        #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
        raw: Vec<u8>,
        /// The diagnosis in words ([`crate::pdu::diag::describe`]).
        words: Vec<String>,
    },
    /// A parameterisation or configuration fault.
    Fault {
        /// Station address.
        slave: u8,
        /// What is wrong (serialised in words).
        #[cfg_attr(
            feature = "serde",
            serde(serialize_with = "profibus_fdl::ser::display")
        )]
        reason: FaultReason,
    },
    /// A reported fault is over (the slave reached Data_Exchange or
    /// reports another fault).
    FaultEnded {
        /// Station address.
        slave: u8,
        /// The fault (serialised in words).
        #[cfg_attr(
            feature = "serde",
            serde(serialize_with = "profibus_fdl::ser::display")
        )]
        reason: FaultReason,
        /// Start-ups that ended in it in a row.
        repeats: u64,
    },
    /// Cfg_Fault: the configuration the master sent (Chk_Cfg) and the
    /// slave's real one (Get_Cfg), each split into identifier groups.
    CfgMismatch {
        /// Station address.
        slave: u8,
        /// The master's configuration.
        configured: Vec<CfgGroup>,
        /// The slave's answer to Get_Cfg.
        actual: Vec<CfgGroup>,
    },
    /// A DP-V1 alarm, once acknowledged or given up
    /// ([`MasterEvent::Alarm`]).
    Alarm(AlarmReport),
    /// A job ended.
    Job {
        /// The job's number.
        id: u32,
        /// The data it returned, if any.
        #[cfg_attr(
            feature = "serde",
            serde(serialize_with = "profibus_fdl::ser::opt_hex")
        )]
        data: Option<Vec<u8>>,
        /// `ok` for data, otherwise [`JobResult::describe`] (`lost` when the
        /// result was taken already).
        result: String,
    },
    /// Answers from one address keep arriving garbled or twice: possibly
    /// two stations at that address ([`FdlEvent::DuplicateAddress`]).
    DuplicateAddress {
        /// Station address.
        slave: u8,
    },
    /// The token ring changed.
    Ring {
        /// What happened (serialised in words).
        #[cfg_attr(
            feature = "serde",
            serde(serialize_with = "profibus_fdl::ser::display")
        )]
        what: FdlEvent,
    },
}

impl MasterReport {
    /// Resolve `event` against the master: read the diagnosis (described
    /// with the slave's `gsd`, when known) or take the job's result.
    pub fn new(m: &mut DpMaster, event: MasterEvent, gsd: Option<&Gsd>) -> MasterReport {
        match event {
            MasterEvent::StateChanged { address, from, to } => MasterReport::State {
                slave: address,
                from,
                to,
            },
            MasterEvent::Diag { address } => {
                let raw = m.diag(address).unwrap_or(&[]).to_vec();
                let dpv1 = m.slave_params(address).is_some_and(|p| p.dpv1);
                let words = crate::pdu::diag::describe(&raw, gsd, dpv1);
                MasterReport::Diag {
                    slave: address,
                    raw,
                    words,
                }
            }
            MasterEvent::Fault { address, reason } => MasterReport::Fault {
                slave: address,
                reason,
            },
            MasterEvent::FaultEnded {
                address,
                reason,
                repeats,
            } => MasterReport::FaultEnded {
                slave: address,
                reason,
                repeats,
            },
            MasterEvent::CfgMismatch { address } => MasterReport::CfgMismatch {
                slave: address,
                configured: CfgGroup::split(
                    m.slave_params(address).map_or(&[][..], |p| &p.cfg[..]),
                    gsd,
                ),
                actual: CfgGroup::split(m.actual_cfg(address).unwrap_or(&[]), gsd),
            },
            MasterEvent::Alarm { address, alarm } => {
                MasterReport::Alarm(AlarmReport::new(address, &alarm, gsd))
            }
            MasterEvent::JobDone(id) => {
                let (data, result) = match m.take_result(id) {
                    Some(JobResult::Data(d)) => (Some(d), "ok".to_string()),
                    Some(other) => (None, other.describe()),
                    None => (None, "lost".to_string()),
                };
                MasterReport::Job {
                    id: id.0,
                    data,
                    result,
                }
            }
            MasterEvent::Ring(FdlEvent::DuplicateAddress(slave)) => {
                MasterReport::DuplicateAddress { slave }
            }
            MasterEvent::Ring(what) => MasterReport::Ring { what },
        }
    }
}

/// A DP-V1 alarm for people and JSON, as `dpctl master` and `dpctl
/// monitor` report it: `{"event": "alarm", "slave", "type", "slot",
/// "specifier", "seq", "data", "text", "acknowledged"}`, type and
/// specifier in words, data in hex.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct AlarmReport {
    /// Station address.
    pub slave: u8,
    /// Alarm_Type in one word (`diagnostic`, `process`, `pull`, `plug`,
    /// `status`, `update`, `manufacturer`).
    #[cfg_attr(feature = "serde", serde(rename = "type"))]
    pub alarm_type: &'static str,
    /// Slot_Number.
    pub slot: u8,
    /// `appears`, `disappears`, `disappears-still-faulty` (or `none`).
    pub specifier: &'static str,
    /// Sequence number (0..=31).
    pub seq: u8,
    /// Diagnostic_User_Data.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub data: Vec<u8>,
    /// The alarm in words, with the GSD's texts for its data where the
    /// GSD has them ([`crate::pdu::diag::unit_diag_words`]), and why it
    /// was not acknowledged.
    pub text: String,
    /// The slave confirmed the Alarm_Ack.
    pub acknowledged: bool,
}

impl AlarmReport {
    /// The report of `alarm` of slave `slave`, its text with the `gsd`'s
    /// diagnosis texts for the alarm's data.
    pub fn new(slave: u8, alarm: &AlarmNotice, gsd: Option<&Gsd>) -> AlarmReport {
        let b = alarm.block();
        let named = gsd.map_or_else(Vec::new, |g| {
            let mut body = vec![b.alarm_type.code(), b.slot, b.specifier.byte()];
            body.extend_from_slice(b.data);
            crate::pdu::diag::unit_diag_words(g, &body, 24)
        });
        let mut text = if named.is_empty() {
            b.describe()
        } else {
            let plain = AlarmNotice {
                data: vec![],
                ..alarm.clone()
            };
            format!("{}: {}", plain.block().describe(), named.join("; "))
        };
        if let Some(p) = &alarm.problem {
            text = format!("{text} ({p})");
        }
        AlarmReport {
            slave,
            alarm_type: b.alarm_type.word(),
            slot: b.slot,
            specifier: b.specifier.change.word(),
            seq: b.specifier.seq,
            data: alarm.data.clone(),
            text,
            acknowledged: alarm.acknowledged,
        }
    }
}

/// `slave 9 alarm: diagnostic alarm slot 1, seq 0, appears: … [acknowledged]`.
impl fmt::Display for AlarmReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ack = if self.acknowledged {
            "acknowledged"
        } else {
            "NOT acknowledged"
        };
        write!(f, "slave {} alarm: {} [{ack}]", self.slave, self.text)
    }
}

impl fmt::Display for MasterReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MasterReport::State { slave, from, to } => {
                write!(f, "slave {slave}: {} → {}", from.name(), to.name())
            }
            MasterReport::Diag { slave, words, .. } => {
                write!(f, "slave {slave} diagnosis: {}", words.join("; "))
            }
            MasterReport::Fault { slave, reason } => write!(f, "slave {slave} fault: {reason}"),
            MasterReport::Alarm(a) => a.fmt(f),
            MasterReport::FaultEnded {
                slave,
                reason,
                repeats,
            } => write!(
                f,
                "slave {slave} fault over after {repeats} failed start-ups: {reason}"
            ),
            MasterReport::CfgMismatch {
                slave,
                configured,
                actual,
            } => {
                let list = |g: &[CfgGroup]| {
                    if g.is_empty() {
                        return "nothing".to_string();
                    }
                    g.iter()
                        .map(|g| g.to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                write!(
                    f,
                    "slave {slave} configuration mismatch: configured {}; the slave has {}",
                    list(configured),
                    list(actual)
                )
            }
            MasterReport::DuplicateAddress { slave } => write!(
                f,
                "possible duplicate address {slave}: its answers arrive garbled or twice"
            ),
            MasterReport::Job { id, data, result } => {
                write!(f, "job {id}: {result}")?;
                if let Some(d) = data {
                    write!(f, " [{}]", Hex(d))?;
                }
                Ok(())
            }
            MasterReport::Ring { what } => write!(f, "ring: {what}"),
        }
    }
}

/// A run of configuration identifiers that belong together: one GSD
/// module's identifiers, or a single identifier no module has.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct CfgGroup {
    /// The identifier bytes.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub bytes: Vec<u8>,
    /// The identifiers in words ([`crate::pdu::cfg::Identifier`]'s `Display`,
    /// joined by `, `), e.g. `2 words in+out`.
    pub meaning: String,
    /// The GSD module with exactly these bytes (several names joined by
    /// ` or ` when modules share them); `None` without a GSD or match.
    pub module: Option<String>,
}

impl CfgGroup {
    /// Split a configuration (Chk_Cfg / Get_Cfg bytes) into groups: at
    /// each position the longest GSD module whose identifier bytes come
    /// next, else one identifier. Bytes that do not decode end the list
    /// with a group whose meaning is the error.
    pub fn split(bytes: &[u8], gsd: Option<&Gsd>) -> Vec<CfgGroup> {
        let mut out = vec![];
        let mut pos = 0;
        while pos < bytes.len() {
            let rest = &bytes[pos..];
            let modules = gsd.map_or(&[][..], |g| &g.modules[..]);
            let longest = modules
                .iter()
                .filter(|m| !m.cfg.is_empty() && rest.starts_with(&m.cfg))
                .map(|m| m.cfg.len())
                .max();
            let len = match longest {
                Some(n) => n,
                None => match crate::pdu::cfg::identifiers(rest).next() {
                    Some(Ok(id)) => id.raw.len(),
                    Some(Err(e)) => {
                        out.push(CfgGroup {
                            bytes: rest.to_vec(),
                            meaning: e.to_string(),
                            module: None,
                        });
                        break;
                    }
                    None => break,
                },
            };
            let group = &rest[..len];
            let meaning = crate::pdu::cfg::identifiers(group)
                .map(|id| id.map_or_else(|e| e.to_string(), |id| id.to_string()))
                .collect::<Vec<_>>()
                .join(", ");
            let names: Vec<&str> = modules
                .iter()
                .filter(|m| m.cfg == group)
                .map(|m| m.name.as_str())
                .collect();
            out.push(CfgGroup {
                bytes: group.to_vec(),
                meaning,
                module: (!names.is_empty()).then(|| names.join(" or ")),
            });
            pos += len;
        }
        out
    }
}

impl fmt::Display for CfgGroup {
    /// `[71] 2 words in+out ("2 words in/out")`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{}] {}", Hex(&self.bytes), self.meaning)?;
        if let Some(m) = &self.module {
            write!(f, " (\"{m}\")")?;
        }
        Ok(())
    }
}

/// Cycle times in µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct CycleMicros {
    /// Shortest cycle.
    pub min: u64,
    /// Average cycle.
    pub avg: u64,
    /// Longest cycle.
    pub max: u64,
}

impl From<CycleStats> for CycleMicros {
    fn from(c: CycleStats) -> CycleMicros {
        CycleMicros {
            min: c.min_ns / 1000,
            avg: c.avg().as_micros() as u64,
            max: c.max_ns / 1000,
        }
    }
}

/// A snapshot of the master as a whole (its slaves: [`SlaveStatus`]).
/// `Display` is the headline `dpctl master` prints.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MasterStatus {
    /// When (seconds since the clock's start).
    pub t: Instant,
    /// Completed poll cycles.
    pub cycles: u64,
    /// Cycle times.
    pub cycle_us: CycleMicros,
    /// Operate, clear or stop.
    pub operating: OperatingState,
    /// The master's station address.
    #[cfg_attr(feature = "serde", serde(skip))]
    pub address: u8,
    /// The bus's baud rate.
    #[cfg_attr(feature = "serde", serde(skip))]
    pub baud: Baud,
}

impl MasterStatus {
    /// The master's state at `now`, on a bus at `baud`.
    pub fn of(m: &DpMaster, baud: Baud, now: Instant) -> MasterStatus {
        let c = m.cycle_stats();
        MasterStatus {
            t: now,
            cycles: c.cycles,
            cycle_us: c.into(),
            operating: m.operating_state(),
            address: m.address(),
            baud,
        }
    }
}

impl fmt::Display for MasterStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.cycle_us;
        write!(
            f,
            "master {} at {}  {}  cycles {}  cycle min/avg/max {}/{}/{} µs",
            self.address,
            self.baud,
            self.operating.as_str(),
            self.cycles,
            c.min,
            c.avg,
            c.max
        )
    }
}

/// A snapshot of one slave: state, process images, counters. `Display`
/// is the slave's line in `dpctl master`.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SlaveStatus {
    /// Station address.
    pub address: u8,
    /// Name from the configuration.
    pub name: String,
    /// State (`None`: not a slave of this master).
    pub state: Option<SlaveState>,
    /// Input image.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub inputs: Vec<u8>,
    /// Output image.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub outputs: Vec<u8>,
    /// Counters.
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub stats: SlaveStats,
}

impl SlaveStatus {
    /// The slave at `address` now.
    pub fn of(m: &DpMaster, address: u8) -> SlaveStatus {
        SlaveStatus {
            address,
            name: m
                .slave_params(address)
                .map(|p| p.name.clone())
                .unwrap_or_default(),
            state: m.slave_state(address),
            inputs: m.inputs(address).unwrap_or(&[]).to_vec(),
            outputs: m.outputs(address).unwrap_or(&[]).to_vec(),
            stats: m.slave_stats(address).unwrap_or_default(),
        }
    }
}

impl fmt::Display for SlaveStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {:<20} {:<13} in: {}  out: {}  (errors {}, retries {}, late {})",
            self.address,
            self.name,
            self.state.map(SlaveState::name).unwrap_or(""),
            Hex(&self.inputs),
            Hex(&self.outputs),
            self.stats.errors,
            self.stats.retries,
            self.stats.late_replies
        )?;
        if self.stats.failed_startups > 0 {
            write!(f, "  failed start-ups {}", self.stats.failed_startups)?;
        }
        if self.stats.always_one_clear > 0 {
            write!(
                f,
                "  warning: {} diagnoses with the always-1 bit clear",
                self.stats.always_one_clear
            )?;
        }
        Ok(())
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for SlaveState {
    /// [`SlaveState::name`].
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for OperatingState {
    /// [`OperatingState::as_str`].
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}
