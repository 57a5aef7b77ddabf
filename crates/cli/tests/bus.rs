//! End-to-end tests of `dpctl bus` (the virtual RS-485 bus of ptys) and
//! `dpctl sniff`, with real processes.

mod common;

use common::{require, run_dpctl, Bus, Proc, TempDir};
use profibus::fdl::capture::pcap::PcapReader;
use profibus::fdl::wire::{DataTelegram, FunctionCode, RequestKind, Telegram};
use profibus::fdl::Baud;
use profibus_io::transport::Port;
use std::process::Command;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

fn open(bus: &Bus, i: usize) -> Port {
    Port::open(&bus.link_str(i), Baud::B19200).expect("open bus link")
}

/// Read exactly `n` bytes within `timeout`.
async fn read_n(port: &mut Port, n: usize, timeout: Duration) -> Vec<u8> {
    let mut v = vec![0u8; n];
    tokio::time::timeout(timeout, port.read_exact(&mut v))
        .await
        .unwrap_or_else(|_| panic!("timed out reading {n} bytes from {}", port.name()))
        .expect("read");
    v
}

/// Whatever arrives within `wait`.
async fn read_some(port: &mut Port, wait: Duration) -> Vec<u8> {
    let mut v = vec![];
    let mut buf = [0u8; 4096];
    let end = tokio::time::Instant::now() + wait;
    while let Ok(Ok(n)) = tokio::time::timeout_at(end, port.read(&mut buf)).await {
        if n == 0 {
            break;
        }
        v.extend_from_slice(&buf[..n]);
    }
    v
}

fn fdl_status(da: u8, sa: u8) -> Vec<u8> {
    let mut b = [0u8; 6];
    let n = Telegram::Data(DataTelegram {
        da,
        sa,
        fc: FunctionCode::request(RequestKind::FdlStatus),
        dsap: None,
        ssap: None,
        data: &[],
        format: None,
    })
    .emit(&mut b)
    .unwrap();
    b[..n].to_vec()
}

fn sd2(da: u8, sa: u8, data: &[u8]) -> Vec<u8> {
    let mut b = [0u8; 255];
    let n = Telegram::Data(DataTelegram {
        da,
        sa,
        fc: FunctionCode::request(RequestKind::SrdHigh),
        dsap: Some(58),
        ssap: Some(62),
        data,
        format: None,
    })
    .emit(&mut b)
    .unwrap();
    b[..n].to_vec()
}

#[tokio::test]
async fn hub_sends_every_byte_to_every_other_station_in_order() {
    let bus = Bus::start(4, &[]);
    let mut ports: Vec<Port> = (0..4).map(|i| open(&bus, i)).collect();
    // The hub notices new openers within a few ms: wait until it has.
    bus.wait_connected(4);
    for from in 0..4 {
        // 100 writes of 40 numbered bytes each.
        let mut sent = vec![];
        for k in 0..100u32 {
            let chunk: Vec<u8> = (0..40u32)
                .map(|j| ((k * 40 + j) * 7 + from as u32) as u8)
                .collect();
            ports[from].write_all(&chunk).await.unwrap();
            sent.extend_from_slice(&chunk);
        }
        for (to, port) in ports.iter_mut().enumerate() {
            if to == from {
                continue;
            }
            let got = read_n(port, sent.len(), Duration::from_secs(10)).await;
            assert!(got == sent, "station {to} got other bytes from {from}");
        }
        let echo = read_some(&mut ports[from], Duration::from_millis(50)).await;
        assert!(
            echo.is_empty(),
            "station {from} heard itself: {} bytes",
            echo.len()
        );
    }
    drop(ports);
    let out = bus.stop();
    assert!(out.status.success(), "{out:?}");
    assert!(out.stderr.contains("chars 16000"), "{}", out.stderr);
}

#[test]
fn links_are_removed_on_sigint_and_sigterm() {
    for sig in [2, 15] {
        let bus = Bus::start(2, &[]);
        let links = [bus.link(0), bus.link(1)];
        assert!(std::fs::read_link(&links[0])
            .unwrap()
            .starts_with("/dev/pts"));
        bus.proc.signal(sig);
        let Bus { proc, .. } = bus;
        let out = proc.finish(Duration::from_secs(10));
        assert!(out.status.success(), "signal {sig}: {out:?}");
        assert!(
            out.stderr.contains("dpctl bus: transmissions"),
            "{}",
            out.stderr
        );
        for l in &links {
            assert!(
                std::fs::symlink_metadata(l).is_err(),
                "{} left behind",
                l.display()
            );
        }
    }
}

