//! When a program running a [`DpMaster`] stops: after N poll cycles, once
//! every slave has exchanged data N times (however long its start-up
//! took), or at a deadline (`dpctl master --cycles/--exchanges/--timeout`).

use super::DpMaster;
use profibus_fdl::Instant;
use std::time::Duration;

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
}
