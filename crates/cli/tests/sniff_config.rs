//! `dpctl sniff --config BUS.toml`: the bus file's bus parameters are the
//! line's — its rate without `--baud`, and the TTR the token rotations
//! are measured against (`ttr_us`, `over_ttr`), which is not on the wire.

mod common;

use common::{dpctl, repo, Bus, Lines, Proc};
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::Duration;

#[test]
fn sniff_takes_the_rate_and_the_ttr_from_the_bus_file() {
    let bus = Bus::start(3, &["--baud", "1.5M"]);
    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let config = bus.dir().path("bus.toml");
    // TTR 2000 bit times = 1333.3 µs at 1.5 Mbit/s.
    std::fs::write(
        &config,
        format!(
            "[master]\naddress = 2\nbaud = \"1.5M\"\n[bus]\nttr = 2000\n\
             [[slave]]\naddress = 10\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\n",
            gsd.display()
        ),
    )
    .unwrap();
    let mut sniff = Proc::spawn(
        "dpctl sniff",
        Command::new(dpctl())
            .args([
                "sniff",
                "--json",
                "--stats",
                "0.5",
                "--port",
                &bus.link_str(2),
            ])
            .arg("--config")
            .arg(&config)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut lines = Lines::from(&mut sniff);
    let _slave = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--port", &bus.link_str(1), "--addr", "10"])
            .args(["--baud", "1.5M", "--gsd"])
            .arg(&gsd)
            .args(["--module", "2 words in/out"])
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    let _master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--port", &bus.link_str(0), "--config"])
            .arg(&config)
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    let end = std::time::Instant::now() + Duration::from_secs(60);
    let mut found = None;
    while let Some(l) = lines.next_line(end.saturating_duration_since(std::time::Instant::now())) {
        let v: Value = serde_json::from_str(&l).unwrap_or(Value::Null);
        let m = &v["totals"]["stations"]["2"];
        if v["event"] == "stats" && m["token_rotation"]["count"].as_u64() > Some(5) {
            found = Some(m.clone());
            break;
        }
    }
    let m = found.unwrap_or_else(|| panic!("no token rotations of master 2: {:?}", lines.1));
    let ttr = m["ttr_us"]
        .as_f64()
        .unwrap_or_else(|| panic!("no ttr_us: {m}"));
    assert!((ttr - 1333.33).abs() < 0.1, "{m}");
    // The rotations are counted against it.
    assert!(
        m["over_ttr"].as_u64() <= m["token_rotation"]["count"].as_u64(),
        "{m}"
    );
}
