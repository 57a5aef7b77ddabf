//! Benchmark: telegram round trip and throughput through `dpctl bus`
//! (unpaced) compared with a socat pty pair and a bare pty pair.
//!
//! Run with `cargo bench -p dpctl --bench bus_latency` (cargo builds dpctl
//! in the bench profile first; needs socat). A round trip is: this process writes a
//! 6-byte SD1 telegram to end A, an echo thread reads it completely from
//! end B and writes it back, this process reads it completely from A.
//! Through the hub and socat the telegram crosses the relay twice. The
//! paths are measured interleaved (one round trip on each in turn), so
//! that on a shared machine they all see the same load.
//!
//! Environment: `ROUNDS` (default 20000) round trips after 1000 warm-up
//! ones; `MBYTES` (default 8) for the throughput run.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{make_raw, open_tty, Bus, Proc, TempDir};
use std::fs::File;
use std::io::{Read, Write};
use std::process::Command;
use std::time::{Duration, Instant};

const TELEGRAM: [u8; 6] = [0x10, 0x02, 0x01, 0x49, 0x4C, 0x16];

/// Echo telegrams of `TELEGRAM.len()` bytes from `b` back to `b` until
/// `n` have been echoed.
fn spawn_echo(mut b: File, n: usize) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let mut buf = [0u8; TELEGRAM.len()];
        for _ in 0..n {
            b.read_exact(&mut buf).unwrap();
            b.write_all(&buf).unwrap();
        }
    })
}

struct Stats {
    p50: Duration,
    p99: Duration,
    p999: Duration,
    mean: Duration,
}

fn stats(mut times: Vec<Duration>) -> Stats {
    times.sort();
    let pct = |p: f64| times[((times.len() as f64 * p) as usize).min(times.len() - 1)];
    Stats {
        p50: pct(0.50),
        p99: pct(0.99),
        p999: pct(0.999),
        mean: times.iter().sum::<Duration>() / times.len() as u32,
    }
}

/// Round trips on every path in turn (path 0, 1, 2, …, 0, 1, …), so that
/// all paths see the same load on a shared machine.
fn interleaved_round_trips(paths: Vec<(File, File)>, rounds: usize) -> Vec<Stats> {
    let warm = 1000;
    let mut ends = vec![];
    let mut echoes = vec![];
    for (a, b) in paths {
        ends.push(a);
        echoes.push(spawn_echo(b, warm + rounds));
    }
    let mut times = vec![Vec::with_capacity(rounds); ends.len()];
    let mut buf = [0u8; TELEGRAM.len()];
    for i in 0..warm + rounds {
        for (k, a) in ends.iter_mut().enumerate() {
            let t0 = Instant::now();
            a.write_all(&TELEGRAM).unwrap();
            a.read_exact(&mut buf).unwrap();
            let dt = t0.elapsed();
            assert_eq!(buf, TELEGRAM);
            if i >= warm {
                times[k].push(dt);
            }
        }
    }
    for e in echoes {
        e.join().unwrap();
    }
    times.into_iter().map(stats).collect()
}

/// MB/s from `a` to `b` (b only reads).
fn throughput(mut a: File, mut b: File, mbytes: usize) -> f64 {
    let total = mbytes << 20;
    let reader = std::thread::spawn(move || {
        let mut buf = vec![0u8; 1 << 16];
        let mut got = 0;
        while got < total {
            got += b.read(&mut buf).unwrap();
        }
    });
    let chunk = vec![0x55u8; 4096];
    let t0 = Instant::now();
    let mut sent = 0;
    while sent < total {
        a.write_all(&chunk).unwrap();
        sent += chunk.len();
    }
    reader.join().unwrap();
    total as f64 / t0.elapsed().as_secs_f64() / 1e6
}

fn us(d: Duration) -> String {
    format!("{:.1}", d.as_nanos() as f64 / 1000.0)
}

