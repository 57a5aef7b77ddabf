//! Sparkplug B mode: the DP master as a Sparkplug edge node, each slave
//! in Data_Exchange as one of its devices (`dpctl gateway --sparkplug
//! GROUP/EDGE`, or `sparkplug = "GROUP/EDGE"` in the bus file's `[mqtt]`
//! table).
//!
//! An NBIRTH on every connection, a DBIRTH when a slave enters
//! Data_Exchange, DDATA with the metrics that changed, DDEATH when it
//! leaves, NDEATH as the last will; DCMD writes outputs, NCMD asks for a
//! rebirth. Topics, metrics, datatypes, QoS, `seq` and `bdSeq`, and what
//! is not supported: `docs/gateway.md` in the repository. The broker
//! outage and the outputs' safe state: [`crate::outage`].

pub mod metrics;
pub mod proto;
pub mod template;

pub use crate::topics::{IdError, MessageType, SparkplugId, NAMESPACE};

use crate::alerts::AlertWatch;
use crate::outage::Outage;
use crate::session::{LinkSetup, Properties, Publish, Session};
use crate::settings::MqttSettings;
use crate::slave::{slave_infos, SlaveInfo, SlaveInfoError};
use crate::traffic::{ImageFilter, Traffic};
use metrics::{CommandError, Device, OutputWrite};
use profibus_devices::bus::ProfiledBus;
use profibus_devices::channels::Direction;
use profibus_dp::master::{AlarmReport, DpMaster, MasterEvent, SlaveState};
use profibus_fdl::Instant;
use prost::Message;
use proto::{DataType, Metric, MetricValue, Payload};
use std::collections::VecDeque;

/// The node metric that asks for a rebirth.
pub const REBIRTH: &str = "Node Control/Rebirth";
/// The birth/death sequence metric.
pub const BD_SEQ: &str = "bdSeq";
/// Node metric: the master's operating state (`operate`, `clear`,
/// `stop`), String.
pub const BUS_STATE: &str = "Bus/State";
/// Node metric: the mean poll cycle time since the last report, in ms,
/// Double.
pub const CYCLE_TIME: &str = "Bus/Cycle Time";
/// Node metric: the slaves in Data_Exchange, UInt8.
pub const IN_DATA_EXCHANGE: &str = "Bus/Slaves In Data Exchange";
/// Node metric: layer-2 request repetitions of all slaves, UInt64.
pub const RETRIES: &str = "Bus/Retries";
/// Node metric: requests without an answer, all slaves, UInt64.
pub const ERRORS: &str = "Bus/Errors";
/// Node metric: start-ups begun again, all slaves, UInt64.
pub const RESTARTS: &str = "Bus/Restarts";
/// Node metric: the last alert of the `[mqtt] alerts` rules, String, the
/// JSON of `<prefix>/<bus>/alert` (`""` before the first); each alert
/// goes out at once in an NDATA of its own.
pub const ALERT: &str = "Bus/Alert";

/// The node metrics after `bdSeq`, in birth order, with their datatypes;
/// each one's alias is its index.
const NODE_METRICS: [(&str, DataType); 8] = [
    (REBIRTH, DataType::Boolean),
    (BUS_STATE, DataType::String),
    (CYCLE_TIME, DataType::Double),
    (IN_DATA_EXCHANGE, DataType::UInt8),
    (RETRIES, DataType::UInt64),
    (ERRORS, DataType::UInt64),
    (RESTARTS, DataType::UInt64),
    (ALERT, DataType::String),
];

/// The alias of metric `index` of the device of slave `address`: unique
/// in the edge node (the node's metrics are 0..=7).
pub fn device_alias(address: u8, index: usize) -> u64 {
    ((address as u64 + 1) << 16) | index as u64
}

/// The topic of a primary host application's state,
/// `spBv1.0/STATE/<host id>` (Sparkplug 3.0).
pub fn state_topic(host: &str) -> String {
    format!("{NAMESPACE}/STATE/{host}")
}

