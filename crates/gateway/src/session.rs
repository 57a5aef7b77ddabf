//! The interface between a gateway core and its connection: [`Session`],
//! which the plain JSON core ([`crate::Gateway`]) and the Sparkplug B
//! core ([`crate::EdgeNode`]) implement and the link ([`crate::link`])
//! and the drivers use, the [`Publish`]es it queues, and the MQTT 5
//! [`Properties`] of messages both ways (a core fills and reads them
//! whichever protocol version the link speaks; on MQTT 3.1.1 the link
//! sends none and hands in none).

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
    /// Its MQTT 5 properties (not sent on MQTT 3.1.1).
    pub props: Properties,
}

impl Publish {
    /// A message without properties.
    pub fn new(topic: String, payload: Vec<u8>, retain: bool) -> Publish {
        Publish {
            topic,
            payload,
            retain,
            props: Properties::default(),
        }
    }
}

/// The MQTT 5 properties the gateway uses (MQTT 5.0, 3.3.2.3): on
/// requests the client's response topic, correlation data and content
/// type, on answers the correlation data, on value messages the units
/// and the message expiry interval, on every JSON message its content
/// type and payload format. Empty on MQTT 3.1.1, which has no properties.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Properties {
    /// Response Topic: where the requester wants the answer.
    pub response_topic: Option<String>,
    /// Correlation Data: the requester's bytes, returned with the answer.
    pub correlation_data: Option<Vec<u8>>,
    /// User Properties, name and value, in order (a name may repeat).
    pub user: Vec<(String, String)>,
    /// Message Expiry Interval in seconds: the broker drops the message
    /// when it could not deliver it within this time (`None`: never).
    pub message_expiry_s: Option<u32>,
    /// Content Type (MQTT 5.0, 3.3.2.3.9): the payload's media type;
    /// `application/json` on everything the plain gateway publishes, and
    /// a request that gives one must give a JSON one.
    pub content_type: Option<String>,
    /// Payload Format Indicator 1 (MQTT 5.0, 3.3.2.3.2): the payload is
    /// UTF-8 text (set on the plain gateway's JSON).
    pub utf8: bool,
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
    /// A message arrived on a subscribed topic, with its MQTT 5
    /// properties (empty on MQTT 3.1.1).
    fn handle_message_with(&mut self, topic: &str, payload: &[u8], props: &Properties, ts_ms: u64);
    /// A message without properties arrived on a subscribed topic.
    fn handle_message(&mut self, topic: &str, payload: &[u8], ts_ms: u64) {
        self.handle_message_with(topic, payload, &Properties::default(), ts_ms)
    }
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
