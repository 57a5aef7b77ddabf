//! The Wireshark dissector `tools/wireshark/profibus_dl.lua` under tshark
//! (Debian's package, installed by `scripts/setup-test-env`) on a capture
//! of a real start-up: `dpctl bus --pcap` records `dpctl master` bringing
//! a `dpctl slave` into Data_Exchange and running DP-V1 write and read
//! jobs; the decoded fields must match what the processes did. A second
//! test checks that a wrong FCS is flagged. An FMS exchange recorded by
//! `dpctl sniff --pcap` (fms_capture/mod.rs) decodes to the same FMS
//! fields as the sniffer's `--json`. The tests fail when tshark is
//! missing.

mod common;
mod fms_capture;

use common::{counter, dpctl, repo, require, send, Bus, Lines, Proc, TempDir};
use profibus::fdl::capture::pcap::{PcapReader, PcapWriter};
use profibus::fdl::wire::{DataTelegram, FunctionCode, RequestKind, Telegram};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const WAIT: Duration = Duration::from_secs(60);

fn script() -> PathBuf {
    repo().join("tools/wireshark/profibus_dl.lua")
}

/// `tshark -X lua_script:… -r FILE -T fields -e F1 -e F2 …`: one row per
/// packet, the fields separated by `|` (repeated values by `,`), byte
/// fields as plain hex.
fn tshark_fields(capture: &Path, fields: &[&str]) -> Vec<Vec<String>> {
    tshark_filtered(capture, None, fields)
}

/// [`tshark_fields`] of the packets that match the display filter
/// `filter` (`-Y`).
fn tshark_filtered(capture: &Path, filter: Option<&str>, fields: &[&str]) -> Vec<Vec<String>> {
    require("tshark");
    let mut cmd = Command::new("tshark");
    cmd.arg("-X")
        .arg(format!("lua_script:{}", script().display()))
        .arg("-r")
        .arg(capture)
        .args(["-T", "fields", "-E", "separator=|", "-E", "occurrence=a"]);
    if let Some(f) = filter {
        cmd.args(["-Y", f]);
    }
    for f in fields {
        cmd.args(["-e", f]);
    }
    let out = cmd.output().expect("run tshark");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "tshark failed: {err}");
    assert!(!err.contains("Lua Error"), "the dissector failed: {err}");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!text.contains("Lua Error"), "the dissector failed: {text}");
    // Byte fields print as `0102` or `01:02` depending on the version.
    text.lines()
        .map(|l| l.split('|').map(|v| v.replace(':', "")).collect())
        .collect()
}

/// Records a start-up with DP-V1 jobs; returns the capture's path.
fn record_startup(dir: &TempDir) -> PathBuf {
    let pcap = dir.path("startup.pcapng");
    let bus = Bus::start(2, &["--pcap", pcap.to_str().unwrap()]);
    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let mut slave = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--port", &bus.link_str(1), "--addr", "10"])
            .args(["--baud", "1.5M", "--gsd"])
            .arg(&gsd)
            .args(["--module", "2 words in/out"])
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    let config = dir.path("bus.toml");
    std::fs::write(
        &config,
        format!(
            // The capture is under test, not lost-slave detection: a slave
            // process the loaded VM does not schedule for a few ms must
            // not drop out between the status line and the DP-V1 jobs.
            "[master]\naddress = 2\nbaud = \"1.5M\"\n[options]\nlost_after = 20\n\
             [[slave]]\naddress = 10\ngsd = \"{}\"\n\
             modules = [\"2 words in/out\"]\nwatchdog_ms = 5000\ninitial_outputs = [1, 2, 3, 4]\n",
            gsd.display()
        ),
    )
    .unwrap();
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--input", "-"])
            .args(["--latency", "20", "--port", &bus.link_str(0), "--config"])
            .arg(&config)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut lines = Lines::from(&mut master);
    // Data_Exchange with the echoed initial outputs.
    wait_json(&mut lines, "Data_Exchange with echoed inputs", |v| {
        v["event"] == "status"
            && v["slaves"].as_array().is_some_and(|a| {
                a.iter().any(|s| {
                    s["address"] == 10
                        && s["state"] == "data_exchange"
                        && s["inputs"] == "01 02 03 04"
                })
            })
    });
    send(
        &mut master,
        r#"{"dpv1_write": 10, "slot": 1, "index": 7, "data": "CA FE"}"#,
    );
    send(
        &mut master,
        r#"{"dpv1_read": 10, "slot": 1, "index": 7, "length": 2}"#,
    );
    let read = wait_json(&mut lines, "the DP-V1 read job", |v| {
        v["event"] == "job" && v["id"] == 2
    });
    assert_eq!(read["data"], "CA FE", "{read}");
    master.terminate(Duration::from_secs(10));
    slave.terminate(Duration::from_secs(10));
    let out = bus.stop();
    assert!(out.status.success(), "dpctl bus: {}", out.stderr);
    pcap
}

