//! Report by exception on the simulated plant of `dpctl gateway --sim`:
//! a BK3000 with two KL3102 analog inputs (±10 V, sine waves that change
//! in every poll cycle) published by both cores, with the default
//! deadband and minimum interval and with both off. No broker.

use profibus_devices::bus::ProfiledBus;
use profibus_fdl::Instant;
use profibus_gateway::sparkplug::devices;
use profibus_gateway::{slave_infos, EdgeNode, Gateway, MqttSettings, Session, SparkplugId};
use profibus_plant::Plant;
use std::time::Duration;

/// A BK3000 (40) with two KL3102: four analog inputs; `mqtt` is the
/// `[mqtt]` table.
fn bus(mqtt: &str) -> ProfiledBus {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../devices/gsd/plant.toml");
    let text = format!(
        "[master]\naddress = 1\nbaud = \"1.5M\"\n\n\
         [[slave]]\naddress = 40\ndevice = \"bk3000\"\nterminals = [\"KL3102\", \"KL3102\", \"KL9010\"]\n\n\
         [mqtt]\nbus = \"p\"\n{mqtt}\n"
    );
    ProfiledBus::parse(&dir, &text).unwrap()
}

/// Run `session` on the plant for `ms` of bus time (a step per ms, the
/// bus time as the wall clock); the publish times (ms) of `topic`.
fn run(bus: &ProfiledBus, session: &mut impl Session, topic: &str, ms: u64) -> Vec<u64> {
    let mut plant = Plant::from_bus(bus).unwrap();
    session.connected(0);
    let mut at = vec![];
    for t in 1..=ms {
        let now = Instant::ZERO + Duration::from_millis(t);
        plant.run_until(now);
        session.step(plant.master(), now, t);
        while let Some(p) = session.poll_publish() {
            if p.topic == topic {
                at.push(t);
            }
        }
    }
    at
}

fn json(mqtt: &str) -> (ProfiledBus, Gateway) {
    let b = bus(mqtt);
    let s = MqttSettings::from_table(b.file.mqtt.as_ref(), "p").unwrap();
    let g = Gateway::new(s, slave_infos(&b).unwrap());
    (b, g)
}

fn edge(mqtt: &str) -> (ProfiledBus, EdgeNode) {
    let b = bus(mqtt);
    let s = MqttSettings::from_table(b.file.mqtt.as_ref(), "p").unwrap();
    let n = EdgeNode::new(s, SparkplugId::parse("G/E").unwrap(), devices(&b).unwrap());
    (b, n)
}

/// The rate (per s) of the publishes in `at` after the first second
/// (start-up: the slave's parameterisation).
fn rate(at: &[u64], ms: u64) -> f64 {
    at.iter().filter(|t| **t > 1000).count() as f64 / ((ms - 1000) as f64 / 1000.0)
}

/// No two publishes closer than `min` ms (after the first).
fn spaced(at: &[u64], min: u64) -> bool {
    at.windows(2).skip(1).all(|w| w[1] - w[0] >= min)
}

#[test]
fn a_noisy_analog_slave_is_a_few_messages_per_second_by_default() {
    const MS: u64 = 4000;
    let topic = "profibus/p/40/inputs";
    let (b, mut g) = json("");
    let default = run(&b, &mut g, topic, MS);
    let (b, mut g) = json("deadband = 0\nmin_interval_ms = 0");
    let every = run(&b, &mut g, topic, MS);
    let (d, e) = (rate(&default, MS), rate(&every, MS));
    eprintln!("JSON inputs of a BK3000 with 4 analog inputs: {d:.1}/s by default, {e:.1}/s with deadband 0 and min_interval_ms 0");
    assert!(e > 300.0, "every change is a message without them: {e}/s");
    assert!((1.0..=4.0).contains(&d), "{d}/s by default");
    assert!(spaced(&default, 250), "{default:?}");
    // A longer interval per slave.
    let (b, mut g) = json("[[mqtt.slave]]\naddress = 40\nmin_interval_ms = 1000");
    let slow = run(&b, &mut g, topic, MS);
    assert!(spaced(&slow, 1000), "{slow:?}");
    assert!(rate(&slow, MS) <= 1.0);
    // A per-channel deadband of 2 V: fewer.
    let (b, mut g) = json("min_interval_ms = 0\n[[mqtt.slave]]\naddress = 40\ndeadband = 2.0");
    let coarse = rate(&run(&b, &mut g, topic, MS), MS);
    assert!(coarse < d * 2.0 && coarse > 0.0, "{coarse}/s with 2 V");
}

#[test]
fn sparkplug_ddata_is_bounded_the_same_way() {
    const MS: u64 = 4000;
    let topic = "spBv1.0/G/DDATA/E/40";
    let (b, mut n) = edge("");
    let default = run(&b, &mut n, topic, MS);
    let (b, mut n) = edge("deadband = 0\nmin_interval_ms = 0");
    let every = run(&b, &mut n, topic, MS);
    let (d, e) = (rate(&default, MS), rate(&every, MS));
    eprintln!("Sparkplug DDATA of the same slave: {d:.1}/s by default, {e:.1}/s with deadband 0 and min_interval_ms 0");
    assert!(e > 300.0, "{e}/s");
    assert!((1.0..=4.0).contains(&d), "{d}/s by default");
    assert!(spaced(&default, 250), "{default:?}");
}