/// The devices of a bus file's slaves: channels from the device
/// profiles, or one byte per GSD module.
pub fn devices(profiled: &ProfiledBus) -> Result<Vec<Device>, SlaveInfoError> {
    // `slave_infos` gives every slave channels: its profile's, or its
    // modules' bytes.
    let infos = slave_infos(profiled)?;
    Ok(infos
        .into_iter()
        .map(|info| {
            let mut d = Device::of_info(info);
            // A device profile names the type; the generic one is its GSD's.
            if let Some(p) = profiled.profile(d.info.layout.address) {
                if p.name() != "generic" {
                    d.kind = p.name().to_string();
                }
            }
            d
        })
        .collect())
}

/// What the edge node knows of one device.
#[derive(Debug)]
struct Entry {
    device: Device,
    /// Born (DBIRTH sent, no DDEATH since), with the values last sent.
    born: Option<Vec<Option<MetricValue>>>,
    /// Report by exception of the input and output images.
    filters: [ImageFilter; 2],
    /// Its template definition (an index into `EdgeNode::definitions`),
    /// if it has channels.
    template: Option<usize>,
}

/// A checked DCMD waiting for the next cycle boundary.
#[derive(Debug)]
struct Pending {
    address: u8,
    write: OutputWrite,
}

/// The DP master as a Sparkplug B edge node (sans-IO, like
/// [`crate::Gateway`]): drive it through [`Session`] at the master's
/// cycle boundaries.
#[derive(Debug)]
pub struct EdgeNode {
    settings: MqttSettings,
    id: SparkplugId,
    devices: Vec<Entry>,
    pending: Vec<Pending>,
    out: VecDeque<Publish>,
    online: bool,
    /// An NBIRTH is due (new connection or rebirth request).
    birth_due: bool,
    bd_seq: u8,
    seq: u8,
    /// The broker outage and the outputs' safe state.
    outage: Outage,
    /// The primary host application is online (always, without one).
    host_online: bool,
    /// The timestamp of the last STATE message taken.
    host_ts: u64,
    /// The node metrics last sent (`None`: no NBIRTH yet).
    node_sent: Option<Vec<Option<MetricValue>>>,
    /// When the next NDATA may go out (ms).
    next_ndata_ms: u64,
    /// Cycles and their summed time at the last node report.
    cycles_at: (u64, u64),
    /// The alert rules' interval statistics.
    alerts: AlertWatch,
    /// The JSON of the last alert (`Bus/Alert`).
    last_alert: String,
    /// The template definitions of the devices' types (published with
    /// `sparkplug_templates`).
    definitions: Vec<template::Definition>,
}

/// A metric of a data message: its alias only, no name, no datatype (the
/// birth has them).
fn data_metric(alias: u64, datatype: DataType, value: Option<MetricValue>, ts: u64) -> Metric {
    Metric {
        name: None,
        alias: Some(alias),
        datatype: None,
        ..metric("", datatype, value, ts)
    }
}

fn metric(name: &str, datatype: DataType, value: Option<MetricValue>, ts: u64) -> Metric {
    Metric {
        name: Some(name.into()),
        timestamp: Some(ts),
        datatype: Some(datatype.code()),
        is_null: value.is_none().then_some(true),
        value,
        ..Default::default()
    }
}

/// The NDEATH payload with `bd_seq`: one metric, no `seq`.
fn ndeath(bd_seq: u8) -> Vec<u8> {
    Payload {
        metrics: vec![Metric {
            name: Some(BD_SEQ.into()),
            datatype: Some(DataType::Int64.code()),
            value: Some(MetricValue::LongValue(bd_seq as u64)),
            ..Default::default()
        }],
        ..Default::default()
    }
    .encode_to_vec()
}