/// Wait for a JSON line of `dpctl master --json` that satisfies `ok`.
fn wait_json(
    lines: &mut Lines,
    what: &str,
    ok: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let end = Instant::now() + WAIT;
    let mut seen = 0;
    loop {
        while seen < lines.1.len() {
            let l = &lines.1[seen];
            seen += 1;
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(l) {
                if ok(&v) {
                    return v;
                }
            }
        }
        let left = end.saturating_duration_since(Instant::now());
        assert!(
            lines.next_line(left).is_some() || Instant::now() < end,
            "timed out waiting for {what}: {:#?}",
            &lines.1[lines.1.len().saturating_sub(5)..]
        );
    }
}

fn rows_with<'a>(rows: &'a [Vec<String>], col: usize, value: &str) -> Vec<&'a Vec<String>> {
    rows.iter().filter(|r| r[col] == value).collect()
}

#[test]
fn dissector_decodes_a_recorded_startup() {
    let dir = TempDir::new("wireshark");
    let pcap = record_startup(&dir);

    // Layer 2: every telegram type of the start-up, addresses, FC, FCS.
    let rows = tshark_fields(
        &pcap,
        &[
            "pbdl.type",
            "pbdl.sa.addr",
            "pbdl.da.addr",
            "pbdl.da.ext",
            "pbdl.fc.function",
            "pbdl.dsap",
            "pbdl.ssap",
            "pbdl.fcs.good",
            "pbdp.service",
        ],
    );
    assert!(rows.len() > 20, "too few packets: {rows:?}");
    for t in ["SD1", "SD2", "SD4", "SC"] {
        assert!(
            rows.iter().any(|r| r[0] == t),
            "no {t} telegram decoded: {rows:?}"
        );
    }
    for r in &rows {
        assert!(!r[0].is_empty(), "undecoded packet: {r:?}");
        if r[0] == "SD1" || r[0] == "SD2" || r[0] == "SD3" {
            assert_eq!(r[7], "1", "FCS of {r:?}");
        }
    }
    let tokens = rows_with(&rows, 0, "SD4");
    assert!(
        tokens.iter().any(|r| r[1] == "2" && r[2] == "2"),
        "{tokens:?}"
    );
    let set_prm = rows_with(&rows, 8, "Set_Prm");
    assert!(!set_prm.is_empty(), "no Set_Prm: {rows:?}");
    let p = set_prm[0];
    assert_eq!((p[1].as_str(), p[2].as_str()), ("2", "10"), "{p:?}");
    assert_eq!(p[3], "1", "DA extension bit of {p:?}");
    assert_eq!(p[4], "SRD_high", "{p:?}");
    assert_eq!((p[5].as_str(), p[6].as_str()), ("61", "62"), "SAPs {p:?}");
    // The slave answers DP services with DL and its SAP as SSAP.
    let diag_resp: Vec<_> = rows_with(&rows, 8, "Slave_Diag")
        .into_iter()
        .filter(|r| r[1] == "10")
        .collect();
    assert!(!diag_resp.is_empty(), "no Slave_Diag response: {rows:?}");
    assert!(diag_resp[0][4].starts_with("DL"), "{:?}", diag_resp[0]);
    assert_eq!(diag_resp[0][6], "60", "{:?}", diag_resp[0]);
    assert!(
        rows.iter()
            .any(|r| r[8] == "Data_Exchange" && r[1] == "10" && r[5].is_empty()),
        "no Data_Exchange response without SAPs"
    );

    // DP: Set_Prm fields, Chk_Cfg identifiers, Slave_Diag bits.
    let rows = tshark_fields(
        &pcap,
        &[
            "pbdp.service",
            "pbdp.prm.ident",
            "pbdp.prm.wd_on",
            "pbdp.prm.wd_fact_1",
            "pbdp.prm.wd_fact_2",
            "pbdp.cfg.id",
            "pbdp.cfg.inputs",
            "pbdp.cfg.outputs",
            "pbdp.diag.prm_req",
            "pbdp.diag.station_not_ready",
            "pbdp.diag.master_add",
            "pbdp.diag.ident",
            "pbdp.outputs",
            "pbdp.inputs",
        ],
    );
    let p = rows_with(&rows, 0, "Set_Prm")[0];
    assert_eq!(p[1], "0x0dce", "Ident_Number {p:?}");
    assert_eq!(p[2], "1", "WD_On {p:?}");
    let wd: u32 = p[3].parse::<u32>().unwrap() * p[4].parse::<u32>().unwrap();
    assert_eq!(wd * 10, 5000, "watchdog of the bus file {p:?}");
    let c = rows_with(&rows, 0, "Chk_Cfg")
        .into_iter()
        .find(|r| !r[5].is_empty())
        .expect("Chk_Cfg with identifiers");
    assert_eq!(c[5], "0x71", "identifier of 2 words in/out {c:?}");
    assert_eq!((c[6].as_str(), c[7].as_str()), ("4", "4"), "{c:?}");
    let diags: Vec<_> = rows_with(&rows, 0, "Slave_Diag")
        .into_iter()
        .filter(|r| !r[11].is_empty())
        .collect();
    assert!(
        diags.iter().any(|r| r[8] == "1" && r[10] == "255"),
        "a fresh slave asks for parameters and has no master: {diags:?}"
    );
    let last = diags.last().unwrap();
    assert_eq!(
        (last[8].as_str(), last[9].as_str(), last[10].as_str()),
        ("0", "0", "2"),
        "the slave ready for master 2: {last:?}"
    );
    assert_eq!(last[11], "0x0dce");
    assert!(
        rows.iter()
            .any(|r| r[0] == "Data_Exchange" && r[12] == "01020304"),
        "initial outputs 01 02 03 04 not seen"
    );
    assert!(
        rows.iter()
            .any(|r| r[0] == "Data_Exchange" && r[13] == "01020304"),
        "the echoing slave's inputs not seen"
    );

    // Global_Control and DP-V1.
    let rows = tshark_fields(
        &pcap,
        &[
            "pbdp.service",
            "pbdp.gc.command",
            "pbdl.da.addr",
            "pbdp.dpv1.function",
            "pbdp.dpv1.slot",
            "pbdp.dpv1.index",
            "pbdp.dpv1.length",
            "pbdp.dpv1.data",
            "pbdl.fc.request",
        ],
    );
    let gc = rows_with(&rows, 0, "Global_Control");
    assert!(!gc.is_empty(), "no Global_Control");
    assert!(
        gc.iter().all(|r| r[2] == "127" && !r[1].is_empty()),
        "{gc:?}"
    );
    let v1: Vec<_> = rows_with(&rows, 0, "DP-V1")
        .into_iter()
        .filter(|r| !r[3].is_empty())
        .collect();
    let write_req = v1
        .iter()
        .find(|r| r[3] == "0x5f" && r[8] == "1")
        .unwrap_or_else(|| panic!("no DP-V1 write request: {v1:?}"));
    assert_eq!(
        &write_req[4..8],
        &["1", "7", "2", "cafe"],
        "slot, index, length, data"
    );
    let read_resp = v1
        .iter()
        .find(|r| r[3] == "0x5e" && r[8] == "0" && !r[7].is_empty())
        .unwrap_or_else(|| panic!("no DP-V1 read response with data: {v1:?}"));
    assert_eq!(&read_resp[4..8], &["1", "7", "2", "cafe"]);
}

