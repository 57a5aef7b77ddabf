//! Latency of the gateway: a slave's input change on the simulated bus
//! (1.5 Mbit/s, paced on the wall clock by the `Pacer` of `dpctl gateway
//! --sim`) to its receipt by an MQTT subscriber, through a real mosquitto
//! started here on a free localhost port.
//!
//! `cargo bench -p profibus-gateway --bench latency [-- SAMPLES]`
//!
//! The slave echoes its outputs into its inputs; every 50 ms the bench
//! writes a new output value. The bus runs each turn in 25 µs pieces, so
//! the bench knows when (in bus time, i.e. on the wall clock the line is
//! paced on) the master first held the new inputs. Measured per sample:
//! that input change, the gateway's step that sent the message (the
//! `…/3/inputs` publish handed to the MQTT client), the subscriber's
//! receipt (its own client and runtime, like another process), and the
//! output write that caused it.

mod support;

use profibus_gateway::link;
use profibus_gateway::payload::hex;
use profibus_io::pace::Pacer;
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use support::{pct, run_gateway, Broker};

/// Master 1 with the echo slave at 3, writable over MQTT.
const BUS: &str = include_str!("data/latency_bus.toml");

/// The times of one sample, by the inputs' hex.
#[derive(Default, Clone, Copy)]
struct Sample {
    write: Option<Instant>,
    change: Option<Instant>,
    step: Option<Instant>,
    receipt: Option<Instant>,
}

fn ms(a: Instant, b: Instant) -> f64 {
    b.saturating_duration_since(a).as_secs_f64() * 1e3
}

fn main() {
    let samples: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(300);
    let broker = Broker::start("latency", "");
    let port = broker.port;
    let book: Arc<Mutex<HashMap<String, Sample>>> = Arc::default();
    let done = Arc::new(AtomicBool::new(false));

    // The subscriber: a runtime of its own on another thread.
    let (b2, d2) = (book.clone(), done.clone());
    let subscriber = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async move {
            let (sub, mut ev) =
                AsyncClient::new(MqttOptions::new("bench-sub", "127.0.0.1", port), 64);
            sub.subscribe("profibus/bench/3/inputs", QoS::AtMostOnce)
                .await
                .unwrap();
            let mut received = 0;
            while let Ok(e) = ev.poll().await {
                if let Event::Incoming(Packet::Publish(p)) = e {
                    let at = Instant::now();
                    let v: serde_json::Value = serde_json::from_slice(&p.payload).unwrap();
                    let h = v["hex"].as_str().unwrap_or("").to_string();
                    if let Some(s) = b2.lock().unwrap().get_mut(&h) {
                        if s.change.is_some() && s.receipt.is_none() {
                            s.receipt = Some(at);
                            received += 1;
                        }
                    }
                }
                if received >= samples {
                    d2.store(true, Ordering::Relaxed);
                    return;
                }
            }
        });
    });

    let cycle_us = run_gateway(BUS, port, |plant, pacer, gw, link| {
        let piece = Duration::from_micros(25);
        let mut value: u32 = 0;
        let mut next_write = Instant::now() + Duration::from_millis(500);
        let mut unseen: Option<String> = None;
        // A bound in case messages are lost: three times the planned run.
        let deadline = Instant::now() + Duration::from_millis(150 * samples as u64 + 10_000);
        while !done.load(Ordering::Relaxed) && Instant::now() < deadline {
            let (target, behind) = pacer.target(plant.now());
            while plant.now() < target {
                let t = (plant.now() + piece).min(target);
                plant.run_until(t);
                let Some(h) = unseen.as_ref() else { continue };
                if hex(plant.master().inputs(3).unwrap()) == *h {
                    let at = pacer.wall_time(plant.now());
                    book.lock().unwrap().entry(h.clone()).or_default().change = Some(at);
                    unseen = None;
                }
            }
            let now = Instant::now();
            let m = plant.master();
            if unseen.is_none()
                && now >= next_write
                && m.slave_state(3).map(|s| s.name()) == Some("data_exchange")
            {
                next_write = now + Duration::from_millis(50);
                value += 1;
                let b = value.to_be_bytes();
                m.set_outputs(3, &b);
                let h = hex(&b);
                book.lock().unwrap().entry(h.clone()).or_default().write = Some(now);
                unseen = Some(h);
            }
            let bus_now = plant.now();
            link::step(link, gw, plant.master(), bus_now);
            let sent = Instant::now();
            for s in book.lock().unwrap().values_mut() {
                if s.change.is_some() && s.step.is_none() {
                    s.step = Some(sent);
                }
            }
            if !behind {
                std::thread::sleep(Pacer::TICK);
            }
        }
        plant.master().cycle_stats().avg().as_micros()
    });
    // The subscriber thread ends with the process.
    drop(subscriber);
    drop(broker);

    let book = book.lock().unwrap();
    let full: Vec<Sample> = book
        .values()
        .filter(|s| s.receipt.is_some())
        .copied()
        .collect();
    let col = |f: &dyn Fn(&Sample) -> f64| -> Vec<f64> { full.iter().map(f).collect() };
    let rows: [(&str, Vec<f64>); 4] = [
        (
            "slave input change -> subscriber",
            col(&|s| ms(s.change.unwrap(), s.receipt.unwrap())),
        ),
        (
            "  input change -> gateway step sent (pacing)",
            col(&|s| ms(s.change.unwrap(), s.step.unwrap())),
        ),
        (
            "  gateway step sent -> subscriber (client, broker)",
            col(&|s| ms(s.step.unwrap(), s.receipt.unwrap())),
        ),
        (
            "output write -> echoed inputs at the subscriber",
            col(&|s| ms(s.write.unwrap(), s.receipt.unwrap())),
        ),
    ];
    let cyc = cycle_us as f64 / 1e3;
    println!(
        "samples {}, bus cycle avg {cyc:.3} ms (1.5 Mbit/s, 1 slave), tick {} us, target p99 <= {:.2} ms",
        full.len(),
        Pacer::TICK.as_micros(),
        cyc + 2.0
    );
    for (name, mut v) in rows {
        let (p50, p99) = (pct(&mut v, 0.5), pct(&mut v, 0.99));
        println!(
            "{name}: p50 {p50:.2} ms ({:.1} cycles), p99 {p99:.2} ms ({:.1} cycles)",
            p50 / cyc,
            p99 / cyc
        );
    }
}
