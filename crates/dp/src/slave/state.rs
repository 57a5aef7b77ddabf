//! The slave's DP state and the events it reports to its application.

use super::device::{ClearReason, DeviceEvent};
use super::reason::{Reason, Service};
use crate::pdu::c2::Abort;
use crate::pdu::control::ControlCommand;
use std::collections::VecDeque;
use std::fmt;
use std::time::Duration;

/// The DP state of a slave (EN 50170 part 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SlaveState {
    /// Wait_Prm: waits for a valid Set_Prm (after power-on, a watchdog
    /// expiry, a fault or an unlock). Prm_Req is set.
    WaitPrm,
    /// Wait_Cfg: parameterised, waits for a matching Chk_Cfg.
    WaitCfg,
    /// Data_Exch: cyclic data exchange with the master that parameterised
    /// the slave.
    DataExch,
}

impl SlaveState {
    /// The standard's name.
    pub fn as_str(self) -> &'static str {
        match self {
            SlaveState::WaitPrm => "Wait_Prm",
            SlaveState::WaitCfg => "Wait_Cfg",
            SlaveState::DataExch => "Data_Exch",
        }
    }
}

impl fmt::Display for SlaveState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Something the slave reports to its application (the CLI prints them).
///
/// With the feature `serde` it serialises as a JSON object whose
/// `"event"` field is [`SlaveEvent::kind`], durations in ms
/// (`watchdog_ms`, `after_ms`), reasons and commands in words.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize), serde(tag = "event"))]
pub enum SlaveEvent {
    /// The DP state changed.
    #[cfg_attr(feature = "serde", serde(rename = "state"))]
    State {
        /// Previous state.
        from: SlaveState,
        /// New state.
        to: SlaveState,
    },
    /// A Set_Prm was accepted.
    #[cfg_attr(feature = "serde", serde(rename = "prm_ok"))]
    PrmAccepted {
        /// The master that sent it (and now owns the slave if `locked`).
        master: u8,
        /// The slave is locked to `master`.
        locked: bool,
        /// Watchdog time, if on.
        #[cfg_attr(
            feature = "serde",
            serde(
                rename = "watchdog_ms",
                serialize_with = "profibus_fdl::ser::opt_millis"
            )
        )]
        watchdog: Option<Duration>,
        /// min TSDR in force (bit times).
        min_tsdr: u8,
        /// Group_Ident.
        group_ident: u8,
    },
    /// A Set_Prm with Unlock_Req released the slave (Wait_Prm).
    #[cfg_attr(feature = "serde", serde(rename = "unlocked"))]
    Unlocked {
        /// The master that released it.
        master: u8,
    },
    /// A Set_Prm was rejected: Prm_Fault (and Not_Supported when
    /// `not_supported`) is set, the slave stays in Wait_Prm.
    #[cfg_attr(feature = "serde", serde(rename = "prm_fault"))]
    PrmFault {
        /// The master that sent it.
        master: u8,
        /// Why, in words.
        reason: Reason,
        /// The fault is an unsupported function (Not_Supported).
        not_supported: bool,
    },
    /// A Chk_Cfg matched; the cyclic layout is fixed.
    #[cfg_attr(feature = "serde", serde(rename = "cfg_ok"))]
    CfgAccepted {
        /// The master that sent it.
        master: u8,
        /// Input bytes.
        inputs: usize,
        /// Output bytes.
        outputs: usize,
    },
    /// A Chk_Cfg did not match: Cfg_Fault is set.
    #[cfg_attr(feature = "serde", serde(rename = "cfg_fault"))]
    CfgFault {
        /// The master that sent it.
        master: u8,
        /// Why, in words.
        reason: Reason,
    },
    /// The watchdog expired: outputs cleared, back to Wait_Prm.
    #[cfg_attr(feature = "serde", serde(rename = "watchdog"))]
    WatchdogExpired {
        /// The master that stopped talking.
        master: u8,
        /// The watchdog time.
        #[cfg_attr(
            feature = "serde",
            serde(rename = "after_ms", serialize_with = "profibus_fdl::ser::millis")
        )]
        after: Duration,
    },
    /// The outputs went to their safe state.
    #[cfg_attr(feature = "serde", serde(rename = "outputs_cleared"))]
    OutputsCleared {
        /// Why.
        reason: ClearReason,
    },
    /// Set_Slave_Add changed the address.
    #[cfg_attr(feature = "serde", serde(rename = "address"))]
    AddressChanged {
        /// Old address.
        old: u8,
        /// New address.
        new: u8,
        /// No further changes through the bus.
        no_add_chg: bool,
    },
    /// A Global_Control from the owning master was executed (only
    /// reported when its command or group differs from the previous one).
    #[cfg_attr(feature = "serde", serde(rename = "global_control"))]
    GlobalControl {
        /// The master.
        master: u8,
        /// The command bits.
        #[cfg_attr(feature = "serde", serde(serialize_with = "command_words"))]
        command: ControlCommand,
        /// Group_Select.
        group_select: u8,
    },
    /// A request was refused (answered negatively or ignored), e.g.
    /// because another master owns the slave.
    #[cfg_attr(feature = "serde", serde(rename = "refused"))]
    Refused {
        /// The master that sent it.
        master: u8,
        /// The DP service.
        service: Service,
        /// Why, in words.
        reason: Reason,
    },
    /// A class-2 master opened an MSAC_C2 connection (Initiate).
    #[cfg_attr(feature = "serde", serde(rename = "c2_open"))]
    C2Opened {
        /// The class-2 master.
        master: u8,
        /// The connection SAP the resource manager assigned (0..=48).
        sap: u8,
        /// Send_Timeout of the connection.
        #[cfg_attr(
            feature = "serde",
            serde(
                rename = "send_timeout_ms",
                serialize_with = "profibus_fdl::ser::millis"
            )
        )]
        send_timeout: Duration,
    },
    /// A class-2 connection closed: the master aborted it, or the slave
    /// did (Send_Timeout expired, a sequence error, an invalid PDU).
    #[cfg_attr(feature = "serde", serde(rename = "c2_closed"))]
    C2Closed {
        /// The class-2 master.
        master: u8,
        /// The connection SAP.
        sap: u8,
        /// The master sent the Abort (else the slave aborted).
        by_master: bool,
        /// The Abort (instance and reason), serialised in words.
        #[cfg_attr(feature = "serde", serde(serialize_with = "abort_words"))]
        abort: Abort,
    },
    /// A DP-V1 alarm was raised, refused or acknowledged.
    #[cfg_attr(feature = "serde", serde(rename = "alarm"))]
    Alarm(AlarmEvent),
    /// The device reported something.
    #[cfg_attr(feature = "serde", serde(rename = "device"))]
    Device(DeviceEvent),
    /// Events were dropped because nobody drained the queue.
    #[cfg_attr(feature = "serde", serde(rename = "lost"))]
    Lost(#[cfg_attr(feature = "serde", serde(serialize_with = "lost_count"))] u64),
}

