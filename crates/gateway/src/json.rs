//! The plain JSON core, [`Gateway`]: sans-IO, topics and payloads from a
//! DP master's slaves, and writes and requests from MQTT messages. No
//! broker, no clock: the driver hands in messages and the time, and
//! sends what [`Gateway::poll_publish`] returns.

use crate::alerts::{self, AlertWatch};
use crate::outage::Outage;
use crate::payload::{
    hex, to_bytes, AlarmPayload, Answer, AnswerData, DiagPayload, ImagePayload, OutputsTimeout,
    SlaveStatePayload, Status,
};
use crate::request::{parse_request, OutputWrite, ReplyTo, Request, RequestError, QUEUE_LIMIT};
use crate::session::{LinkSetup, Properties, Publish, Session};
use crate::settings::{MqttSettings, PublishMode};
use crate::slave::SlaveInfo;
use crate::topics::{Service, SlaveTopic, Topics};
use crate::traffic::{ImageFilter, Traffic};
use profibus_devices::channels::{Direction, OutputWriteError};
use profibus_devices::pkw::client::PkwClient;
use profibus_devices::pkw::{self, PKW_LEN};
use profibus_devices::rfid::client::RfidClient;
use profibus_dp::master::{
    AlarmReport, DpMaster, Job, JobId, JobResult, MasterEvent, OperatingState, SlaveHandle,
    SlaveState,
};
use profibus_fdl::Instant;
use std::collections::VecDeque;

/// The last published state of a slave.
#[derive(Debug, Default, Clone)]
struct Published {
    state: Option<SlaveState>,
    inputs: Option<Vec<u8>>,
    outputs: Option<Vec<u8>>,
    diag: Option<Vec<u8>>,
}

/// Where an answer goes: service, slave, id, topic.
#[derive(Debug, Clone)]
struct Target {
    service: Service,
    address: u8,
    to: ReplyTo,
}

/// A PKW or RFID job waiting for the slave's client.
#[derive(Debug)]
struct Queued {
    request: Request,
    target: Target,
}

#[derive(Debug)]
struct Entry {
    info: SlaveInfo,
    published: Published,
    fault: Option<String>,
    /// Output writes and DP-V1 jobs for the next step.
    pending: VecDeque<Queued>,
    /// PKW or RFID jobs waiting for the client.
    queue: VecDeque<Queued>,
    pkw: Option<PkwClient>,
    rfid: Option<RfidClient>,
    /// The job the client runs.
    running: Option<Target>,
    /// Report by exception of the input and output images.
    filters: [ImageFilter; 2],
}

/// An answer's body: the result's fields on success, the error otherwise.
type Outcome = Result<Option<AnswerData>, RequestError>;

/// The gateway between one DP master and one MQTT broker.
///
/// Drive it from the master's application step (between two polls of the
/// master, i.e. at a cycle boundary): [`Gateway::handle_message`] for each
/// message received, [`Gateway::step`] with the master, then send
/// everything [`Gateway::poll_publish`] returns. After each (re)connection
/// call [`Gateway::connected`]: the status and every retained topic are
/// published again; after a loss [`Gateway::disconnected`].
#[derive(Debug)]
pub struct Gateway {
    settings: MqttSettings,
    topics: Topics,
    slaves: Vec<Entry>,
    /// DP-V1 jobs the master runs.
    jobs: Vec<(JobId, Target)>,
    out: VecDeque<Publish>,
    next_interval_ms: u64,
    online: bool,
    /// The master state in the last status published (`None`: due).
    status_master: Option<OperatingState>,
    /// The broker outage and the outputs' safe state.
    outage: Outage,
    /// The alert rules' interval statistics.
    alerts: AlertWatch,
}

impl Gateway {
    /// A gateway for these slaves.
    pub fn new(settings: MqttSettings, slaves: Vec<SlaveInfo>) -> Gateway {
        let timeout = settings.job_timeout;
        Gateway {
            topics: Topics::new(&settings.prefix, &settings.bus),
            slaves: slaves
                .into_iter()
                .map(|info| Entry {
                    filters: {
                        let t = Traffic::of(&settings, &info);
                        [
                            t.filter(&info, Direction::Input),
                            t.filter(&info, Direction::Output),
                        ]
                    },
                    pkw: info.pkw.map(|d| PkwClient::new(d, timeout)),
                    rfid: info.rfid().then(|| RfidClient::new(timeout)),
                    info,
                    published: Published::default(),
                    fault: None,
                    pending: VecDeque::new(),
                    queue: VecDeque::new(),
                    running: None,
                })
                .collect(),
            settings,
            jobs: vec![],
            out: VecDeque::new(),
            next_interval_ms: 0,
            online: false,
            status_master: None,
            outage: Outage::default(),
            alerts: AlertWatch::new(),
        }
    }

    /// The settings.
    pub fn settings(&self) -> &MqttSettings {
        &self.settings
    }

    /// The topics.
    pub fn topics(&self) -> &Topics {
        &self.topics
    }

    /// The last will to register when connecting: the status, offline,
    /// retained.
    pub fn last_will(&self) -> Publish {
        Publish::new(self.topics.status(), to_bytes(&Status::Offline), true)
    }

    /// The broker accepted the connection: at the next [`Gateway::step`]
    /// the status (online) and every retained slave topic are published.
    pub fn connected(&mut self, _ts_ms: u64) {
        self.online = true;
        self.outage.connected();
        self.status_master = None;
        for e in &mut self.slaves {
            e.published = Published::default();
            e.filters.iter_mut().for_each(ImageFilter::reset);
        }
    }