impl EdgeNode {
    /// An edge node `id` for these devices.
    pub fn new(settings: MqttSettings, id: SparkplugId, devices: Vec<Device>) -> EdgeNode {
        let (definitions, of) = template::definitions(&devices);
        EdgeNode {
            id,
            devices: devices
                .into_iter()
                .zip(of)
                .map(|(device, template)| {
                    let t = Traffic::of(&settings, &device.info);
                    Entry {
                        filters: [
                            t.filter(&device.info, Direction::Input),
                            t.filter(&device.info, Direction::Output),
                        ],
                        device,
                        born: None,
                        template,
                    }
                })
                .collect(),
            definitions,
            settings,
            pending: vec![],
            out: VecDeque::new(),
            online: false,
            birth_due: false,
            bd_seq: 0,
            seq: 0,
            outage: Outage::default(),
            host_online: false,
            host_ts: 0,
            node_sent: None,
            next_ndata_ms: 0,
            cycles_at: (0, 0),
            alerts: AlertWatch::new(),
            last_alert: String::new(),
        }
    }

    /// The primary host application's STATE (Sparkplug 3.0: JSON
    /// `{"online": bool, "timestamp": ms}`, retained). One older than
    /// the last taken is ignored. Offline: births and data are held (no
    /// device is born any more); online again: a rebirth (NBIRTH, every
    /// DBIRTH).
    fn host_state(&mut self, payload: &[u8]) {
        #[derive(serde::Deserialize)]
        struct State {
            online: bool,
            timestamp: Option<u64>,
        }
        let s: State = match serde_json::from_slice(payload) {
            Ok(s) => s,
            Err(e) => {
                return tracing::warn!(error = %e, "primary host STATE is not {{\"online\", \"timestamp\"}}")
            }
        };
        let ts = s.timestamp.unwrap_or(0);
        if ts < self.host_ts {
            return tracing::debug!(ts, "an older primary host STATE ignored");
        }
        self.host_ts = ts;
        match (s.online, self.host_online) {
            (true, false) => {
                tracing::info!("primary host application online: rebirth");
                self.host_online = true;
                self.birth_due = true;
            }
            (false, true) => {
                tracing::warn!("primary host application offline: data held");
                self.host_online = false;
                self.node_sent = None;
                for e in &mut self.devices {
                    e.born = None;
                }
            }
            _ => {}
        }
    }

    /// Whether births and data may go out: no primary host configured,
    /// or it is online.
    fn may_publish(&self) -> bool {
        self.settings.primary_host.is_none() || self.host_online
    }

    /// The values of the node metrics ([`NODE_METRICS`]) now; the cycle
    /// time since the last call.
    fn node_values(&mut self, m: &DpMaster) -> Vec<Option<MetricValue>> {
        let c = m.cycle_stats();
        let (cycles, sum) = (
            c.cycles.saturating_sub(self.cycles_at.0),
            c.sum_ns.saturating_sub(self.cycles_at.1),
        );
        self.cycles_at = (c.cycles, c.sum_ns);
        let cycle_ms = match (cycles, &self.node_sent) {
            (0, Some(last)) => last[2].clone(),
            (0, None) => None,
            _ => Some(MetricValue::DoubleValue(
                (sum as f64 / cycles as f64 / 1e4).round() / 100.0,
            )),
        };
        let (mut exchanging, mut stats) = (0u32, [0u64; 3]);
        for e in &self.devices {
            let a = e.device.info.layout.address;
            if let Some(h) = m.handle(a) {
                exchanging += (m.slave(h).state == SlaveState::DataExchange) as u32;
            }
            if let Some(s) = m.slave_stats(a) {
                stats[0] += s.retries;
                stats[1] += s.errors;
                stats[2] += s.restarts;
            }
        }
        vec![
            Some(MetricValue::BooleanValue(false)),
            Some(MetricValue::StringValue(
                m.operating_state().as_str().into(),
            )),
            cycle_ms,
            Some(MetricValue::IntValue(exchanging)),
            Some(MetricValue::LongValue(stats[0])),
            Some(MetricValue::LongValue(stats[1])),
            Some(MetricValue::LongValue(stats[2])),
            Some(MetricValue::StringValue(self.last_alert.clone())),
        ]
    }

