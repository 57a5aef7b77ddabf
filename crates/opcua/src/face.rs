//! The OPC UA face of the gateway core: [`Face`], a [`Session`] around
//! the plain JSON [`Gateway`] that also samples the master for the
//! address space and carries OPC UA writes and method calls into the
//! core as requests, so that they pass exactly the checks and
//! permissions of MQTT requests (`[mqtt] writable`, queue limits, job
//! timeouts) and are applied at a cycle boundary.
//!
//! With `--mqtt` too, the same core talks to the broker: the face hands
//! the core's publishes to the MQTT link and keeps only the answers to
//! its own requests. Alone, it drops the publishes.
//!
//! The core's alarm reports (`<addr>/alarm`) also become OPC UA events
//! ([`crate::events`]); DP-V1 slaves' I&M0 is read once for their
//! identity ([`crate::identity`]); when a reload (SIGHUP) changes
//! `[mqtt] writable`, the output variables' access levels follow.

use crate::identity::Identities;
use crate::space::{access_levels, Sampler, SlaveNodes, Update};
use profibus_dp::master::DpMaster;
use profibus_fdl::Instant;
use profibus_gateway::topics::Service;
use profibus_gateway::WriteAccess;
use profibus_gateway::{Gateway, LinkSetup, MqttSettings, Properties, Publish, Session};
use std::collections::{HashMap, VecDeque};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};

/// The topic prefix of the answers to the face's own requests; never
/// sent to a broker.
const REPLY_PREFIX: &str = "dpctl-opcua/reply/";

/// A request from an OPC UA session waiting for the next cycle boundary.
struct Job {
    address: u8,
    service: Service,
    body: serde_json::Map<String, serde_json::Value>,
    answer: mpsc::Sender<serde_json::Value>,
}

/// Where the server's callbacks leave requests for the core: shared by
/// the server's sessions and the bus thread.
#[derive(Default)]
pub struct Requests {
    queue: Mutex<VecDeque<Job>>,
}

impl Requests {
    /// Queue a request of `service` on slave `address` with JSON `body`
    /// (the MQTT request payload without `id` and `reply_to`); the
    /// receiver gets the core's answer, `{"ok": …}`.
    pub fn submit(
        &self,
        address: u8,
        service: Service,
        body: serde_json::Map<String, serde_json::Value>,
    ) -> mpsc::Receiver<serde_json::Value> {
        let (tx, rx) = mpsc::channel();
        let job = Job {
            address,
            service,
            body,
            answer: tx,
        };
        self.queue
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push_back(job);
        rx
    }

    fn take(&self) -> Vec<Job> {
        let mut q = self.queue.lock().unwrap_or_else(|e| e.into_inner());
        q.drain(..).collect()
    }
}

/// What the bus thread hands the OPC UA server.
#[derive(Debug)]
pub enum ToServer {
    /// Values that changed.
    Values(Vec<Update>),
    /// An alarm report of the core (the JSON of `<addr>/alarm`) to raise
    /// as an event of slave `address`.
    Alarm {
        /// The station address.
        address: u8,
        /// The report.
        report: serde_json::Value,
    },
    /// New access levels of output variables: writable or not.
    Access(Vec<(opcua::types::NodeId, bool)>),
}

/// The gateway core with its OPC UA face (see the module documentation).
pub struct Face {
    core: Gateway,
    requests: Arc<Requests>,
    sampler: Sampler,
    identities: Identities,
    slaves: Vec<SlaveNodes>,
    writable: Vec<WriteAccess>,
    updates: tokio::sync::mpsc::UnboundedSender<ToServer>,
    waiting: HashMap<u64, mpsc::Sender<serde_json::Value>>,
    next: u64,
    mqtt: bool,
    started: bool,
    out: VecDeque<Publish>,
}

impl Face {
    /// The face of `core`: requests from `requests`, value updates,
    /// events and access levels to `updates`; `identities` reads I&M0,
    /// `slaves` are the nodes of the space; `mqtt`: whether a broker
    /// link also uses the core.
    pub fn new(
        core: Gateway,
        sampler: Sampler,
        identities: Identities,
        slaves: Vec<SlaveNodes>,
        requests: Arc<Requests>,
        updates: tokio::sync::mpsc::UnboundedSender<ToServer>,
        mqtt: bool,
    ) -> Face {
        let writable = core.settings().writable.clone();
        Face {
            core,
            requests,
            sampler,
            identities,
            slaves,
            writable,
            updates,
            waiting: HashMap::new(),
            next: 0,
            mqtt,
            started: false,
            out: VecDeque::new(),
        }
    }

