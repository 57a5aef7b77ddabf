//! The MQTT connection: a thin driver around the `rumqttc` client.
//!
//! The client's event loop runs in a task of its own: it connects,
//! reconnects after a loss with a growing pause (100 ms doubling to 5 s),
//! subscribes to the write topics on every connection, and hands
//! connections, losses and messages to the gateway's loop as
//! [`LinkEvent`]s. It logs (target `profibus_gateway::link`, which
//! `dpctl` shows by default) one line each at the start, on connecting,
//! on reconnecting and when a connection is lost, with the broker's URL;
//! retries stay quiet, and a clean close ([`MqttLink::close`]) logs no
//! loss. Publishing never blocks the bus: a message that finds
//! the client's queue full (the broker is away) is dropped, and the
//! gateway republishes every retained topic when the broker is back.
//!
//! It speaks MQTT 3.1.1 or, with `[mqtt] version = 5`, MQTT 5 (the
//! client of `rumqttc::v5`): the version is the link's business alone;
//! the cores fill and read [`Properties`] either way and the 3.1.1 link
//! leaves them out. Both versions connect with a clean session (clean
//! start, no session kept: the gateway subscribes again and republishes
//! its retained topics on every connection). On MQTT 5 the line of a
//! lost connection gives the reason code of the broker's DISCONNECT or
//! refusing CONNACK.

use crate::session::{Properties, Publish, Session};
use crate::settings::{
    parse_broker, Broker, MqttSettings, MqttVersion, PasswordSource, SettingsError,
};
use profibus_dp::master::DpMaster;
use profibus_fdl::Instant;
use rumqttc::v5::mqttbytes::v5 as mqtt5;
use rumqttc::{Event, LastWill, MqttOptions, Outgoing, Packet, QoS, TlsConfiguration, Transport};
use std::path::PathBuf;
use std::time::Duration;
use tokio::sync::mpsc;

/// What the connection reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkEvent {
    /// The broker accepted the connection (first or again).
    Connected,
    /// The connection was lost or refused.
    Disconnected(String),
    /// A message arrived.
    Message {
        /// Topic.
        topic: String,
        /// Payload.
        payload: Vec<u8>,
        /// Its MQTT 5 properties (empty on MQTT 3.1.1).
        props: Properties,
    },
}

/// A failed publish (the client's queue is full or closed). The message
/// includes the cause, which is therefore not also returned as
/// `source()`: a printed error chain names it once.
#[derive(Debug, thiserror::Error)]
#[error("MQTT publish failed: {0}")]
pub struct LinkError(String);

impl From<rumqttc::ClientError> for LinkError {
    fn from(e: rumqttc::ClientError) -> Self {
        LinkError(e.to_string())
    }
}

impl From<rumqttc::v5::ClientError> for LinkError {
    fn from(e: rumqttc::v5::ClientError) -> Self {
        LinkError(e.to_string())
    }
}

/// Why a connection cannot be set up.
#[derive(Debug, thiserror::Error)]
pub enum ConnectionError {
    /// The broker URL.
    #[error(transparent)]
    Settings(#[from] SettingsError),
    /// A file named in the settings.
    #[error("cannot read {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The cause (in the message; not also `source()`, so that a
        /// printed error chain names it once).
        error: std::io::Error,
    },
    /// The password's environment variable is not set.
    #[error("environment variable {0} (password_env) is not set")]
    NoEnv(String),
    /// `ca_file` without TLS.
    #[error("ca_file is set but the broker URL is not mqtts://")]
    CaWithoutTls,
}

/// Where and how to connect: the broker, the credentials, the CA
/// certificates (read when the connection is set up, so a secret is
/// never in the bus file).
#[derive(Clone, PartialEq, Eq)]
pub struct Connection {
    /// The broker.
    pub broker: Broker,
    /// User name and password.
    pub credentials: Option<(String, String)>,
    /// CA certificates (PEM) for TLS; `None`: the system's.
    pub ca_pem: Option<Vec<u8>>,
}

