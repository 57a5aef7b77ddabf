//! Benchmark: telegram round trip and throughput through `dpctl bus`
//! (unpaced) compared with a socat pty pair and a bare pty pair.
//!
//! Run with `cargo bench -p profibus --bench bus_latency` (builds dpctl in
//! release mode; needs socat). A round trip is: this process writes a
//! 6-byte SD1 telegram to end A, an echo thread reads it completely from
//! end B and writes it back, this process reads it completely from A.
//! Through the hub and socat the telegram crosses the relay twice.
//!
//! Environment: `ROUNDS` (default 20000) round trips after 1000 warm-up
//! ones; `MBYTES` (default 8) for the throughput run.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Bus, Proc, TempDir};
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

const TELEGRAM: [u8; 6] = [0x10, 0x02, 0x01, 0x49, 0x4C, 0x16];

fn open_tty(path: &Path) -> File {
    OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(nix::libc::O_NOCTTY)
        .open(path)
        .unwrap_or_else(|e| panic!("open {}: {e}", path.display()))
}

fn make_raw(f: &File) {
    use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
    let mut t = tcgetattr(f).unwrap();
    cfmakeraw(&mut t);
    tcsetattr(f, SetArg::TCSANOW, &t).unwrap();
}

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

fn round_trips(mut a: File, b: File, rounds: usize) -> Stats {
    let warm = 1000;
    let echo = spawn_echo(b, warm + rounds);
    let mut buf = [0u8; TELEGRAM.len()];
    let mut times = Vec::with_capacity(rounds);
    for i in 0..warm + rounds {
        let t0 = Instant::now();
        a.write_all(&TELEGRAM).unwrap();
        a.read_exact(&mut buf).unwrap();
        let dt = t0.elapsed();
        assert_eq!(buf, TELEGRAM);
        if i >= warm {
            times.push(dt);
        }
    }
    echo.join().unwrap();
    times.sort();
    let pct = |p: f64| times[((times.len() as f64 * p) as usize).min(times.len() - 1)];
    Stats {
        p50: pct(0.50),
        p99: pct(0.99),
        p999: pct(0.999),
        mean: times.iter().sum::<Duration>() / times.len() as u32,
    }
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
    let (a, b) = pair();
    let direct = round_trips(a, b, rounds);
    let (a, b) = pair();
    let direct_mbs = throughput(a, b, mbytes);
    report("pty pair (no relay)", &direct, direct_mbs);

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
    let p = socat();
    let s = round_trips(open_tty(&pa), open_tty(&pb), rounds);
    drop(p);
    common::wait_for("socat gone", Duration::from_secs(10), || !pa.exists());
    let p = socat();
    let s_mbs = throughput(open_tty(&pa), open_tty(&pb), mbytes);
    drop(p);
    report("socat pty pair", &s, s_mbs);

    // dpctl bus, 2 stations, unpaced.
    let bus = Bus::start(2, &[]);
    let (a, b) = (open_tty(&bus.link(0)), open_tty(&bus.link(1)));
    // The hub checks for new openers every 5 ms.
    std::thread::sleep(Duration::from_millis(50));
    let h = round_trips(a, b, rounds);
    let (a, b) = (open_tty(&bus.link(0)), open_tty(&bus.link(1)));
    std::thread::sleep(Duration::from_millis(50));
    let h_mbs = throughput(a, b, mbytes);
    let out = bus.stop();
    assert!(out.status.success(), "{out:?}");
    report("dpctl bus, 2 stations, unpaced", &h, h_mbs);

    let bus = Bus::start(8, &[]);
    let (a, b) = (open_tty(&bus.link(0)), open_tty(&bus.link(1)));
    // Six more stations listening (and reading) as on a real bus.
    let listeners: Vec<_> = (2..8)
        .map(|i| {
            let mut f = open_tty(&bus.link(i));
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
    std::thread::sleep(Duration::from_millis(50));
    let h8 = round_trips(a, b, rounds);
    let out = bus.stop();
    assert!(out.status.success(), "{out:?}");
    for l in listeners {
        let _ = l.join();
    }
    report(
        "dpctl bus, 8 stations (6 listening), unpaced",
        &h8,
        f64::NAN,
    );

    println!();
    let added = |x: Duration, base: Duration| {
        x.as_nanos() as f64 / 1000.0 - base.as_nanos() as f64 / 1000.0
    };
    println!(
        "hub added to a round trip vs socat: p50 {:+.1} µs, p99 {:+.1} µs; vs a bare pty pair: p50 {:+.1} µs, p99 {:+.1} µs (target: ≤ 20 µs at p99)",
        added(h.p50, s.p50),
        added(h.p99, s.p99),
        added(h.p50, direct.p50),
        added(h.p99, direct.p99)
    );
}
