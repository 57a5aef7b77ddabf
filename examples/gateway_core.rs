//! The MQTT gateway's core without a broker: `profibus_gateway::Gateway`
//! is sans-IO, so it can be stepped next to a DP master on the simulated
//! plant of `dpctl gateway --sim` and its messages printed instead of
//! published. An Omega drive (address 25) is written by channel name
//! through the topic a client would use, and its inputs follow. The
//! protocol: docs/gateway.md.
//!
//! Run: `cargo run --example gateway_core`

use profibus::devices::bus::ProfiledBus;
use profibus_gateway::{slave_infos, Gateway, MqttSettings};
use profibus_plant::Plant;
use std::time::Duration;

const BUS: &str = r#"
[master]
address = 2
baud = "1.5M"

[[slave]]
address = 25
device = "omega"

[mqtt]
bus = "line1"
writable = [25]
"#;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Relative file names in a bus file are relative to its directory.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("line1.toml");
    let bus = ProfiledBus::parse(&dir, BUS)?;
    let settings = MqttSettings::from_table(bus.file.mqtt.as_ref(), "line1")?;
    let mut gateway = Gateway::new(settings, slave_infos(&bus)?);
    let mut plant = Plant::from_bus(&bus)?;
    gateway.connected(0);
    for ms in 1..=300u64 {
        // One millisecond of bus time, then the gateway at the boundary.
        let t = plant.now() + Duration::from_millis(1);
        plant.run_until(t);
        gateway.step(plant.master(), t, ms);
        if ms == 100 {
            let set = br#"{"channels": {"setpoint1": 1500}, "id": 1}"#;
            gateway.handle_message("profibus/line1/25/outputs/set", set, ms);
        }
        while let Some(p) = gateway.poll_publish() {
            let interesting = p.topic.ends_with("/inputs") || p.topic.contains("response");
            if interesting || ms == 1 {
                let payload = String::from_utf8_lossy(&p.payload);
                println!("{ms:>3} ms  {}  {payload}", p.topic);
            }
        }
    }
    Ok(())
}
