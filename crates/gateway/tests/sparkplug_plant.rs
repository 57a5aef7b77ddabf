//! The Sparkplug B core on the simulated plant of `dpctl gateway --sim`:
//! births, data, commands, rebirths, bdSeq and seq, the safe state. No
//! broker.

use profibus_devices::bus::ProfiledBus;
use profibus_fdl::Instant;
use profibus_gateway::sparkplug::proto::{DataType, Metric, MetricValue, Payload};
use profibus_gateway::sparkplug::{devices, metrics, BD_SEQ, REBIRTH};
use profibus_gateway::{EdgeNode, MqttSettings, SafeState, Session, SparkplugId};
use profibus_plant::Plant;
use prost::Message;

/// Master 1 with two GSD slaves, 3 (named) and 4; 3 writable.
const BUS: &str = include_str!("data/sparkplug_bus.toml");

struct Rig {
    plant: Plant,
    node: EdgeNode,
    t: u64,
    /// The metric names by alias, from the births.
    names: std::collections::HashMap<u64, String>,
}

impl Rig {
    fn new() -> Rig {
        Rig::with(|_| {})
    }

    /// A rig whose settings `f` changes first.
    fn with(f: impl FnOnce(&mut MqttSettings)) -> Rig {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../devices/gsd/bus.toml");
        let bus = ProfiledBus::parse(&dir, BUS).unwrap();
        let mut settings = MqttSettings::from_table(bus.file.mqtt.as_ref(), "line").unwrap();
        f(&mut settings);
        let node = EdgeNode::new(
            settings,
            SparkplugId::parse("G/E").unwrap(),
            devices(&bus).unwrap(),
        );
        Rig {
            plant: Plant::from_bus(&bus).unwrap(),
            node,
            t: 0,
            names: Default::default(),
        }
    }

    /// Run 1 ms of bus time, step the node; what it published.
    fn tick(&mut self) -> Vec<(String, Payload)> {
        self.t += 1;
        self.plant
            .run_until(Instant::from_nanos(self.t * 1_000_000));
        let now = self.plant.now();
        self.node.step(self.plant.master(), now, 1000 + self.t);
        let msgs: Vec<_> = std::iter::from_fn(|| self.node.poll_publish())
            .map(|p| {
                assert!(!p.retain);
                (p.topic, Payload::decode(p.payload.as_slice()).unwrap())
            })
            .collect();
        // Births name and alias every metric (but bdSeq); data messages
        // carry the alias only: named here from the births.
        msgs.into_iter()
            .map(|(t, mut p)| {
                let birth = t.contains("BIRTH/");
                for m in &mut p.metrics {
                    if birth && m.name.as_deref() != Some(BD_SEQ) {
                        let alias = m.alias.expect("every born metric has an alias");
                        self.names.insert(alias, m.name.clone().unwrap());
                    } else if t.contains("DATA/") {
                        assert_eq!(m.name, None, "data by alias only");
                        m.name = Some(self.names[&m.alias.unwrap()].clone());
                    }
                }
                (t, p)
            })
            .collect()
    }

    /// Tick until `topic` is published (at most 2 s of bus time);
    /// everything published meanwhile.
    fn until(&mut self, topic: &str) -> Vec<(String, Payload)> {
        let mut all = vec![];
        for _ in 0..2000 {
            all.extend(self.tick());
            if all.iter().any(|(t, _)| t == topic) {
                return all;
            }
        }
        panic!(
            "no {topic}; got {:?}",
            all.iter().map(|m| &m.0).collect::<Vec<_>>()
        );
    }
}

fn value<'a>(p: &'a Payload, name: &str) -> Option<&'a MetricValue> {
    p.metrics
        .iter()
        .find(|m| m.name.as_deref() == Some(name))
        .and_then(|m| m.value.as_ref())
}

fn find<'a>(msgs: &'a [(String, Payload)], topic: &str) -> &'a Payload {
    &msgs.iter().rev().find(|(t, _)| t == topic).unwrap().1
}

fn cmd(metrics: Vec<Metric>) -> Vec<u8> {
    Payload {
        timestamp: Some(1),
        metrics,
        ..Default::default()
    }
    .encode_to_vec()
}

fn write(name: &str, v: MetricValue) -> Metric {
    Metric {
        name: Some(name.into()),
        value: Some(v),
        ..Default::default()
    }
}

