//! When a program running a [`DpMaster`] stops: after N poll cycles, once
//! every slave has exchanged data N times (however long its start-up
//! took), or at a deadline (`dpctl master --cycles/--exchanges/--timeout`).

use super::{DpMaster, OperatingState};
use crate::pdu::control::ControlCommand;
use profibus_fdl::station::active::RingState;
use profibus_fdl::Instant;
use std::time::Duration;

/// The deadline of [`StopWhen::new`] when N Data_Exchange cycles are
/// waited for and no deadline is given: 60 s (`dpctl master --exchanges N`
/// without `--timeout`). Every slave of a working bus is in Data_Exchange
/// within a few seconds even at 9.6 kbit/s; a slave that never answers
/// must not keep a script waiting for ever.
pub const EXCHANGES_TIMEOUT: Duration = Duration::from_secs(60);

/// Stop conditions of a running master; each is optional.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StopWhen {
    /// After this many poll cycles.
    pub cycles: Option<u64>,
    /// Once every slave has completed this many Data_Exchange cycles.
    pub exchanges: Option<u64>,
    /// At this time since [`Instant::ZERO`].
    pub deadline: Option<Duration>,
}

/// Why [`StopWhen::check`] says stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The deadline passed.
    Deadline,
    /// The poll cycles are done.
    Cycles,
    /// Every slave exchanged data often enough.
    Exchanged,
}

impl StopWhen {
    /// The stop conditions of `dpctl master`: waiting for `exchanges`
    /// without a `deadline` gets [`EXCHANGES_TIMEOUT`].
    pub fn new(
        cycles: Option<u64>,
        exchanges: Option<u64>,
        deadline: Option<Duration>,
    ) -> StopWhen {
        let deadline = deadline.or(exchanges.map(|_| EXCHANGES_TIMEOUT));
        StopWhen {
            cycles,
            exchanges,
            deadline,
        }
    }

    /// Whether `m` should stop at `now`, and why (the deadline first).
    pub fn check(&self, m: &DpMaster, now: Instant) -> Option<StopReason> {
        if self.deadline.is_some_and(|d| now - Instant::ZERO >= d) {
            Some(StopReason::Deadline)
        } else if self.cycles.is_some_and(|n| m.cycle_stats().cycles >= n) {
            Some(StopReason::Cycles)
        } else if self.exchanges.is_some_and(|n| m.all_exchanged(n)) {
            Some(StopReason::Exchanged)
        } else {
            None
        }
    }
}

/// The longest a [`Farewell`] takes: 1 s, some ten poll cycles of a
/// full segment at 19.2 kbit/s and many token rotations at 1.5 Mbit/s.
pub const FAREWELL_LIMIT: Duration = Duration::from_secs(1);

/// The clean stop of a master that was asked to end (`dpctl master` and
/// `dpctl gateway` on SIGTERM or Ctrl-C). Sans-IO: [`Farewell::begin`]
/// once, then ask [`Farewell::done`] at every step until it says stop.
///
/// 1. **Clear**: the master goes to Clear, which sends a Global_Control
///    with Clear_Data to all slaves (broadcast SDN to SAP 58; the
///    standard's "master in Clear": slaves set their outputs to the safe
///    state, IEC 61158-6-3 / reference profibus-dp.md, Global_Control),
///    and then exchanges data with zero outputs. `done` waits until the
///    Global_Control is sent and one whole poll cycle in Clear has
///    followed it, so every slave in Data_Exchange has seen Clear_Data or
///    zero outputs — at once, not after its watchdog (often seconds).
/// 2. **Leave the ring**: PROFIBUS has no telegram for leaving; a master
///    leaves cleanly by not holding the token when it falls silent (the
///    others then drop it from their LAS when it takes no token pass,
///    instead of waiting for a lost token and claiming a new one). `done`
///    waits until the station has passed the token on (Active_Idle), or is
///    alone in the ring.
///
/// Both bounded by [`FAREWELL_LIMIT`]: a segment that does not let the
/// master finish (no token, a broken line) still ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Farewell {
    /// Poll cycles completed when the Clear began.
    cycles: u64,
    /// When to give up waiting.
    until: Instant,
}

impl Farewell {
    /// Start the clean stop of `m` at `now`: Clear with a Global_Control
    /// Clear_Data to all slaves (sent again if `m` already is in Clear).
    pub fn begin(m: &mut DpMaster, now: Instant) -> Farewell {
        if m.operating_state() == OperatingState::Clear {
            m.global_control(ControlCommand::empty(), 0);
        } else {
            m.set_operating_state(OperatingState::Clear);
        }
        Farewell {
            cycles: m.cycle_stats().cycles,
            until: now + FAREWELL_LIMIT,
        }
    }

    /// Whether the slaves saw the Clear: the Global_Control sent and a
    /// whole poll cycle after it.
    pub fn cleared(&self, m: &DpMaster) -> bool {
        // The cycle running at `begin` ends (+1), then a whole one (+2).
        !m.global_control_pending() && m.cycle_stats().cycles >= self.cycles + 2
    }

    /// Whether the master may fall silent now: cleared and not holding
    /// the token (`ring` the station's state, `alone` when it is the only
    /// master in its ring), or [`FAREWELL_LIMIT`] passed.
    pub fn done(&self, m: &DpMaster, ring: RingState, alone: bool, now: Instant) -> bool {
        if now >= self.until {
            return true;
        }
        let token_held = matches!(ring, RingState::UseToken | RingState::CheckTokenPass);
        self.cleared(m) && (alone || !token_held)
    }

    /// Whether the bound passed (the stop was not clean).
    pub fn timed_out(&self, now: Instant) -> bool {
        now >= self.until
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::master::{MasterConfig, MasterOptions, SlaveParams};
    use profibus_fdl::{Baud, BusParams};

    #[test]
    fn stops_at_the_deadline_first_and_waits_for_every_slave() {
        let m = DpMaster::new(&MasterConfig {
            address: 2,
            params: BusParams::defaults(Baud::B1500000),
            slaves: vec![SlaveParams::new(8, 0x1234, vec![0x11, 0x21])],
            options: MasterOptions::default(),
        })
        .unwrap();
        let at = |ms| Instant::ZERO + Duration::from_millis(ms);
        let when = StopWhen {
            cycles: Some(5),
            exchanges: Some(1),
            deadline: Some(Duration::from_secs(1)),
        };
        // No cycle yet, slave 8 never exchanged data.
        assert_eq!(when.check(&m, at(10)), None);
        assert_eq!(when.check(&m, at(1000)), Some(StopReason::Deadline));
        assert_eq!(m.not_exchanging(), [8]);
        assert!(!m.all_exchanged(1) && m.all_exchanged(0));
        let zero = StopWhen {
            exchanges: Some(0),
            ..StopWhen::default()
        };
        assert_eq!(zero.check(&m, at(10)), Some(StopReason::Exchanged));
        assert_eq!(StopWhen::default().check(&m, at(10)), None);
    }

    #[test]
    fn waiting_for_exchanges_has_a_default_deadline() {
        let s = Some(Duration::from_secs(3));
        assert_eq!(
            StopWhen::new(None, Some(5), None).deadline,
            Some(EXCHANGES_TIMEOUT)
        );
        assert_eq!(StopWhen::new(None, Some(5), s).deadline, s);
        assert_eq!(StopWhen::new(Some(5), None, None).deadline, None);
        assert_eq!(StopWhen::new(None, None, s).deadline, s);
    }
}