#[test]
fn dissector_flags_a_wrong_fcs() {
    let dir = TempDir::new("wireshark-fcs");
    let path = dir.path("bad.pcapng");
    let mut w = PcapWriter::new(
        std::fs::File::create(&path).unwrap(),
        Duration::from_secs(1),
    )
    .unwrap();
    // Slave_Diag request 2 → 10, first with the right FCS, then with a
    // wrong one; a token.
    let good = [0x68, 5, 5, 0x68, 0x8A, 0x82, 0x6D, 0x3C, 0x3E, 0x00, 0x16];
    let fcs = good[4..9].iter().fold(0u8, |a, b| a.wrapping_add(*b));
    let mut good = good;
    good[9] = fcs;
    let mut bad = good;
    bad[9] = fcs.wrapping_add(1);
    w.write_packet(Duration::from_millis(1), &good).unwrap();
    w.write_packet(Duration::from_millis(2), &bad).unwrap();
    w.write_packet(Duration::from_millis(3), &[0xDC, 0x02, 0x02])
        .unwrap();
    w.flush().unwrap();
    drop(w);
    let rows = tshark_fields(
        &path,
        &[
            "pbdl.type",
            "pbdl.fcs.good",
            "pbdl.fcs.status",
            "pbdp.service",
            "_ws.expert.message",
        ],
    );
    assert_eq!(rows.len(), 3, "{rows:?}");
    assert_eq!(&rows[0][..4], &["SD2", "1", "Good", "Slave_Diag"]);
    assert_eq!(&rows[1][..4], &["SD2", "0", "Bad", "Slave_Diag"]);
    assert!(rows[1][4].contains("FCS"), "expert info: {:?}", rows[1]);
    assert_eq!(rows[2][0], "SD4");
}

