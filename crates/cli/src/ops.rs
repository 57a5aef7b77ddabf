//! `dpctl gateway` in operation: the bus's log lines (slaves entering
//! and leaving Data_Exchange), the health topic and `--health-file`, the
//! `[mqtt]` reload on SIGHUP and the offline health on a clean stop.
//!
//! [`Operated`] wraps the gateway core ([`Session`]): it sees every
//! cycle boundary (`step` gets the master) and every connection change,
//! so it knows what a supervisor needs without touching the bus.

use profibus_dp::master::{DpMaster, SlaveState};
use profibus_fdl::Instant;
use profibus_gateway::{LinkSetup, MqttSettings, Properties, Publish, Session};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::Duration;

/// The log target of the gateway's operation lines (on at `info` by
/// default, see [`crate::logs::DEFAULT_LOG`]).
pub const TARGET: &str = "dpctl::ops";

/// How often the health topic is published while nothing changes.
pub const HEALTH_PERIOD: Duration = Duration::from_secs(5);

/// How often `--health-file` is rewritten.
pub const HEALTH_FILE_PERIOD: Duration = Duration::from_secs(1);

/// No cycle boundary for this long: the bus is `stalled`.
pub const STALLED_AFTER: Duration = Duration::from_secs(2);

/// What a supervisor watches: the health topic's payload and the
/// `--health-file`'s content.
#[derive(Clone, Debug, Serialize, PartialEq, Eq)]
pub struct Health {
    /// `ok` (cycles run, every slave in Data_Exchange, broker connected),
    /// `degraded` (cycles run, but a slave is out of Data_Exchange or the
    /// broker away), `stalled` (no cycle for 2 s), `starting` (no cycle
    /// yet) or `offline` (stopped).
    pub state: &'static str,
    /// Whether the process does its job: cycles run (`ok` or `degraded`).
    /// A supervisor restarts on `false`; a slave or broker outage is no
    /// reason to (the gateway rides it out).
    pub healthy: bool,
    /// The master's operating state (`operate`, `clear`, `stop`).
    pub bus: &'static str,
    /// Configured slaves.
    pub slaves: usize,
    /// Slaves in Data_Exchange.
    pub data_exchange: usize,
    /// Whether the MQTT broker is connected.
    pub broker_connected: bool,
    /// Milliseconds since the last cycle boundary (`null` before the
    /// first).
    pub last_cycle_age_ms: Option<u64>,
    /// Wall clock, ms since the Unix epoch.
    pub ts: u64,
}

/// What the gateway knows of itself, shared between the bus side
/// ([`Operated`]) and the health file's writer.
#[derive(Debug)]
struct Snapshot {
    bus: &'static str,
    slaves: usize,
    data_exchange: usize,
    broker: bool,
    last_cycle: Option<std::time::Instant>,
    stopped: bool,
}

impl Snapshot {
    fn health(&self) -> Health {
        let age = self.last_cycle.map(|t| t.elapsed());
        let state = match (self.stopped, age) {
            (true, _) => "offline",
            (false, None) => "starting",
            (false, Some(a)) if a >= STALLED_AFTER => "stalled",
            _ if self.broker && self.data_exchange == self.slaves => "ok",
            _ => "degraded",
        };
        Health {
            state,
            healthy: matches!(state, "ok" | "degraded"),
            bus: self.bus,
            slaves: self.slaves,
            data_exchange: self.data_exchange,
            broker_connected: self.broker,
            last_cycle_age_ms: age.map(|a| a.as_millis() as u64),
            ts: profibus_gateway::link::wall_ms(),
        }
    }
}

/// Stop handshake between the shutdown signal and [`Operated`]: the
/// signal side [`begin`](Stopping::begin)s, the core publishes its
/// offline health and the signal side's [`sent`](Stopping::sent)
/// completes.
#[derive(Clone, Default)]
pub struct Stopping {
    begun: Arc<AtomicBool>,
    sent: Arc<tokio::sync::Notify>,
}

impl Stopping {
    /// Ask the core to publish its offline health.
    pub fn begin(&self) {
        self.begun.store(true, Ordering::Relaxed);
    }

    /// Completes once the offline health is handed to the link (or at
    /// once without a health topic); bound it with a timeout.
    pub async fn sent(&self) {
        self.sent.notified().await
    }
}

/// The gateway core `S` with the operation around it.
pub struct Operated<S> {
    inner: S,
    health_topic: String,
    shared: Arc<Mutex<Snapshot>>,
    states: BTreeMap<u8, SlaveState>,
    reloads: mpsc::Receiver<Reload>,
    stopping: Stopping,
    /// The health last published and when (wall ms).
    published: Option<(Health, u64)>,
    offline_sent: bool,
    health_path: Option<PathBuf>,
}

/// New settings for the running core, and what changed (for the log).
pub struct Reload {
    /// The settings to take.
    pub settings: MqttSettings,
    /// The keys that changed, in words.
    pub changes: Vec<String>,
}

/// The sending side of reloads (the SIGHUP task).
pub type ReloadSender = mpsc::Sender<Reload>;

