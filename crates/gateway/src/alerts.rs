//! Alerts from the gateway's own master: its per-slave counters, taken
//! as interval statistics by [`MasterCounters`] and checked against the
//! rules of `[mqtt] alerts` / `dpctl gateway --alert` with the alert
//! rules of `dpctl sniff` and `dpctl monitor`
//! ([`profibus_dp::monitor::alert`]). The JSON core publishes each
//! [`Alert`] on `<prefix>/<bus>/alert`, the Sparkplug B core as the node
//! metric [`crate::sparkplug::ALERT`] in an NDATA.

use crate::settings::MqttSettings;
use profibus_dp::master::DpMaster;
use profibus_dp::monitor::alert::{Alert, AlertRule};
use profibus_dp::monitor::counters::MasterCounters;
use profibus_fdl::Instant;

/// The interval clock and counters of the alert rules.
#[derive(Debug, Default, Clone)]
pub struct AlertWatch {
    counters: MasterCounters,
    next: Option<Instant>,
}

impl AlertWatch {
    /// Nothing counted yet.
    pub fn new() -> AlertWatch {
        AlertWatch::default()
    }

    /// One step at a cycle boundary: the alerts of the interval that
    /// ended, when one did (`settings.alert_interval` after the last).
    /// Without rules nothing is counted.
    pub fn step(&mut self, settings: &MqttSettings, m: &DpMaster, now: Instant) -> Vec<Alert> {
        if settings.alerts.is_empty() {
            return vec![];
        }
        self.counters.observe(m);
        let next = *self.next.get_or_insert(now + settings.alert_interval);
        if now < next {
            return vec![];
        }
        self.next = Some(now + settings.alert_interval);
        let report = self.counters.report(m, now);
        let alerts = AlertRule::alerts(&settings.alerts, &report);
        for a in &alerts {
            tracing::warn!("{a}");
        }
        alerts
    }
}

/// `<prefix>/<bus>/alert`: the JSON core's alert topic.
pub fn topic(settings: &MqttSettings) -> String {
    format!("{}/{}/alert", settings.prefix, settings.bus)
}