impl std::fmt::Debug for Connection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Connection")
            .field("broker", &self.broker)
            .field("user", &self.credentials.as_ref().map(|c| &c.0))
            .field("ca_pem", &self.ca_pem.as_ref().map(Vec::len))
            .finish()
    }
}

impl Connection {
    /// A plain connection to `broker` without credentials.
    pub fn plain(broker: Broker) -> Connection {
        Connection {
            broker,
            credentials: None,
            ca_pem: None,
        }
    }

    /// The connection `settings` describe, to the broker at `url`: reads
    /// the password (file or environment) and the CA file.
    pub fn from_settings(
        settings: &MqttSettings,
        url: &str,
    ) -> Result<Connection, ConnectionError> {
        let broker = parse_broker(url)?;
        let read = |path: &PathBuf| {
            std::fs::read(path).map_err(|error| ConnectionError::Read {
                path: path.clone(),
                error,
            })
        };
        let password = match &settings.password {
            None => String::new(),
            Some(PasswordSource::File(f)) => {
                let text = read(f)?;
                String::from_utf8_lossy(&text)
                    .lines()
                    .next()
                    .unwrap_or("")
                    .trim_end()
                    .to_string()
            }
            Some(PasswordSource::Env(v)) => {
                std::env::var(v).map_err(|_| ConnectionError::NoEnv(v.clone()))?
            }
        };
        let ca_pem = settings.ca_file.as_ref().map(read).transpose()?;
        if ca_pem.is_some() && !broker.tls {
            return Err(ConnectionError::CaWithoutTls);
        }
        Ok(Connection {
            broker,
            credentials: settings.username.clone().map(|u| (u, password)),
            ca_pem,
        })
    }

    fn transport(&self) -> Transport {
        match (&self.ca_pem, self.broker.tls) {
            (_, false) => Transport::tcp(),
            (Some(ca), true) => Transport::tls(ca.clone(), None, None),
            (None, true) => Transport::tls_with_config(TlsConfiguration::default()),
        }
    }

    /// The client and its event loop: clean session, keep-alive 5 s,
    /// the last will `will`.
    fn client(
        &self,
        version: MqttVersion,
        client_id: String,
        will: Publish,
        will_qos: QoS,
    ) -> (Client, EventLoop) {
        let (host, port) = (self.broker.host.clone(), self.broker.port);
        let keep_alive = Duration::from_secs(5);
        match version {
            MqttVersion::V311 => {
                let mut o = MqttOptions::new(client_id, host, port);
                if let Some((u, p)) = &self.credentials {
                    o.set_credentials(u.clone(), p.clone());
                }
                o.set_transport(self.transport());
                o.set_keep_alive(keep_alive);
                o.set_clean_session(true);
                let (client, el) = rumqttc::AsyncClient::new(o, QUEUE);
                let mut el = EventLoop::V4(el);
                el.set_last_will(will, will_qos);
                (Client::V4(client), el)
            }
            MqttVersion::V5 => {
                let mut o = rumqttc::v5::MqttOptions::new(client_id, host, port);
                if let Some((u, p)) = &self.credentials {
                    o.set_credentials(u.clone(), p.clone());
                }
                o.set_transport(self.transport());
                o.set_keep_alive(keep_alive);
                // Clean Start, Session Expiry Interval 0 (absent): no
                // session outlives the connection.
                o.set_clean_start(true);
                let (client, el) = rumqttc::v5::AsyncClient::new(o, QUEUE);
                let mut el = EventLoop::V5(el);
                el.set_last_will(will, will_qos);
                (Client::V5(client), el)
            }
        }
    }
}

/// The client half of either protocol version.
#[derive(Clone)]
enum Client {
    V4(rumqttc::AsyncClient),
    V5(rumqttc::v5::AsyncClient),
}