    /// An NDATA with the node metrics that changed: at once for the
    /// master's state, else at most every `interval_ms`.
    fn ndata(&mut self, m: &DpMaster, ts: u64) {
        let Some(last) = self.node_sent.clone() else {
            return;
        };
        let state_changed = last[1].as_ref()
            != Some(&MetricValue::StringValue(
                m.operating_state().as_str().into(),
            ));
        if !state_changed && ts < self.next_ndata_ms {
            return;
        }
        self.next_ndata_ms = ts + self.settings.interval.as_millis() as u64;
        let values = self.node_values(m);
        let changed: Vec<Metric> = NODE_METRICS
            .iter()
            .zip(values.iter().zip(&last))
            .enumerate()
            .filter(|(_, (_, (now, before)))| now != before)
            .map(|(i, ((_, dt), (now, _)))| data_metric(i as u64, *dt, now.clone(), ts))
            .collect();
        if !changed.is_empty() {
            self.push(self.id.node_topic(MessageType::NData), changed, ts);
            self.node_sent = Some(values);
        }
    }

    /// An edge node for slaves described by [`SlaveInfo`]s only (slaves
    /// without named channels get none).
    pub fn from_infos(settings: MqttSettings, id: SparkplugId, infos: Vec<SlaveInfo>) -> EdgeNode {
        let devices = infos.into_iter().map(Device::of_info).collect();
        EdgeNode::new(settings, id, devices)
    }

    /// The group and edge node id.
    pub fn id(&self) -> &SparkplugId {
        &self.id
    }

    /// The bdSeq of the current (or next) connection.
    pub fn bd_seq(&self) -> u8 {
        self.bd_seq
    }

    fn next_seq(&mut self) -> u64 {
        let s = self.seq;
        self.seq = self.seq.wrapping_add(1);
        s as u64
    }

    fn push(&mut self, topic: String, metrics: Vec<Metric>, ts: u64) {
        let payload = Payload {
            timestamp: Some(ts),
            metrics,
            seq: Some(self.next_seq()),
            ..Default::default()
        };
        self.out
            .push_back(Publish::new(topic, payload.encode_to_vec(), false));
    }

    fn nbirth(&mut self, m: &DpMaster, ts: u64) {
        self.seq = 0;
        let mut metrics = vec![metric(
            BD_SEQ,
            DataType::Int64,
            Some(MetricValue::LongValue(self.bd_seq as u64)),
            ts,
        )];
        let values = self.node_values(m);
        for (i, ((name, dt), v)) in NODE_METRICS.iter().zip(&values).enumerate() {
            metrics.push(Metric {
                alias: Some(i as u64),
                ..metric(name, *dt, v.clone(), ts)
            });
        }
        self.node_sent = Some(values);
        self.next_ndata_ms = ts + self.settings.interval.as_millis() as u64;
        if self.settings.sparkplug_templates {
            metrics.extend(self.definitions.iter().map(|d| d.metric(ts)));
        }
        self.push(self.id.node_topic(MessageType::NBirth), metrics, ts);
        for e in &mut self.devices {
            e.born = None;
        }
    }