fn report(name: &str, s: &Stats, mbs: f64) {
    println!(
        "| {name} | {} | {} | {} | {} | {mbs:.1} |",
        us(s.p50),
        us(s.p99),
        us(s.p999),
        us(s.mean)
    );
}

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else to parse.
    let rounds = env_usize("ROUNDS", 20_000);
    let mbytes = env_usize("MBYTES", 8);
    common::require("socat");
    println!("round trip of a 6-byte telegram, {rounds} rounds; throughput {mbytes} MiB one way");
    println!();
    println!("| path | p50 µs | p99 µs | p99.9 µs | mean µs | MB/s |");
    println!("|---|---|---|---|---|---|");

    // Bare pty pair: no relay process.
    let pair = || {
        let pty = nix::pty::openpty(None, None).unwrap();
        let (a, b) = (File::from(pty.master), File::from(pty.slave));
        make_raw(&b);
        (a, b)
    };
    // socat pty pair.
    let dir = TempDir::new("bench");
    let (pa, pb) = (dir.path("a"), dir.path("b"));
    let socat = || {
        let mut cmd = Command::new("socat");
        cmd.arg(format!("pty,raw,echo=0,link={}", pa.display()))
            .arg(format!("pty,raw,echo=0,link={}", pb.display()));
        let p = Proc::spawn_captured(cmd);
        common::wait_for("socat", Duration::from_secs(10), || {
            pa.exists() && pb.exists()
        });
        std::thread::sleep(Duration::from_millis(50));
        p
    };
    // dpctl bus with 2 stations, and with 8 (6 of them only listening).
    let bus2 = Bus::start(2, &[]);
    let bus8 = Bus::start(8, &[]);
    let listeners: Vec<_> = (2..8)
        .map(|i| {
            let mut f = open_tty(&bus8.link(i));
            std::thread::spawn(move || {
                let mut buf = [0u8; 4096];
                while let Ok(n) = f.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                }
            })
        })
        .collect();

    let p = socat();
    let paths = vec![
        pair(),
        (open_tty(&pa), open_tty(&pb)),
        (open_tty(&bus2.link(0)), open_tty(&bus2.link(1))),
        (open_tty(&bus8.link(0)), open_tty(&bus8.link(1))),
    ];
    // The hub checks for new openers every 5 ms.
    std::thread::sleep(Duration::from_millis(50));
    let st = interleaved_round_trips(paths, rounds);
    drop(p);
    common::wait_for("socat gone", Duration::from_secs(10), || !pa.exists());

    let (a, b) = pair();
    let direct_mbs = throughput(a, b, mbytes);
    let p = socat();
    let socat_mbs = throughput(open_tty(&pa), open_tty(&pb), mbytes);
    drop(p);
    let (a, b) = (open_tty(&bus2.link(0)), open_tty(&bus2.link(1)));
    // Bytes are only delivered once the hub has seen the new openers.
    std::thread::sleep(Duration::from_millis(50));
    let hub_mbs = throughput(a, b, mbytes);

    report("pty pair (no relay)", &st[0], direct_mbs);
    report("socat pty pair", &st[1], socat_mbs);
    report("dpctl bus, 2 stations, unpaced", &st[2], hub_mbs);
    report(
        "dpctl bus, 8 stations (6 listening), unpaced",
        &st[3],
        f64::NAN,
    );
    for bus in [bus2, bus8] {
        let out = bus.stop();
        assert!(out.status.success(), "{out:?}");
    }
    for l in listeners {
        let _ = l.join();
    }

    println!();
    let added = |x: Duration, base: Duration| {
        x.as_nanos() as f64 / 1000.0 - base.as_nanos() as f64 / 1000.0
    };
    let (h, s, d) = (&st[2], &st[1], &st[0]);
    println!(
        "hub added to a round trip vs socat: p50 {:+.1} µs, p99 {:+.1} µs; vs a bare pty pair: p50 {:+.1} µs, p99 {:+.1} µs (target: ≤ 20 µs at p99)",
        added(h.p50, s.p50),
        added(h.p99, s.p99),
        added(h.p50, d.p50),
        added(h.p99, d.p99)
    );
}