/// One capture of hand-made telegrams: an SD3 Slave_Diag response (8 data
/// bytes with the SAPs) and a Set_Slave_Add request to the delivery
/// address 126.
#[test]
fn dissector_decodes_sd3_and_set_slave_add() {
    use profibus::fdl::wire::{DataTelegram, Format, FunctionCode, RequestKind, ResponseStatus};
    use profibus::fdl::Telegram;
    let dir = TempDir::new("wireshark-sd3");
    let path = dir.path("sd3.pcapng");
    let emit = |t: Telegram<'_>| {
        let mut buf = [0u8; 64];
        let n = t.emit(&mut buf).unwrap();
        buf[..n].to_vec()
    };
    // Slave 10 → master 2: Slave_Diag (SSAP 60 → DSAP 62) in SD3, Prm_Req
    // and Station_Not_Ready, no master yet, ident 0x0DCE.
    let sd3 = emit(Telegram::Data(DataTelegram {
        da: 2,
        sa: 10,
        fc: FunctionCode::slave_response(ResponseStatus::Dl),
        dsap: Some(62),
        ssap: Some(60),
        data: &[0x02, 0x05, 0x00, 0xFF, 0x0D, 0xCE],
        format: Some(Format::Sd3),
    }));
    assert_eq!(sd3[0], 0xA2);
    assert_eq!(sd3.len(), 14);
    // Master 2 → 126: Set_Slave_Add to 7, ident 0x0DCE, No_Add_Chg 1.
    let ssa = emit(Telegram::Data(DataTelegram {
        da: 126,
        sa: 2,
        fc: FunctionCode::Request {
            kind: RequestKind::SdaHigh,
            fcb: true,
            fcv: false,
        },
        dsap: Some(55),
        ssap: Some(62),
        data: &[7, 0x0D, 0xCE, 1],
        format: None,
    }));
    let mut w = PcapWriter::new(
        std::fs::File::create(&path).unwrap(),
        Duration::from_secs(1),
    )
    .unwrap();
    w.write_packet(Duration::from_millis(1), &sd3).unwrap();
    w.write_packet(Duration::from_millis(2), &ssa).unwrap();
    w.write_packet(Duration::from_millis(3), &[0xE5]).unwrap();
    w.flush().unwrap();
    drop(w);
    let rows = tshark_fields(
        &path,
        &[
            "pbdl.type",
            "pbdl.sa.addr",
            "pbdl.da.addr",
            "pbdl.dsap",
            "pbdl.ssap",
            "pbdl.fcs.good",
            "pbdp.service",
            "pbdp.diag.prm_req",
            "pbdp.diag.station_not_ready",
            "pbdp.diag.master_add",
            "pbdp.diag.ident",
            "pbdp.ssa.new_address",
            "pbdp.ssa.ident",
            "pbdp.ssa.no_add_chg",
        ],
    );
    assert_eq!(rows.len(), 3, "{rows:?}");
    let d = &rows[0];
    assert_eq!(
        &d[..7],
        &["SD3", "10", "2", "62", "60", "1", "Slave_Diag"],
        "{d:?}"
    );
    assert_eq!(&d[7..11], &["1", "1", "255", "0x0dce"], "{d:?}");
    let s = &rows[1];
    assert_eq!(
        &s[..7],
        &["SD2", "2", "126", "55", "62", "1", "Set_Slave_Add"],
        "{s:?}"
    );
    assert_eq!(&s[11..14], &["7", "0x0dce", "1"], "{s:?}");
    assert_eq!(rows[2][0], "SC");
}

