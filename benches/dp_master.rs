//! DP master benchmarks (issue: DP master), in one run:
//!
//! (a)  Data_Exchange transactions per second with one slave over a socat
//!      pty pair and through an unpaced `dpctl bus`: `dpctl master`
//!      (default: several poll cycles per token visit while the token
//!      hold time lasts; `--busy-poll 300`, `--gather`,
//!      `alone_hold_bits = 3000`, `alone_hold_bits = 0` (the token after
//!      every poll cycle) and `--anticipate 100`) and pyprofibus's master
//!      against the same `dpctl slave`, next to the raw round trip of the
//!      same path (a bare echo of a 13-byte telegram) as the physical
//!      limit, with CPU seconds per 10 000 exchanges of each master;
//!      every row with its ratio to its line-timing floor.
//! (a') CPU cost of the master core per Data_Exchange in process (an FDL
//!      active station with the DP master against a canned responder),
//!      next to pyprofibus's master on its in-process dummy PHY.
//! (b)  4 and 32 slaves on an unpaced `dpctl bus` and over a socat pty
//!      pair: all exchanges per second against the line-timing floors,
//!      by default (the token held alone) and with `alone_hold_bits = 0`
//!      (the token after every poll cycle). A tty has one reader, so on
//!      the pty pair one thread of this bench answers for all n slaves
//!      (the slave cores of `dpctl slave`, `PassiveStation<DpSlave>`).
//! (c)  Resident memory of `dpctl master` with 125 configured slaves.
//!
//! Run: `cargo bench --bench dp_master` (needs socat and the .venv of
//! `scripts/setup-test-env`; builds `dpctl` in release mode first).

use profibus::dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams};
use profibus::fdl::station::active::{ActiveConfig, ActiveStation};
use profibus::fdl::station::Station;
use profibus::fdl::wire::{DataTelegram, FunctionCode, ResponseStatus, Telegram};
use profibus::fdl::{Baud, BusParams, Instant};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn dpctl() -> PathBuf {
    let st = Command::new(env!("CARGO"))
        .args(["build", "--release", "-q", "-p", "dpctl"])
        .current_dir(repo())
        .status()
        .expect("cargo build");
    assert!(st.success(), "building dpctl failed");
    repo().join("target/release/dpctl")
}