fn qos5(q: QoS) -> rumqttc::v5::mqttbytes::QoS {
    use rumqttc::v5::mqttbytes::QoS as Q5;
    match q {
        QoS::AtMostOnce => Q5::AtMostOnce,
        QoS::AtLeastOnce => Q5::AtLeastOnce,
        QoS::ExactlyOnce => Q5::ExactlyOnce,
    }
}

impl Client {
    /// Queue `p` without waiting; on MQTT 5 with its properties.
    fn try_publish(&self, p: Publish, q: QoS) -> Result<(), LinkError> {
        match self {
            Client::V4(c) => c.try_publish(p.topic, q, p.retain, p.payload)?,
            Client::V5(c) => {
                let props = mqtt5::PublishProperties {
                    message_expiry_interval: p.props.message_expiry_s,
                    response_topic: p.props.response_topic,
                    correlation_data: p.props.correlation_data.map(Into::into),
                    user_properties: p.props.user,
                    content_type: p.props.content_type,
                    payload_format_indicator: p.props.utf8.then_some(1),
                    ..Default::default()
                };
                c.try_publish_with_properties(p.topic, qos5(q), p.retain, p.payload, props)?
            }
        }
        Ok(())
    }

    fn try_subscribe(&self, filter: String, q: QoS) -> Result<(), LinkError> {
        match self {
            Client::V4(c) => c.try_subscribe(filter, q)?,
            Client::V5(c) => c.try_subscribe(filter, qos5(q))?,
        }
        Ok(())
    }

    fn try_disconnect(&self) -> Result<(), LinkError> {
        match self {
            Client::V4(c) => c.try_disconnect()?,
            Client::V5(c) => c.try_disconnect()?,
        }
        Ok(())
    }
}

/// The event loop of either protocol version (one per link, never moved
/// once its task runs: the size of the variants does not matter).
#[allow(clippy::large_enum_variant)]
enum EventLoop {
    V4(rumqttc::EventLoop),
    V5(rumqttc::v5::EventLoop),
}

/// What the event loop reports, whichever the version.
enum Polled {
    /// The broker accepted the connection.
    ConnAck {
        /// Whether the broker kept a session (never, with clean start).
        session_present: bool,
    },
    /// A message.
    Message(String, Vec<u8>, Properties),
    /// Our DISCONNECT went out.
    Disconnected,
    /// Anything else.
    Other,
}

impl EventLoop {
    /// The next event, or why the connection failed (on MQTT 5 with the
    /// reason code of the broker's DISCONNECT or CONNACK).
    async fn poll(&mut self) -> Result<Polled, String> {
        match self {
            EventLoop::V4(el) => Ok(match el.poll().await.map_err(|e| e.to_string())? {
                Event::Incoming(Packet::ConnAck(a)) => Polled::ConnAck {
                    session_present: a.session_present,
                },
                Event::Incoming(Packet::Publish(p)) => {
                    Polled::Message(p.topic, p.payload.to_vec(), Properties::default())
                }
                Event::Outgoing(Outgoing::Disconnect) => Polled::Disconnected,
                _ => Polled::Other,
            }),
            EventLoop::V5(el) => {
                use rumqttc::v5::{ConnectionError as E, Event as Ev, StateError};
                let ev = el.poll().await.map_err(|e| match e {
                    E::ConnectionRefused(code) => {
                        format!("connection refused, CONNACK reason {code:?}")
                    }
                    E::MqttState(StateError::ServerDisconnect {
                        reason_code,
                        reason_string,
                    }) => format!(
                        "DISCONNECT from the broker, reason code 0x{:02x} ({reason_code:?}){}",
                        reason_code as u8,
                        reason_string.map(|r| format!(": {r}")).unwrap_or_default()
                    ),
                    e => e.to_string(),
                })?;
                Ok(match ev {
                    Ev::Incoming(mqtt5::Packet::ConnAck(a)) => Polled::ConnAck {
                        session_present: a.session_present,
                    },
                    Ev::Incoming(mqtt5::Packet::Publish(p)) => {
                        let props = p.properties.map(|q| Properties {
                            response_topic: q.response_topic,
                            correlation_data: q.correlation_data.map(|c| c.to_vec()),
                            user: q.user_properties,
                            message_expiry_s: q.message_expiry_interval,
                            content_type: q.content_type,
                            utf8: q.payload_format_indicator == Some(1),
                        });
                        Polled::Message(
                            String::from_utf8_lossy(&p.topic).into_owned(),
                            p.payload.to_vec(),
                            props.unwrap_or_default(),
                        )
                    }
                    Ev::Outgoing(Outgoing::Disconnect) => Polled::Disconnected,
                    _ => Polled::Other,
                })
            }
        }
    }