#[test]
fn births_data_commands_rebirth_and_bdseq() {
    let mut r = Rig::new();
    // The wills of successive connection attempts count bdSeq.
    let mut setup = r.node.link_setup();
    assert_eq!((setup.qos, setup.will_qos), (0, 1));
    assert_eq!(setup.filters, ["spBv1.0/G/NCMD/E", "spBv1.0/G/DCMD/E/+"]);
    for bd in 0..3u64 {
        let w = (setup.will)();
        assert_eq!(w.topic, "spBv1.0/G/NDEATH/E");
        let p = Payload::decode(w.payload.as_slice()).unwrap();
        assert_eq!((p.seq, p.metrics.len()), (None, 1));
        assert_eq!(value(&p, BD_SEQ), Some(&MetricValue::LongValue(bd)));
    }
    // Nothing before the connection.
    assert!(r.tick().is_empty());
    r.node.connected(0);
    let msgs = r.until("spBv1.0/G/DBIRTH/E/4");
    let mut msgs = msgs.into_iter();
    let (t, nbirth) = msgs.next().unwrap();
    assert_eq!(t, "spBv1.0/G/NBIRTH/E");
    assert_eq!(nbirth.seq, Some(0));
    assert_eq!(value(&nbirth, BD_SEQ), Some(&MetricValue::LongValue(0)));
    assert_eq!(
        value(&nbirth, REBIRTH),
        Some(&MetricValue::BooleanValue(false))
    );
    let births: Vec<_> = msgs.collect();
    assert_eq!(births.len(), 2, "{births:?}");
    assert_eq!(births[0].0, "spBv1.0/G/DBIRTH/E/3");
    assert_eq!(births[0].1.seq, Some(1));
    assert_eq!(births[1].1.seq, Some(2));
    let b3 = &births[0].1;
    assert_eq!(
        value(b3, metrics::NAME),
        Some(&MetricValue::StringValue("echo".into()))
    );
    let ch = b3
        .metrics
        .iter()
        .find(|m| m.name.as_deref() == Some("Outputs/2 words in_out[0]"))
        .unwrap();
    assert_eq!(ch.datatype, Some(DataType::UInt8.code()));
    assert!(b3.metrics.iter().all(|m| m.datatype.is_some()));

    // A DCMD: the image and a channel at once; the echo slave's
    // inputs follow, in one DDATA with only what changed.
    r.node.handle_message(
        "spBv1.0/G/DCMD/E/3",
        &cmd(vec![
            write(
                metrics::OUTPUT_IMAGE,
                MetricValue::BytesValue(vec![1, 2, 3, 4]),
            ),
            write("Outputs/2 words in_out[3]", MetricValue::IntValue(0xaa)),
        ]),
        0,
    );
    let msgs = r.until("spBv1.0/G/DDATA/E/3");
    assert_eq!(r.plant.master().outputs(3).unwrap(), [1, 2, 3, 0xaa]);
    let echoed = |msgs: &[(String, Payload)]| {
        msgs.iter().any(|(t, p)| {
            t == "spBv1.0/G/DDATA/E/3"
                && value(p, metrics::INPUT_IMAGE)
                    == Some(&MetricValue::BytesValue(vec![1, 2, 3, 0xaa]))
        })
    };
    let mut later = msgs.clone();
    for _ in 0..2000 {
        if echoed(&later) {
            break;
        }
        later.extend(r.tick());
    }
    assert!(echoed(&later), "the echoed inputs in a DDATA");
    let dd = find(&msgs, "spBv1.0/G/DDATA/E/3");
    assert!(dd.metrics.iter().all(|m| m.datatype.is_none()));
    assert!(value(dd, metrics::NAME).is_none(), "only changes");
    assert!(dd.seq.unwrap() >= 3);

    // Refused, nothing written: a slave not writable, an unknown
    // metric next to a good one, an input, a value out of range.
    for (topic, ms) in [
        (
            "spBv1.0/G/DCMD/E/4",
            vec![write(
                metrics::OUTPUT_IMAGE,
                MetricValue::BytesValue(vec![9; 4]),
            )],
        ),
        (
            "spBv1.0/G/DCMD/E/3",
            vec![
                write("Outputs/2 words in_out[0]", MetricValue::IntValue(9)),
                write("Outputs/nope", MetricValue::IntValue(9)),
            ],
        ),
        (
            "spBv1.0/G/DCMD/E/3",
            vec![write("Inputs/2 words in_out[0]", MetricValue::IntValue(9))],
        ),
        (
            "spBv1.0/G/DCMD/E/3",
            vec![write(
                "Outputs/2 words in_out[0]",
                MetricValue::IntValue(300),
            )],
        ),
        (
            "spBv1.0/G/DCMD/E/3",
            vec![write(
                metrics::OUTPUT_IMAGE,
                MetricValue::BytesValue(vec![9; 3]),
            )],
        ),
        ("spBv1.0/G/DCMD/E/9", vec![]),
    ] {
        r.node.handle_message(topic, &cmd(ms), 0);
        r.tick();
        assert_eq!(
            r.plant.master().outputs(3).unwrap(),
            [1, 2, 3, 0xaa],
            "{topic}"
        );
        assert_eq!(r.plant.master().outputs(4).unwrap(), [0; 4], "{topic}");
    }
    r.node.handle_message("spBv1.0/G/DCMD/E/3", b"\xff\xff", 0);

    // Rebirth: NBIRTH (seq 0, same bdSeq) and both DBIRTHs again.
    r.node.handle_message(
        "spBv1.0/G/NCMD/E",
        &cmd(vec![write(REBIRTH, MetricValue::BooleanValue(true))]),
        0,
    );
    let msgs = r.tick();
    let topics: Vec<&str> = msgs.iter().map(|(t, _)| t.as_str()).collect();
    assert_eq!(
        topics,
        [
            "spBv1.0/G/NBIRTH/E",
            "spBv1.0/G/DBIRTH/E/3",
            "spBv1.0/G/DBIRTH/E/4"
        ]
    );
    assert_eq!(msgs[0].1.seq, Some(0));
    assert_eq!(value(&msgs[0].1, BD_SEQ), Some(&MetricValue::LongValue(0)));
    assert_eq!(msgs[2].1.seq, Some(2));

    // A new connection: bdSeq 1 in the NBIRTH and the will.
    r.node.disconnected(0);
    assert!(r.tick().is_empty());
    r.node.connected(0);
    let msgs = r.until("spBv1.0/G/DBIRTH/E/4");
    assert_eq!(value(&msgs[0].1, BD_SEQ), Some(&MetricValue::LongValue(1)));
    let will = Payload::decode(r.node.last_will().payload.as_slice()).unwrap();
    assert_eq!(value(&will, BD_SEQ), Some(&MetricValue::LongValue(1)));
}