/// What happened to a DP-V1 alarm of the slave's queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize),
    serde(rename_all = "snake_case")
)]
pub enum AlarmAction {
    /// Queued (it is in Slave_Diag once the limit of outstanding alarms
    /// allows).
    Raised,
    /// Not queued (see `reason`).
    Refused,
    /// The master acknowledged it (Alarm_Ack): it left Slave_Diag.
    Acknowledged,
}

/// A DP-V1 alarm of the slave's queue ([`SlaveEvent::Alarm`]): type and
/// specifier in words, data in hex, as the master's alarm event.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct AlarmEvent {
    /// What happened.
    pub action: AlarmAction,
    /// The alarm type in words (`diagnostic`, `process`, …).
    #[cfg_attr(feature = "serde", serde(rename = "type"))]
    pub alarm_type: String,
    /// Slot.
    pub slot: u8,
    /// `appears`, `disappears`, `disappears-still-faulty`.
    pub specifier: String,
    /// Sequence number (none when refused).
    pub seq: Option<u8>,
    /// Diagnostic_User_Data.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub data: Vec<u8>,
    /// Why it was refused.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub reason: Option<String>,
}

impl AlarmEvent {
    pub(crate) fn new(
        action: AlarmAction,
        a: &super::Alarm,
        seq: Option<u8>,
        reason: Option<String>,
    ) -> AlarmEvent {
        AlarmEvent {
            action,
            alarm_type: a.alarm_type.word().into(),
            slot: a.slot,
            specifier: a.change.word().into(),
            seq,
            data: a.data.clone(),
            reason,
        }
    }
}