    /// The last will of the next connection attempt.
    fn set_last_will(&mut self, w: Publish, q: QoS) {
        match self {
            EventLoop::V4(el) => {
                el.mqtt_options
                    .set_last_will(LastWill::new(w.topic, w.payload, q, w.retain));
            }
            EventLoop::V5(el) => {
                el.options.set_last_will(mqtt5::LastWill::new(
                    w.topic,
                    w.payload,
                    qos5(q),
                    w.retain,
                    None,
                ));
            }
        }
    }
}

/// The connection to the broker of one gateway.
pub struct MqttLink {
    client: Client,
    qos: QoS,
    will_qos: QoS,
    events: mpsc::UnboundedReceiver<LinkEvent>,
    task: tokio::task::JoinHandle<()>,
    /// Set by [`MqttLink::close`]: the client's task ends instead of
    /// reconnecting.
    closing: tokio::sync::watch::Sender<bool>,
}

fn qos(q: u8) -> QoS {
    match q {
        0 => QoS::AtMostOnce,
        1 => QoS::AtLeastOnce,
        _ => QoS::ExactlyOnce,
    }
}

/// Messages the client queues while the broker is away.
const QUEUE: usize = 1024;

impl MqttLink {
    /// Start connecting over `conn` for `gateway` (its client id, last
    /// will and subscriptions, and the protocol version of its
    /// settings). Needs a tokio runtime.
    pub fn connect(conn: &Connection, gateway: &impl Session) -> MqttLink {
        let s = gateway.settings();
        let version = s.version;
        let setup = gateway.link_setup();
        let q = qos(setup.qos);
        let will_qos = qos(setup.will_qos);
        let mut will = setup.will;
        let (client, mut eventloop) = conn.client(version, s.client_id.clone(), will(), will_qos);
        let (tx, events) = mpsc::unbounded_channel();
        let filters = setup.filters;
        let sub = client.clone();
        let (closing, mut closed) = tokio::sync::watch::channel(false);
        let url = conn.broker.to_string();
        tracing::info!(
            "MQTT gateway starting: broker {url}, MQTT {version}, client id `{}`",
            s.client_id
        );
        let task = tokio::spawn(async move {
            let mut pause = Duration::from_millis(100);
            // Whether the broker ever accepted us, and whether the loss
            // of the connection (or the failed first attempt) was logged.
            let (mut ever, mut lost) = (false, false);
            loop {
                match eventloop.poll().await {
                    Ok(Polled::ConnAck { session_present }) => {
                        pause = Duration::from_millis(100);
                        let session = match session_present {
                            false => "clean session",
                            true => "session present",
                        };
                        match ever {
                            false => tracing::info!(
                                "connected to the MQTT broker {url} (MQTT {version}, {session})"
                            ),
                            true => tracing::info!(
                                "reconnected to the MQTT broker {url} (MQTT {version}, {session})"
                            ),
                        }
                        (ever, lost) = (true, false);
                        for f in &filters {
                            if let Err(e) = sub.try_subscribe(f.clone(), q) {
                                tracing::warn!(error = %e, "cannot subscribe to {f}");
                            }
                        }
                        if tx.send(LinkEvent::Connected).is_err() {
                            return;
                        }
                    }
                    Ok(Polled::Message(topic, payload, props)) => {
                        let ev = LinkEvent::Message {
                            topic,
                            payload,
                            props,
                        };
                        if tx.send(ev).is_err() {
                            return;
                        }
                    }
                    // Our clean disconnect went out (`MqttLink::close`).
                    Ok(Polled::Disconnected) => return,
                    Ok(Polled::Other) => {}
                    // The broker closing the connection we are closing.
                    Err(_) if *closed.borrow() => return,
                    Err(e) => {
                        // One line per outage; the retries are quiet.
                        match (lost, ever) {
                            (true, _) => {
                                tracing::debug!(error = %e, "MQTT broker {url}: still away")
                            }
                            (false, true) => {
                                tracing::warn!("MQTT connection to {url} lost ({e}); reconnecting")
                            }
                            (false, false) => tracing::warn!(
                                "cannot connect to the MQTT broker {url} ({e}); retrying"
                            ),
                        }
                        lost = true;
                        if tx.send(LinkEvent::Disconnected(e)).is_err() {
                            return;
                        }
                        // The next poll connects again, with the next will.
                        eventloop.set_last_will(will(), will_qos);
                        // Reconnection backoff, not a wait for an event;
                        // a close ends it.
                        tokio::select! {
                            _ = tokio::time::sleep(pause) => {}
                            _ = closed.wait_for(|&c| c) => return,
                        }
                        pause = (pause * 2).min(Duration::from_secs(5));
                    }
                }
            }
        });
        MqttLink {
            client,
            qos: q,
            will_qos,
            events,
            task,
            closing,
        }
    }