/// A DCMD with a new output image for slave 3 at every tick, until `n`
/// messages are published; their seqs.
fn seqs_of_writes(r: &mut Rig, n: usize) -> Vec<u64> {
    let mut seqs = vec![];
    for i in 1..=4 * n as u32 {
        r.node.handle_message(
            "spBv1.0/G/DCMD/E/3",
            &cmd(vec![write(
                metrics::OUTPUT_IMAGE,
                MetricValue::BytesValue(i.to_le_bytes().to_vec()),
            )]),
            0,
        );
        seqs.extend(r.tick().iter().map(|(_, p)| p.seq.unwrap()));
        if seqs.len() >= n {
            return seqs;
        }
    }
    panic!("only {} messages", seqs.len());
}

#[test]
fn seq_wraps_after_255() {
    // A DDATA at every tick: no minimum interval.
    let mut r = Rig::with(|s| s.min_interval = std::time::Duration::ZERO);
    r.node.connected(0);
    r.until("spBv1.0/G/DBIRTH/E/4");
    // The births had 0..=2; the DDATAs count on to 200.
    let seqs = seqs_of_writes(&mut r, 198);
    assert_eq!(seqs[..198], (3..=200).collect::<Vec<u64>>());
    // A rebirth restarts at 0 whatever came before.
    r.node.handle_message(
        "spBv1.0/G/NCMD/E",
        &cmd(vec![write(REBIRTH, MetricValue::BooleanValue(true))]),
        0,
    );
    let seqs: Vec<_> = r.tick().iter().map(|(_, p)| p.seq).collect();
    assert_eq!(seqs, [Some(0), Some(1), Some(2)]);
    // 255, then 0: DDATAs of the outputs written and of the inputs the
    // echo slave sends back.
    let seqs = seqs_of_writes(&mut r, 254);
    let want: Vec<u64> = (3..=255).chain([0]).collect();
    assert_eq!(seqs[..254], want);
}