impl fmt::Display for AlarmEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let action = match self.action {
            AlarmAction::Raised => "raised",
            AlarmAction::Refused => "refused",
            AlarmAction::Acknowledged => "acknowledged",
        };
        write!(
            f,
            "{} alarm slot {} {}",
            self.alarm_type, self.slot, self.specifier
        )?;
        if let Some(seq) = self.seq {
            write!(f, " seq {seq}")?;
        }
        if !self.data.is_empty() {
            write!(f, " data {}", profibus_fdl::wire::Hex(&self.data))?;
        }
        write!(f, ": {action}")?;
        if let Some(r) = &self.reason {
            write!(f, " ({r})")?;
        }
        Ok(())
    }
}

/// `Lost(n)` as `{"count": n}`.
#[cfg(feature = "serde")]
fn lost_count<S: serde::Serializer>(n: &u64, s: S) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeStruct;
    let mut st = s.serialize_struct("Lost", 1)?;
    st.serialize_field("count", n)?;
    st.end()
}

/// An Abort in words ([`Abort::describe`]).
#[cfg(feature = "serde")]
fn abort_words<S: serde::Serializer>(a: &Abort, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&a.describe())
}

/// A Control_Command as [`control_words`].
#[cfg(feature = "serde")]
fn command_words<S: serde::Serializer>(c: &ControlCommand, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&control_words(*c))
}

#[cfg(feature = "serde")]
impl serde::Serialize for SlaveState {
    /// The standard's name, as [`SlaveState::as_str`].
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl SlaveEvent {
    /// A short machine-readable name of the event.
    pub fn kind(&self) -> &'static str {
        match self {
            SlaveEvent::State { .. } => "state",
            SlaveEvent::PrmAccepted { .. } => "prm_ok",
            SlaveEvent::Unlocked { .. } => "unlocked",
            SlaveEvent::PrmFault { .. } => "prm_fault",
            SlaveEvent::CfgAccepted { .. } => "cfg_ok",
            SlaveEvent::CfgFault { .. } => "cfg_fault",
            SlaveEvent::WatchdogExpired { .. } => "watchdog",
            SlaveEvent::OutputsCleared { .. } => "outputs_cleared",
            SlaveEvent::AddressChanged { .. } => "address",
            SlaveEvent::GlobalControl { .. } => "global_control",
            SlaveEvent::Refused { .. } => "refused",
            SlaveEvent::C2Opened { .. } => "c2_open",
            SlaveEvent::C2Closed { .. } => "c2_closed",
            SlaveEvent::Alarm(_) => "alarm",
            SlaveEvent::Device(_) => "device",
            SlaveEvent::Lost(_) => "lost",
        }
    }
}

/// Words for a Control_Command, e.g. `"Sync, Freeze"` or `"Operate"`.
pub fn control_words(c: ControlCommand) -> String {
    let mut v = vec![];
    for (f, n) in [
        (ControlCommand::CLEAR_DATA, "Clear_Data"),
        (ControlCommand::SYNC, "Sync"),
        (ControlCommand::UNSYNC, "Unsync"),
        (ControlCommand::FREEZE, "Freeze"),
        (ControlCommand::UNFREEZE, "Unfreeze"),
    ] {
        if c.contains(f) {
            v.push(n);
        }
    }
    if v.is_empty() {
        "Operate".into()
    } else {
        v.join(", ")
    }
}