    /// The edge node's response to a command payload on `topic`
    /// (NCMD: rebirth; DCMD: output writes, applied at the next step).
    fn command(&mut self, topic: &str, payload: &[u8]) -> Result<(), CommandError> {
        let ncmd = self.id.node_topic(MessageType::NCmd);
        let dcmd = self.id.node_topic(MessageType::DCmd);
        let p = Payload::decode(payload).map_err(|e| CommandError::Decode(e.to_string()))?;
        if topic == ncmd {
            for m in &p.metrics {
                // By name, or by its alias from the NBIRTH (0).
                let name = m
                    .name
                    .as_deref()
                    .or((m.alias == Some(0)).then_some(REBIRTH));
                match (name, &m.value) {
                    (Some(REBIRTH), Some(MetricValue::BooleanValue(true))) => {
                        tracing::info!("Sparkplug rebirth requested");
                        self.birth_due = true;
                    }
                    (name, _) => tracing::warn!(?name, "NCMD metric ignored"),
                }
            }
            return Ok(());
        }
        let Some(device) = topic
            .strip_prefix(dcmd.as_str())
            .and_then(|r| r.strip_prefix('/'))
        else {
            return Ok(());
        };
        let Some(e) = self.devices.iter().find(|e| e.device.id() == device) else {
            return Err(CommandError::UnknownDevice(device.into()));
        };
        let address = e.device.info.layout.address;
        let access = self
            .settings
            .access(address)
            .ok_or(CommandError::Unauthorised(address))?;
        // Template instances as their members; metrics by alias: named
        // as in the DBIRTH.
        let named: Vec<Metric> = template::expand(address, &p.metrics)
            .iter()
            .map(|m| match (&m.name, m.alias) {
                (None, Some(alias)) if alias >> 16 == address as u64 + 1 => Metric {
                    name: e
                        .device
                        .metrics
                        .get((alias & 0xFFFF) as usize)
                        .map(|d| d.name.clone()),
                    ..m.clone()
                },
                _ => m.clone(),
            })
            .collect();
        let write = e.device.check_command(&named)?;
        if let Some(allowed) = &access.channels {
            let refused = match &write.image {
                Some(_) => Some(metrics::OUTPUT_IMAGE.to_string()),
                None => write
                    .channels
                    .iter()
                    .find(|(n, _)| !allowed.contains(n))
                    .map(|(n, _)| n.clone()),
            };
            if let Some(name) = refused {
                return Err(CommandError::NotWritable {
                    device: device.into(),
                    name,
                });
            }
        }
        self.pending.push(Pending { address, write });
        Ok(())
    }

    fn apply(m: &mut DpMaster, p: &Pending, device: &Device) -> Result<(), CommandError> {
        let Some(current) = m.outputs(p.address) else {
            return Err(CommandError::UnknownDevice(p.address.to_string()));
        };
        let mut img = p.write.image.clone().unwrap_or_else(|| current.to_vec());
        if img.len() != current.len() {
            return Err(CommandError::Value {
                device: device.id(),
                name: metrics::OUTPUT_IMAGE.into(),
                problem: format!("the slave has {} output bytes", current.len()),
            });
        }
        device
            .channels
            .write_outputs(
                p.write.channels.iter().map(|(n, v)| (n.as_str(), *v)),
                &mut img,
            )
            .map_err(|e| CommandError::Value {
                device: device.id(),
                name: "Outputs".into(),
                problem: e.to_string(),
            })?;
        m.set_outputs(p.address, &img);
        Ok(())
    }