#[test]
fn outputs_go_to_the_safe_state_without_a_broker() {
    let mut r = Rig::with(|s| {
        s.outputs_timeout = Some(std::time::Duration::from_millis(100));
        s.safe_state = SafeState::Zero;
    });
    r.node.connected(0);
    r.until("spBv1.0/G/DBIRTH/E/4");
    r.node.handle_message(
        "spBv1.0/G/DCMD/E/3",
        &cmd(vec![write(
            metrics::OUTPUT_IMAGE,
            MetricValue::BytesValue(vec![5; 4]),
        )]),
        0,
    );
    r.tick();
    assert_eq!(r.plant.master().outputs(3).unwrap(), [5; 4]);
    // The broker goes away at ts 1000 + t; 100 ms later the outputs
    // of the writable slave are zero.
    r.node.disconnected(1000 + r.t);
    for _ in 0..99 {
        r.tick();
    }
    assert_eq!(r.plant.master().outputs(3).unwrap(), [5; 4], "not yet");
    for _ in 0..2 {
        r.tick();
    }
    assert_eq!(r.plant.master().outputs(3).unwrap(), [0; 4]);
}

/// Aliases unique in the node; the node's own metrics in NBIRTH and
/// NDATA; commands by alias.
#[test]
fn aliases_node_metrics_and_commands_by_alias() {
    use profibus_gateway::sparkplug::{device_alias, BUS_STATE, CYCLE_TIME, IN_DATA_EXCHANGE};
    let mut r = Rig::new();
    r.node.connected(0);
    let msgs = r.until("spBv1.0/G/DBIRTH/E/4");
    let mut aliases: Vec<u64> = msgs
        .iter()
        .flat_map(|(_, p)| p.metrics.iter().filter_map(|m| m.alias))
        .collect();
    let n = aliases.len();
    aliases.sort();
    aliases.dedup();
    assert_eq!(aliases.len(), n, "aliases unique in the edge node");
    let nbirth = find(&msgs, "spBv1.0/G/NBIRTH/E");
    assert_eq!(
        value(nbirth, BUS_STATE),
        Some(&MetricValue::StringValue("operate".into()))
    );
    // The node metrics change: an NDATA within interval_ms (1 s).
    let msgs = r.until("spBv1.0/G/NDATA/E");
    let nd = find(&msgs, "spBv1.0/G/NDATA/E");
    assert!(
        matches!(value(nd, CYCLE_TIME), Some(MetricValue::DoubleValue(ms)) if *ms > 0.0 && *ms < 10.0),
        "{nd:?}"
    );
    assert_eq!(value(nd, IN_DATA_EXCHANGE), Some(&MetricValue::IntValue(2)));
    // The master goes to Clear: an NDATA at once.
    r.plant
        .master()
        .set_operating_state(profibus_dp::master::OperatingState::Clear);
    let nd = r.tick();
    assert_eq!(
        value(find(&nd, "spBv1.0/G/NDATA/E"), BUS_STATE),
        Some(&MetricValue::StringValue("clear".into()))
    );
    r.plant
        .master()
        .set_operating_state(profibus_dp::master::OperatingState::Operate);
    // A DCMD by alias: `Image/Outputs` of slave 3 is its metric 4 (after
    // address, name, ident, inputs).
    let alias = *r
        .names
        .iter()
        .find(|(a, n)| **a >> 16 == 4 && *n == metrics::OUTPUT_IMAGE)
        .unwrap()
        .0;
    assert_eq!(alias, device_alias(3, 4));
    r.node.handle_message(
        "spBv1.0/G/DCMD/E/3",
        &cmd(vec![Metric {
            alias: Some(alias),
            value: Some(MetricValue::BytesValue(vec![5, 6, 7, 8])),
            ..Default::default()
        }]),
        0,
    );
    r.tick();
    assert_eq!(r.plant.master().outputs(3).unwrap(), [5, 6, 7, 8]);
    // A rebirth by the alias of `Node Control/Rebirth` (0).
    r.node.handle_message(
        "spBv1.0/G/NCMD/E",
        &cmd(vec![Metric {
            alias: Some(0),
            value: Some(MetricValue::BooleanValue(true)),
            ..Default::default()
        }]),
        0,
    );
    let t: Vec<String> = r.tick().into_iter().map(|m| m.0).collect();
    assert_eq!(
        t[..3],
        [
            "spBv1.0/G/NBIRTH/E",
            "spBv1.0/G/DBIRTH/E/3",
            "spBv1.0/G/DBIRTH/E/4"
        ]
    );
}

