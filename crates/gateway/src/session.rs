//! The interface between a gateway core and its connection: [`Session`],
//! which the plain JSON core ([`crate::Gateway`]) and the Sparkplug B
//! core ([`crate::EdgeNode`]) implement and the link ([`crate::link`])
//! and the drivers use, and the [`Publish`]es it queues.

use crate::settings::MqttSettings;
use profibus_dp::master::DpMaster;
use profibus_fdl::Instant;

/// A message for the broker.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Publish {
    /// Topic.
    pub topic: String,
    /// Payload (JSON text).
    pub payload: Vec<u8>,
    /// Whether the broker keeps it for late subscribers.
    pub retain: bool,
}

/// A gateway core as the link and the driver see it: the plain JSON
/// [`crate::Gateway`] or the Sparkplug B [`crate::EdgeNode`]. All
/// sans-IO: the driver hands in link events and the master, and sends
/// what [`Session::poll_publish`] returns.
pub trait Session {
    /// The settings (client id, QoS, …).
    fn settings(&self) -> &MqttSettings;
    /// The settings, to change while running (`dpctl gateway` on
    /// SIGHUP). Only keys the core reads as it runs take effect (what is
    /// published when, `writable`, the outage settings); the connection's
    /// (broker, client id, topics, QoS) need a new core.
    fn settings_mut(&mut self) -> &mut MqttSettings;
    /// Take `settings` while running (`dpctl gateway` on SIGHUP): what
    /// [`Session::settings_mut`] takes, and the traffic keys
    /// (`min_interval_ms`, `deadband`, `[[mqtt.slave]]`) for the next
    /// publish of every slave.
    fn reload(&mut self, settings: MqttSettings) {
        *self.settings_mut() = settings;
    }
    /// What the connection needs of this core: subscriptions and wills.
    fn link_setup(&self) -> LinkSetup;
    /// The broker accepted the connection.
    fn connected(&mut self, ts_ms: u64);
    /// The connection was lost (or a connection attempt failed).
    fn disconnected(&mut self, ts_ms: u64);
    /// A message arrived on a subscribed topic.
    fn handle_message(&mut self, topic: &str, payload: &[u8], ts_ms: u64);
    /// One step at a cycle boundary of the master; `now` is the master's
    /// time, `ts_ms` the wall clock in ms since the Unix epoch.
    fn step(&mut self, m: &mut DpMaster, now: Instant, ts_ms: u64);
    /// The next message to send, if any.
    fn poll_publish(&mut self) -> Option<Publish>;
    /// The message to publish before a clean disconnect (the broker sends
    /// no will then).
    fn last_will(&self) -> Publish;
}

/// What a [`Session`] asks of its connection.
pub struct LinkSetup {
    /// QoS of every publish and subscription (0..=2).
    pub qos: u8,
    /// QoS of the last will.
    pub will_qos: u8,
    /// Topic filters subscribed to on every connection.
    pub filters: Vec<String>,
    /// The last will of the next connection attempt, called before the
    /// first and before every later attempt (after each
    /// `LinkEvent::Disconnected` of the link).
    pub will: Box<dyn FnMut() -> Publish + Send>,
}