    /// Queue what changed: an NBIRTH when due, then per device a DBIRTH
    /// on entering Data_Exchange, a DDEATH on leaving it, a DDATA with
    /// the metrics that changed.
    fn publish_changes(&mut self, m: &DpMaster, ts: u64) {
        if !self.may_publish() {
            // Held while the primary host application is offline.
            return;
        }
        if self.birth_due {
            self.birth_due = false;
            self.nbirth(m, ts);
        }
        self.ndata(m, ts);
        for i in 0..self.devices.len() {
            let addr = self.devices[i].device.info.layout.address;
            let Some(h) = m.handle(addr) else { continue };
            let v = m.slave(h);
            let exchanging = v.state == SlaveState::DataExchange;
            // Report by exception: whether each image is due (the image
            // metrics of a DDATA wait for it).
            let due = {
                let f = &mut self.devices[i].filters;
                [f[0].due(v.inputs, ts), f[1].due(v.outputs, ts)]
            };
            let dev = &self.devices[i].device;
            let def = (self.devices[i].template)
                .filter(|_| self.settings.sparkplug_templates)
                .map(|t| &self.definitions[t]);
            let topic = |t| self.id.device_topic(t, &dev.id());
            match (&self.devices[i].born, exchanging) {
                (None, true) => {
                    let values = dev.values(&v);
                    let metrics = template::birth(dev, def, &values, ts);
                    let t = topic(MessageType::DBirth);
                    self.push(t, metrics, ts);
                    let e = &mut self.devices[i];
                    e.born = Some(values);
                    e.filters[0].published(v.inputs, ts);
                    e.filters[1].published(v.outputs, ts);
                }
                (Some(_), false) => {
                    let t = topic(MessageType::DDeath);
                    self.push(t, vec![], ts);
                    self.devices[i].born = None;
                }
                (Some(last), true) => {
                    let mut values = dev.values(&v);
                    for (k, d) in dev.metrics.iter().enumerate() {
                        let held = match d.image(&dev.channels) {
                            Some(Direction::Input) => !due[0],
                            Some(Direction::Output) => !due[1],
                            None => false,
                        };
                        if held {
                            values[k] = last[k].clone();
                        }
                    }
                    let changed: Vec<_> = (values.iter().zip(last))
                        .enumerate()
                        .filter(|(_, (now, before))| now != before)
                        .map(|(k, (now, _))| (k, now.clone()))
                        .collect();
                    let changed = template::data(dev, def, changed, ts);
                    let t = topic(MessageType::DData);
                    let e = &mut self.devices[i];
                    if due[0] {
                        e.filters[0].published(v.inputs, ts);
                    }
                    if due[1] {
                        e.filters[1].published(v.outputs, ts);
                    }
                    if !changed.is_empty() {
                        self.push(t, changed, ts);
                        self.devices[i].born = Some(values);
                    }
                }
                (None, false) => {}
            }
        }
    }
}

impl Session for EdgeNode {
    fn settings(&self) -> &MqttSettings {
        &self.settings
    }
    fn settings_mut(&mut self) -> &mut MqttSettings {
        &mut self.settings
    }
    fn reload(&mut self, settings: MqttSettings) {
        for e in &mut self.devices {
            let t = Traffic::of(&settings, &e.device.info);
            let [fin, fout] = &mut e.filters;
            fin.retune(t.filter(&e.device.info, Direction::Input));
            fout.retune(t.filter(&e.device.info, Direction::Output));
        }
        self.settings = settings;
    }

    /// QoS 0 for everything but the will (QoS 1); subscribed to NCMD and
    /// DCMD; the will is the NDEATH with the bdSeq of each attempt.
    fn link_setup(&self) -> LinkSetup {
        let mut bd = self.bd_seq;
        LinkSetup {
            qos: 0,
            will_qos: 1,
            filters: [
                self.id.node_topic(MessageType::NCmd),
                self.id.device_topic(MessageType::DCmd, "+"),
            ]
            .into_iter()
            .chain(self.settings.primary_host.as_deref().map(state_topic))
            .collect(),
            will: Box::new({
                let topic = self.id.node_topic(MessageType::NDeath);
                move || {
                    let p = Publish::new(topic.clone(), ndeath(bd), false);
                    bd = bd.wrapping_add(1);
                    p
                }
            }),
        }
    }

    /// The NBIRTH is due; with a primary host application it waits for
    /// its STATE (retained: the broker sends it on subscribing).
    fn connected(&mut self, _ts_ms: u64) {
        self.outage.connected();
        self.online = true;
        self.birth_due = true;
        self.host_online = false;
    }

    /// Every lost connection or failed attempt: the next CONNECT carries
    /// the next bdSeq.
    fn disconnected(&mut self, ts_ms: u64) {
        self.outage.disconnected(self.online, ts_ms);
        self.online = false;
        self.birth_due = false;
        self.out.clear();
        self.bd_seq = self.bd_seq.wrapping_add(1);
        self.node_sent = None;
        for e in &mut self.devices {
            e.born = None;
        }
    }