struct Kill(Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn socat(a: &Path, b: &Path) -> Kill {
    let c = Command::new("socat")
        .arg(format!("pty,raw,echo=0,link={}", a.display()))
        .arg(format!("pty,raw,echo=0,link={}", b.display()))
        .stderr(Stdio::null())
        .spawn()
        .expect("socat is missing: run scripts/setup-test-env");
    let end = std::time::Instant::now() + Duration::from_secs(5);
    while !(a.exists() && b.exists()) {
        assert!(std::time::Instant::now() < end, "no pty pair");
        std::thread::sleep(Duration::from_millis(10));
    }
    Kill(c)
}

fn raw_tty(path: &Path) -> std::fs::File {
    // socat already set raw mode on both ends.
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .expect("open pty")
}

/// Round trips per second of a 13-byte message (a Data_Exchange with 4
/// bytes of data) through a pty pair with
/// a bare echo on the other end.
fn raw_echo_rate(dpctl: &Path, dir: &Path, kind: &Line, n: u32) -> f64 {
    let (a, b, _s) = line(dpctl, dir, kind, "e");
    let mut far = raw_tty(&b);
    let echo = std::thread::spawn(move || {
        let mut buf = [0u8; 64];
        let mut left = n as usize * 13;
        while left > 0 {
            let k = far.read(&mut buf).unwrap();
            far.write_all(&buf[..k]).unwrap();
            left -= k;
        }
    });
    let mut near = raw_tty(&a);
    let msg = [0x68, 7, 7, 0x68, 8, 2, 0x7D, 1, 2, 3, 4, 0x91, 0x16];
    let mut got = [0u8; 13];
    let t = std::time::Instant::now();
    for _ in 0..n {
        near.write_all(&msg).unwrap();
        near.read_exact(&mut got).unwrap();
    }
    let rate = n as f64 / t.elapsed().as_secs_f64();
    echo.join().unwrap();
    rate
}

fn start_slave(dpctl: &Path, port: &Path) -> Kill {
    Kill(
        Command::new(dpctl)
            .args(["slave", "--addr", "8", "--baud", "1.5M", "--port"])
            .arg(port)
            .arg("--gsd")
            .arg(repo().join("crates/devices/gsd/DPCTL_GEN.GSD"))
            .args(["--module", "2 words in/out"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    )
}

/// A master's rate and CPU: exchanges per second in the steady state and
/// CPU seconds (user + system) per 10 000 exchanges.
#[derive(Clone, Copy, Debug, Default)]
struct Rate {
    per_s: f64,
    cpu_per_10k: f64,
}

/// CPU seconds (utime + stime) of process `pid` so far.
fn cpu_of(pid: u32) -> f64 {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let f: Vec<&str> = s
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks: f64 = f.get(11).and_then(|x| x.parse().ok()).unwrap_or(0.0)
        + f.get(12).and_then(|x| x.parse().ok()).unwrap_or(0.0);
    ticks / 100.0
}

/// Where the master and its slave meet: a socat pty pair, or two links of
/// an unpaced `dpctl bus`.
enum Line {
    Socat,
    Hub,
}

/// Two connected pty paths (near, far) and what keeps them alive.
fn line(dpctl: &Path, dir: &Path, kind: &Line, tag: &str) -> (PathBuf, PathBuf, Kill) {
    match kind {
        Line::Socat => {
            let (a, b) = (dir.join(format!("{tag}a")), dir.join(format!("{tag}b")));
            // A killed socat leaves its links behind (see below).
            let _ = std::fs::remove_file(&a);
            let _ = std::fs::remove_file(&b);
            let k = socat(&a, &b);
            (a, b, k)
        }
        Line::Hub => {
            let prefix = dir.join(format!("{tag}h"));
            // A killed hub leaves its links behind, pointing at ptys that
            // may already belong to someone else.
            for i in 0..2 {
                let _ = std::fs::remove_file(format!("{}{i}", prefix.display()));
            }
            let k = Kill(
                Command::new(dpctl)
                    .args(["bus", "--stations", "2", "--link"])
                    .arg(&prefix)
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap(),
            );
            let (a, b) = (
                PathBuf::from(format!("{}0", prefix.display())),
                PathBuf::from(format!("{}1", prefix.display())),
            );
            let end = std::time::Instant::now() + Duration::from_secs(5);
            while !(a.exists() && b.exists()) {
                assert!(std::time::Instant::now() < end, "no bus links");
                std::thread::sleep(Duration::from_millis(10));
            }
            (a, b, k)
        }
    }
}

/// `dpctl master` Data_Exchange rate in the steady state: the growth of
/// the slave's Data_Exchange count between the first status line in
/// Data_Exchange and the last one, over `secs` seconds; CPU per exchange
/// from the master's whole run (start-up included).
fn dpctl_rate(
    dpctl: &Path,
    dir: &Path,
    kind: &Line,
    secs: f64,
    extra: &[&str],
    options: &str,
) -> Rate {
    let (a, b, _line) = line(dpctl, dir, kind, "d");
    let _slave = start_slave(dpctl, &b);
    // One slave, one master: HSA = the master's address keeps the GAP
    // (live list) polls to one address per 100 token visits.
    let cfg = dir.join("bus.toml");
    std::fs::write(
        &cfg,
        format!(
            "[master]\naddress = 2\nbaud = \"1.5M\"\n[bus]\nhsa = 2\ngap_factor = 100\n\
             [options]\n{options}\n\
             [[slave]]\naddress = 8\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\n",
            repo().join("crates/devices/gsd/DPCTL_GEN.GSD").display()
        ),
    )
    .unwrap();
    let mut child = Kill(
        Command::new(dpctl)
            .args(["master", "--json", "--interval", "100"])
            .args(extra)
            .arg("--port")
            .arg(&a)
            .arg("--config")
            .arg(&cfg)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let out = child.0.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        use std::io::BufRead;
        std::io::BufReader::new(out)
            .lines()
            .map_while(Result::ok)
            .filter(|l| l.contains("\"status\""))
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(&l).ok())
            .filter(|v| v["slaves"][0]["state"] == "data_exchange")
            .map(|v| {
                (
                    v["t"].as_f64().unwrap(),
                    v["slaves"][0]["data_exchanges"].as_f64().unwrap(),
                )
            })
            .collect::<Vec<_>>()
    });
    std::thread::sleep(Duration::from_secs_f64(secs));
    let cpu = cpu_of(child.0.id());
    drop(child);
    let rows = reader.join().unwrap();
    let (first, last) = (rows.first().expect("data exchange"), rows.last().unwrap());
    Rate {
        per_s: (last.1 - first.1) / (last.0 - first.0),
        cpu_per_10k: cpu / last.1 * 10_000.0,
    }
}

/// `dpctl master` with `n` slaves (addresses 8..) on an unpaced `dpctl
/// bus` of n + 1 links: Data_Exchange transactions per second of all
/// slaves together in the steady state (every slave in Data_Exchange).
fn dpctl_rate_n(dpctl: &Path, dir: &Path, kind: &Line, n: u8, secs: f64, options: &str) -> f64 {
    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let prefix = dir.join(format!("n{n}h"));
    let link = |i: u8| PathBuf::from(format!("{}{i}", prefix.display()));
    // What keeps the line and the slaves alive.
    let mut _keep: Vec<Kill> = vec![];
    let mut _responder = None;
    let master_port = match kind {
        Line::Hub => {
            for i in 0..=n {
                let _ = std::fs::remove_file(link(i));
            }
            _keep.push(Kill(
                Command::new(dpctl)
                    .args(["bus", "--stations", &(n + 1).to_string(), "--link"])
                    .arg(&prefix)
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap(),
            ));
            let end = std::time::Instant::now() + Duration::from_secs(10);
            while !(0..=n).all(|i| link(i).exists()) {
                assert!(std::time::Instant::now() < end, "no bus links");
                std::thread::sleep(Duration::from_millis(10));
            }
            for k in 0..n {
                _keep.push(Kill(
                    Command::new(dpctl)
                        .args(["slave", "--baud", "1.5M", "--addr", &(8 + k).to_string()])
                        .arg("--port")
                        .arg(link(k + 1))
                        .arg("--gsd")
                        .arg(&gsd)
                        .args(["--module", "2 words in/out"])
                        .stdout(Stdio::null())
                        .stderr(Stdio::null())
                        .spawn()
                        .unwrap(),
                ));
            }
            link(0)
        }
        Line::Socat => {
            let (a, b, k) = line(dpctl, dir, kind, &format!("n{n}s"));
            _keep.push(k);
            _responder = Some(Responder::start(&b, n));
            a
        }
    };
    let mut text = format!(
        "[master]\naddress = 2\nbaud = \"1.5M\"\n[bus]\nhsa = 2\ngap_factor = 100\n[options]\n{options}\n"
    );
    for k in 0..n {
        text.push_str(&format!(
            "[[slave]]\naddress = {}\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\n",
            8 + k,
            gsd.display()
        ));
    }
    let cfg = dir.join(format!("bus{n}.toml"));
    std::fs::write(&cfg, text).unwrap();
    let mut child = Kill(
        Command::new(dpctl)
            .args(["master", "--json", "--interval", "100", "--port"])
            .arg(&master_port)
            .arg("--config")
            .arg(&cfg)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let out = child.0.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        use std::io::BufRead;
        std::io::BufReader::new(out)
            .lines()
            .map_while(Result::ok)
            .filter(|l| l.contains("\"status\""))
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(&l).ok())
            .filter(|v| {
                v["slaves"]
                    .as_array()
                    .is_some_and(|a| a.iter().all(|s| s["state"] == "data_exchange"))
            })
            .map(|v| {
                let sum: f64 = v["slaves"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|s| s["data_exchanges"].as_f64().unwrap_or(0.0))
                    .sum();
                (v["t"].as_f64().unwrap(), sum)
            })
            .collect::<Vec<_>>()
    });
    std::thread::sleep(Duration::from_secs_f64(secs));
    drop(child);
    let rows = reader.join().unwrap();
    match (rows.first(), rows.last()) {
        (Some(first), Some(last)) if last.0 > first.0 => (last.1 - first.1) / (last.0 - first.0),
        _ => 0.0,
    }
}

