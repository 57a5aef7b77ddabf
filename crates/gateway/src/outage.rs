//! The outputs while the broker is away: after `outputs_timeout` without
//! a connection they go to the configured safe state, once per outage
//! (see [`crate::settings`]). Shared by both gateway cores.

use crate::settings::{MqttSettings, SafeState};
use profibus_dp::master::{DpMaster, OperatingState};

/// The broker outage state of a gateway core.
#[derive(Debug, Default)]
pub struct Outage {
    /// Since when the broker is away (ms).
    offline_since: Option<u64>,
    /// When the safe state was applied in this or the last outage (ms).
    safe_applied: Option<u64>,
    /// The master's state before [`SafeState::Clear`] put it in Clear.
    cleared_from: Option<OperatingState>,
}

impl Outage {
    /// The broker accepted the connection.
    pub fn connected(&mut self) {
        self.offline_since = None;
    }

    /// The connection was lost (or an attempt failed) at `ts_ms`;
    /// `was_online`: there was a connection until now.
    pub fn disconnected(&mut self, was_online: bool, ts_ms: u64) {
        if was_online || self.offline_since.is_none() {
            self.offline_since = Some(ts_ms);
            self.safe_applied = None;
        }
    }

    /// When the safe state was applied in the current or last outage.
    pub fn safe_applied(&self) -> Option<u64> {
        self.safe_applied
    }

    /// At a cycle boundary: without a broker for `outputs_timeout`, the
    /// safe state, once per outage; with the broker back after
    /// [`SafeState::Clear`], the master's state from before.
    pub fn step(&mut self, settings: &MqttSettings, online: bool, m: &mut DpMaster, ts_ms: u64) {
        if online {
            if let Some(s) = self.cleared_from.take() {
                tracing::info!(state = s.as_str(), "broker back: master leaves Clear");
                m.set_operating_state(s);
            }
            return;
        }
        let since = *self.offline_since.get_or_insert(ts_ms);
        let Some(timeout) = settings.outputs_timeout else {
            return;
        };
        if self.safe_applied.is_some() || ts_ms < since + timeout.as_millis() as u64 {
            return;
        }
        self.safe_applied = Some(ts_ms);
        let s = settings.safe_state;
        tracing::warn!(
            safe_state = s.as_str(),
            "no broker for {} ms: outputs to the safe state",
            timeout.as_millis()
        );
        match s {
            SafeState::Keep => {}
            SafeState::Zero => {
                for w in &settings.writable {
                    if let Some(len) = m.outputs(w.address).map(<[u8]>::len) {
                        m.set_outputs(w.address, &vec![0; len]);
                    }
                }
            }
            SafeState::Clear => {
                let before = m.operating_state();
                if before != OperatingState::Clear {
                    self.cleared_from = Some(before);
                    m.set_operating_state(OperatingState::Clear);
                }
            }
        }
    }
}