/// `dpctl bus --pcap` on a line that flips bits (seeded) keeps the
/// corrupted telegrams in the recording, flagged: the dissector's filter
/// `pbdl.fcs.good == 0` finds exactly the flagged packets.
#[test]
fn bus_pcap_keeps_corrupted_telegrams_for_the_fcs_filter() {
    require("tshark");
    let dir = TempDir::new("wireshark-corrupt");
    let pcap = dir.path("flipped.pcapng");
    let bus = Bus::start(
        2,
        &[
            "--flip",
            "0.002",
            "--seed",
            "9",
            "--pcap",
            pcap.to_str().unwrap(),
        ],
    );
    let mut port = std::fs::OpenOptions::new()
        .write(true)
        .open(bus.link(0))
        .unwrap();
    let fc = FunctionCode::Request {
        kind: RequestKind::SrdHigh,
        fcb: true,
        fcv: true,
    };
    let mut written = 0u64;
    for k in 0..400u32 {
        let du = [k as u8; 16];
        let t = Telegram::Data(DataTelegram::new(3, 1, fc, &du))
            .to_vec()
            .unwrap();
        port.write_all(&t).unwrap();
        port.flush().unwrap();
        written += t.len() as u64;
    }
    // The hub carried every character the test wrote.
    bus.wait_status(&format!("{written} chars"), |s| {
        counter(s, "chars ").is_some_and(|n| n >= written)
    });
    drop(port);
    let out = bus.stop();
    assert!(out.status.success(), "dpctl bus: {}", out.stderr);
    let packets: Vec<_> = PcapReader::new(std::fs::File::open(&pcap).unwrap())
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let flagged: Vec<String> = (packets.iter().enumerate())
        .filter(|(_, p)| p.is_corrupt())
        .map(|(i, _)| (i + 1).to_string())
        .collect();
    // 400 × 25 bytes × 8 bits × 0.002 ≈ 160 flips.
    assert!(
        flagged.len() > 20,
        "{} of {} packets flagged",
        flagged.len(),
        packets.len()
    );
    assert!(packets.len() > 300, "{} packets", packets.len());
    let found: Vec<String> = tshark_filtered(&pcap, Some("pbdl.fcs.good == 0"), &["frame.number"])
        .into_iter()
        .map(|r| r[0].clone())
        .collect();
    assert_eq!(found, flagged);
    assert!(
        out.stderr.contains(&format!(" {} corrupt", flagged.len())),
        "{}",
        out.stderr
    );
}

/// DP-V1 alarms: an alarm and a status block in a Slave_Diag, the
/// master's Alarm_Ack (SAP 51 → 50) and the slave's echo, written from
/// the layouts of dpv1-c2-im-alarms.md §4.4-4.5.
#[test]
fn dissector_decodes_alarm_blocks_and_alarm_ack() {
    use profibus::fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus};
    use profibus::fdl::Telegram;
    let dir = TempDir::new("wireshark-alarms");
    let path = dir.path("alarms.pcapng");
    let emit = |t: Telegram<'_>| {
        let mut buf = [0u8; 80];
        let n = t.emit(&mut buf).unwrap();
        buf[..n].to_vec()
    };
    let request = FunctionCode::Request {
        kind: RequestKind::SrdHigh,
        fcb: true,
        fcv: true,
    };
    let response = FunctionCode::slave_response(ResponseStatus::Dl);
    // Slave 9 → master 2: Ext_Diag; a diagnostic alarm of slot 1, seq 5,
    // Add_Ack, appears (0x2D), data 02 00; a module status block.
    let diag = emit(Telegram::Data(DataTelegram {
        da: 2,
        sa: 9,
        fc: response,
        dsap: Some(62),
        ssap: Some(60),
        data: &[
            0x08, 0x0C, 0x00, 0x02, 0x0D, 0xCA, 0x06, 0x01, 0x01, 0x2D, 0x02, 0x00, 0x05, 0x82,
            0x00, 0x01, 0x10,
        ],
        format: None,
    }));
    let ack = [0x5C, 0x01, 0x01, 0x2D];
    let ack_req = emit(Telegram::Data(DataTelegram {
        da: 9,
        sa: 2,
        fc: request,
        dsap: Some(50),
        ssap: Some(51),
        data: &ack,
        format: None,
    }));
    let ack_res = emit(Telegram::Data(DataTelegram {
        da: 2,
        sa: 9,
        fc: response,
        dsap: Some(51),
        ssap: Some(50),
        data: &ack,
        format: None,
    }));
    let mut w = PcapWriter::new(
        std::fs::File::create(&path).unwrap(),
        Duration::from_secs(1),
    )
    .unwrap();
    for (i, t) in [diag, ack_req, ack_res].iter().enumerate() {
        w.write_packet(Duration::from_millis(i as u64 + 1), t)
            .unwrap();
    }
    w.flush().unwrap();
    drop(w);
    let rows = tshark_fields(
        &path,
        &[
            "pbdp.service",
            "pbdp.alarm.type",
            "pbdp.alarm.slot",
            "pbdp.alarm.seq",
            "pbdp.alarm.add_ack",
            "pbdp.alarm.change",
            "pbdp.alarm.data",
            "pbdp.status.type",
            "pbdp.dpv1.function",
        ],
    );
    assert_eq!(rows.len(), 3, "{rows:?}");
    let d = &rows[0];
    assert_eq!(d[0], "Slave_Diag", "{d:?}");
    // The status block's slot (0) follows the alarm's (1).
    assert_eq!(
        &d[1..8],
        &["1", "1,0", "5", "1", "1,1", "0200,10", "0x82"],
        "{d:?}"
    );
    for r in &rows[1..] {
        assert_eq!(r[0], "Alarm_Ack", "{r:?}");
        assert_eq!(&r[1..6], &["1", "1", "5", "1", "1"], "{r:?}");
        assert_eq!(r[8], "0x5c", "{r:?}");
    }
}