impl fmt::Display for SlaveEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SlaveEvent::State { from, to } => write!(f, "state {from} -> {to}"),
            SlaveEvent::PrmAccepted {
                master,
                locked,
                watchdog,
                min_tsdr,
                group_ident,
            } => {
                write!(f, "Set_Prm from master {master} accepted")?;
                if *locked {
                    write!(f, ", locked")?;
                }
                match watchdog {
                    Some(d) => write!(f, ", watchdog {} ms", d.as_millis())?,
                    None => write!(f, ", watchdog off")?,
                }
                write!(f, ", min TSDR {min_tsdr} bit")?;
                if *group_ident != 0 {
                    write!(f, ", groups 0x{group_ident:02X}")?;
                }
                Ok(())
            }
            SlaveEvent::Unlocked { master } => {
                write!(f, "Set_Prm from master {master}: Unlock_Req, slave released")
            }
            SlaveEvent::PrmFault {
                master,
                reason,
                not_supported,
            } => {
                write!(f, "Prm_Fault (Set_Prm from master {master}): {reason}")?;
                if *not_supported {
                    write!(f, " [Not_Supported]")?;
                }
                Ok(())
            }
            SlaveEvent::CfgAccepted {
                master,
                inputs,
                outputs,
            } => write!(
                f,
                "Chk_Cfg from master {master} accepted: {inputs} input bytes, {outputs} output bytes"
            ),
            SlaveEvent::CfgFault { master, reason } => {
                write!(f, "Cfg_Fault (Chk_Cfg from master {master}): {reason}")
            }
            SlaveEvent::WatchdogExpired { master, after } => write!(
                f,
                "watchdog expired: no telegram from master {master} for {} ms",
                after.as_millis()
            ),
            SlaveEvent::OutputsCleared { reason } => {
                write!(f, "outputs cleared: {}", reason.as_str())
            }
            SlaveEvent::AddressChanged {
                old,
                new,
                no_add_chg,
            } => {
                write!(f, "address changed {old} -> {new}")?;
                if *no_add_chg {
                    write!(f, " (No_Add_Chg: no further changes)")?;
                }
                Ok(())
            }
            SlaveEvent::GlobalControl {
                master,
                command,
                group_select,
            } => write!(
                f,
                "Global_Control from master {master}: {} (groups 0x{group_select:02X})",
                control_words(*command)
            ),
            SlaveEvent::Refused {
                master,
                service,
                reason,
            } => write!(f, "{service} from master {master} refused: {reason}"),
            SlaveEvent::C2Opened {
                master,
                sap,
                send_timeout,
            } => write!(
                f,
                "class-2 connection of master {master} opened on SAP {sap} (Send_Timeout {} ms)",
                send_timeout.as_millis()
            ),
            SlaveEvent::C2Closed {
                master,
                sap,
                by_master,
                abort,
            } => write!(
                f,
                "class-2 connection of master {master} on SAP {sap} closed by the {}: {}",
                if *by_master { "master" } else { "slave" },
                abort.describe()
            ),
            SlaveEvent::Alarm(a) => a.fmt(f),
            SlaveEvent::Device(e) => write!(f, "{}: {}", e.kind, e.text),
            SlaveEvent::Lost(n) => write!(f, "{n} events lost (queue full)"),
        }
    }
}

/// Bounded event queue; allocated once, so pushing never allocates.
#[derive(Debug)]
pub(crate) struct EventQueue {
    q: VecDeque<SlaveEvent>,
    lost: u64,
}

/// Events kept before the oldest are dropped.
pub(crate) const EVENT_CAPACITY: usize = 64;

impl EventQueue {
    pub(crate) fn new() -> EventQueue {
        EventQueue {
            q: VecDeque::with_capacity(EVENT_CAPACITY),
            lost: 0,
        }
    }

    pub(crate) fn push(&mut self, e: SlaveEvent) {
        tracing::debug!(event = %e, "dp slave");
        if self.q.len() >= EVENT_CAPACITY {
            self.q.pop_front();
            self.lost += 1;
        }
        self.q.push_back(e);
    }

    pub(crate) fn pop(&mut self) -> Option<SlaveEvent> {
        if self.lost > 0 {
            let n = self.lost;
            self.lost = 0;
            return Some(SlaveEvent::Lost(n));
        }
        self.q.pop_front()
    }
}
