//! Benchmark: `dpctl sniff` with statistics on a saturated 12 Mbit/s
//! `dpctl bus` (issue 31): does it keep up, and what does a telegram cost?
//!
//! Run with `cargo bench -p dpctl --bench sniff_rate` (cargo builds dpctl
//! in the bench profile first; needs socat). A synthetic DP segment —
//! master 2 polls slaves 3 … 34 with Data_Exchange (4 bytes each way,
//! FCB alternating, inputs changing), its token to itself after every 32
//! exchanges, no idle time between telegrams — reaches `dpctl sniff
//! --baud 12M --stats 1`, once with `--json` and once with plain lines,
//! its output read by this process, from one of two sources:
//!
//! - `socat`: written as fast as the sniffer takes it into one end of a
//!   socat pty pair (flow-controlled: nothing is lost, the sniffer sets
//!   the pace; shows what the sniffer could do above the line's rate);
//! - `bus`: written into station 0 of `dpctl bus --baud 12M`, the sniffer
//!   on station 1: the bus paces it at 12 Mbit/s (the wall time cannot
//!   beat the line's) and drops what the sniffer does not take in time
//!   (its backlog: one second of line), so telegrams lost and the bus's
//!   overruns show whether the sniffer keeps up with a saturated line.
//!
//! Printed per source and mode, as a Markdown table: telegrams sent,
//! decoded and lost, the bus's overruns (bytes), the time a 12 Mbit/s
//! line needs for them (11 bit per character, no idle), the wall time
//! the sniffer took, its rate against the line's, its CPU time (user +
//! system, from /proc), CPU µs per telegram, the rate one core could
//! decode at that cost, and the bus's own CPU time.
//!
//! Environment: `TELEGRAMS` (default 600000, a multiple of 66); `SOURCE`
//! = `socat`, `bus` or `all` (default `all`).

#[path = "../tests/common/mod.rs"]
mod common;

use common::{counter, dpctl, make_raw, open_tty, pty_pair, Bus, Proc, TempDir};
use std::io::Write;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// Bits per character on the line.
const CHAR_BITS: u64 = 11;
/// The line's rate.
const BAUD: u64 = 12_000_000;

/// An SD2 telegram: `68 LE LEr 68 DA SA FC data FCS 16`.
fn sd2(da: u8, sa: u8, fc: u8, data: &[u8]) -> Vec<u8> {
    let le = 3 + data.len() as u8;
    let mut t = vec![0x68, le, le, 0x68, da, sa, fc];
    t.extend_from_slice(data);
    let fcs = t[4..].iter().fold(0u8, |a, b| a.wrapping_add(*b));
    t.extend_from_slice(&[fcs, 0x16]);
    t
}

/// `n` telegrams of the synthetic segment (cycles of 32 exchanges and a
/// token: 65 telegrams, plus one more exchange so the count divides).
fn segment(n: usize) -> (Vec<u8>, usize) {
    let mut out = Vec::with_capacity(n * 13);
    let mut count = 0;
    let mut fcb = [false; 35];
    let mut cycle = 0u32;
    while count < n {
        for slave in 3u8..=34 {
            let i = usize::from(slave);
            // SRD high with FCV; FCB alternates per slave.
            let fc = 0x5D | if fcb[i] { 0x20 } else { 0 };
            fcb[i] = !fcb[i];
            let out_data = cycle.to_be_bytes();
            out.extend(sd2(slave, 2, fc, &out_data));
            let in_data = (cycle ^ u32::from(slave) << 24).to_be_bytes();
            out.extend(sd2(2, slave, 0x08, &in_data));
            count += 2;
        }
        // The token to itself (master alone in the ring).
        out.extend([0xDC, 2, 2]);
        count += 1;
        cycle += 1;
    }
    (out, count)
}

/// User + system CPU time of process `pid` so far.
fn cpu_time(pid: u32) -> Duration {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    // Fields after the command name (in parentheses, may hold spaces).
    let rest = &stat[stat.rfind(')').unwrap() + 2..];
    let f: Vec<&str> = rest.split(' ').collect();
    let ticks: u64 = f[11].parse::<u64>().unwrap() + f[12].parse::<u64>().unwrap();
    // /proc counts in USER_HZ, 100 per second on Linux.
    let hz = 100;
    Duration::from_nanos(ticks * 1_000_000_000 / hz)
}

struct Run {
    sent: usize,
    decoded: u64,
    wire: Duration,
    cpu: Duration,
    wall: Duration,
    /// With `dpctl bus`: its overruns (bytes) and CPU time.
    bus: Option<(u64, Duration)>,
}

/// Where the segment comes from.
#[derive(Clone, Copy, PartialEq)]
enum Source {
    Socat,
    Bus,
}

fn run(source: Source, json: bool, n: usize) -> Run {
    match source {
        Source::Socat => {
            let dir = TempDir::new("sniff-rate");
            let (a, b) = (dir.path("a"), dir.path("b"));
            let socat = pty_pair(&a, &b);
            let r = sniff_run(&a, &b, json, n, Duration::from_secs(30), &|| {});
            drop(socat);
            r
        }
        Source::Bus => {
            let bus = Bus::start(2, &["--baud", "12M"]);
            let cpu0 = cpu_time(bus.proc.pid());
            // Lost telegrams never come: stop waiting 5 s after the last.
            let ready = || bus.wait_connected(2);
            let mut r = sniff_run(
                &bus.link(0),
                &bus.link(1),
                json,
                n,
                Duration::from_secs(5),
                &ready,
            );
            let cpu = cpu_time(bus.proc.pid()) - cpu0;
            let out = bus.stop();
            let last = out
                .stderr
                .lines()
                .rfind(|l| l.starts_with("dpctl bus: transmissions"))
                .expect("the bus's counters at exit");
            let overruns = counter(last, "overruns ").expect("overruns in the bus's counters");
            r.bus = Some((overruns, cpu));
            r
        }
    }
}