    /// The connection was lost at `ts_ms`: nothing is queued until
    /// [`Gateway::connected`]; after `outputs_timeout` the safe state.
    pub fn disconnected(&mut self, ts_ms: u64) {
        self.outage.disconnected(self.online, ts_ms);
        self.online = false;
        self.out.clear();
    }

    fn push(&mut self, topic: String, payload: &impl serde::Serialize, retain: bool) {
        let props = self.properties(retain, vec![]);
        self.push_with(topic, to_bytes(payload), retain, props);
    }

    fn push_with(&mut self, topic: String, payload: Vec<u8>, retain: bool, props: Properties) {
        if self.online {
            self.out.push_back(Publish {
                topic,
                payload,
                retain,
                props,
            });
        }
    }

    /// The MQTT 5 properties of a message: `user`, the content type
    /// `application/json` and the payload format UTF-8, and the message
    /// expiry interval when it is not retained (a retained message is the
    /// topic's current value: with report by exception a steady value is
    /// not published again, so it must not expire).
    fn properties(&self, retain: bool, user: Vec<(String, String)>) -> Properties {
        Properties {
            user,
            message_expiry_s: self.settings.message_expiry_s.filter(|_| !retain),
            content_type: Some(crate::request::JSON.into()),
            utf8: true,
            ..Properties::default()
        }
    }

    fn answer(&mut self, t: Target, outcome: Outcome, ts_ms: u64) {
        let (data, error) = match outcome {
            Ok(data) => (data, None),
            Err(e) => {
                tracing::warn!(address = t.address, service = t.service.request(), error = %e, "MQTT request refused or failed");
                (None, Some(e.to_string()))
            }
        };
        let a = Answer {
            ok: error.is_none(),
            error,
            data,
            id: t.to.id,
            ts: ts_ms,
        };
        let topic = t.to.topic.unwrap_or_else(|| {
            self.topics
                .slave(t.address, SlaveTopic::Response(t.service))
        });
        let props = Properties {
            correlation_data: t.to.correlation_data,
            ..self.properties(false, vec![])
        };
        self.push_with(topic, to_bytes(&a), false, props);
    }

    /// Check `request` for slave `address` against the configuration and
    /// the permissions.
    fn check(&self, address: u8, request: &Request) -> Result<(), RequestError> {
        let Some(entry) = self
            .slaves
            .iter()
            .find(|e| e.info.layout.address == address)
        else {
            return Err(RequestError::UnknownSlave(address.to_string()));
        };
        let unsupported = |what| Err(RequestError::Unsupported { address, what });
        match request {
            Request::Dpv1Read { .. } | Request::Dpv1Write { .. } if !entry.info.layout.dpv1 => {
                return unsupported("DP-V1 (`dpv1 = true` in the bus file)")
            }
            Request::Pkw { .. } | Request::PkwNamed { .. } if entry.info.pkw.is_none() => {
                return unsupported("PKW channel")
            }
            Request::Rfid(_) if !entry.info.rfid() => return unsupported("RFID reader handshake"),
            _ => {}
        }
        if !request.writes() {
            return Ok(());
        }
        let access = self
            .settings
            .access(address)
            .ok_or(RequestError::Unauthorised(address))?;
        let allowed = access.channels.as_deref();
        match (request, allowed) {
            (Request::Outputs(w), _) => w.check(address, entry.info.channels.as_ref(), allowed)?,
            // Channel access only: no other writes.
            (_, Some(allowed)) => {
                return Err(OutputWriteError::ChannelsOnly {
                    address,
                    allowed: allowed.to_vec(),
                }
                .into())
            }
            (_, None) => {}
        }
        Ok(())
    }

    /// A PKW request by name as one by number: the device profile's
    /// parameter of that name ([`profibus_devices::pkw_parameter`]).
    fn resolve(&self, address: u8, r: Request) -> Result<Request, RequestError> {
        let Request::PkwNamed { name, command } = r else {
            return Ok(r);
        };
        let info = &self
            .slaves
            .iter()
            .find(|e| e.info.layout.address == address)
            .expect("checked")
            .info;
        info.layout
            .gsd
            .as_ref()
            .and_then(|g| profibus_devices::pkw_parameter(info.layout.ident_number, g, &name))
            .map(|pnu| Request::Pkw { pnu, command })
            .ok_or(RequestError::NoParameter { address, name })
    }

    /// A message from the broker. Requests are checked now (a refused
    /// one is answered at once and changes nothing) and carried out from
    /// the next [`Gateway::step`]. Messages on other topics are ignored.
    pub fn handle_message(&mut self, topic: &str, payload: &[u8], ts_ms: u64) {
        self.handle_message_with(topic, payload, &Properties::default(), ts_ms)
    }

    /// [`Gateway::handle_message`] with the message's MQTT 5 properties:
    /// a request with a Response Topic is answered there instead of on
    /// the slave's response topic (or its `"reply_to"`), and its
    /// Correlation Data goes back with the answer.
    pub fn handle_message_with(
        &mut self,
        topic: &str,
        payload: &[u8],
        props: &Properties,
        ts_ms: u64,
    ) {
        let (service, address) = match self.topics.parse_request(topic) {
            None => return,
            Some((s, Ok(a))) => (s, a),
            Some((_, Err(e))) => {
                // No station to answer for: logged only.
                tracing::warn!(topic, error = %e, "MQTT request refused");
                return;
            }
        };
        let (mut to, request) = parse_request(service, payload);
        let request = to
            .take_properties(
                props.response_topic.as_deref(),
                props.correlation_data.as_deref(),
            )
            .and_then(|()| crate::request::check_content_type(props.content_type.as_deref()))
            .and(request);
        let target = Target {
            service,
            address,
            to,
        };
        let request = request
            .and_then(|r| self.check(address, &r).map(|()| r))
            .and_then(|r| self.resolve(address, r));
        let request = match request {
            Ok(r) => r,
            Err(e) => return self.answer(target, Err(e), ts_ms),
        };
        let q = Queued { request, target };
        let e = self
            .slaves
            .iter_mut()
            .find(|e| e.info.layout.address == address)
            .expect("checked");
        let waiting = match q.request {
            Request::Outputs(_) | Request::Dpv1Read { .. } | Request::Dpv1Write { .. } => {
                &mut e.pending
            }
            Request::Pkw { .. } | Request::PkwNamed { .. } | Request::Rfid(_) => &mut e.queue,
        };
        if waiting.len() >= QUEUE_LIMIT {
            return self.answer(q.target, Err(RequestError::Busy(address)), ts_ms);
        }
        waiting.push_back(q);
    }