/// `n` generic slaves (addresses 8..) answering on one end of a pty
/// pair, in a thread of this process: the slave cores of `dpctl slave`
/// fed from one reader (a tty has one), spinning while an answer is due
/// within 2 ms, otherwise waiting in `ppoll`.
struct Responder {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Responder {
    fn start(far: &Path, n: u8) -> Responder {
        use profibus::devices::generic::InputPattern;
        use profibus::dp::config::gsd::{Gsd, ParseOptions};
        use profibus::fdl::station::passive::PassiveStation;
        use std::os::fd::AsFd;
        use std::sync::atomic::Ordering;
        let text =
            std::fs::read_to_string(repo().join("crates/devices/gsd/DPCTL_GEN.GSD")).unwrap();
        let gsd = Gsd::parse(&text, ParseOptions::default()).unwrap().gsd;
        let mut b = profibus_plant::Plant::builder()
            .baud(Baud::B1500000)
            .master(2);
        for k in 0..n {
            b = b
                .generic(
                    8 + k,
                    &format!("s{k}"),
                    &gsd,
                    &["2 words in/out"],
                    InputPattern::Echo,
                )
                .unwrap();
        }
        let params = BusParams::defaults(Baud::B1500000);
        // The pty allowance of `dpctl slave` (5 ms).
        let mut slaves: Vec<_> = b
            .stations()
            .unwrap()
            .slaves
            .into_iter()
            .map(|(_, st)| {
                PassiveStation::with_latency_allowance(
                    st.into_app(),
                    params,
                    Duration::from_millis(5),
                )
            })
            .collect();
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = stop.clone();
        let mut tty = raw_tty(far);
        let thread = std::thread::spawn(move || {
            use nix::poll::{PollFd, PollFlags};
            use nix::sys::time::TimeSpec;
            let t0 = std::time::Instant::now();
            let clock = || Instant::from_nanos(t0.elapsed().as_nanos() as u64);
            let mut buf = [0u8; 512];
            while !flag.load(Ordering::Relaxed) {
                let now = clock();
                let next = slaves.iter().filter_map(|s| s.poll_timeout()).min();
                let wait = match next {
                    Some(d) if d.saturating_duration_since(now) < Duration::from_millis(2) => {
                        Duration::ZERO
                    }
                    _ => Duration::from_millis(1),
                };
                let readable = {
                    let mut fds = [PollFd::new(tty.as_fd(), PollFlags::POLLIN)];
                    nix::poll::ppoll(&mut fds, Some(TimeSpec::from_duration(wait)), None)
                        .unwrap_or(0)
                        > 0
                };
                if readable {
                    let Ok(k) = tty.read(&mut buf) else {
                        break;
                    };
                    let now = clock();
                    for s in &mut slaves {
                        s.handle_rx(now, &buf[..k]);
                    }
                }
                let now = clock();
                for s in &mut slaves {
                    if s.poll_timeout().is_some_and(|d| d <= now) {
                        s.handle_timeout(now);
                    }
                    while let Some(bytes) = s.poll_transmit(now) {
                        if tty.write_all(bytes).is_err() {
                            return;
                        }
                    }
                }
            }
        });
        Responder {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Responder {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// CPU seconds of reaped children so far.
fn children_cpu() -> f64 {
    use nix::sys::resource::{getrusage, UsageWho};
    use nix::sys::time::TimeValLike;
    let Ok(ru) = getrusage(UsageWho::RUSAGE_CHILDREN) else {
        return 0.0;
    };
    (ru.user_time().num_microseconds() + ru.system_time().num_microseconds()) as f64 * 1e-6
}

fn python() -> PathBuf {
    let p = repo().join(".venv/bin/python");
    assert!(p.exists(), ".venv is missing: run scripts/setup-test-env");
    p
}

/// pyprofibus master rate against the same kind of `dpctl slave`.
fn pyprofibus_rate(dpctl: &Path, dir: &Path, kind: &Line, n: u32) -> Rate {
    let (a, b, _s) = line(dpctl, dir, kind, "p");
    let _slave = start_slave(dpctl, &b);
    let cpu0 = children_cpu();
    let out = Command::new(python())
        .arg(repo().join("tests/interop/pyprofibus_master.py"))
        .arg("--port")
        .arg(&a)
        .arg("--gsd")
        .arg(repo().join("crates/devices/gsd/DPCTL_GEN.GSD"))
        .args([
            "--addr",
            "8",
            "--baud",
            "1500000",
            "--out-len",
            "4",
            "--in-len",
            "4",
        ])
        .args(["--module", "2 words in/out"])
        .args(["--cycles", &n.to_string()])
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    let s: serde_json::Value = serde_json::from_str(text.lines().last().expect("summary")).unwrap();
    let cpu = children_cpu() - cpu0;
    let cycles = s["cycles"].as_f64().unwrap();
    let secs = s["seconds"].as_f64().unwrap() - s["first_dx_s"].as_f64().unwrap_or(0.0);
    Rate {
        per_s: cycles / secs,
        cpu_per_10k: cpu / cycles * 10_000.0,
    }
}

/// A responder that answers every Data_Exchange with a canned DL reply
/// (and nothing else): the cheapest possible far end, so the loop's time
/// is the master's.
struct Canned {
    reply: Vec<u8>,
    diag: Vec<u8>,
    ack: [u8; 1],
    out: Option<usize>,
}

impl Station for Canned {
    fn handle_rx(&mut self, _: Instant, bytes: &[u8]) {
        // Start-up services carry SAPs (DA with bit 7 set): Slave_Diag
        // gets a "ready" diagnosis, Set_Prm/Chk_Cfg a short ack.
        self.out = match bytes {
            [0x68, _, _, 0x68, da, _, _, dsap, ..] if da & 0x80 != 0 && *dsap == 60 => Some(1),
            [0x68, _, _, 0x68, da, ..] | [0x10, da, ..] if da & 0x80 != 0 => Some(2),
            [0x68, ..] | [0x10, _, _, 0x7D | 0x5D, ..] => Some(0),
            _ => None,
        };
    }
    fn handle_timeout(&mut self, _: Instant) {}
    fn poll_transmit(&mut self, _: Instant) -> Option<&[u8]> {
        match self.out.take()? {
            0 => Some(&self.reply),
            1 => Some(&self.diag),
            _ => Some(&self.ack),
        }
    }
    fn poll_timeout(&self) -> Option<Instant> {
        None
    }
}

fn emit(t: Telegram<'_>) -> Vec<u8> {
    let mut b = vec![0u8; 255];
    let n = t.emit(&mut b).unwrap();
    b.truncate(n);
    b
}

/// CPU time per Data_Exchange of ActiveStation<DpMaster> in process.
fn core_cost(cycles: u64) -> f64 {
    let params = BusParams::defaults(Baud::B12000000);
    let mut p = SlaveParams::new(8, 0x0DCE, vec![0x20, 0x10]);
    p.watchdog = None;
    let cfg = MasterConfig {
        address: 2,
        params,
        slaves: vec![p],
        options: MasterOptions::default(),
    };
    let mut bus = cfg.params;
    bus.hsa = 2;
    bus.gap_factor = 100;
    let mut m = ActiveStation::new(
        ActiveConfig::new(2, bus),
        DpMaster::new(&MasterConfig { params: bus, ..cfg }).unwrap(),
    );
    let resp = |data: &'static [u8], dsap, ssap| {
        emit(Telegram::Data(DataTelegram {
            da: 2,
            sa: 8,
            fc: FunctionCode::slave_response(ResponseStatus::Dl),
            dsap,
            ssap,
            data,
            format: None,
        }))
    };
    let mut far = Canned {
        reply: resp(&[0x42], None, None),
        diag: resp(&[0, 0x04, 0, 2, 0x0D, 0xCE], Some(62), Some(60)),
        ack: [0xE5],
        out: None,
    };
    let mut now = Instant::ZERO;
    let mut buf = [0u8; 256];
    let mut step = |m: &mut ActiveStation<DpMaster>, far: &mut Canned, now: &mut Instant| {
        if let Some(b) = m.poll_transmit(*now) {
            let n = b.len();
            buf[..n].copy_from_slice(b);
            far.handle_rx(*now, &buf[..n]);
            if let Some(r) = far.poll_transmit(*now) {
                m.handle_rx(*now, r);
            }
            return;
        }
        *now = (*now).max(m.poll_timeout().unwrap());
        m.handle_timeout(*now);
    };
    while m.app().cycle_stats().cycles < 100 {
        step(&mut m, &mut far, &mut now);
    }
    let start = m.app().slave_stats(8).unwrap().data_exchanges;
    let t = cpu_time();
    while m.app().slave_stats(8).unwrap().data_exchanges < start + cycles {
        step(&mut m, &mut far, &mut now);
    }
    (cpu_time() - t) / cycles as f64
}

fn cpu_time() -> f64 {
    // getrusage through /proc: utime + stime of this process in clock ticks.
    let s = std::fs::read_to_string("/proc/self/stat").unwrap();
    let f: Vec<&str> = s.rsplit(')').next().unwrap().split_whitespace().collect();
    let ticks: f64 = f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap();
    ticks / 100.0
}

fn pyprofibus_cost(n: u32) -> f64 {
    let out = Command::new(python())
        .arg(repo().join("benches/support/pyprofibus_dummy.py"))
        .arg(repo().join("crates/devices/gsd/corpus/pyprofibus_dummy_compact.gsd"))
        .arg(n.to_string())
        .stderr(Stdio::null())
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("pyprofibus JSON");
    v["cpu_s"].as_f64().unwrap() / v["cycles"].as_f64().unwrap()
}

/// RSS of `dpctl master` with 125 configured slaves (none answering).
fn rss_125(dpctl: &Path, dir: &Path) -> u64 {
    let (a, b) = (dir.join("ra"), dir.join("rb"));
    let _s = socat(&a, &b);
    let mut t = String::from("[master]\naddress = 0\nbaud = \"1.5M\"\n");
    for addr in 1..=125 {
        t.push_str(&format!(
            "[[slave]]\naddress = {addr}\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\n",
            repo().join("crates/devices/gsd/DPCTL_GEN.GSD").display()
        ));
    }
    let cfg = dir.join("big.toml");
    std::fs::write(&cfg, t).unwrap();
    let child = Kill(
        Command::new(dpctl)
            .args(["master", "--json", "--port"])
            .arg(&a)
            .arg("--config")
            .arg(&cfg)
            .stdout(Stdio::null())
            .spawn()
            .unwrap(),
    );
    std::thread::sleep(Duration::from_secs(3));
    let status = std::fs::read_to_string(format!("/proc/{}/status", child.0.id())).unwrap();
    status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|k| k.parse().ok())
        .expect("VmHWM")
}

/// The Min_Slave_Interval of the bench's slaves (DPCTL_GEN.GSD,
/// `Min_Slave_Intervall` in units of 100 µs), in seconds: a master polls
/// each slave at most once per interval, a bound of every floor.
fn min_slave_interval() -> f64 {
    use profibus::dp::config::gsd::{Gsd, ParseOptions};
    let gsd = Gsd::from_file(
        repo().join("crates/devices/gsd/DPCTL_GEN.GSD"),
        ParseOptions::LENIENT,
    )
    .expect("DPCTL_GEN.GSD")
    .gsd;
    f64::from(gsd.min_slave_intervall.unwrap_or(0)) * 100e-6
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return;
    }
    let dpctl = dpctl();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().to_path_buf();

    // Three rounds, each path in turn, so that all see the same load;
    // medians reported. `DP_MASTER_ROUNDS=N` changes the number of rounds.
    let rounds: usize = std::env::var("DP_MASTER_ROUNDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3);
    let n = 3000;
    for kind in [Line::Socat, Line::Hub] {
        let name = match kind {
            Line::Socat => "a socat pty pair",
            Line::Hub => "dpctl bus (unpaced)",
        };
        let mut rows: Vec<[Rate; 8]> = vec![];
        for _ in 0..rounds {
            let raw = Rate {
                per_s: raw_echo_rate(&dpctl, &dir, &kind, n),
                cpu_per_10k: 0.0,
            };
            let ours = dpctl_rate(&dpctl, &dir, &kind, 2.5, &[], "");
            let busy = dpctl_rate(&dpctl, &dir, &kind, 2.5, &["--busy-poll", "300"], "");
            let gather = dpctl_rate(&dpctl, &dir, &kind, 2.5, &["--gather"], "");
            let each = dpctl_rate(&dpctl, &dir, &kind, 2.5, &[], "alone_hold_bits = 3000");
            let ant = dpctl_rate(&dpctl, &dir, &kind, 2.5, &["--anticipate", "100"], "");
            let zero = dpctl_rate(&dpctl, &dir, &kind, 2.5, &[], "alone_hold_bits = 0");
            let py = pyprofibus_rate(&dpctl, &dir, &kind, n);
            println!(
                "  round ({name}): raw {:.0}/s, dpctl master {:.0}/s ({:.2} s CPU/10k), --busy-poll 300 {:.0}/s ({:.2} s), --gather {:.0}/s ({:.2} s), alone_hold_bits = 3000 {:.0}/s ({:.2} s), --anticipate 100 {:.0}/s ({:.2} s), alone_hold_bits = 0 {:.0}/s ({:.2} s), pyprofibus {:.0}/s ({:.2} s)",
                raw.per_s, ours.per_s, ours.cpu_per_10k, busy.per_s, busy.cpu_per_10k,
                gather.per_s, gather.cpu_per_10k, each.per_s, each.cpu_per_10k, ant.per_s,
                ant.cpu_per_10k, zero.per_s, zero.cpu_per_10k, py.per_s, py.cpu_per_10k
            );
            rows.push([raw, ours, busy, gather, py, each, ant, zero]);
        }
        let median = |i: usize, cpu: bool| {
            let mut v: Vec<f64> = rows
                .iter()
                .map(|r| if cpu { r[i].cpu_per_10k } else { r[i].per_s })
                .collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (raw, py) = (median(0, false), median(4, false));
        // The fastest a master can poll while keeping the line timing: the
        // raw round trip plus the slave's min TSDR before its answer and
        // the master's TID1 (TSYN + safety margin) before its next request.
        // With a token to itself after every poll cycle
        // (`alone_hold_bits = 0`) the token (3 characters) and a second
        // TID1 come on top.
        // One slave is polled at most once per its Min_Slave_Interval
        // (100 µs for this GSD): the floor is never above that rate.
        let p = BusParams::defaults(Baud::B1500000);
        let gaps = p.bits((p.min_tsdr + p.tid1()) as u64).as_secs_f64();
        let msi = min_slave_interval();
        let floor = 1.0 / (1.0 / raw + gaps).max(msi);
        let token_gaps = gaps
            + p.bits(p.tid1() as u64).as_secs_f64()
            + Baud::B1500000.chars_to_duration(3).as_secs_f64();
        let token_floor = 1.0 / (1.0 / raw + token_gaps).max(msi);
        println!("(a) Data_Exchange over {name}, 1 slave, medians of {rounds} rounds");
        println!(
            "| peer | transactions/s | vs raw | vs pyprofibus | CPU s per 10 000 | vs its floor |"
        );
        println!("|---|---|---|---|---|---|");
        println!(
            "| raw round trip (bare echo, 13 bytes) | {raw:.0} | 100 % | | | {:.0} % (F) |",
            100.0 * raw / floor
        );
        println!(
            "| F: line-timing floor, several cycles per token visit (raw + min TSDR + TID1 = {:.1} µs, at least Min_Slave_Interval {:.0} µs) | {floor:.0} | {:.0} % | {:.2}× | | 100 % |",
            gaps * 1e6,
            msi * 1e6,
            100.0 * floor / raw,
            floor / py
        );
        println!(
            "| T: line-timing floor, token to itself every cycle (raw + {:.1} µs) | {token_floor:.0} | {:.0} % | {:.2}× | | 100 % |",
            token_gaps * 1e6,
            100.0 * token_floor / raw,
            token_floor / py
        );
        for (i, label, token_every_cycle) in [
            (1, "dpctl master (default)", false),
            (2, "dpctl master --busy-poll 300", false),
            (3, "dpctl master --gather (benchmark option)", false),
            (5, "dpctl master, alone_hold_bits = 3000", false),
            (6, "dpctl master --anticipate 100", false),
            (7, "dpctl master, alone_hold_bits = 0", true),
            // pyprofibus passes no token and keeps no TSYN: F is the
            // floor of a master that keeps the line timing.
            (4, "pyprofibus 1.13 master", false),
        ] {
            let r = median(i, false);
            // Each row against its floor: F when the token is held for
            // several cycles per visit, T with the token every cycle.
            let (f, tag) = if token_every_cycle {
                (token_floor, "T")
            } else {
                (floor, "F")
            };
            println!(
                "| {label} | {r:.0} | {:.0} % | {:.2}× | {:.2} | {:.0} % ({tag}) |",
                100.0 * r / raw,
                r / py,
                median(i, true),
                100.0 * r / f
            );
        }
        println!();
    }

    // (b) More slaves on dpctl bus: the token's share of a poll cycle
    // shrinks. Floors per exchange as above; with the token to itself
    // after every poll cycle of n slaves, one token and TID1 per n
    // exchanges.
    let p = BusParams::defaults(Baud::B1500000);
    let gaps = p.bits((p.min_tsdr + p.tid1()) as u64).as_secs_f64();
    let token =
        p.bits(p.tid1() as u64).as_secs_f64() + Baud::B1500000.chars_to_duration(3).as_secs_f64();
    println!("(b) Data_Exchange with n slaves, all together (one round)");
    println!("| line | slaves | raw | F: floor | T: floor, token every cycle | dpctl master (default) | vs F | alone_hold_bits = 0 | vs T |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for kind in [Line::Socat, Line::Hub] {
        let name = match kind {
            Line::Socat => "socat pty pair",
            Line::Hub => "dpctl bus (unpaced)",
        };
        for n in [4u8, 32] {
            let raw = raw_echo_rate(&dpctl, &dir, &kind, 3000);
            let msi = min_slave_interval();
            let floor = n as f64 / (n as f64 * (1.0 / raw + gaps)).max(msi);
            let per_cycle = n as f64 * (1.0 / raw + gaps) + token;
            let token_floor = n as f64 / per_cycle.max(msi);
            let secs = if n > 8 { 6.0 } else { 3.0 };
            let ours = dpctl_rate_n(&dpctl, &dir, &kind, n, secs, "");
            let each = dpctl_rate_n(&dpctl, &dir, &kind, n, secs, "alone_hold_bits = 0");
            println!(
                "| {name} | {n} | {raw:.0} | {floor:.0} | {token_floor:.0} | {ours:.0} | {:.0} % | {each:.0} | {:.0} % |",
                100.0 * ours / floor,
                100.0 * each / token_floor
            );
        }
    }
    println!();

    let ours_cpu = core_cost(2_000_000);
    let py_cpu = pyprofibus_cost(20_000);
    println!();
    println!("(a') CPU per Data_Exchange, in process");
    println!("| master | CPU per transaction | ratio |");
    println!("|---|---|---|");
    println!(
        "| profibus ActiveStation<DpMaster> (canned responder) | {:.3} µs | {:.0}× less |",
        ours_cpu * 1e6,
        py_cpu / ours_cpu
    );
    println!(
        "| pyprofibus 1.13 (dummy_slave PHY) | {:.2} µs | 1× |",
        py_cpu * 1e6
    );

    let rss = rss_125(&dpctl, &dir);
    println!();
    println!(
        "(c) dpctl master with 125 configured slaves: peak RSS {:.1} MiB",
        rss as f64 / 1024.0
    );
    let _ = std::fs::remove_dir_all(&dir);
}
