//! The gateway's MQTT message handler (`Gateway::handle_message`, which
//! turns a topic and payload into an output write) with arbitrary topics
//! and payloads, and `Gateway::step` applying what it accepted to a DP
//! master's output images. No broker. Checks: no panic; every publish is
//! a JSON document on a topic under the gateway's prefix; output images
//! keep their configured lengths; a write to a slave not listed in
//! `writable` never changes its outputs.
//!
//! Records: `topic, len, payload[len]`. `topic % 8`: 0-3 the write topic
//! of slave 8, 9, 10 or 77 (unknown); 4 a topic from the payload's first
//! line; 5 another gateway's write topic; 6 `step` with the master;
//! 7 `connected` (republish everything), then `disconnected`.
//!
//! Run: `cd fuzz && cargo +nightly fuzz run gateway_message`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams};
use profibus_fdl::{Baud, BusParams};
use profibus_fuzz::{cached, profile_fixture, Fixture};
use profibus_gateway::core::{Gateway, SlaveInfo};
use profibus_gateway::settings::MqttSettings;
use std::sync::OnceLock;

static OMEGA: OnceLock<Fixture> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let fx = cached(&OMEGA, || profile_fixture("omega", ""));
    let mut table = toml::Table::new();
    table.insert(
        "writable".into(),
        toml::Value::Array(vec![8.into(), 9.into()]),
    );
    let settings = MqttSettings::from_table(Some(&table), "fuzz").unwrap();
    let mut omega = fx.params.clone();
    omega.address = 8;
    let slaves = vec![
        omega,
        SlaveParams::new(9, 0x0DCE, vec![0x21]),
        SlaveParams::new(10, 0x0DCE, vec![0x21]),
    ];
    let mut master = DpMaster::new(&MasterConfig {
        address: 2,
        params: BusParams::defaults(Baud::B1500000),
        slaves,
        options: MasterOptions::default(),
    })
    .unwrap();
    let info = |address: u8, channels| SlaveInfo {
        address,
        name: format!("s{address}"),
        channels,
        gsd: None,
        dpv1: false,
    };
    let mut gw = Gateway::new(
        settings,
        vec![
            info(8, fx.profile().channels(&fx.params.cfg).ok()),
            info(9, None),
            info(10, None),
        ],
    );
    let before10 = master.outputs(10).unwrap().to_vec();
    let mut ts = 1_700_000_000_000u64;
    let mut rest = data;
    while let [sel, len, tail @ ..] = rest {
        let n = (*len as usize * 4).min(tail.len());
        let (payload, tail) = tail.split_at(n);
        rest = tail;
        ts += 7;
        let topic;
        let t: &str = match sel % 8 {
            s @ 0..=3 => {
                topic = format!("profibus/fuzz/{}/outputs/set", [8, 9, 10, 77][s as usize]);
                &topic
            }
            4 => {
                let text = String::from_utf8_lossy(payload);
                topic = text.lines().next().unwrap_or("").to_string();
                &topic
            }
            5 => "profibus/other/8/outputs/set",
            6 => {
                gw.step(&mut master, ts);
                continue;
            }
            _ => {
                gw.connected(ts);
                gw.disconnected();
                continue;
            }
        };
        gw.handle_message(t, payload, ts);
    }
    gw.step(&mut master, ts);
    while let Some(p) = gw.poll_publish() {
        assert!(p.topic.starts_with("profibus/fuzz/"), "topic {}", p.topic);
        if let Err(e) = serde_json::from_slice::<serde_json::Value>(&p.payload) {
            panic!(
                "{}: not JSON ({e}): {:?}",
                p.topic,
                String::from_utf8_lossy(&p.payload)
            );
        }
    }
    for a in [8u8, 9, 10] {
        let want = master.slave_params(a).unwrap().io_lengths().unwrap().1;
        assert_eq!(master.outputs(a).unwrap().len(), want);
    }
    assert_eq!(
        master.outputs(10).unwrap(),
        &before10[..],
        "unwritable slave written"
    );
});
