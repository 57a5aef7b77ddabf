//! The analyser's statistics on a faulty line: `dpctl sniff --stats`
//! on a `dpctl bus` with `--drop`, `--flip` and `--noise`, a master and a
//! slave that is killed and started again. The sniffer's line counters
//! match the hub's own (its recording framer's), the restart is counted
//! on the slave, and `--alert restart` fires for it.

mod common;

use common::{dpctl, repo, Bus, Proc};
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The hub's recording counters from its status line: packets, corrupt
/// packets, garbage bytes, bad FCS, other codec errors.
fn pcap_counters(status: &str) -> [u64; 5] {
    let tail = status
        .split("; pcap ")
        .nth(1)
        .unwrap_or_else(|| panic!("no pcap counters in {status}"));
    let nums: Vec<u64> = tail
        .split(|c: char| !c.is_ascii_digit())
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().unwrap())
        .collect();
    [nums[0], nums[1], nums[2], nums[3], nums[4]]
}

fn slave(bus: &Bus, gsd: &std::path::Path) -> Proc {
    Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--port", &bus.link_str(1), "--addr", "10"])
            .args(["--baud", "1.5M", "--gsd"])
            .arg(gsd)
            .args(["--module", "2 words in/out"])
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
}

#[test]
fn sniff_statistics_match_the_hubs_fault_counters_and_restarts() {
    let pcap = tempfile::NamedTempFile::new().unwrap();
    let pcap_path = pcap.path().to_string_lossy().into_owned();
    let bus = Bus::start(
        3,
        &[
            "--baud", "1.5M", "--drop", "0.0003", "--flip", "0.00003", "--noise", "5", "--seed",
            "31", "--pcap", &pcap_path,
        ],
    );
    let before = pcap_counters(&bus.status());
    let mut cmd = Command::new(dpctl());
    cmd.args([
        "sniff",
        "--json",
        "--port",
        &bus.link_str(2),
        "--baud",
        "1.5M",
    ])
    .args([
        "--stats",
        "3600",
        "--alert",
        "restart",
        "--alert",
        "10:health<=100",
    ]);
    let sniff = Proc::spawn_captured(cmd);
    bus.wait_connected(1);
    let connected = pcap_counters(&bus.status());

    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let config = bus.dir().path("bus.toml");
    std::fs::write(
        &config,
        format!(
            "[master]\naddress = 2\nbaud = \"1.5M\"\n[options]\nlost_after = 20\n\
             [[slave]]\naddress = 10\ngsd = \"{}\"\n\
             modules = [\"2 words in/out\"]\nwatchdog_ms = 5000\n",
            gsd.display()
        ),
    )
    .unwrap();
    let mut slave1 = slave(&bus, &gsd);
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--port", &bus.link_str(0), "--config"])
            .arg(&config)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut master_lines = common::Lines::from(&mut master);
    let dx = "\"to\":\"data_exchange\"";
    assert!(
        master_lines.wait_for(dx, Duration::from_secs(60)),
        "slave 10 never reached Data_Exchange: {:?}",
        master_lines.rest()
    );
    // Some Data_Exchange cycles (the master reports data_exchange on the
    // diagnosis that says ready, before the first exchange).
    let chars = |s: &str| common::counter(s, "chars ").unwrap_or(0);
    let c0 = chars(&bus.status());
    bus.wait_status("Data_Exchange cycles", |s| chars(s) > c0 + 2000);
    // Kill the slave; the master loses it, and takes it through a new
    // start-up when it is back.
    slave1.terminate(Duration::from_secs(10));
    assert!(
        master_lines.wait_for("\"to\":\"offline\"", Duration::from_secs(60)),
        "the master never lost slave 10: {:?}",
        master_lines.rest()
    );
    let _slave2 = slave(&bus, &gsd);
    assert!(
        master_lines.wait_for(dx, Duration::from_secs(60)),
        "slave 10 never came back: {:?}",
        master_lines.rest()
    );
    // Some Data_Exchange cycles on the faulty line, then quiet.
    let faults = bus.wait_status("faults on the line", |s| {
        common::counter(s, "dropped ").unwrap_or(0) > 0
            && common::counter(s, "bits flipped ").unwrap_or(0) > 0
            && s.contains("noise bursts")
            && !s.contains("noise bursts 0 ")
    });
    assert!(faults.contains("pcap"), "{faults}");
    master.terminate(Duration::from_secs(10));
    drop(_slave2);
    // The hub's counters just before and just after the sniffer stops
    // (noise bursts go on while the line is idle).
    let end = Instant::now() + Duration::from_secs(30);
    let mut settled = pcap_counters(&bus.status());
    loop {
        std::thread::sleep(Duration::from_millis(300));
        let again = pcap_counters(&bus.status());
        // Only noise now: few packets in 300 ms.
        if again[0] - settled[0] < 10 || Instant::now() > end {
            break;
        }
        settled = again;
    }
    let h1 = pcap_counters(&bus.status());
    let out = sniff.stop();
    let h2 = pcap_counters(&bus.status());
    let lines: Vec<Value> = (out.stdout)
        .lines()
        .filter(|l| !l.contains("\"t_us\""))
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    let stats = lines
        .iter()
        .rev()
        .find(|v| v["event"] == "stats")
        .unwrap_or_else(|| panic!("no stats line: {lines:#?}"));
    let totals = &stats["totals"];
    let line = &totals["line"];
    let n = |v: &Value| v.as_u64().unwrap();
    // Valid telegrams and garbage bytes: what the hub's framer counted
    // between the sniffer's start and end.
    let telegrams = n(&line["telegrams"]);
    let (lo, hi) = (
        h1[0] - h1[1] - (connected[0] - connected[1]),
        h2[0] - h2[1] - (before[0] - before[1]),
    );
    assert!(
        (lo..=hi).contains(&telegrams),
        "sniff saw {telegrams} telegrams, the hub {lo} … {hi}"
    );
    let garbage = n(&line["errors"]["garbage_bytes"]);
    let (lo, hi) = (h1[2] - connected[2], h2[2] - before[2]);
    assert!(
        (lo..=hi).contains(&garbage),
        "sniff skipped {garbage} garbage bytes, the hub {lo} … {hi}"
    );
    // Rejected candidates (bad FCS, delimiter, length, truncated): the
    // sniffer gives up an incomplete telegram after its --idle-ms on the
    // pty, the hub after the line's own idle time, so a few candidates
    // end differently; the totals agree within 5 %.
    let e = &line["errors"];
    let rejected = [
        "bad_fcs",
        "bad_length",
        "bad_end_delimiter",
        "bad_format",
        "truncated",
    ]
    .iter()
    .map(|k| n(&e[k]))
    .sum::<u64>();
    let hub = (h1[3] + h1[4]) - (connected[3] + connected[4]);
    assert!(hub > 0, "no rejected candidates: {faults}");
    assert!(
        rejected.abs_diff(hub) * 20 <= hub.max(20),
        "sniff rejected {rejected} candidates, the hub {hub}"
    );
    assert!(n(&line["illegal"]) > 0);
    // The slave restarted once, after it was killed.
    let s10 = &totals["stations"]["10"];
    // One kill, one restart; a corrupted diagnosis on a faulty line can
    // look like one more, never more than the start-ups after the first.
    let restarts = n(&s10["restarts"]);
    assert!(restarts >= 1 && restarts < n(&s10["set_prm"]), "{s10}");
    assert_eq!(s10["role"], "slave");
    assert_eq!(s10["dp_state"], "data_exchange");
    assert!(n(&s10["requests"]) > 0 && n(&s10["answers"]) > 0, "{s10}");
    assert!(n(&s10["set_prm"]) >= 2 && n(&s10["chk_cfg"]) >= 2, "{s10}");
    assert!(s10["response_time"]["max_us"].is_number(), "{s10}");
    assert_eq!(totals["stations"]["2"]["role"], "master");
    // The GAP polling of absent addresses counts against no station.
    assert!(totals["stations"].get("100").is_none(), "{totals}");
    // `--alert restart` fired for slave 10; `10:health<=100` on every
    // interval.
    let alerts: Vec<&Value> = lines.iter().filter(|v| v["event"] == "alert").collect();
    assert!(
        alerts.iter().any(|a| a["rule"] == "restart"
            && a["station"] == 10
            && a["value"].as_f64() >= Some(1.0)),
        "{alerts:#?}"
    );
    assert!(alerts.iter().any(|a| a["rule"] == "10:health<=100"));
    assert!(out.status.success());
    drop(pcap);
}

#[test]
fn a_bad_alert_rule_names_its_column_and_the_closest_statistic() {
    let out = Command::new(dpctl())
        .args(["sniff", "--port", "/nonexistent", "--alert", "retrys>1%"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("column 1: unknown statistic `retrys` (did you mean `retries`?)"),
        "{err}"
    );
}
