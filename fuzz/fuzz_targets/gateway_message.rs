//! The gateway's MQTT message handlers (`Gateway::handle_message`: a topic
//! and payload become an output write, a DP-V1 read/write, a PKW job or
//! an RFID command, or a refusal) with arbitrary topics and payloads, and
//! `Gateway::step` carrying out what it accepted on a DP master (not
//! polling: jobs stay pending or time out). No broker. Checks: no panic;
//! every publish goes to a topic without wildcards and carries a JSON
//! document; output images keep their lengths; the outputs of a slave
//! not listed in `writable` never change.
//!
//! Slaves: 8 an Omega drive (PKW, named channels, one channel writable),
//! 9 an RFID reader, 10 a DP-V1 slave (both writable), 11 not writable.
//! Records: `sel, len, payload[len·4]`. `sel % 16`: 0-11 the request
//! topic of service `sel % 4` (outputs, dpv1, pkw, rfid) of slave
//! 8 + (sel / 4) % 3; 12 slave 11's outputs topic; 13 a topic from the
//! payload's first line; 14 `step` (`sel >> 4` × 50 ms later);
//! 15 `disconnected` then `connected`.
//!
//! Run: `cd fuzz && cargo +nightly fuzz run gateway_message`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_devices::channels::Direction;
use profibus_dp::config::layout::{Capabilities, SlaveLayout};
use profibus_dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams};
use profibus_fdl::{Baud, BusParams, Instant};
use profibus_fuzz::{cached, profile_fixture, Fixture};
use profibus_gateway::settings::MqttSettings;
use profibus_gateway::{Gateway, Service, SlaveInfo};
use std::sync::OnceLock;
use std::time::Duration;

static OMEGA: OnceLock<Fixture> = OnceLock::new();
static RFID: OnceLock<Fixture> = OnceLock::new();

/// Every publish: a topic without wildcards, a JSON payload.
fn drain(gw: &mut Gateway) {
    while let Some(p) = gw.poll_publish() {
        assert!(
            !p.topic.is_empty() && !p.topic.contains(['+', '#', '\0']),
            "published to {:?}",
            p.topic
        );
        if let Err(e) = serde_json::from_slice::<serde_json::Value>(&p.payload) {
            panic!(
                "{}: not JSON ({e}): {:?}",
                p.topic,
                String::from_utf8_lossy(&p.payload)
            );
        }
    }
}

struct Setup {
    settings: MqttSettings,
    slaves: Vec<SlaveInfo>,
    master: MasterConfig,
}

fn setup() -> Setup {
    let omega = cached(&OMEGA, || profile_fixture("omega", ""));
    let rfid = cached(&RFID, || profile_fixture("rfid", ""));
    let omega_map = omega.profile().channels(&omega.params.cfg).ok();
    let first_out = omega_map
        .as_ref()
        .and_then(|m| m.of(Direction::Output).next())
        .map_or("none".to_string(), |c| c.name.clone());
    let table: toml::Table = toml::from_str(&format!(
        "writable = [9, 10, {{ address = 8, channels = [\"{first_out}\"] }}]\njob_timeout_ms = 100"
    ))
    .unwrap();
    let settings = MqttSettings::from_table(Some(&table), "fuzz").unwrap();
    let mut p8 = omega.params.clone();
    p8.address = 8;
    let mut p9 = rfid.params.clone();
    p9.address = 9;
    let mut p10 = SlaveParams::new(10, 0x0DCE, vec![0x21, 0x11]);
    p10.dpv1 = true;
    p10.user_prm_data = vec![0x80, 0, 0];
    let p11 = SlaveParams::new(11, 0x0DCE, vec![0x21]);
    let master = MasterConfig {
        address: 2,
        params: BusParams::defaults(Baud::B1500000),
        slaves: vec![p8, p9, p10, p11],
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
            dpv1: address == 10,
            modules: vec![],
            capabilities: if address == 9 {
                Capabilities::RFID
            } else {
                Capabilities::empty()
            },
        },
        channels: if address == 8 {
            omega_map.clone()
        } else {
            None
        },
        pkw: if address == 8 {
            profibus_devices::profile("omega").unwrap().pkw
        } else {
            None
        },
    };
    Setup {
        settings,
        slaves: vec![info(8), info(9), info(10), info(11)],
        master,
    }
}

static SETUP: OnceLock<Setup> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let setup = SETUP.get_or_init(setup);
    let mut master = DpMaster::new(&setup.master).unwrap();
    let mut gw = Gateway::new(setup.settings.clone(), setup.slaves.clone());
    let before11 = master.outputs(11).unwrap().to_vec();
    let mut ts = 1_700_000_000_000u64;
    let mut now = Instant::ZERO;
    let mut rest = data;
    while let [sel, len, tail @ ..] = rest {
        let n = (*len as usize * 4).min(tail.len());
        let (payload, tail) = tail.split_at(n);
        rest = tail;
        ts += 7;
        let topic = match sel % 16 {
            s @ 0..=11 => format!(
                "profibus/fuzz/{}/{}",
                8 + (s / 4) % 3,
                Service::ALL[s as usize % 4].request()
            ),
            12 => "profibus/fuzz/11/outputs/set".to_string(),
            13 => String::from_utf8_lossy(payload)
                .lines()
                .next()
                .unwrap_or("")
                .to_string(),
            14 => {
                let dt = Duration::from_millis((sel >> 4) as u64 * 50);
                now += dt;
                ts += dt.as_millis() as u64;
                gw.step(&mut master, now, ts);
                drain(&mut gw);
                continue;
            }
            _ => {
                gw.disconnected(ts);
                gw.connected(ts);
                continue;
            }
        };
        gw.handle_message(&topic, payload, ts);
        drain(&mut gw);
    }
    now += Duration::from_secs(1);
    gw.step(&mut master, now, ts + 1000);
    drain(&mut gw);
    for a in [8u8, 9, 10, 11] {
        let want = master.slave_params(a).unwrap().io_lengths().unwrap().1;
        assert_eq!(master.outputs(a).unwrap().len(), want);
    }
    assert_eq!(
        master.outputs(11).unwrap(),
        &before11[..],
        "unwritable slave written"
    );
});