/// The FMS exchange of fms_capture/mod.rs (a BK3000 in mixed mode and an
/// FMS client on a `dpctl bus`), recorded by `dpctl sniff --pcap`: every
/// telegram the sniffer decoded as FMS with data, the dissector decodes
/// into the same `pbfms` fields, in the same order.
#[test]
fn dissector_decodes_an_fms_exchange_like_the_sniffer() {
    require("tshark");
    let cap = fms_capture::record();
    let want: Vec<&serde_json::Value> = cap
        .json
        .iter()
        .filter_map(|l| l.get("fms"))
        .filter(|f| f["lli"] != "poll" && f["lli"] != "empty")
        .collect();
    let rows = tshark_filtered(
        &cap.pcap,
        Some("pbfms"),
        &[
            "pbfms.lli",
            "pbfms.pdu",
            "pbfms.invoke_id",
            "pbfms.index",
            "pbfms.data",
            "pbfms.identify.vendor",
            "pbfms.error.text",
            "pbfms.monitoring_ms",
            "pbfms.malformed",
            "pbdl.dsap",
        ],
    );
    assert_eq!(rows.len(), want.len(), "{rows:#?}\n{want:#?}");
    // Associate, five services, the garbled request and its Reject (each
    // with its answer), Abort.
    assert_eq!(want.len(), 15, "{want:#?}");
    let text = |v: &serde_json::Value| match v {
        serde_json::Value::Null => String::new(),
        serde_json::Value::String(s) => s.replace(' ', "").to_lowercase(),
        other => other.to_string(),
    };
    for (r, w) in rows.iter().zip(&want) {
        if w["lli"] == "malformed" {
            // The dissector keeps the fields it read before the fault.
            assert_eq!(
                (r[0].as_str(), r[8].as_str()),
                ("malformed", w["error"].as_str().unwrap())
            );
            continue;
        }
        let expect = [
            text(&w["lli"]),
            text(&w["pdu"]),
            text(&w["invoke_id"]),
            text(&w["index"]),
            text(&w["data"]),
            w["vendor"].as_str().unwrap_or("").to_string(),
        ];
        // Hex and names compared without case; the vendor as it is.
        let mut got: Vec<String> = r[..5].iter().map(|c| c.to_lowercase()).collect();
        got.push(r[5].clone());
        assert_eq!(got, expect, "{r:?} vs {w}");
        if w["pdu"] == "error" {
            assert_eq!(r[6], w["error"].as_str().unwrap(), "{r:?}");
        }
        if w["lli"] == "associate" {
            assert_eq!(r[7], "2000", "{r:?}");
        }
    }
    // Requests go to the coupler's LSAP 40.
    assert!(rows.iter().any(|r| r[9] == "40"), "{rows:?}");
}
