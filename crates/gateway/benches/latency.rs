//! Latency of the gateway: a slave's input change on the simulated bus
//! (1.5 Mbit/s, paced on the wall clock, the loop of `dpctl gateway
//! --sim`) to its receipt by an MQTT subscriber, through a real mosquitto
//! started here on a free localhost port.
//!
//! `cargo bench -p profibus-gateway --bench latency [-- SAMPLES]`
//!
//! The slave echoes its outputs into its inputs; every 50 ms the bench
//! writes a new output value. Measured per sample: from the moment the
//! master holds the new inputs (seen after a bus step) and from the
//! output write, to the subscriber's receipt of `…/3/inputs` with it.

use profibus_devices::bus::ProfiledBus;
use profibus_fdl::Instant as BusInstant;
use profibus_gateway::link::{flush, pump, wall_ms};
use profibus_gateway::sim::{slave_infos, SimPlant};
use profibus_gateway::{Gateway, MqttLink, MqttSettings};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use std::collections::HashMap;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BUS: &str = r#"[master]
address = 1
baud = "1.5M"

[[slave]]
address = 3
gsd = "DPCTL_GEN.GSD"
modules = ["2 words in/out"]

[mqtt]
bus = "bench"
writable = [3]
"#;

fn mosquitto() -> String {
    for p in ["mosquitto", "/usr/sbin/mosquitto"] {
        if Command::new(p)
            .arg("-h")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok()
        {
            return p.into();
        }
    }
    panic!("mosquitto is missing: run scripts/setup-test-env");
}

fn pct(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn main() {
    let samples: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(300);
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let dir = std::env::temp_dir().join(format!("gw-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let conf = dir.join("mosquitto.conf");
    std::fs::write(
        &conf,
        format!("listener {port} 127.0.0.1\nallow_anonymous true\n"),
    )
    .unwrap();
    let mut broker = Command::new(mosquitto())
        .arg("-c")
        .arg(&conf)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        std::thread::sleep(Duration::from_millis(5));
    }

    let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../gsd/bus.toml"));
    let profiled = ProfiledBus::parse(path, BUS).unwrap();
    let settings = MqttSettings::from_table(profiled.file.mqtt.as_ref(), "bench").unwrap();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let (in_ms, write_ms, cycle_us) = rt.block_on(async move {
        let mut gw = Gateway::new(settings, slave_infos(&profiled).unwrap());
        let mut link = MqttLink::connect("127.0.0.1", port, &gw);
        // The subscriber.
        let (sub, mut ev) = AsyncClient::new(MqttOptions::new("bench-sub", "127.0.0.1", port), 64);
        sub.subscribe("profibus/bench/3/inputs", QoS::AtMostOnce)
            .await
            .unwrap();
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<(Instant, String)>();
        tokio::spawn(async move {
            while let Ok(e) = ev.poll().await {
                if let Event::Incoming(Packet::Publish(p)) = e {
                    let v: serde_json::Value = serde_json::from_slice(&p.payload).unwrap();
                    let _ = tx.send((Instant::now(), v["hex"].as_str().unwrap_or("").to_string()));
                }
            }
        });
        let mut plant = SimPlant::new(&profiled).unwrap();
        let start = tokio::time::Instant::now();
        let tick = Duration::from_millis(2);
        let mut written: HashMap<String, Instant> = HashMap::new();
        let mut seen: HashMap<String, Instant> = HashMap::new();
        let (mut in_ms, mut write_ms) = (vec![], vec![]);
        let mut value: u32 = 0;
        let mut next_write = Instant::now() + Duration::from_millis(500);
        while in_ms.len() < samples {
            plant.run_until(BusInstant::from_nanos(start.elapsed().as_nanos() as u64));
            let bus_now = plant.now();
            let m = plant.master();
            let now = Instant::now();
            let inputs = profibus_gateway::core::hex(m.inputs(3).unwrap());
            if written.contains_key(&inputs) && !seen.contains_key(&inputs) {
                seen.insert(inputs.clone(), now);
            }
            if now >= next_write && m.slave_state(3).map(|s| s.name()) == Some("data_exchange") {
                next_write = now + Duration::from_millis(50);
                value += 1;
                let b = value.to_be_bytes();
                m.set_outputs(3, &b);
                written.insert(profibus_gateway::core::hex(&b), now);
            }
            let ts = wall_ms();
            pump(&mut link, &mut gw, ts);
            gw.step(m, bus_now, ts);
            flush(&link, &mut gw);
            while let Ok((at, hex)) = rx.try_recv() {
                if let (Some(w), Some(s)) = (written.get(&hex), seen.get(&hex)) {
                    write_ms.push((at - *w).as_secs_f64() * 1e3);
                    in_ms.push((at - *s).as_secs_f64() * 1e3);
                }
            }
            tokio::time::sleep(tick).await;
        }
        (
            in_ms,
            write_ms,
            plant.master().cycle_stats().avg().as_micros(),
        )
    });
    let _ = broker.kill();
    let _ = broker.wait();
    let _ = std::fs::remove_dir_all(&dir);
    let (mut a, mut b) = (in_ms, write_ms);
    let cyc = cycle_us as f64 / 1e3;
    println!(
        "samples {}, bus cycle avg {cyc:.3} ms (1.5 Mbit/s, 1 slave)",
        a.len()
    );
    let (a50, a99) = (pct(&mut a, 0.5), pct(&mut a, 0.99));
    let (b50, b99) = (pct(&mut b, 0.5), pct(&mut b, 0.99));
    println!("inputs at the master -> subscriber: p50 {a50:.2} ms ({:.1} cycles), p99 {a99:.2} ms ({:.1} cycles)", a50 / cyc, a99 / cyc);
    println!("output write -> echoed inputs at the subscriber: p50 {b50:.2} ms ({:.1} cycles), p99 {b99:.2} ms ({:.1} cycles)", b50 / cyc, b99 / cyc);
}