    /// The next event, without waiting.
    pub fn try_recv(&mut self) -> Option<LinkEvent> {
        self.events.try_recv().ok()
    }

    /// The next event.
    pub async fn recv(&mut self) -> Option<LinkEvent> {
        self.events.recv().await
    }

    /// Queue a message for the broker without waiting (on MQTT 5 with its
    /// properties).
    pub fn publish(&self, p: Publish) -> Result<(), LinkError> {
        self.client.try_publish(p, self.qos)
    }

    /// Publish `p` and disconnect cleanly (the broker then does not send
    /// the last will: publish the offline status with this). Never waits
    /// long: with the broker away nothing is sent, and the client's task
    /// is given at most [`CLOSE_WAIT`] to send both.
    pub async fn close(self, last: Publish) {
        self.closing.send_replace(true);
        let _ = self.client.try_publish(last, self.will_qos);
        let _ = self.client.try_disconnect();
        let _ = tokio::time::timeout(CLOSE_WAIT, self.task).await;
    }
}

/// The longest [`MqttLink::close`] waits for the last message and the
/// disconnect to go out.
pub const CLOSE_WAIT: Duration = Duration::from_secs(2);

/// Hand every link event to `gateway`; `ts_ms` is the wall-clock time in
/// ms since the Unix epoch.
pub fn pump(link: &mut MqttLink, gateway: &mut impl Session, ts_ms: u64) {
    while let Some(ev) = link.try_recv() {
        match ev {
            LinkEvent::Connected => gateway.connected(ts_ms),
            LinkEvent::Disconnected(_) => gateway.disconnected(ts_ms),
            LinkEvent::Message {
                topic,
                payload,
                props,
            } => gateway.handle_message_with(&topic, &payload, &props, ts_ms),
        }
    }
}

/// Send everything `gateway` has queued.
pub fn flush(link: &MqttLink, gateway: &mut impl Session) {
    while let Some(p) = gateway.poll_publish() {
        if let Err(e) = link.publish(p) {
            tracing::debug!(error = %e, "dropped a publish");
        }
    }
}

/// One step of `gateway` at a cycle boundary of the master `m` (bus time
/// `now`): hand it the link's events, step it, send what it queued.
pub fn step(link: &mut MqttLink, gateway: &mut impl Session, m: &mut DpMaster, now: Instant) {
    let ts = wall_ms();
    pump(link, gateway, ts);
    gateway.step(m, now, ts);
    flush(link, gateway);
}

/// Milliseconds since the Unix epoch, for payload timestamps.
pub fn wall_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}