    /// One step at a cycle boundary; `now` is the master's time,
    /// `ts_ms` the wall-clock time in ms since the Unix epoch.
    ///
    /// Takes the master's events (DP-V1 job results, faults), applies the
    /// pending output writes (each to one slave's whole image at once, so
    /// one Data_Exchange carries all of it), starts DP-V1 jobs, drives
    /// the PKW and RFID clients, puts the outputs into the safe state
    /// when the broker has been away for `outputs_timeout`, then queues
    /// what changed (and, in interval mode, what is due).
    pub fn step(&mut self, m: &mut DpMaster, now: Instant, ts_ms: u64) {
        let mut answers: Vec<(Target, Outcome)> = vec![];
        while let Some(ev) = m.poll_event() {
            match ev {
                MasterEvent::Fault { address, reason } => {
                    tracing::warn!(address, %reason, "slave fault");
                    if let Some(e) = self
                        .slaves
                        .iter_mut()
                        .find(|e| e.info.layout.address == address)
                    {
                        e.fault = Some(reason.to_string());
                        e.published.state = None;
                    }
                }
                MasterEvent::Alarm { address, alarm } => {
                    let gsd = self
                        .slaves
                        .iter()
                        .find(|e| e.info.layout.address == address)
                        .and_then(|e| e.info.layout.gsd.as_ref());
                    let payload = AlarmPayload {
                        alarm: AlarmReport::new(address, &alarm, gsd),
                        ts: ts_ms,
                    };
                    let topic = self.topics.slave(address, SlaveTopic::Alarm);
                    self.push(topic, &payload, false);
                }
                MasterEvent::JobDone(id) => {
                    if let Some(i) = self.jobs.iter().position(|(j, _)| *j == id) {
                        let t = self.jobs.swap_remove(i).1;
                        let outcome = match m.take_result(id) {
                            Some(JobResult::Data(d)) => {
                                Ok(Some(AnswerData::Record { hex: hex(&d) }))
                            }
                            Some(JobResult::Done) => Ok(None),
                            Some(r) => Err(RequestError::Failed(r.describe())),
                            None => Err(RequestError::Failed("result lost".into())),
                        };
                        answers.push((t, outcome));
                    }
                }
                _ => {}
            }
        }
        self.outage.step(&self.settings, self.online, m, ts_ms);
        let pending: Vec<Queued> = self
            .slaves
            .iter_mut()
            .flat_map(|e| e.pending.drain(..))
            .collect();
        for q in pending {
            let outcome = self.carry_out(m, &q);
            if let Some(o) = outcome {
                if o.is_ok() {
                    tracing::info!(address = q.target.address, "MQTT write applied");
                }
                answers.push((q.target, o));
            }
        }
        for e in &mut self.slaves {
            drive(e, m, now, &mut answers);
        }
        for (t, o) in answers {
            self.answer(t, o, ts_ms);
        }
        for a in self.alerts.step(&self.settings, m, now) {
            self.push(alerts::topic(&self.settings), &a, false);
        }
        if self.online {
            self.publish_state(m, ts_ms);
        }
    }

    /// Apply an output write (`Some(outcome)`) or start a DP-V1 job
    /// (`None` while it runs).
    fn carry_out(&mut self, m: &mut DpMaster, q: &Queued) -> Option<Outcome> {
        let a = q.target.address;
        let job = match &q.request {
            Request::Outputs(w) => return Some(self.apply(m, a, w).map(|()| None)),
            Request::Dpv1Read {
                slot,
                index,
                length,
            } => Job::Dpv1Read {
                address: a,
                slot: *slot,
                index: *index,
                length: *length,
            },
            Request::Dpv1Write { slot, index, data } => Job::Dpv1Write {
                address: a,
                slot: *slot,
                index: *index,
                data: data.clone(),
            },
            Request::Pkw { .. } | Request::PkwNamed { .. } | Request::Rfid(_) => return None,
        };
        match m.submit(job) {
            Some(id) => {
                self.jobs.push((id, q.target.clone()));
                None
            }
            None => Some(Err(RequestError::Busy(a))),
        }
    }

    fn apply(&self, m: &mut DpMaster, address: u8, w: &OutputWrite) -> Result<(), RequestError> {
        let current = m
            .outputs(address)
            .ok_or_else(|| RequestError::UnknownSlave(address.to_string()))?;
        let map = self
            .slaves
            .iter()
            .find(|e| e.info.layout.address == address)
            .and_then(|e| e.info.channels.as_ref());
        let allowed = self
            .settings
            .access(address)
            .and_then(|a| a.channels.as_deref());
        let image = w.apply(address, current, map, allowed)?;
        m.set_outputs(address, &image);
        Ok(())
    }

    fn status(&self, m: &DpMaster, ts_ms: u64) -> Status {
        Status::Online {
            master: m.operating_state(),
            ts: ts_ms,
            slaves: self.slaves.iter().map(|e| e.info.layout.address).collect(),
            writable: self.settings.writable.iter().map(|w| w.address).collect(),
            outputs_timeout: self.outage.safe_applied().map(|at| OutputsTimeout {
                safe_state: self.settings.safe_state,
                at,
            }),
        }
    }