    /// Move the core's publishes on: answers to our requests to their
    /// waiters, the rest to the broker (or nowhere without one).
    fn route(&mut self) {
        while let Some(p) = self.core.poll_publish() {
            if let Some(n) = p.topic.strip_prefix(REPLY_PREFIX) {
                let n = n.parse::<u64>().ok();
                if let Some(tx) = n.and_then(|n| self.waiting.remove(&n)) {
                    let v = serde_json::from_slice(&p.payload).unwrap_or_default();
                    // The caller may have given up waiting.
                    let _ = tx.send(v);
                }
                continue;
            }
            if p.topic.ends_with("/alarm") {
                self.alarm(&p);
            }
            if self.mqtt {
                self.out.push_back(p);
            }
        }
    }

    /// An alarm report of the core, `<base>/<addr>/alarm`, as an event.
    fn alarm(&mut self, p: &Publish) {
        let Ok(report) = serde_json::from_slice::<serde_json::Value>(&p.payload) else {
            return;
        };
        let Some(address) = report["slave"].as_u64().and_then(|a| u8::try_from(a).ok()) else {
            return;
        };
        // The server may be gone while the bus stops.
        let _ = self.updates.send(ToServer::Alarm { address, report });
    }

    /// After a reload of `[mqtt]`: the access levels that `writable`
    /// gives now.
    fn follow_writable(&mut self) {
        let now = &self.core.settings().writable;
        if *now == self.writable {
            return;
        }
        self.writable = now.clone();
        let levels = access_levels(&self.slaves, now);
        tracing::info!("OPC UA access levels follow the reloaded `writable`");
        let _ = self.updates.send(ToServer::Access(levels));
    }

    fn take_requests(&mut self, ts_ms: u64) {
        for job in self.requests.take() {
            let n = self.next;
            self.next += 1;
            let mut body = job.body;
            body.insert("reply_to".into(), format!("{REPLY_PREFIX}{n}").into());
            let s = self.core.settings();
            let topic = format!(
                "{}/{}/{}/{}",
                s.prefix,
                s.bus,
                job.address,
                job.service.request()
            );
            self.waiting.insert(n, job.answer);
            let payload = serde_json::Value::Object(body).to_string();
            self.core.handle_message(&topic, payload.as_bytes(), ts_ms);
            self.route();
        }
    }
}

impl Session for Face {
    fn settings(&self) -> &MqttSettings {
        self.core.settings()
    }

    fn settings_mut(&mut self) -> &mut MqttSettings {
        Session::settings_mut(&mut self.core)
    }

    /// The core's reload (its report-by-exception filters retuned); the
    /// access levels follow at the next [`step`](Session::step).
    fn reload(&mut self, settings: MqttSettings) {
        self.core.reload(settings);
    }

    fn link_setup(&self) -> LinkSetup {
        Session::link_setup(&self.core)
    }

    fn connected(&mut self, ts_ms: u64) {
        self.core.connected(ts_ms);
    }

    fn disconnected(&mut self, ts_ms: u64) {
        self.core.disconnected(ts_ms);
    }

    fn handle_message_with(&mut self, topic: &str, payload: &[u8], props: &Properties, ts_ms: u64) {
        self.core.handle_message_with(topic, payload, props, ts_ms);
        self.route();
    }

    fn step(&mut self, m: &mut DpMaster, now: Instant, ts_ms: u64) {
        if !self.started {
            self.started = true;
            if !self.mqtt {
                // No broker: the core answers at once, never "offline".
                self.core.connected(ts_ms);
            }
        }
        self.follow_writable();
        self.take_requests(ts_ms);
        self.core.step(m, now, ts_ms);
        self.route();
        let mut updates = self.sampler.sample(m, ts_ms);
        updates.extend(self.identities.step(m, now, ts_ms));
        if !updates.is_empty() {
            // The server may be gone while the bus stops.
            let _ = self.updates.send(ToServer::Values(updates));
        }
    }

    fn poll_publish(&mut self) -> Option<Publish> {
        self.route();
        self.out.pop_front()
    }

    fn last_will(&self) -> Publish {
        self.core.last_will()
    }
}