/// With `primary_host`: no NBIRTH before its STATE says online; data
/// held while it is offline; a rebirth when it is back; an older STATE
/// ignored.
#[test]
fn primary_host_state_holds_data_and_rebirths() {
    let state = |online: bool, ts: u64| format!(r#"{{"online": {online}, "timestamp": {ts}}}"#);
    let mut r = Rig::with(|s| s.primary_host = Some("scada".into()));
    let filters = r.node.link_setup().filters;
    assert_eq!(filters[2], "spBv1.0/STATE/scada");
    r.node.connected(0);
    for _ in 0..200 {
        assert!(r.tick().is_empty(), "nothing before the host is online");
    }
    r.node
        .handle_message("spBv1.0/STATE/scada", state(true, 10).as_bytes(), 0);
    r.until("spBv1.0/G/DBIRTH/E/4");
    // Offline: nothing, whatever changes.
    r.node
        .handle_message("spBv1.0/STATE/scada", state(false, 20).as_bytes(), 0);
    r.node.handle_message(
        "spBv1.0/G/DCMD/E/3",
        &cmd(vec![write(
            metrics::OUTPUT_IMAGE,
            MetricValue::BytesValue(vec![9, 9, 9, 9]),
        )]),
        0,
    );
    for _ in 0..600 {
        assert!(r.tick().is_empty(), "held while the host is offline");
    }
    assert_eq!(r.plant.master().outputs(3).unwrap(), [9, 9, 9, 9]);
    // An older online STATE (a stale retained one) changes nothing.
    r.node
        .handle_message("spBv1.0/STATE/scada", state(true, 15).as_bytes(), 0);
    assert!(r.tick().is_empty());
    // Online again: NBIRTH (seq 0) and every DBIRTH, with the values now.
    r.node
        .handle_message("spBv1.0/STATE/scada", state(true, 30).as_bytes(), 0);
    let msgs = r.tick();
    assert_eq!(msgs[0].0, "spBv1.0/G/NBIRTH/E");
    assert_eq!(msgs[0].1.seq, Some(0));
    let b3 = find(&msgs, "spBv1.0/G/DBIRTH/E/3");
    assert_eq!(
        value(b3, metrics::INPUT_IMAGE),
        Some(&MetricValue::BytesValue(vec![9, 9, 9, 9]))
    );
}

/// `[mqtt] alerts`: the NBIRTH declares `Bus/Alert` (String, alias 7,
/// empty before the first alert); a rule that holds sends each alert in
/// an NDATA of its own, by alias, with the alert's JSON (rule, station,
/// value), at most once per alert interval.
#[test]
fn alerts_go_out_as_the_bus_alert_node_metric() {
    use profibus_dp::monitor::alert::AlertRule;
    use profibus_gateway::sparkplug::ALERT;
    let mut r = Rig::with(|s| {
        s.alerts = vec![AlertRule::parse("3:requests>0").unwrap()];
        s.alert_interval = std::time::Duration::from_millis(200);
    });
    r.node.connected(0);
    let msgs = r.until("spBv1.0/G/DBIRTH/E/4");
    let nbirth = find(&msgs, "spBv1.0/G/NBIRTH/E");
    let born = nbirth
        .metrics
        .iter()
        .find(|m| m.name.as_deref() == Some(ALERT))
        .expect("Bus/Alert in the NBIRTH");
    assert_eq!(born.alias, Some(7));
    assert_eq!(born.datatype, Some(DataType::String as u32));
    assert_eq!(born.value, Some(MetricValue::StringValue(String::new())));
    // The rule holds in every interval (slave 3 is polled): alerts come
    // as NDATA with only Bus/Alert in them.
    let mut alerts = vec![];
    let start = r.t;
    while alerts.len() < 3 {
        assert!(r.t - start < 2000, "3 alerts within 2 s of bus time");
        for (t, p) in r.tick() {
            if t != "spBv1.0/G/NDATA/E" {
                continue;
            }
            if let Some(MetricValue::StringValue(json)) = value(&p, ALERT) {
                assert_eq!(p.metrics.len(), 1, "an alert in an NDATA of its own");
                assert_eq!(p.metrics[0].alias, Some(7));
                alerts.push((r.t, json.clone()));
            }
        }
    }
    for (_, json) in &alerts {
        let v: serde_json::Value = serde_json::from_str(json).unwrap();
        assert_eq!(v["rule"], "3:requests>0", "{v}");
        assert_eq!(v["station"], 3, "{v}");
        assert!(v["value"].as_f64().unwrap() > 0.0, "{v}");
    }
    let gaps: Vec<u64> = alerts.windows(2).map(|w| w[1].0 - w[0].0).collect();
    assert!(
        gaps.iter().all(|g| *g >= 190),
        "one per 200 ms interval: {gaps:?}"
    );
}
