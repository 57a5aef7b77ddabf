//! The gateway's Sparkplug B message handler (`EdgeNode`, a `Session`:
//! NCMD and DCMD protobuf payloads become rebirths and output writes) with
//! arbitrary topics and payloads, raw or built from metrics the input
//! chooses, and `step` applying what it accepted to a DP master. No
//! broker. Checks: no panic; every publish goes to a topic without
//! wildcards; output images keep their lengths; the outputs of the slave
//! not listed in `writable` never change.
//!
//! Slaves: 8 an Omega drive (named channels, one writable), 10 and 11 plain
//! slaves (10 writable). Records: `sel, len, payload[len·4]`. `sel % 8`:
//! 0 NCMD with the raw payload; 1-3 DCMD of device 8, 10, 11 with the raw
//! payload; 4-5 DCMD of device 8 / 10 with metrics built from the payload
//! (4 bytes each: name, data type, value); 6 `step`; 7 `disconnected`
//! then `connected`.
//!
//! Run: `cd fuzz && cargo +nightly fuzz run sparkplug_message`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_devices::channels::Direction;
use profibus_dp::config::layout::{Capabilities, SlaveLayout};
use profibus_dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams};
use profibus_fdl::{Baud, BusParams, Instant};
use profibus_fuzz::{cached, profile_fixture, Fixture};
use profibus_gateway::sparkplug::proto::{Metric, MetricValue, Payload};
use profibus_gateway::sparkplug::{metrics, MessageType, REBIRTH};
use profibus_gateway::{EdgeNode, MqttSettings, Session, SlaveInfo, SparkplugId};
use prost::Message;
use std::sync::OnceLock;
use std::time::Duration;

static OMEGA: OnceLock<Fixture> = OnceLock::new();

struct Setup {
    settings: MqttSettings,
    slaves: Vec<SlaveInfo>,
    master: MasterConfig,
    names: Vec<String>,
}

fn setup() -> Setup {
    let omega = cached(&OMEGA, || profile_fixture("omega", ""));
    let map = omega.profile().channels(&omega.params.cfg).ok();
    let outs: Vec<String> = map
        .as_ref()
        .map(|m| m.of(Direction::Output).map(|c| c.name.clone()).collect())
        .unwrap_or_default();
    let first = outs.first().cloned().unwrap_or_else(|| "none".into());
    let table: toml::Table = toml::from_str(&format!(
        "writable = [10, {{ address = 8, channels = [\"{first}\"] }}]"
    ))
    .unwrap();
    let settings = MqttSettings::from_table(Some(&table), "fuzz").unwrap();
    let mut p8 = omega.params.clone();
    p8.address = 8;
    let master = MasterConfig {
        address: 2,
        params: BusParams::defaults(Baud::B1500000),
        slaves: vec![
            p8,
            SlaveParams::new(10, 0x0DCE, vec![0x21, 0x11]),
            SlaveParams::new(11, 0x0DCE, vec![0x21]),
        ],
        options: MasterOptions::default(),
    };
    let info = |address: u8| SlaveInfo {
        layout: SlaveLayout {
            address,
            name: format!("s{address}"),
            ident_number: master
                .slaves
                .iter()
                .find(|s| s.address == address)
                .map_or(0, |s| s.ident_number),
            gsd: None,
            dpv1: false,
            modules: vec![],
            capabilities: Capabilities::empty(),
        },
        channels: if address == 8 { map.clone() } else { None },
        pkw: None,
    };
    let mut names = outs;
    names.extend(
        [
            metrics::OUTPUT_IMAGE,
            metrics::INPUT_IMAGE,
            metrics::NAME,
            REBIRTH,
        ]
        .map(String::from),
    );
    Setup {
        settings,
        slaves: vec![info(8), info(10), info(11)],
        master,
        names,
    }
}

static SETUP: OnceLock<Setup> = OnceLock::new();

/// A payload of metrics described by `b` (4 bytes each).
fn built(names: &[String], b: &[u8]) -> Vec<u8> {
    let metrics = b
        .chunks(4)
        .map(|c| {
            let g = |i: usize| c.get(i).copied().unwrap_or(0);
            let value = match g(1) % 8 {
                0 => None,
                1 => Some(MetricValue::IntValue(u32::from_le_bytes([
                    g(2),
                    g(3),
                    0,
                    g(2),
                ]))),
                2 => Some(MetricValue::LongValue(g(2) as u64 * 0x0101_0101_0101)),
                3 => Some(MetricValue::FloatValue(f32::from_bits(u32::from_le_bytes(
                    [g(2), g(3), g(2), g(3)],
                )))),
                4 => Some(MetricValue::DoubleValue(g(2) as f64 - g(3) as f64 * 1e3)),
                5 => Some(MetricValue::BooleanValue(g(2) & 1 != 0)),
                6 => Some(MetricValue::StringValue(format!(
                    "{:02x}{:02x}",
                    g(2),
                    g(3)
                ))),
                _ => Some(MetricValue::BytesValue(c.to_vec())),
            };
            Metric {
                name: Some(names[g(0) as usize % names.len()].clone()),
                datatype: Some((g(1) >> 3) as u32 % 20),
                value,
                ..Default::default()
            }
        })
        .collect();
    Payload {
        metrics,
        ..Default::default()
    }
    .encode_to_vec()
}

fn drain(node: &mut EdgeNode) {
    while let Some(p) = node.poll_publish() {
        assert!(
            !p.topic.is_empty() && !p.topic.contains(['+', '#', '\0']),
            "published to {:?}",
            p.topic
        );
    }
}

fuzz_target!(|data: &[u8]| {
    let s = SETUP.get_or_init(setup);
    let mut master = DpMaster::new(&s.master).unwrap();
    let id: SparkplugId = "fuzz/edge".parse().unwrap();
    let mut node = EdgeNode::from_infos(s.settings.clone(), id.clone(), s.slaves.clone());
    node.connected(0);
    let before11 = master.outputs(11).unwrap().to_vec();
    let mut now = Instant::ZERO;
    let mut ts = 1_700_000_000_000u64;
    let mut rest = data;
    while let [sel, len, tail @ ..] = rest {
        let n = (*len as usize * 4).min(tail.len());
        let (payload, tail) = tail.split_at(n);
        rest = tail;
        ts += 7;
        let dcmd = |d: &str| id.device_topic(MessageType::DCmd, d);
        match sel % 8 {
            0 => node.handle_message(&id.node_topic(MessageType::NCmd), payload, ts),
            k @ 1..=3 => node.handle_message(&dcmd(["8", "10", "11"][k as usize - 1]), payload, ts),
            k @ 4..=5 => {
                let p = built(&s.names, payload);
                node.handle_message(&dcmd(["8", "10"][k as usize - 4]), &p, ts)
            }
            6 => {
                now += Duration::from_millis(50);
                node.step(&mut master, now, ts);
            }
            _ => {
                node.disconnected(ts);
                node.connected(ts);
            }
        }
        drain(&mut node);
    }
    node.step(&mut master, now, ts);
    drain(&mut node);
    for a in [8u8, 10, 11] {
        let want = master.slave_params(a).unwrap().io_lengths().unwrap().1;
        assert_eq!(master.outputs(a).unwrap().len(), want);
    }
    assert_eq!(
        master.outputs(11).unwrap(),
        &before11[..],
        "unwritable slave written"
    );
});
