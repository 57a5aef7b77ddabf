//! The class-2 master (`dpctl dpv1 --class2`, `dpctl im`) with real
//! processes on `dpctl bus`: next to a class-1 `dpctl master` that keeps
//! the slave in Data_Exchange all along, it writes and reads a record,
//! runs Data_Transport, writes and reads I&M; a Send_Timeout below the
//! slave's minimum is aborted by the slave (STO, in words); a slave
//! without class 2 refuses SAP 49; a silent slave is a timeout; I&M over
//! class 1 takes the `dpctl dpv1` path.

mod common;

use common::{dpctl, repo, run_dpctl, slave_of, Bus, Lines, Proc, TempDir};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

/// The generic GSD with class 2 added (2 connections, 240 bytes).
fn c2_gsd(dir: &TempDir) -> PathBuf {
    let gen = std::fs::read_to_string(repo().join("crates/devices/gsd/DPCTL_GEN.GSD")).unwrap();
    let c2 = gen.replace(
        "C1_Response_Timeout=100",
        "C1_Response_Timeout=100\nC2_Read_Write_supp=1\nC2_Max_Data_Len=240\n\
         C2_Response_Timeout=300\nC2_Max_Count_Channels=2\nMax_Initiate_PDU_Length=52",
    );
    assert_ne!(
        gen, c2,
        "DPCTL_GEN.GSD has no C1_Response_Timeout line any more"
    );
    let p = dir.path("DPCTL_C2.GSD");
    std::fs::write(&p, c2).unwrap();
    p
}