    fn publish_state(&mut self, m: &mut DpMaster, ts_ms: u64) {
        if self.status_master != Some(m.operating_state()) {
            self.status_master = Some(m.operating_state());
            let s = self.status(m, ts_ms);
            self.push(self.topics.status(), &s, true);
        }
        let interval_due =
            self.settings.publish != PublishMode::OnChange && ts_ms >= self.next_interval_ms;
        if interval_due {
            self.next_interval_ms = ts_ms + self.settings.interval.as_millis() as u64;
        }
        let on_change = self.settings.publish != PublishMode::Interval;
        let cycle = m.cycle_stats().cycles;
        for i in 0..self.slaves.len() {
            let addr = self.slaves[i].info.layout.address;
            let Some(h) = m.handle(addr) else { continue };
            let v = m.slave(h);
            let e = &mut self.slaves[i];
            let mut msgs = vec![];
            if e.published.state != Some(v.state) {
                e.published.state = Some(v.state);
                let p = SlaveStatePayload {
                    address: addr,
                    name: &e.info.layout.name,
                    state: v.state,
                    fault: e.fault.as_deref(),
                    ts: ts_ms,
                    cycle,
                };
                msgs.push((SlaveTopic::State, to_bytes(&p), true, vec![]));
            }
            let [fin, fout] = &mut e.filters;
            for (t, dir, img, last, filter) in [
                (
                    SlaveTopic::Inputs,
                    Direction::Input,
                    v.inputs,
                    &mut e.published.inputs,
                    fin,
                ),
                (
                    SlaveTopic::Outputs,
                    Direction::Output,
                    v.outputs,
                    &mut e.published.outputs,
                    fout,
                ),
            ] {
                // Report by exception: deadbands and the minimum interval.
                let changed = on_change && filter.due(img, ts_ms);
                if changed || interval_due || last.is_none() {
                    filter.published(img, ts_ms);
                    *last = Some(img.to_vec());
                    // The library's decoded image: `{"name": value}`.
                    let values = e.info.channels.as_ref().map(|map| match dir {
                        Direction::Input => map.values(img, &[]).inputs,
                        Direction::Output => map.values(&[], img).outputs,
                    });
                    let p = ImagePayload::new(addr, img, values, ts_ms, cycle);
                    // MQTT 5: each unit as a user property `unit`,
                    // `channel=unit`.
                    let units = (p.units.0.iter())
                        .map(|(name, unit)| ("unit".to_string(), format!("{name}={unit}")))
                        .collect();
                    msgs.push((t, to_bytes(&p), self.settings.retain_values, units));
                }
            }
            if e.published.diag.as_deref() != Some(v.diag) {
                e.published.diag = Some(v.diag.to_vec());
                let text = if v.diag.is_empty() {
                    vec![]
                } else {
                    profibus_dp::pdu::diag::describe(
                        v.diag,
                        e.info.layout.gsd.as_ref(),
                        e.info.layout.dpv1,
                    )
                };
                let p = DiagPayload::new(addr, v.diag, text, ts_ms, cycle);
                msgs.push((SlaveTopic::Diag, to_bytes(&p), true, vec![]));
            }
            for (t, payload, retain, user) in msgs {
                let props = self.properties(retain, user);
                self.push_with(self.topics.slave(addr, t), payload, retain, props);
            }
        }
    }

    /// The next message to send, if any.
    pub fn poll_publish(&mut self) -> Option<Publish> {
        self.out.pop_front()
    }
}

fn failed(e: impl std::fmt::Display) -> RequestError {
    RequestError::Failed(e.to_string())
}

/// A slave's job client as [`drive`] runs it: PKW or RFID.
trait JobClient {
    fn is_idle(&self) -> bool;
    /// Start `r`; `None` when it is not this client's kind.
    fn begin(&mut self, now: Instant, r: &Request) -> Option<Result<(), RequestError>>;
    /// Drive the running job; its outcome when it ends.
    fn poll(&mut self, now: Instant, m: &mut DpMaster, h: SlaveHandle) -> Option<Outcome>;
}

impl JobClient for PkwClient {
    fn is_idle(&self) -> bool {
        PkwClient::is_idle(self)
    }
    fn begin(&mut self, now: Instant, r: &Request) -> Option<Result<(), RequestError>> {
        let Request::Pkw { pnu, command } = r else {
            return None;
        };
        Some(self.start(now, *pnu, *command).map_err(failed))
    }
    fn poll(&mut self, now: Instant, m: &mut DpMaster, h: SlaveHandle) -> Option<Outcome> {
        let words = |p: pkw::Pkw| {
            let mut b = [0u8; PKW_LEN];
            p.emit(&mut b);
            hex(&b)
        };
        let r = self.drive(now, m, h)?;
        Some(
            r.map(|a| {
                Some(AnswerData::Pkw {
                    value: a.reply.value(),
                    dword: a.reply.is_dword(),
                    request: words(a.request),
                    response: words(a.response),
                })
            })
            .map_err(failed),
        )
    }
}

impl JobClient for RfidClient {
    fn is_idle(&self) -> bool {
        RfidClient::is_idle(self)
    }
    fn begin(&mut self, now: Instant, r: &Request) -> Option<Result<(), RequestError>> {
        let Request::Rfid(line) = r else {
            return None;
        };
        Some(self.start(now, line).map_err(failed))
    }
    fn poll(&mut self, now: Instant, m: &mut DpMaster, h: SlaveHandle) -> Option<Outcome> {
        let r = self.poll_master(now, m, h)?;
        Some(
            r.map(|a| {
                let text = String::from_utf8_lossy(a);
                Some(AnswerData::Rfid {
                    answer: text.trim_end_matches('\r').into(),
                    hex: hex(a),
                })
            })
            .map_err(failed),
        )
    }
}