impl<S: Session> Operated<S> {
    /// `inner` with operation; `slaves` the configured slaves' count.
    /// Returns the sender of reloads and the stop handshake.
    pub fn new(inner: S, slaves: usize) -> (Operated<S>, ReloadSender, Stopping) {
        let s = inner.settings();
        let health_topic = format!("{}/{}/health", s.prefix, s.bus);
        let (tx, reloads) = mpsc::channel();
        let stopping = Stopping::default();
        let op = Operated {
            inner,
            health_topic,
            shared: Arc::new(Mutex::new(Snapshot {
                bus: "stop",
                slaves,
                data_exchange: 0,
                broker: false,
                last_cycle: None,
                stopped: false,
            })),
            states: BTreeMap::new(),
            reloads,
            stopping: stopping.clone(),
            published: None,
            offline_sent: false,
            health_path: None,
        };
        (op, tx, stopping)
    }

    /// Rewrite `path` with the health every [`HEALTH_FILE_PERIOD`] on a
    /// thread of its own (the age grows there even when the bus thread
    /// hangs), `offline` once the gateway stopped.
    pub fn health_file(&mut self, path: PathBuf) {
        self.health_path = Some(path.clone());
        let shared = self.shared.clone();
        std::thread::spawn(move || loop {
            let (health, stopped) = {
                let s = shared.lock().unwrap_or_else(|e| e.into_inner());
                (s.health(), s.stopped)
            };
            if let Err(e) = write_atomically(&path, &health) {
                tracing::warn!(target: TARGET, "cannot write the health file {}: {e}", path.display());
            }
            if stopped {
                return;
            }
            // The file's period, not a wait for an event.
            std::thread::sleep(HEALTH_FILE_PERIOD);
        });
    }

    /// What marks the gateway stopped (the health file says `offline`),
    /// to call once it stopped.
    pub fn stopped_handle(&self) -> impl FnOnce() {
        let shared = self.shared.clone();
        let path = self.health_path.clone();
        move || {
            let health = {
                let mut s = shared.lock().unwrap_or_else(|e| e.into_inner());
                s.stopped = true;
                s.health()
            };
            // The writer thread may not get to it before the process
            // ends.
            if let Some(path) = path {
                if let Err(e) = write_atomically(&path, &health) {
                    tracing::warn!(target: TARGET, "cannot write the health file {}: {e}", path.display());
                }
            }
        }
    }

    fn snapshot(&self) -> std::sync::MutexGuard<'_, Snapshot> {
        self.shared.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn watch_slaves(&mut self, m: &DpMaster) {
        let mut dx = 0;
        for a in m.slave_addresses().collect::<Vec<_>>() {
            let Some(now) = m.slave_state(a) else {
                continue;
            };
            dx += usize::from(now == SlaveState::DataExchange);
            let before = self.states.insert(a, now);
            match (before, now) {
                (b, SlaveState::DataExchange) if b != Some(SlaveState::DataExchange) => {
                    tracing::info!(target: TARGET, slave = a, "slave {a} in Data_Exchange")
                }
                (Some(SlaveState::DataExchange), s) if s != SlaveState::DataExchange => {
                    tracing::warn!(
                        target: TARGET,
                        slave = a,
                        state = s.name(),
                        "slave {a} left Data_Exchange ({})",
                        s.name()
                    )
                }
                _ => {}
            }
        }
        let bus = m.operating_state().as_str();
        let mut s = self.snapshot();
        if s.bus != bus && s.last_cycle.is_some() {
            tracing::info!(target: TARGET, "master now in {bus}");
        }
        s.bus = bus;
        s.data_exchange = dx;
        s.last_cycle = Some(std::time::Instant::now());
    }

    fn take_reloads(&mut self) {
        while let Ok(r) = self.reloads.try_recv() {
            // The connection's version (maybe from --mqtt-version) stays.
            let mut settings = r.settings;
            settings.version = self.inner.settings().version;
            self.inner.reload(settings);
            match r.changes.is_empty() {
                true => tracing::info!(target: TARGET, "reloaded [mqtt]: nothing changed"),
                false => tracing::info!(
                    target: TARGET,
                    "reloaded [mqtt]: {}",
                    r.changes.join(", ")
                ),
            }
        }
    }

    /// The health to publish now, if it changed or is due.
    fn health_due(&mut self, ts_ms: u64) -> Option<Publish> {
        if self.offline_sent {
            return None;
        }
        let stopping = self.stopping.begun.load(Ordering::Relaxed);
        let mut health = self.snapshot().health();
        if stopping {
            health.state = "offline";
            health.healthy = false;
        }
        if !health.broker_connected {
            return None;
        }
        let due = match &self.published {
            None => true,
            Some((h, at)) => {
                stopping
                    || (h.state, h.bus, h.data_exchange)
                        != (health.state, health.bus, health.data_exchange)
                    || ts_ms >= at + HEALTH_PERIOD.as_millis() as u64
            }
        };
        if !due {
            return None;
        }
        let payload = serde_json::to_vec(&health).unwrap_or_default();
        self.published = Some((health, ts_ms));
        if stopping {
            self.offline_sent = true;
        }
        Some(Publish::new(self.health_topic.clone(), payload, true))
    }
}