fn slave(link: &Path, addr: u8, gsd: &Path) -> Proc {
    Proc::spawn(
        &format!("dpctl slave {addr}"),
        Command::new(dpctl())
            .args(["slave", "--port"])
            .arg(link)
            .args(["--addr", &addr.to_string(), "--baud", "1.5M", "--gsd"])
            .arg(gsd)
            .args(["--module", "2 words in/out"])
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
}

fn bus_file(dir: &TempDir, master: u8, slave: u8, gsd: &Path) -> PathBuf {
    let t = format!(
        "[master]\naddress = {master}\nbaud = \"1.5M\"\n[options]\nreprobe_ms = 50\n\
         [[slave]]\naddress = {slave}\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\n\
         watchdog_ms = 5000\n",
        gsd.display()
    );
    let p = dir.path("bus.toml");
    std::fs::write(&p, t).unwrap();
    p
}

/// `dpctl master --json` on `link` with status lines every 100 ms.
fn master(link: &Path, config: &Path) -> (Proc, Lines) {
    let mut p = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100"])
            .args(["--latency", "100", "--port"])
            .arg(link)
            .arg("--config")
            .arg(config)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let lines = Lines::from(&mut p);
    (p, lines)
}

/// `dpctl ARGS --class2` to `slave` as master 3 on `link`, with the
/// bus file.
fn class2(link: &Path, config: &Path, slave: u8, args: &[&str]) -> common::Output {
    let (cmd, rest) = args.split_first().unwrap();
    let link = link.display().to_string();
    let config = config.display().to_string();
    let slave = slave.to_string();
    let mut all = vec![
        *cmd,
        "--class2",
        "--addr",
        "3",
        "--port",
        &link,
        "--config",
        &config,
        "--latency",
        "100",
        "--slave",
        &slave,
    ];
    all.extend_from_slice(rest);
    run_dpctl(&all)
}

#[test]
fn a_class2_master_next_to_a_class1_master_keeps_the_slave_in_data_exchange() {
    let dir = TempDir::new("class2");
    let gsd = c2_gsd(&dir);
    let bus = Bus::start(3, &[]);
    let _s = slave(&bus.link(1), 10, &gsd);
    let cfg = bus_file(&dir, 2, 10, &gsd);
    let (mut m, mut lines) = master(&bus.link(2), &cfg);
    let dx0 = lines.status_from(&mut 0, "data exchange", |v| {
        slave_of(v, 10)["state"] == "data_exchange"
    });
    let dx0 = slave_of(&dx0, 10)["data_exchanges"].as_u64().unwrap();
    let link = bus.link(0);

    let out = class2(
        &link,
        &cfg,
        10,
        &["dpv1", "--slot", "1", "--index", "7", "write", "CA FE"],
    );
    assert!(out.status.success(), "write: {}", out.stderr);
    assert_eq!(out.stdout.trim(), "slave 10 slot 1 index 7: written");
    let out = class2(
        &link,
        &cfg,
        10,
        &[
            "dpv1", "--slot", "1", "--index", "7", "read", "--length", "2",
        ],
    );
    assert!(out.status.success(), "read: {}", out.stderr);
    assert_eq!(out.stdout.trim(), "slave 10 slot 1 index 7: 2 bytes CA FE");

    // Data_Transport: the generic device's answer, data or a refusal in
    // words, never a protocol failure.
    let out = class2(
        &link,
        &cfg,
        10,
        &[
            "dpv1",
            "--json",
            "--slot",
            "1",
            "--index",
            "7",
            "transport",
            "01 02",
        ],
    );
    let v: Value = serde_json::from_str(out.stdout.trim())
        .unwrap_or_else(|_| panic!("transport: {} / {}", out.stdout, out.stderr));
    assert_eq!(v["op"], "transport", "{v}");
    if v["ok"] == false {
        let e = v["error"].as_str().unwrap();
        assert!(e.starts_with("data transport failed: "), "{v}");
    }

    // I&M: write the tag, read it back with I&M0.
    let out = class2(
        &link,
        &cfg,
        10,
        &["im", "--json", "--write-tag", "pump 3", "hall B"],
    );
    assert!(out.status.success(), "im: {} / {}", out.stdout, out.stderr);
    let im: Value = serde_json::from_str(out.stdout.trim()).unwrap();
    assert_eq!(im["class"], 2);
    assert_eq!(im["write_tag"]["ok"], true, "{im}");
    assert_eq!(im["im1"]["tag_function"], "pump 3", "{im}");
    assert_eq!(im["im1"]["tag_location"], "hall B", "{im}");
    let sw = im["im0"]["software_revision"].as_str().unwrap();
    assert!(sw.starts_with('V'), "{im}");
    assert!(im["im0"]["im_supported"]["raw"]
        .as_str()
        .unwrap()
        .starts_with("0x"));
    let out = class2(&link, &cfg, 10, &["im"]);
    assert!(out.status.success(), "im: {}", out.stderr);
    assert!(
        out.stdout.contains("slave 10 I&M0 (class 2, SAP ")
            && out.stdout.contains("  software revision  V")
            && out
                .stdout
                .contains("slave 10 I&M1: tag function \"pump 3\", tag location \"hall B\""),
        "{}",
        out.stdout
    );

    // A Send_Timeout below the slave's minimum (1 s at 1.5 Mbit/s):
    // the slave aborts, and says why.
    let out = class2(
        &link,
        &cfg,
        10,
        &["dpv1", "--send-timeout", "100", "read", "--length", "1"],
    );
    assert!(!out.status.success());
    assert!(
        out.stderr
            .contains("aborted the connection: aborted by MSAC_C2: Send_Timeout too small (STO)"),
        "{}",
        out.stderr
    );

    // The class-1 master kept its slave all along.
    let v = lines.status_from(&mut 0, "data exchange goes on", |v| {
        slave_of(v, 10)["data_exchanges"].as_u64().unwrap() > dx0 + 20
    });
    assert_eq!(slave_of(&v, 10)["state"], "data_exchange");
    let left: Vec<&String> = lines
        .1
        .iter()
        .filter(|l| l.contains(r#""event":"state""#) && l.contains(r#""from":"data_exchange""#))
        .collect();
    assert!(left.is_empty(), "the slave left Data_Exchange: {left:#?}");
    m.terminate(Duration::from_secs(5));
}

#[test]
fn refusal_silence_and_i_and_m_over_class_1() {
    let dir = TempDir::new("class2-errors");
    let gsd = c2_gsd(&dir);
    let plain = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let bus = Bus::start(3, &[]);
    let _with = slave(&bus.link(1), 10, &gsd);
    let _without = slave(&bus.link(2), 11, &plain);
    let cfg = bus_file(&dir, 2, 10, &gsd);
    let link = bus.link(0);

    // No class 2 in its GSD: SAP 49 is not activated.
    let out = class2(&link, &cfg, 11, &["dpv1", "read"]);
    assert!(!out.status.success());
    assert_eq!(
        out.stderr.trim(),
        "dpctl: slave 11 slot 0 index 0: the slave refused class 2 (SAP 49, MSAC_C2 Initiate): \
         SAP not activated (RS)"
    );
    // Nobody at 20: silent past Send_Timeout.
    let out = class2(&link, &cfg, 20, &["im", "--send-timeout", "500"]);
    assert!(!out.status.success());
    assert_eq!(
        out.stderr.trim(),
        "dpctl: slave 20 does not answer: silent for longer than the Send_Timeout of 500 ms"
    );
    // Class 1: the bus file's master parameterises slave 10 and reads
    // I&M0 over MSAC_C1.
    let out = run_dpctl(&[
        "im",
        "--port",
        &link.display().to_string(),
        "--config",
        &cfg.display().to_string(),
        "--slave",
        "10",
        "--latency",
        "100",
        "--json",
    ]);
    assert!(out.status.success(), "{} / {}", out.stdout, out.stderr);
    let im: Value = serde_json::from_str(out.stdout.trim()).unwrap();
    assert_eq!(im["class"], 1);
    assert!(im["im0"]["order_id"].is_string(), "{im}");
    // Without --class2 Data_Transport is refused before anything runs.
    let out = run_dpctl(&[
        "dpv1",
        "--port",
        &link.display().to_string(),
        "--config",
        &cfg.display().to_string(),
        "--slave",
        "10",
        "transport",
        "01",
    ]);
    assert_eq!(
        out.stderr.trim(),
        "dpctl: Data_Transport is a class-2 service (MSAC_C2): add --class2"
    );
}