/// Write the segment into `a`, sniff `b`; `ready` returns when both have
/// their port open; `quiet` without a telegram line ends the wait.
fn sniff_run(a: &Path, b: &Path, json: bool, n: usize, quiet: Duration, ready: &dyn Fn()) -> Run {
    let mut cmd = Command::new(dpctl());
    cmd.arg("sniff")
        .arg("--port")
        .arg(b)
        .args(["--baud", "12M", "--stats", "1"])
        .arg(if json { "--json" } else { "--plain" });
    let sniff = Proc::spawn_captured(cmd);
    let mut tx = open_tty(a);
    make_raw(&tx);
    ready();
    let is_telegram = |l: &str| {
        if json {
            l.contains("\"t_us\"") && !l.contains("\"event\"")
        } else {
            l.starts_with(' ') || l.as_bytes().first().is_some_and(u8::is_ascii_digit)
        }
    };
    // One exchange first: the sniffer is reading once it prints it.
    let (warm, _) = segment(1);
    tx.write_all(&warm[..26]).unwrap();
    sniff.wait_stdout("warm-up telegrams", 2, is_telegram);
    let (bytes, sent) = segment(n);
    let wire = Duration::from_nanos(bytes.len() as u64 * CHAR_BITS * 1_000_000_000 / BAUD);
    let cpu0 = cpu_time(sniff.pid());
    let t0 = Instant::now();
    let writer = std::thread::spawn(move || {
        tx.write_all(&bytes).unwrap();
        tx
    });
    let mut seen = 0;
    let mut last = t0;
    while seen < sent {
        match sniff.stdout_line(quiet) {
            Some(l) if is_telegram(&l) => {
                seen += 1;
                last = Instant::now();
            }
            Some(_) => {}
            None => break,
        }
    }
    let wall = last - t0;
    let cpu = cpu_time(sniff.pid()) - cpu0;
    drop(writer.join().unwrap());
    let out = sniff.stop();
    // The summary line counts what the codec framed (warm-up included).
    let decoded = out
        .stdout
        .lines()
        .rev()
        .find_map(|l| {
            if json {
                serde_json::from_str::<serde_json::Value>(l).ok()?["summary"]["telegrams"].as_u64()
            } else {
                let s = l.strip_prefix("summary: ")?;
                s.split(|c: char| !c.is_ascii_digit())
                    .find(|w| !w.is_empty())?
                    .parse()
                    .ok()
            }
        })
        .unwrap_or(seen as u64 + 2)
        .saturating_sub(2);
    Run {
        sent,
        decoded,
        wire,
        cpu,
        wall,
        bus: None,
    }
}

fn main() {
    let n = std::env::var("TELEGRAMS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(600_000);
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "sniff_rate: {n} telegrams at 12 Mbit/s, load average {}",
        load.trim()
    );
    // The line's ceiling for comparison: the shortest legal exchange
    // (SD1 request, TSYN 33 bit before it, TSDR 11 bit, SC answer):
    // 66 + 33 + 11 + 11 = 121 bit for 2 telegrams.
    let ceiling = 2.0 * BAUD as f64 / 121.0;
    println!(
        "12 Mbit/s line ceiling: {:.0} telegrams/s (SD1 + SC, minimal idle); this segment's mix without idle: {:.0}/s",
        ceiling,
        65.0 * BAUD as f64 / ((64 * 13 + 3) as f64 * CHAR_BITS as f64)
    );
    let sources: &[Source] = match std::env::var("SOURCE").as_deref() {
        Ok("socat") => &[Source::Socat],
        Ok("bus") => &[Source::Bus],
        Ok("all") | Err(_) => &[Source::Socat, Source::Bus],
        Ok(other) => panic!("SOURCE={other}: use socat, bus or all"),
    };
    println!("| source | mode | sent | decoded | lost | bus overruns (bytes) | 12 Mbit/s line time (s) | wall (s) | telegrams/s | × the line | CPU (s) | CPU µs / telegram | decodable / s on one core | bus CPU (s) |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for &source in sources {
        for json in [true, false] {
            let r = run(source, json, n);
            let per = r.cpu.as_secs_f64() * 1e6 / r.decoded.max(1) as f64;
            let (overruns, bus_cpu) = match r.bus {
                Some((o, c)) => (o.to_string(), format!("{:.2}", c.as_secs_f64())),
                None => ("–".into(), "–".into()),
            };
            println!(
                "| {} | {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.0} | {:.2} | {:.2} | {:.2} | {:.0} | {} |",
                if source == Source::Bus {
                    "`dpctl bus --baud 12M`"
                } else {
                    "socat pty pair"
                },
                if json {
                    "`--json --stats 1`"
                } else {
                    "`--plain --stats 1`"
                },
                r.sent,
                r.decoded,
                r.sent as u64 - r.decoded.min(r.sent as u64),
                overruns,
                r.wire.as_secs_f64(),
                r.wall.as_secs_f64(),
                r.decoded as f64 / r.wall.as_secs_f64(),
                r.wire.as_secs_f64() / r.wall.as_secs_f64(),
                r.cpu.as_secs_f64(),
                per,
                1e6 / per,
                bus_cpu
            );
        }
    }
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!("load average at the end: {}", load.trim());
}