impl<S: Session> Session for Operated<S> {
    fn settings(&self) -> &MqttSettings {
        self.inner.settings()
    }
    fn settings_mut(&mut self) -> &mut MqttSettings {
        self.inner.settings_mut()
    }
    fn reload(&mut self, settings: MqttSettings) {
        self.inner.reload(settings)
    }
    fn link_setup(&self) -> LinkSetup {
        self.inner.link_setup()
    }
    fn connected(&mut self, ts_ms: u64) {
        self.snapshot().broker = true;
        // Retained: publish again on every connection.
        self.published = None;
        self.inner.connected(ts_ms)
    }
    fn disconnected(&mut self, ts_ms: u64) {
        self.snapshot().broker = false;
        self.inner.disconnected(ts_ms)
    }
    fn handle_message_with(&mut self, topic: &str, payload: &[u8], props: &Properties, ts_ms: u64) {
        self.inner.handle_message_with(topic, payload, props, ts_ms)
    }
    fn step(&mut self, m: &mut DpMaster, now: Instant, ts_ms: u64) {
        self.take_reloads();
        self.watch_slaves(m);
        self.inner.step(m, now, ts_ms)
    }
    fn poll_publish(&mut self) -> Option<Publish> {
        if let Some(p) = self.inner.poll_publish() {
            return Some(p);
        }
        let p = self.health_due(profibus_gateway::link::wall_ms());
        if p.is_some() && self.offline_sent {
            self.stopping.sent.notify_one();
        }
        p
    }
    fn last_will(&self) -> Publish {
        self.inner.last_will()
    }
}

/// Write `health` to `path` through a temporary file and a rename: a
/// reader never sees half a file.
fn write_atomically(path: &std::path::Path, health: &Health) -> std::io::Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let mut text = serde_json::to_string(health).map_err(std::io::Error::other)?;
    text.push('\n');
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}

/// `[mqtt]` keys a running gateway cannot take: its connection (broker,
/// identity, credentials), its topics and subscriptions, its mode. The
/// report-by-exception keys (`min_interval_ms`, `deadband`,
/// `[[mqtt.slave]]`) are taken ([`Session::reload`]).
pub const RESTART_KEYS: &[&str] = &[
    "broker",
    "client_id",
    "prefix",
    "bus",
    "qos",
    "username",
    "password_file",
    "password_env",
    "ca_file",
    "sparkplug",
    "job_timeout_ms",
    "version",
    "primary_host",
    "sparkplug_templates",
];

/// The keys of two `[mqtt]` tables that differ, as `key: old → new`
/// (`(none)` for a missing key), in key order.
pub fn changes(old: Option<&toml::Table>, new: Option<&toml::Table>) -> Vec<(String, String)> {
    let empty = toml::Table::new();
    let (old, new) = (old.unwrap_or(&empty), new.unwrap_or(&empty));
    let keys: std::collections::BTreeSet<&String> = old.keys().chain(new.keys()).collect();
    let show = |v: Option<&toml::Value>| v.map_or("(none)".to_string(), |v| v.to_string());
    keys.into_iter()
        .filter(|k| old.get(*k) != new.get(*k))
        .map(|k| {
            (
                k.clone(),
                format!("{k}: {} → {}", show(old.get(k)), show(new.get(k))),
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(s: &str) -> toml::Table {
        s.parse().unwrap()
    }

    #[test]
    fn changes_name_each_key_that_differs() {
        let old = table("publish = \"change\"\nwritable = [3]\nqos = 1");
        let new = table("publish = \"interval\"\nqos = 1\ninterval_ms = 500");
        let c: Vec<String> = changes(Some(&old), Some(&new))
            .into_iter()
            .map(|c| c.1)
            .collect();
        assert_eq!(
            c,
            [
                "interval_ms: (none) → 500",
                "publish: \"change\" → \"interval\"",
                "writable: [3] → (none)",
            ]
        );
        assert!(changes(Some(&old), Some(&old)).is_empty());
        assert_eq!(changes(None, Some(&table("qos = 2"))).len(), 1);
    }

    #[test]
    fn health_states() {
        let mut s = Snapshot {
            bus: "operate",
            slaves: 2,
            data_exchange: 2,
            broker: true,
            last_cycle: None,
            stopped: false,
        };
        assert_eq!(s.health().state, "starting");
        assert!(!s.health().healthy);
        s.last_cycle = Some(std::time::Instant::now());
        assert_eq!(s.health().state, "ok");
        s.data_exchange = 1;
        assert_eq!(s.health().state, "degraded");
        assert!(s.health().healthy, "a slave outage is no reason to restart");
        s.last_cycle = std::time::Instant::now().checked_sub(STALLED_AFTER);
        assert_eq!(s.health().state, "stalled");
        assert!(!s.health().healthy);
        s.stopped = true;
        assert_eq!(s.health().state, "offline");
    }
}