/// Start the next PKW or RFID job of a slave when its client is idle,
/// and drive the running one.
fn drive(e: &mut Entry, m: &mut DpMaster, now: Instant, answers: &mut Vec<(Target, Outcome)>) {
    let Some(h) = m.handle(e.info.layout.address) else {
        return;
    };
    let client: Option<&mut dyn JobClient> = match (&mut e.pkw, &mut e.rfid) {
        (Some(c), _) => Some(c),
        (None, Some(c)) => Some(c),
        (None, None) => None,
    };
    let Some(c) = client else { return };
    while c.is_idle() && e.running.is_none() {
        let Some(q) = e.queue.pop_front() else { break };
        match c.begin(now, &q.request) {
            None => continue,
            Some(Ok(())) => e.running = Some(q.target),
            Some(Err(err)) => answers.push((q.target, Err(err))),
        }
    }
    if !c.is_idle() {
        if let Some(outcome) = c.poll(now, m, h) {
            if let Some(t) = e.running.take() {
                answers.push((t, outcome));
            }
        }
    }
}

impl Session for Gateway {
    fn settings(&self) -> &MqttSettings {
        Gateway::settings(self)
    }
    fn settings_mut(&mut self) -> &mut MqttSettings {
        &mut self.settings
    }
    fn reload(&mut self, settings: MqttSettings) {
        for e in &mut self.slaves {
            let t = Traffic::of(&settings, &e.info);
            let [fin, fout] = &mut e.filters;
            fin.retune(t.filter(&e.info, Direction::Input));
            fout.retune(t.filter(&e.info, Direction::Output));
        }
        self.settings = settings;
    }
    fn link_setup(&self) -> LinkSetup {
        let will = Gateway::last_will(self);
        LinkSetup {
            qos: self.settings().qos,
            will_qos: self.settings().qos,
            filters: self.topics().request_filters(),
            will: Box::new(move || will.clone()),
        }
    }
    fn connected(&mut self, ts_ms: u64) {
        Gateway::connected(self, ts_ms)
    }
    fn disconnected(&mut self, ts_ms: u64) {
        Gateway::disconnected(self, ts_ms)
    }
    fn handle_message_with(&mut self, topic: &str, payload: &[u8], props: &Properties, ts_ms: u64) {
        Gateway::handle_message_with(self, topic, payload, props, ts_ms)
    }
    fn step(&mut self, m: &mut DpMaster, now: Instant, ts_ms: u64) {
        Gateway::step(self, m, now, ts_ms)
    }
    fn poll_publish(&mut self) -> Option<Publish> {
        Gateway::poll_publish(self)
    }
    fn last_will(&self) -> Publish {
        Gateway::last_will(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::SafeState;
    use profibus_devices::channels::{ChannelMap, ChannelType};
    use profibus_dp::config::layout::SlaveLayout;
    use profibus_dp::master::{MasterConfig, MasterOptions, SlaveParams};
    use profibus_fdl::{Baud, BusParams};
    use serde_json::json;

    type Msgs = Vec<(String, serde_json::Value, bool)>;

    /// A master with slave 3 (2 words in/out, writable, named channels),
    /// slave 4 (2 bytes out, not writable) and slave 5 (only channel
    /// `speed` writable).
    fn setup() -> (Gateway, DpMaster) {
        let cfg = MasterConfig {
            address: 1,
            params: BusParams::defaults(Baud::B1500000),
            slaves: vec![
                SlaveParams::new(3, 0x1234, vec![0x71]),
                SlaveParams::new(4, 0x1234, vec![0x21]),
                SlaveParams::new(5, 0x1234, vec![0x71]),
            ],
            options: MasterOptions::default(),
        };
        let m = DpMaster::new(&cfg).unwrap();
        let mut ch = ChannelMap::new();
        ch.push("speed", Direction::Output, 0, ChannelType::I16);
        ch.push("torque", Direction::Output, 2, ChannelType::I16);
        ch.push("actual", Direction::Input, 0, ChannelType::I16);
        let t: toml::Table = toml::from_str(
            "writable = [3, { address = 5, channels = [\"speed\"] }]\nmin_interval_ms = 0",
        )
        .unwrap();
        let settings = crate::MqttSettings::from_table(Some(&t), "l1").unwrap();
        let info = |address, channels| SlaveInfo {
            layout: SlaveLayout {
                address,
                name: format!("s{address}"),
                ident_number: 0x1234,
                ..SlaveLayout::default()
            },
            channels,
            pkw: None,
        };
        let g = Gateway::new(
            settings,
            vec![info(3, Some(ch.clone())), info(4, None), info(5, Some(ch))],
        );
        (g, m)
    }

    fn drain(g: &mut Gateway) -> Msgs {
        std::iter::from_fn(|| g.poll_publish())
            .map(|p| {
                (
                    p.topic,
                    serde_json::from_slice(&p.payload).unwrap(),
                    p.retain,
                )
            })
            .collect()
    }

    fn find<'a>(msgs: &'a Msgs, topic: &str) -> Option<&'a serde_json::Value> {
        msgs.iter().find(|(t, _, _)| t == topic).map(|(_, v, _)| v)
    }

