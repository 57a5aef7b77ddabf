//! The simulated plant of `dpctl demo`: a DP master and the emulated
//! slaves of `profibus-plant`'s demo plant (generic GSD devices, BM4-O-PRO-01,
//! Omega, BK3000, JX2-PROFI1; `dpctl demo` adds its RFID reader) on a
//! paced 1.5 Mbit/s line in virtual time, with the
//! demo's PLC program writing outputs and running PKW jobs. Runs two
//! seconds of bus time as fast as the machine can, then prints each
//! slave's state and the plant's summary.
//!
//! Run: `cargo run --example sim_plant`

use profibus::fdl::Instant;
use profibus_plant::demo::DemoPlant;
use std::time::Duration;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut plant = DemoPlant::new(vec![])?;
    let end = Instant::ZERO + Duration::from_secs(2);
    while plant.now() < end {
        plant.advance(None); // one step of bus time
        for job in plant.step(|_| false) {
            println!("{job:?}");
        }
    }
    let addresses: Vec<u8> = plant.master().slave_addresses().collect();
    for address in addresses {
        let state = plant.master().slave_state(address);
        println!("slave {address}: {state:?}");
    }
    println!("{}", plant.summary());
    Ok(())
}