    /// NCMD and DCMD; with a primary host application its STATE. (MQTT
    /// 3.1.1 only: no properties.)
    fn handle_message_with(
        &mut self,
        topic: &str,
        payload: &[u8],
        _props: &Properties,
        _ts_ms: u64,
    ) {
        if let Some(host) = &self.settings.primary_host {
            if topic == state_topic(host) {
                return self.host_state(payload);
            }
        }
        if let Err(e) = self.command(topic, payload) {
            tracing::warn!(topic, error = %e, "Sparkplug command refused");
        }
    }

    /// Apply the pending DCMD writes (each to one slave's whole image at
    /// once), put the outputs into the safe state after `outputs_timeout`
    /// without a broker (see [`crate::outage`]), then queue births,
    /// deaths and data.
    fn step(&mut self, m: &mut DpMaster, now: Instant, ts_ms: u64) {
        while let Some(ev) = m.poll_event() {
            match ev {
                MasterEvent::Fault { address, reason } => {
                    tracing::warn!(address, %reason, "slave fault");
                }
                MasterEvent::Alarm { address, alarm } => {
                    // The metric of its type: sent with the next DDATA.
                    let Some(e) = self
                        .devices
                        .iter_mut()
                        .find(|e| e.device.info.layout.address == address)
                    else {
                        continue;
                    };
                    let d = &mut e.device;
                    let report = AlarmReport::new(address, &alarm, d.info.layout.gsd.as_ref());
                    let json = serde_json::to_string(&report).expect("alarms serialise");
                    d.alarms.insert(alarm.alarm_type.word(), json);
                }
                _ => {}
            }
        }
        for p in std::mem::take(&mut self.pending) {
            let Some(e) = self
                .devices
                .iter()
                .find(|e| e.device.info.layout.address == p.address)
            else {
                continue;
            };
            match Self::apply(m, &p, &e.device) {
                Ok(()) => tracing::info!(address = p.address, "Sparkplug DCMD applied"),
                Err(e) => tracing::warn!(address = p.address, error = %e, "Sparkplug DCMD refused"),
            }
        }
        self.outage.step(&self.settings, self.online, m, ts_ms);
        for a in self.alerts.step(&self.settings, m, now) {
            self.last_alert = serde_json::to_string(&a).expect("alerts serialise");
            let value = Some(MetricValue::StringValue(self.last_alert.clone()));
            let i = NODE_METRICS.len() - 1;
            if let (true, Some(sent)) = (self.online, &mut self.node_sent) {
                sent[i] = value.clone();
                let metric = data_metric(i as u64, DataType::String, value, ts_ms);
                self.push(self.id.node_topic(MessageType::NData), vec![metric], ts_ms);
            }
        }
        if self.online {
            self.publish_changes(m, ts_ms);
        }
    }

    fn poll_publish(&mut self) -> Option<Publish> {
        self.out.pop_front()
    }

    /// The NDEATH of the current connection.
    fn last_will(&self) -> Publish {
        Publish::new(
            self.id.node_topic(MessageType::NDeath),
            ndeath(self.bd_seq),
            false,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_values_are_twos_complement() {
        let v = encode_value(DataType::Int16, Value::Int(-2)).unwrap();
        assert_eq!(v, MetricValue::IntValue(0xFFFF_FFFE));
        assert_eq!(decode_value(DataType::Int16, &v), Some(Value::Int(-2)));
        assert_eq!(
            decode_value(DataType::UInt32, &MetricValue::IntValue(0xFFFF_FFFE)),
            Some(Value::Int(0xFFFF_FFFE))
        );
        assert_eq!(
            decode_value(DataType::UInt8, &MetricValue::StringValue("1".into())),
            None
        );
    }

    use metrics::{decode_value, encode_value};
    use profibus_devices::channels::Value;
}