    #[test]
    fn publishes_retained_state_and_republishes_after_reconnect() {
        let (mut g, mut m) = setup();
        g.step(&mut m, Instant::ZERO, 5);
        assert!(
            drain(&mut g).is_empty(),
            "nothing before the first connection"
        );
        g.connected(10);
        g.step(&mut m, Instant::ZERO, 11);
        let msgs = drain(&mut g);
        let st = find(&msgs, "profibus/l1/status").unwrap();
        assert_eq!(
            (st["state"].as_str(), st["master"].as_str()),
            (Some("online"), Some("operate"))
        );
        assert_eq!(st["writable"], json!([3, 5]));
        let st = find(&msgs, "profibus/l1/3/state").unwrap();
        assert_eq!(
            (st["state"].as_str(), st["name"].as_str()),
            (Some(SlaveState::Diag.name()), Some("s3"))
        );
        let inp = find(&msgs, "profibus/l1/3/inputs").unwrap();
        assert_eq!(inp["hex"], "00000000");
        assert_eq!(inp["values"]["actual"], 0);
        assert!(find(&msgs, "profibus/l1/4/outputs")
            .unwrap()
            .get("values")
            .is_none());
        assert!(msgs.iter().all(|(_, _, r)| *r));
        // Nothing changed: nothing new.
        g.step(&mut m, Instant::ZERO, 12);
        assert!(drain(&mut g).is_empty());
        // The master goes to Clear: the status says so at once.
        m.set_operating_state(OperatingState::Clear);
        g.step(&mut m, Instant::ZERO, 13);
        let msgs = drain(&mut g);
        assert_eq!(
            find(&msgs, "profibus/l1/status").unwrap()["master"],
            "clear"
        );
        m.set_operating_state(OperatingState::Operate);
        g.step(&mut m, Instant::ZERO, 14);
        drain(&mut g);
        // A new connection: everything again.
        g.disconnected(15);
        g.connected(20);
        g.step(&mut m, Instant::ZERO, 21);
        assert_eq!(drain(&mut g).len(), 1 + 3 * 4);
        assert_eq!(g.last_will().payload, br#"{"state":"offline"}"#);
    }

    fn publishes(g: &mut Gateway) -> Vec<Publish> {
        std::iter::from_fn(|| g.poll_publish()).collect()
    }

    #[test]
    fn mqtt5_json_has_its_content_type_and_requests_of_another_type_are_refused() {
        let (mut g, mut m) = setup();
        g.connected(0);
        g.step(&mut m, Instant::ZERO, 0);
        let all = publishes(&mut g);
        assert!(!all.is_empty());
        assert!(all
            .iter()
            .all(|p| p.props.content_type.as_deref() == Some("application/json") && p.props.utf8));
        let props = |ct: &str| Properties {
            response_topic: Some("client/ct".into()),
            content_type: Some(ct.into()),
            ..Properties::default()
        };
        // Not JSON: refused on the response topic, nothing written.
        g.handle_message_with(
            "profibus/l1/3/outputs/set",
            br#"{"channels": {"speed": 7}}"#,
            &props("text/plain"),
            1,
        );
        g.step(&mut m, Instant::ZERO, 2);
        assert_eq!(m.outputs(3).unwrap(), [0, 0, 0, 0]);
        let a = publishes(&mut g)
            .into_iter()
            .find(|p| p.topic == "client/ct")
            .unwrap();
        let v: serde_json::Value = serde_json::from_slice(&a.payload).unwrap();
        assert_eq!(v["ok"], false);
        assert_eq!(
            v["error"],
            "content type `text/plain` is not JSON (send application/json or no content type)"
        );
        // JSON with parameters, in any case, and `+json` types: taken.
        for (i, ct) in [
            "Application/JSON; charset=utf-8",
            "application/merge-patch+json",
        ]
        .into_iter()
        .enumerate()
        {
            g.handle_message_with(
                "profibus/l1/3/outputs/set",
                format!(r#"{{"channels": {{"speed": {}}}}}"#, 8 + i).as_bytes(),
                &props(ct),
                3,
            );
            g.step(&mut m, Instant::ZERO, 4);
            assert_eq!(m.outputs(3).unwrap(), [0, 8 + i as u8, 0, 0], "{ct}");
            publishes(&mut g);
        }
    }

    #[test]
    fn mqtt5_requests_are_answered_on_their_response_topic_with_their_correlation_data() {
        let (mut g, mut m) = setup();
        g.connected(0);
        g.step(&mut m, Instant::ZERO, 0);
        drain(&mut g);
        let props = |topic: Option<&str>, data: &[u8]| Properties {
            response_topic: topic.map(Into::into),
            correlation_data: Some(data.to_vec()),
            ..Properties::default()
        };
        // No `id`, no `reply_to`: the properties say where and which.
        g.handle_message_with(
            "profibus/l1/3/outputs/set",
            br#"{"channels": {"speed": 5}}"#,
            &props(Some("client/7/answers"), b"\xca\xfe"),
            1,
        );
        g.step(&mut m, Instant::ZERO, 2);
        assert_eq!(m.outputs(3).unwrap(), [0, 5, 0, 0]);
        let all = publishes(&mut g);
        assert!(all
            .iter()
            .all(|p| p.topic != "profibus/l1/3/outputs/response"));
        let a = all.iter().find(|p| p.topic == "client/7/answers").unwrap();
        assert_eq!(a.props.correlation_data.as_deref(), Some(&b"\xca\xfe"[..]));
        assert_eq!(a.props.message_expiry_s, Some(10), "not retained: expires");
        assert!(!a.retain);
        let v: serde_json::Value = serde_json::from_slice(&a.payload).unwrap();
        assert_eq!(v["ok"], true);
        assert!(v.get("id").is_none(), "{v}");
        // Retained images never expire.
        let img = all
            .iter()
            .find(|p| p.topic == "profibus/l1/3/outputs")
            .unwrap();
        assert_eq!((img.retain, img.props.message_expiry_s), (true, None));
        // The Response Topic wins over `reply_to`; a refusal goes there too.
        g.handle_message_with(
            "profibus/l1/4/outputs/set",
            br#"{"hex": "0102", "reply_to": "elsewhere"}"#,
            &props(Some("client/7/answers"), b"2"),
            3,
        );
        let all = publishes(&mut g);
        assert_eq!(all.len(), 1);
        assert_eq!(
            (
                all[0].topic.as_str(),
                all[0].props.correlation_data.as_deref()
            ),
            ("client/7/answers", Some(&b"2"[..]))
        );
        let v: serde_json::Value = serde_json::from_slice(&all[0].payload).unwrap();
        assert_eq!(v["ok"], false);
        // Correlation Data alone: the slave's response topic; a wildcard
        // Response Topic is refused there, with the data.
        for (topic, error) in [(None, None), (Some("client/+"), Some("wildcards"))] {
            g.handle_message_with(
                "profibus/l1/3/outputs/set",
                br#"{"channels": {"speed": 6}}"#,
                &props(topic, b"3"),
                4,
            );
            g.step(&mut m, Instant::ZERO, 5);
            let all = publishes(&mut g);
            let a = all
                .iter()
                .find(|p| p.topic == "profibus/l1/3/outputs/response")
                .unwrap();
            assert_eq!(a.props.correlation_data.as_deref(), Some(&b"3"[..]));
            let v: serde_json::Value = serde_json::from_slice(&a.payload).unwrap();
            assert_eq!(v["ok"], error.is_none(), "{v}");
            if let Some(e) = error {
                assert!(v["error"].as_str().unwrap().contains(e), "{v}");
            }
        }
    }

    #[test]
    fn images_carry_their_units_and_expire_when_not_retained() {
        use profibus_devices::channels::{Channel, Scale};
        let (_, mut m) = setup();
        let mut ch = ChannelMap::new();
        ch.channels.push(
            Channel::new("ai", Direction::Input, 0, ChannelType::I16).scaled(Scale {
                num: 10,
                den: 32767,
                unit: "V".into(),
            }),
        );
        ch.push("count", Direction::Input, 2, ChannelType::U16);
        let info = SlaveInfo {
            layout: SlaveLayout {
                address: 3,
                ..SlaveLayout::default()
            },
            channels: Some(ch),
            pkw: None,
        };
        for (text, retain, expiry) in [
            ("", true, None),
            ("retain_values = false", false, Some(10)),
            ("retain_values = false\nmessage_expiry_s = 0", false, None),
        ] {
            let t: toml::Table = toml::from_str(text).unwrap();
            let settings = crate::MqttSettings::from_table(Some(&t), "l1").unwrap();
            let mut g = Gateway::new(settings, vec![info.clone()]);
            g.connected(0);
            g.step(&mut m, Instant::ZERO, 0);
            let all = publishes(&mut g);
            let inputs = all
                .iter()
                .find(|p| p.topic == "profibus/l1/3/inputs")
                .unwrap();
            assert_eq!(
                inputs.props.user,
                [("unit".to_string(), "ai=V".to_string())],
                "{text}"
            );
            assert_eq!(
                (inputs.retain, inputs.props.message_expiry_s),
                (retain, expiry),
                "{text}"
            );
            let state = all
                .iter()
                .find(|p| p.topic == "profibus/l1/3/state")
                .unwrap();
            assert_eq!((state.retain, state.props.message_expiry_s), (true, None));
            assert!(state.props.user.is_empty());
        }
    }

    #[test]
    fn writes_are_checked_then_applied_at_the_step() {
        let (mut g, mut m) = setup();
        g.connected(0);
        g.step(&mut m, Instant::ZERO, 0);
        drain(&mut g);
        g.handle_message(
            "profibus/l1/3/outputs/set",
            br#"{"channels": {"speed": -2, "torque": 3}, "id": 1}"#,
            1,
        );
        assert_eq!(
            m.outputs(3).unwrap(),
            [0, 0, 0, 0],
            "applied at the step, not before"
        );
        g.step(&mut m, Instant::ZERO, 2);
        assert_eq!(m.outputs(3).unwrap(), [0xff, 0xfe, 0, 3]);
        let msgs = drain(&mut g);
        let r = find(&msgs, "profibus/l1/3/outputs/response").unwrap();
        assert_eq!((r["ok"].as_bool(), r["id"].as_i64()), (Some(true), Some(1)));
        assert_eq!(
            find(&msgs, "profibus/l1/3/outputs").unwrap()["values"]["speed"],
            -2
        );
        // Slave 5 takes its `speed` channel, answered on `reply_to`.
        g.handle_message(
            "profibus/l1/5/outputs/set",
            br#"{"channels": {"speed": 7}, "id": "s", "reply_to": "client/9"}"#,
            3,
        );
        g.step(&mut m, Instant::ZERO, 4);
        let msgs = drain(&mut g);
        assert_eq!(find(&msgs, "client/9").unwrap()["ok"], true);
        assert_eq!(m.outputs(5).unwrap(), [0, 7, 0, 0]);

        // Refused writes change nothing and are answered.
        for (topic, payload, error) in [
            ("profibus/l1/4/outputs/set", &b"0001"[..], "not writable"),
            ("profibus/l1/9/outputs/set", b"0001", "no slave 9"),
            ("profibus/l1/3/outputs/set", b"01", "4 output bytes"),
            (
                "profibus/l1/3/outputs/set",
                b"{\"channels\": {\"nope\": 1}}",
                "no output channel",
            ),
            (
                "profibus/l1/3/outputs/set",
                b"{\"channels\": {\"speed\": 70000}}",
                "",
            ),
            ("profibus/l1/3/outputs/set", b"junk", "malformed"),
            (
                "profibus/l1/5/outputs/set",
                b"{\"channels\": {\"speed\": 1, \"torque\": 1}}",
                "only the output channels `speed` are writable",
            ),
            ("profibus/l1/5/outputs/set", b"00010001", "only the output"),
            (
                "profibus/l1/3/pkw/request",
                b"{\"op\": \"read\", \"pnu\": 1}",
                "no PKW channel",
            ),
            (
                "profibus/l1/3/rfid/request",
                b"{\"command\": \"VER\"}",
                "no RFID",
            ),
            (
                "profibus/l1/3/dpv1/request",
                b"{\"op\": \"read\", \"slot\": 0, \"index\": 1}",
                "no DP-V1",
            ),
        ] {
            g.handle_message(topic, payload, 5);
            g.step(&mut m, Instant::ZERO, 6);
            let msgs = drain(&mut g);
            let response = topic
                .replace("/set", "/response")
                .replace("/request", "/response");
            let r = find(&msgs, &response).unwrap_or_else(|| panic!("{msgs:?}"));
            assert_eq!(r["ok"], false, "{topic} {payload:?}");
            assert!(r["error"].as_str().unwrap().contains(error), "{r}");
            assert_eq!(m.outputs(3).unwrap(), [0xff, 0xfe, 0, 3]);
            assert_eq!(m.outputs(4).unwrap(), [0, 0]);
            assert_eq!(m.outputs(5).unwrap(), [0, 7, 0, 0]);
        }
        // Other topics are not ours.
        g.handle_message("profibus/l1/3/outputs", b"0000", 7);
        g.step(&mut m, Instant::ZERO, 8);
        assert!(drain(&mut g).is_empty());
    }

    #[test]
    fn a_full_write_queue_refuses_the_next_write_and_changes_nothing() {
        let (mut g, mut m) = setup();
        g.connected(0);
        g.step(&mut m, Instant::ZERO, 0);
        drain(&mut g);
        for i in 0..=QUEUE_LIMIT {
            let p = format!(r#"{{"hex": "000000{i:02x}", "id": {i}}}"#);
            g.handle_message("profibus/l1/3/outputs/set", p.as_bytes(), 1);
        }
        // The write over the limit is answered at once: busy.
        let msgs = drain(&mut g);
        assert_eq!(msgs.len(), 1, "{msgs:?}");
        let r = find(&msgs, "profibus/l1/3/outputs/response").unwrap();
        assert_eq!(
            (r["ok"].as_bool(), r["id"].as_u64()),
            (Some(false), Some(QUEUE_LIMIT as u64))
        );
        let e = r["error"].as_str().unwrap();
        assert!(e.contains("too many requests waiting (at most 8)"), "{e}");
        // Another slave has a queue of its own.
        g.handle_message(
            "profibus/l1/5/outputs/set",
            br#"{"channels": {"speed": 9}}"#,
            1,
        );
        g.step(&mut m, Instant::ZERO, 2);
        let msgs = drain(&mut g);
        let ok = |t: &str| {
            msgs.iter()
                .filter(|(topic, v, _)| topic == t && v["ok"] == true)
                .count()
        };
        assert_eq!(ok("profibus/l1/3/outputs/response"), QUEUE_LIMIT);
        assert_eq!(ok("profibus/l1/5/outputs/response"), 1);
        // The queued writes applied in order; the refused one did not.
        assert_eq!(m.outputs(3).unwrap(), [0, 0, 0, QUEUE_LIMIT as u8 - 1]);
        assert_eq!(m.outputs(5).unwrap(), [0, 9, 0, 0]);
        // The step emptied the queue: writes are taken again.
        g.handle_message("profibus/l1/3/outputs/set", b"00000063", 3);
        g.step(&mut m, Instant::ZERO, 4);
        assert_eq!(m.outputs(3).unwrap(), [0, 0, 0, 0x63]);
    }

    #[test]
    fn outputs_timeout_puts_the_outputs_in_the_safe_state_once() {
        for (safe, want3, master) in [
            ("keep", [0xff, 0xfe, 0, 3], "operate"),
            ("zero", [0, 0, 0, 0], "operate"),
            ("clear", [0xff, 0xfe, 0, 3], "clear"),
        ] {
            let (g, mut m) = setup();
            let mut s = g.settings().clone();
            s.outputs_timeout = Some(std::time::Duration::from_millis(100));
            s.safe_state = match safe {
                "keep" => SafeState::Keep,
                "zero" => SafeState::Zero,
                _ => SafeState::Clear,
            };
            let mut g = Gateway::new(s, g.slaves.iter().map(|e| e.info.clone()).collect());
            g.connected(0);
            g.handle_message("profibus/l1/3/outputs/set", b"fffe0003", 0);
            g.step(&mut m, Instant::ZERO, 0);
            g.disconnected(1000);
            g.step(&mut m, Instant::ZERO, 1099);
            assert_eq!(
                m.outputs(3).unwrap(),
                [0xff, 0xfe, 0, 3],
                "{safe}: too early"
            );
            g.step(&mut m, Instant::ZERO, 1100);
            assert_eq!(m.outputs(3).unwrap(), want3, "{safe}");
            assert_eq!(m.operating_state().as_str(), master, "{safe}");
            // The broker is back: reported in the status; Clear ends.
            g.connected(2000);
            g.step(&mut m, Instant::ZERO, 2000);
            let msgs = drain(&mut g);
            let st = find(&msgs, "profibus/l1/status").unwrap();
            assert_eq!(st["outputs_timeout"]["safe_state"], safe, "{st}");
            assert_eq!(st["outputs_timeout"]["at"], 1100, "{st}");
            assert_eq!(st["master"], "operate", "{st}");
            assert_eq!(m.operating_state(), OperatingState::Operate);
        }
    }
}
