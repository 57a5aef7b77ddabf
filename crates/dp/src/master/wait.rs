//! Waiting for one slave to reach Data_Exchange before an acyclic job
//! (PKW, DP-V1, an RFID command) runs on it, with a start-up timeout:
//! sans-IO, fed the master and the time on each tick.

use super::{DpMaster, SlaveState};
use profibus_fdl::Instant;
use std::time::Duration;

/// The slave did not reach Data_Exchange in time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "slave {address} did not reach Data_Exchange within {} ms (state {})",
    timeout.as_millis(),
    state.map_or("unknown", SlaveState::name)
)]
pub struct StartupTimeout {
    /// The slave.
    pub address: u8,
    /// How long it was given.
    pub timeout: Duration,
    /// Its state when the time ran out.
    pub state: Option<SlaveState>,
}

/// Waits for a slave; see the module docs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlaveWait {
    address: u8,
    timeout: Duration,
    started: Option<Instant>,
}

impl SlaveWait {
    /// Wait up to `timeout` (from the first [`SlaveWait::check`]) for the
    /// slave at `address`.
    pub fn new(address: u8, timeout: Duration) -> SlaveWait {
        SlaveWait {
            address,
            timeout,
            started: None,
        }
    }

    /// The slave's address.
    pub fn address(&self) -> u8 {
        self.address
    }

    /// True when the slave is in Data_Exchange now. `busy`: a job is
    /// running on it, so the timeout does not apply (a running job ends
    /// on its own timeout).
    pub fn check(
        &mut self,
        m: &DpMaster,
        now: Instant,
        busy: bool,
    ) -> Result<bool, StartupTimeout> {
        let t0 = *self.started.get_or_insert(now);
        let state = m.slave_state(self.address);
        if state == Some(SlaveState::DataExchange) {
            return Ok(true);
        }
        if !busy && now.saturating_duration_since(t0) > self.timeout {
            return Err(StartupTimeout {
                address: self.address,
                timeout: self.timeout,
                state,
            });
        }
        Ok(false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::master::{MasterConfig, MasterOptions, SlaveParams};
    use profibus_fdl::{Baud, BusParams};

    #[test]
    fn times_out_only_when_idle_and_names_the_state() {
        let cfg = MasterConfig {
            address: 1,
            params: BusParams::defaults(Baud::B1500000),
            slaves: vec![SlaveParams::new(8, 0x0DCE, vec![0x11, 0x21])],
            options: MasterOptions::default(),
        };
        let m = DpMaster::new(&cfg).unwrap();
        let mut w = SlaveWait::new(8, Duration::from_millis(100));
        let t = |ms| Instant::ZERO + Duration::from_millis(ms);
        assert_eq!(w.check(&m, t(1000), false), Ok(false));
        assert_eq!(w.check(&m, t(1100), false), Ok(false));
        assert_eq!(w.check(&m, t(1200), true), Ok(false), "a job runs");
        let e = w.check(&m, t(1200), false).unwrap_err();
        assert_eq!(e.address, 8);
        assert!(e.to_string().contains("within 100 ms"), "{e}");
        let mut none = SlaveWait::new(9, Duration::ZERO);
        assert_eq!(none.check(&m, t(0), false), Ok(false));
        assert!(none
            .check(&m, t(1), false)
            .unwrap_err()
            .to_string()
            .contains("state unknown"));
    }
}
