//! `dpctl sniff --config BUS.toml` names the channels of a slave given as
//! a device profile, as `dpctl monitor` does: a `dpctl slave --device
//! bk3000` with pinned inputs, polled through `dpctl bus` by `dpctl
//! master` (which writes an output by name), sniffed on a third link —
//! the Data_Exchange data in the sniffer's JSON carry the slave's values
//! under the channels' names, and its lines show them in words.

mod common;

use common::*;
use serde_json::Value;
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const STRIP: &str = "KL1104,KL2134,KL3102,KL4002,KL9010";
const WAIT: Duration = Duration::from_secs(60);

fn sniffer(bus: &Bus, link: usize, config: &std::path::Path, json: bool) -> (Proc, Lines) {
    let mut cmd = Command::new(dpctl());
    cmd.args(["sniff", "--port", &bus.link_str(link), "--config"])
        .arg(config)
        .arg(if json { "--json" } else { "--plain" })
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    let mut p = Proc::spawn("dpctl sniff", &mut cmd);
    let lines = Lines::from(&mut p);
    (p, lines)
}

fn near(v: &Value, want: f64) -> bool {
    v.as_f64().is_some_and(|x| (x - want).abs() < 0.001)
}

#[test]
fn sniff_names_the_channels_of_a_device_profile_slave() {
    let bus = Bus::start(4, &["--baud", "1.5M"]);
    let dir = bus.dir();
    let config = dir.path("bus.toml");
    std::fs::write(
        &config,
        "[master]\naddress = 2\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 15\n\
         device = \"bk3000\"\nterminals = [\"KL1104\", \"KL2134\", \"KL3102\", \
         \"KL4002\", \"KL9010\"]\nwatchdog_ms = 1000\n",
    )
    .unwrap();
    let (_json_sniff, mut json) = sniffer(&bus, 2, &config, true);
    let (_text_sniff, mut text) = sniffer(&bus, 3, &config, false);

    let mut slave = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--device", "bk3000", "--terminals", STRIP])
            .args(["--switch-ones", "5", "--switch-tens", "1", "--baud", "1.5M"])
            .args(["--control", "-", "--json", "--port", &bus.link_str(1)])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .stdin(Stdio::piped()),
    );
    let mut stdin = slave.child.as_mut().unwrap().stdin.take().unwrap();
    let mut out = started(&mut slave, WAIT);
    // The slave's inputs: -2.5 V on the KL3102's channel 2, the
    // KL1104's input 2 on.
    for (cmd, answer) in [
        ("set 3.KL3102.2 -2.5", "pinned to -2.500 V"),
        ("set 1.KL1104.2 1", "input 1.KL1104.2 pinned to 1"),
    ] {
        writeln!(stdin, "{cmd}").unwrap();
        stdin.flush().unwrap();
        assert!(out.wait_for(answer, WAIT), "{cmd}: {:?}", out.1);
    }
    // The master writes an output by name.
    let cmds = dir.path("cmds.jsonl");
    std::fs::write(&cmds, "{\"slave\": 15, \"set\": {\"4.KL4002.1\": 5.0}}\n").unwrap();
    let _master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--port", &bus.link_str(0), "--config"])
            .arg(&config)
            .arg("--input")
            .arg(&cmds)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .stdin(Stdio::null()),
    );
    // The slave took the output (its own view of the value).
    assert!(out.wait_for("4.KL4002.1=5.000 V", WAIT), "{:?}", out.1);

    // JSON: both directions of slave 15's Data_Exchange, named.
    let (mut inputs, mut outputs) = (None, None);
    let end = Instant::now() + WAIT;
    while inputs.is_none() || outputs.is_none() {
        let Some(l) = json.next_line(end.saturating_duration_since(Instant::now())) else {
            break;
        };
        let v: Value = serde_json::from_str(&l).unwrap_or(Value::Null);
        let dp = &v["dp"];
        if dp["service"] != "Data_Exchange" {
            continue;
        }
        let ch = &dp["channels"];
        if dp["direction"] == "response" && v["sa"] == 15 && near(&ch["3.KL3102.2"], -2.5) {
            inputs = Some(v.clone());
        }
        if dp["direction"] == "request" && v["da"] == 15 && near(&ch["4.KL4002.1"], 5.0) {
            outputs = Some(v.clone());
        }
    }
    let tail = || json.1.iter().rev().take(20).cloned().collect::<Vec<_>>();
    let inputs = inputs.unwrap_or_else(|| panic!("no named inputs: {:?}", tail()));
    let ch = &inputs["dp"]["channels"];
    assert_eq!(ch["1.KL1104.2"], true, "{inputs}");
    // Every input channel of the strip is named, digital as booleans.
    assert!(ch["1.KL1104.4"].is_boolean(), "{inputs}");
    assert!(ch["3.KL3102.1"].is_number(), "{inputs}");
    let outputs = outputs.unwrap_or_else(|| panic!("no named outputs: {:?}", tail()));
    assert!(
        outputs["dp"]["channels"]["2.KL2134.1"].is_boolean(),
        "{outputs}"
    );

    // Lines: the values in words, with units.
    assert!(
        text.wait_for("3.KL3102.2=-2.5", WAIT),
        "{:?}",
        text.1.iter().rev().take(20).collect::<Vec<_>>()
    );
    let line = text
        .1
        .iter()
        .find(|l| l.contains("3.KL3102.2=-2.5"))
        .unwrap();
    assert!(
        line.contains("| Data_Exchange response: inputs ") && line.contains(" V"),
        "{line}"
    );
    assert!(line.contains("1.KL1104.2=1"), "{line}");
}