#[test]
fn bad_arguments_exit_2_with_one_line() {
    let dir = TempDir::new("args");
    let file = dir.path("st0");
    std::fs::write(&file, b"precious").unwrap();
    let prefix = dir.path("st");
    let prefix = prefix.to_str().unwrap();
    let other = dir.path("x");
    let two = ["bus", "--stations", "2", "--link", other.to_str().unwrap()];
    for (args, expect) in [
        (
            vec!["bus", "--stations", "1", "--link", prefix],
            "--stations",
        ),
        (
            vec!["bus", "--stations", "2", "--link", prefix],
            "not a symlink",
        ),
        (
            [&two[..], &["--baud", "115200"]].concat(),
            "unknown baud rate",
        ),
        ([&two[..], &["--drop", "1.5"]].concat(), "probability"),
    ] {
        let out = run_dpctl(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {out:?}");
        let first = out.stderr.lines().next().unwrap_or("");
        assert!(first.contains(expect), "{args:?}: {}", out.stderr);
        // One line of error (clap may add its usual hint after a blank line).
        let lines: Vec<&str> = out.stderr.lines().filter(|l| !l.is_empty()).collect();
        assert!(lines.len() <= 2, "{args:?}: {}", out.stderr);
    }
    assert_eq!(std::fs::read(&file).unwrap(), b"precious");
}

#[tokio::test]
async fn stale_links_are_replaced() {
    let dir = TempDir::new("stale");
    let prefix = dir.path("st");
    std::os::unix::fs::symlink("/dev/pts/nonexistent", dir.path("st0")).unwrap();
    let mut cmd = Command::new(common::dpctl());
    cmd.args(["bus", "--stations", "2", "--link"]).arg(&prefix);
    let proc = Proc::spawn_captured(cmd);
    common::wait_for("links", Duration::from_secs(20), || {
        std::fs::read_link(dir.path("st0")).is_ok_and(|t| t.starts_with("/dev/pts") && t.exists())
            && dir.path("st1").exists()
    });
    let out = proc.stop();
    assert!(out.status.success(), "{out:?}");
}

#[tokio::test]
async fn a_station_may_close_and_reopen_its_pty() {
    let bus = Bus::start(3, &[]);
    let mut a = open(&bus, 0);
    let mut b = open(&bus, 1);
    bus.wait_connected(2);
    a.write_all(b"first").await.unwrap();
    assert_eq!(read_n(&mut b, 5, Duration::from_secs(5)).await, b"first");
    // Station 1 goes away; what is sent meanwhile must not reach it later.
    drop(b);
    bus.wait_connected(1);
    a.write_all(b"while away").await.unwrap();
    // The hub has carried those 10 characters (to nobody) before station 1
    // comes back.
    bus.wait_status("the characters sent while away", |s| {
        common::counter(s, "chars ") == Some(15)
    });
    let mut b = open(&bus, 1);
    bus.wait_connected(2);
    a.write_all(b"again").await.unwrap();
    assert_eq!(read_n(&mut b, 5, Duration::from_secs(5)).await, b"again");
    // And it can talk again.
    b.write_all(b"back").await.unwrap();
    assert_eq!(read_n(&mut a, 4, Duration::from_secs(5)).await, b"back");
    drop((a, b));
    let out = bus.stop();
    assert!(out.status.success(), "{out:?}");
}

/// Run the hub with faults and a seed, send the same bytes, return what a
/// receiver got and the counters the hub printed.
async fn faulty_run(seed: &str) -> (Vec<u8>, String) {
    let bus = Bus::start(2, &["--drop", "0.01", "--flip", "0.001", "--seed", seed]);
    let mut a = open(&bus, 0);
    let mut b = open(&bus, 1);
    bus.wait_connected(2);
    let data: Vec<u8> = (0..20_000u32).map(|i| (i * 13) as u8).collect();
    for c in data.chunks(100) {
        a.write_all(c).await.unwrap();
    }
    // ~1 % is dropped: once the hub has carried all 20 000 characters,
    // the rest arrives (and nothing more).
    let s = bus.wait_status("all characters carried", |s| {
        common::counter(s, "chars ") == Some(20_000)
    });
    let kept = 20_000 - common::counter(&s, "dropped ").expect("drop counter") as usize;
    let mut got = read_n(&mut b, kept, Duration::from_secs(10)).await;
    got.extend(read_some(&mut b, Duration::from_millis(50)).await);
    drop((a, b));
    let out = bus.stop();
    assert!(out.status.success(), "{out:?}");
    // Drop and flip counts depend on the characters only, not on how the
    // reads chunked them (unlike the number of transmissions).
    let line = out.stderr.lines().last().unwrap_or("").to_string();
    let counters = ["chars ", "dropped ", "bits flipped "]
        .iter()
        .map(|k| {
            let v = line
                .split(k)
                .nth(1)
                .unwrap_or("?")
                .split(',')
                .next()
                .unwrap();
            format!("{k}{v}")
        })
        .collect::<Vec<_>>()
        .join(", ");
    (got, counters)
}

#[tokio::test]
async fn fault_injection_is_reproducible_with_a_seed() {
    let (got1, c1) = faulty_run("42").await;
    let (got2, c2) = faulty_run("42").await;
    let (got3, c3) = faulty_run("43").await;
    assert_eq!(c1, c2);
    assert!(got1 == got2, "same seed, different bytes");
    assert_ne!(c1, c3);
    assert!(got1 != got3);
    assert!(c1.contains("chars 20000"), "{c1}");
    // About 200 dropped and 160 flipped bits.
    let dropped: u64 = c1
        .split("dropped ")
        .nth(1)
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!((100..300).contains(&dropped), "{c1}");
    assert_eq!(got1.len() as u64, 20_000 - dropped);
}

#[tokio::test]
async fn pacing_makes_the_bus_as_slow_as_the_wire() {
    // 1920 characters at 19.2 kbit/s take 1.1 s on the wire.
    let bus = Bus::start(2, &["--baud", "19200"]);
    let mut a = open(&bus, 0);
    let mut b = open(&bus, 1);
    bus.wait_connected(2);
    let start = std::time::Instant::now();
    a.write_all(&[0x55; 1920]).await.unwrap();
    // The transmission arrives in one piece when its last character has
    // crossed the wire: no partial telegram with a pause inside.
    let all = read_n(&mut b, 1920, Duration::from_secs(5)).await;
    let t_all = start.elapsed();
    assert!(all.iter().all(|&x| x == 0x55));
    assert!(t_all >= Duration::from_millis(1090), "{t_all:?}");
    assert!(t_all < Duration::from_millis(2500), "{t_all:?}");
    drop((a, b));
    bus.stop();
}

/// The pcap file of `dpctl bus --pcap` and `dpctl sniff --pcap` is read
/// back by tshark with the right number of packets.
#[tokio::test]
async fn pcap_files_are_read_by_tshark() {
    require("tshark");
    let files = TempDir::new("pcap");
    let hub_pcap = files.path("hub.pcapng");
    let sniff_pcap = files.path("sniff.pcapng");
    let bus = Bus::start(3, &["--pcap", hub_pcap.to_str().unwrap()]);
    let mut cmd = Command::new(common::dpctl());
    cmd.args(["sniff", "--port", &bus.link_str(2), "--json", "--pcap"])
        .arg(&sniff_pcap);
    let sniff = Proc::spawn_captured(cmd);
    let mut a = open(&bus, 0);
    let mut b = open(&bus, 1);
    bus.wait_connected(3);
    // 30 exchanges: request, response (SD2), token; plus garbage that must
    // not become packets.
    let mut expect = 0;
    for k in 0..30u8 {
        a.write_all(&fdl_status(2, 1)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(1)).await;
        b.write_all(&sd2(1, 2, &[k; 20])).await.unwrap();
        tokio::time::sleep(Duration::from_millis(1)).await;
        a.write_all(&[0xDC, 2, 1]).await.unwrap();
        b.write_all(&[0x00, 0x42]).await.unwrap();
        b.write_all(&[0xE5]).await.unwrap();
        expect += 4;
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    // The sniffer has printed every telegram and garbage run.
    sniff.wait_stdout("telegrams and errors", expect + 30, |_| true);
    let sniffed = sniff.stop();
    drop((a, b));
    let out = bus.stop();
    assert!(out.status.success(), "{out:?}");
    assert!(sniffed.status.success(), "{sniffed:?}");

    // The sniffer printed one JSON object per telegram and marked the garbage.
    let lines: Vec<serde_json::Value> = sniffed
        .stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect();
    let telegrams = lines.iter().filter(|v| v.get("type").is_some()).count();
    let errors = lines.iter().filter(|v| v.get("error").is_some()).count();
    assert_eq!(telegrams, expect, "{}", sniffed.stdout);
    assert_eq!(errors, 30);
    let summary = &lines.last().unwrap()["summary"];
    assert_eq!(summary["telegrams"], expect);
    assert_eq!(summary["garbage_bytes"], 60);
    assert!(lines[0]["t_us"].as_u64().is_some());

    for file in [&hub_pcap, &sniff_pcap] {
        // Every telegram, and each garbage run as a packet flagged corrupt
        // (so that Wireshark's `pbdl.fcs.good == 0` finds it).
        let packets: Vec<_> = PcapReader::new(std::fs::File::open(file).unwrap())
            .unwrap()
            .map(|p| p.unwrap())
            .collect();
        let corrupt = packets.iter().filter(|p| p.is_corrupt()).count();
        assert_eq!(packets.len() - corrupt, expect, "{}", file.display());
        assert_eq!(corrupt, 30, "{}", file.display());
        let t = Command::new("tshark")
            .arg("-r")
            .arg(file)
            .output()
            .expect("run tshark");
        assert!(
            t.status.success(),
            "tshark: {}",
            String::from_utf8_lossy(&t.stderr)
        );
        let n = String::from_utf8_lossy(&t.stdout).lines().count();
        assert_eq!(
            n,
            packets.len(),
            "tshark read {n} packets from {}",
            file.display()
        );
    }
}

#[tokio::test]
async fn sniff_marks_errors_for_humans() {
    let bus = Bus::start(2, &[]);
    let mut cmd = Command::new(common::dpctl());
    cmd.args(["sniff", "--port", &bus.link_str(1)]);
    let sniff = Proc::spawn_captured(cmd);
    let mut a = open(&bus, 0);
    bus.wait_connected(2);
    let mut bad = fdl_status(3, 1);
    bad[4] ^= 0x10;
    a.write_all(&fdl_status(3, 1)).await.unwrap();
    a.write_all(&bad).await.unwrap();
    a.write_all(&[0xDC, 3, 1]).await.unwrap();
    sniff.wait_stdout("lines", 3, |_| true);
    let out = sniff.stop();
    drop(a);
    bus.stop();
    let lines: Vec<&str> = out.stdout.lines().collect();
    assert_eq!(lines.len(), 4, "{}", out.stdout);
    assert!(
        lines[0].ends_with("SD1 1→3 FDL_Status FCS ok"),
        "{}",
        lines[0]
    );
    assert!(
        lines[1].starts_with("!! ") && lines[1].contains("bad FCS"),
        "{}",
        lines[1]
    );
    assert!(lines[2].ends_with("SD4 token 1→3"), "{}", lines[2]);
    assert!(lines[3].starts_with("summary: 2 telegrams"), "{}", lines[3]);
    assert!(lines[3].contains("1 bad FCS"), "{}", lines[3]);
}

/// Two processes exchange telegrams through the hub: a responder (Python,
/// an independent process) answers each FDL_Status request addressed to
/// it; this test sends the requests and checks the answers.
#[tokio::test]
async fn two_processes_exchange_telegrams_through_the_hub() {
    require("python3");
    let bus = Bus::start(3, &[]);
    let responder = r#"
import os, sys
fd = os.open(sys.argv[1], os.O_RDWR | os.O_NOCTTY)
buf = b""
while True:
    buf += os.read(fd, 256)
    while len(buf) >= 6:
        if buf[0] != 0x10:
            buf = buf[1:]
            continue
        t, buf = buf[:6], buf[6:]
        da, sa, fc = t[1], t[2], t[3]
        if da == 5 and (da + sa + fc) & 0xFF == t[4] and t[5] == 0x16:
            # FDL_Status response: passive station, status OK (FC 0x00).
            r = bytes([0x10, sa, 5, 0x00, (sa + 5) & 0xFF, 0x16])
            os.write(fd, r)
"#;
    let mut cmd = Command::new("python3");
    cmd.arg("-c").arg(responder).arg(bus.link(1));
    let _peer = Proc::spawn_captured(cmd);
    let mut master = open(&bus, 0);
    let mut listener = open(&bus, 2);
    // Wait until the responder runs and the hub has seen it open its pty.
    let mut ready = false;
    for _ in 0..50 {
        master.write_all(&fdl_status(5, 1)).await.unwrap();
        if read_some(&mut master, Duration::from_millis(200))
            .await
            .len()
            == 6
        {
            ready = true;
            break;
        }
    }
    assert!(ready, "the responder never answered");
    read_some(&mut listener, Duration::from_millis(100)).await;
    for _ in 0..200 {
        let req = fdl_status(5, 1);
        master.write_all(&req).await.unwrap();
        let resp = read_n(&mut master, 6, Duration::from_secs(5)).await;
        let (t, _) = Telegram::parse(&resp).expect("valid response");
        let d = t.as_data().expect("data telegram");
        assert_eq!((d.da, d.sa, d.fc.is_request()), (1, 5, false));
        // The third station heard both.
        let heard = read_n(&mut listener, 12, Duration::from_secs(5)).await;
        assert_eq!(&heard[..6], &req[..]);
        assert_eq!(&heard[6..], &resp[..]);
    }
    drop((master, listener));
    let out = bus.stop();
    assert!(out.status.success(), "{out:?}");
}

/// A Port works on a socat pty pair as on a bus link.
#[tokio::test]
async fn port_works_on_a_socat_pty_pair() {
    require("socat");
    let dir = TempDir::new("socat");
    let (pa, pb) = (dir.path("a"), dir.path("b"));
    let mut cmd = Command::new("socat");
    cmd.arg(format!("pty,raw,echo=0,link={}", pa.display()))
        .arg(format!("pty,raw,echo=0,link={}", pb.display()));
    let _socat = Proc::spawn_captured(cmd);
    common::wait_for("socat links", Duration::from_secs(10), || {
        pa.exists() && pb.exists()
    });
    let mut a = Port::open(pa.to_str().unwrap(), Baud::B12000000).unwrap();
    let mut b = Port::open(pb.to_str().unwrap(), Baud::B12000000).unwrap();
    let t = sd2(3, 1, &[0x0D, 0x0A, 0x03, 0x7F, 0xFF]);
    a.write_all(&t).await.unwrap();
    assert_eq!(read_n(&mut b, t.len(), Duration::from_secs(5)).await, t);
    b.write_all(&[0xE5]).await.unwrap();
    assert_eq!(read_n(&mut a, 1, Duration::from_secs(5)).await, [0xE5]);
}

/// A random valid telegram (SD1, SD2, SD3, token, short acknowledge).
fn random_telegram(r: &mut profibus::fdl::rng::Rng) -> Vec<u8> {
    match r.range_inclusive(0, 4) {
        0 => vec![0xE5],
        1 => vec![
            0xDC,
            r.range_inclusive(0, 126) as u8,
            r.range_inclusive(0, 126) as u8,
        ],
        2 => fdl_status(
            r.range_inclusive(0, 126) as u8,
            r.range_inclusive(0, 126) as u8,
        ),
        _ => {
            let len = r.range_inclusive(0, 200) as usize;
            let data: Vec<u8> = (0..len).map(|_| r.next_u8()).collect();
            sd2(
                r.range_inclusive(0, 126) as u8,
                r.range_inclusive(0, 126) as u8,
                &data,
            )
        }
    }
}

/// `--drop 0 --flip 0` changes nothing: 100 000 telegrams arrive intact
/// and the receiver's codec counts no error.
#[tokio::test]
async fn zero_faults_carry_100000_telegrams_unchanged() {
    use profibus::fdl::line::tap::{Tap, TapEvent};
    let bus = Bus::start(2, &["--drop", "0", "--flip", "0", "--seed", "1"]);
    let mut a = open(&bus, 0);
    let mut b = open(&bus, 1);
    bus.wait_connected(2);
    let mut r = profibus::fdl::rng::Rng::new(77);
    let sent: Vec<Vec<u8>> = (0..100_000).map(|_| random_telegram(&mut r)).collect();
    let stream: Vec<u8> = sent.concat();
    // Writer and reader share this test's one thread, and the hub drops
    // bytes for a station that does not read (overruns): the writer keeps
    // at most 256 KiB ahead of what the reader has received.
    let (read_tx, mut read_rx) = tokio::sync::watch::channel(0usize);
    let writer = tokio::spawn(async move {
        for (k, c) in stream.chunks(1000).enumerate() {
            while k * 1000 > *read_rx.borrow() + (256 << 10) {
                read_rx.changed().await.unwrap();
            }
            a.write_all(c).await.unwrap();
        }
        a
    });
    let mut tap = Tap::new();
    let mut got: Vec<Vec<u8>> = Vec::with_capacity(sent.len());
    let mut buf = vec![0u8; 1 << 16];
    while got.len() < sent.len() {
        let n = tokio::time::timeout(Duration::from_secs(10), b.read(&mut buf))
            .await
            .expect("telegrams stopped arriving")
            .unwrap();
        tap.push(profibus::fdl::Instant::ZERO, &buf[..n]);
        read_tx.send_modify(|r| *r += n);
        while let Some(ev) = tap.poll() {
            match ev {
                TapEvent::Telegram { bytes, .. } => got.push(bytes),
                TapEvent::Skipped { bytes, .. } => panic!("skipped {bytes:02X?}"),
            }
        }
    }
    let a = writer.await.unwrap();
    assert!(got == sent, "telegrams changed on the way");
    let s = tap.stats();
    assert_eq!((s.errors(), s.garbage_bytes, s.telegrams), (0, 0, 100_000));
    drop((a, b));
    let out = bus.stop();
    assert!(
        out.stderr.contains("dropped 0, bits flipped 0"),
        "{}",
        out.stderr
    );
}

/// Bits flipped by the hub are caught by the receiver's FCS and framing
/// checks (a pty carries no parity bit) and show in `dpctl sniff`'s
/// counters.
#[tokio::test]
async fn flipped_bits_show_up_as_codec_errors_in_sniff() {
    let bus = Bus::start(3, &["--flip", "0.002", "--seed", "9"]);
    let mut cmd = Command::new(common::dpctl());
    cmd.args(["sniff", "--json", "--port", &bus.link_str(2)]);
    let sniff = Proc::spawn_captured(cmd);
    let mut a = open(&bus, 0);
    bus.wait_connected(2);
    for k in 0..2000u32 {
        a.write_all(&sd2(3, 1, &[k as u8; 16])).await.unwrap();
        if k % 100 == 99 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let out = sniff.stop();
    drop(a);
    let hub = bus.stop();
    let flipped: u64 = hub
        .stderr
        .rsplit("bits flipped ")
        .next()
        .and_then(|s| s.split(',').next())
        .and_then(|s| s.parse().ok())
        .expect("flip counter");
    // 2000 × 25 bytes × 8 bits × 0.002 ≈ 800 flips.
    assert!((500..1100).contains(&flipped), "{}", hub.stderr);
    let last: serde_json::Value = serde_json::from_str(out.stdout.lines().last().unwrap()).unwrap();
    let s = &last["summary"];
    let errors = s["bad_fcs"].as_u64().unwrap()
        + s["bad_length"].as_u64().unwrap()
        + s["bad_end_delimiter"].as_u64().unwrap();
    let good = s["telegrams"].as_u64().unwrap();
    // Most corrupted telegrams are rejected; the intact ones pass.
    assert!(errors > 300, "{s}");
    assert!(good > 1000 && good < 2000, "{s}");
    let marked = out
        .stdout
        .lines()
        .filter(|l| l.contains("\"error\""))
        .count();
    assert!(marked > 300, "{marked}");
}

#[test]
fn counters_on_sigusr1_and_with_stats() {
    let bus = Bus::start(2, &["--stats", "0.1"]);
    let mut periodic = 0;
    while periodic < 3 {
        let l = bus.proc.stderr_line(Duration::from_secs(30));
        let l = l.expect("periodic status lines");
        periodic += l.starts_with("dpctl bus: transmissions") as usize;
    }
    bus.status();
    let out = bus.stop();
    let lines = out
        .stderr
        .lines()
        .filter(|l| l.starts_with("dpctl bus: transmissions"))
        .count();
    // ≥ 3 periodic + 1 on SIGUSR1 + 1 at exit.
    assert!(lines >= 5, "{}", out.stderr);
}
