//! The class-2 master (`dpctl dpv1 --class2`, `dpctl im --class2`) with
//! real processes on `dpctl bus`: a slave without class 2 refuses SAP 49
//! (RS, in words), a silent slave is a timeout after Send_Timeout, and
//! Data_Transport without `--class2` is refused before anything runs.

mod common;

use common::{dpctl, repo, run_dpctl, Bus, Proc, TempDir};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

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
fn a_slave_without_class_2_refuses_and_a_silent_one_times_out() {
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
