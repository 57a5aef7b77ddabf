//! Crash and recovery scenarios with real processes on `dpctl bus`
//! (ptys): a slave killed and restarted, a master killed, the pty under a
//! running `dpctl slave` / `dpctl master` disappearing. Times are
//! measured from the bus's pcap (time stamps of the hub, since the Unix
//! epoch) and the slaves' JSON events; the tests wait for events, never
//! for a fixed time.

mod common;

use common::{all_dx, dpctl, repo, send, slave_of, wall, Bus, Proc, TempDir, Timed};
use profibus::fdl::capture::pcap::PcapReader;
use profibus::fdl::station::active::ActiveConfig;
use profibus::fdl::wire::{FunctionCode, Telegram};
use profibus::fdl::{Baud, BusParams};
use serde_json::Value;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Generous: processes on a loaded 2-core machine.
const WAIT: Duration = Duration::from_secs(60);

fn gen_gsd() -> PathBuf {
    repo().join("crates/devices/gsd/DPCTL_GEN.GSD")
}

/// `dpctl slave --json` on station `i`; stdout piped when `events`
/// (then read it with [`Timed`]), else discarded.
fn slave(bus: &Bus, i: usize, addr: u8, events: bool) -> Proc {
    Proc::spawn(
        &format!("dpctl slave {addr}"),
        Command::new(dpctl())
            .args(["slave", "--json", "--port", &bus.link_str(i)])
            .args(["--addr", &addr.to_string(), "--baud", "1.5M", "--gsd"])
            .arg(gen_gsd())
            .args(["--module", "2 words in/out"])
            .stdin(Stdio::null())
            .stdout(if events {
                Stdio::piped()
            } else {
                Stdio::null()
            })
            .stderr(Stdio::null()),
    )
}

/// A bus file: master `master`, slaves with (address, watchdog ms).
fn bus_file(dir: &TempDir, master: u8, slaves: &[(u8, u64)]) -> PathBuf {
    let mut t =
        format!("[master]\naddress = {master}\nbaud = \"1.5M\"\n[options]\nreprobe_ms = 50\n");
    for (a, wd) in slaves {
        t.push_str(&format!(
            "[[slave]]\naddress = {a}\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\nwatchdog_ms = {wd}\n",
            gen_gsd().display()
        ));
    }
    let p = dir.path(&format!("m{master}.toml"));
    std::fs::write(&p, t).unwrap();
    p
}

fn master(port: &str, config: &Path) -> (Proc, Timed) {
    let mut p = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--input", "-"])
            .args(["--latency", "100", "--port", port])
            .arg("--config")
            .arg(config)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let lines = Timed::from(&mut p);
    (p, lines)
}

fn status_all_dx(v: &Value) -> bool {
    v["event"] == "status" && all_dx(v)
}

/// A telegram from the bus's pcap: time (s since the Unix epoch),
/// source, destination, request?, with SAPs?
#[derive(Debug, Clone, Copy)]
struct Seen {
    t: f64,
    /// A token (SD4) from `sa` to `da`.
    token: bool,
    sa: u8,
    da: u8,
    request: bool,
    saps: bool,
}

fn read_pcap(path: &Path) -> Vec<Seen> {
    let f = std::fs::File::open(path).unwrap();
    let mut r = PcapReader::new(BufReader::new(f)).unwrap();
    let mut out = vec![];
    while let Ok(Some(p)) = r.next_packet() {
        let t = p.ts.as_secs_f64();
        if let Ok((Telegram::Token { da, sa }, _)) = Telegram::parse(&p.data) {
            out.push(Seen {
                t,
                token: true,
                sa,
                da,
                request: true,
                saps: false,
            });
        }
        if let Ok((Telegram::Data(d), _)) = Telegram::parse(&p.data) {
            out.push(Seen {
                t,
                token: false,
                sa: d.sa,
                da: d.da,
                request: matches!(d.fc, FunctionCode::Request { .. }),
                saps: d.dsap.is_some(),
            });
        }
    }
    out
}

#[test]
fn a_killed_slave_is_back_in_data_exchange_within_3_cycles_after_it_answers() {
    let pcap_dir = TempDir::new("scn-slave");
    let pcap = pcap_dir.path("bus.pcapng");
    let bus = Bus::start(3, &["--pcap", pcap.to_str().unwrap()]);
    let _s10 = slave(&bus, 1, 10, false);
    let s11 = slave(&bus, 2, 11, false);
    let cfg = bus_file(&pcap_dir, 2, &[(10, 5000), (11, 5000)]);
    let (mut m, mut ml) = master(&bus.link_str(0), &cfg);
    ml.wait("both slaves in data exchange", status_all_dx);

    s11.signal(9);
    ml.wait("slave 11 offline", |v| {
        v["event"] == "status" && slave_of(v, 11)["state"] == "offline"
    });
    let restarted = wall();
    let _s11 = slave(&bus, 2, 11, false);
    let (_, v) = ml.wait("slave 11 back", status_all_dx);
    let c = v["cycles"].as_u64().unwrap();
    ml.wait("more cycles", |v| {
        v["event"] == "status" && v["cycles"].as_u64().unwrap() > c + 5
    });
    m.terminate(Duration::from_secs(10));
    bus.stop();

    // On the wire: the restarted slave's first answer to the master's
    // Slave_Diag probe, then its first Data_Exchange answer; the master's
    // Data_Exchange polls of slave 10 in between count the cycles.
    let seen = read_pcap(&pcap);
    let first = seen
        .iter()
        .position(|s| s.t > restarted && s.sa == 11 && !s.request && s.saps)
        .expect("slave 11 answered a Slave_Diag after its restart");
    let dx = seen[first..]
        .iter()
        .position(|s| s.sa == 11 && !s.request && !s.saps)
        .expect("a Data_Exchange answer of slave 11")
        + first;
    let cycles = seen[first..dx]
        .iter()
        .filter(|s| s.sa == 2 && s.da == 10 && s.request && !s.saps)
        .count();
    let ms = (seen[dx].t - seen[first].t) * 1e3;
    eprintln!("MEASURED slave restart: back in Data_Exchange {cycles} cycles ({ms:.1} ms) after its first answer");
    assert!(cycles <= 3, "{cycles} cycles");
}

/// One `dpctl slave` per `(address, watchdog ms)` on the bus's links 1…,
/// a `dpctl master` (address 2) on link 0 with them in its bus file, all
/// in Data_Exchange with the outputs `12 34 56 78` echoed back as inputs.
fn slaves_echoing_outputs(
    bus: &Bus,
    dir: &TempDir,
    watchdogs: &[(u8, u64)],
) -> (Vec<(Proc, Timed)>, Proc, Timed) {
    let slaves: Vec<(Proc, Timed)> = watchdogs
        .iter()
        .enumerate()
        .map(|(i, &(a, _))| {
            let mut p = slave(bus, i + 1, a, true);
            let t = Timed::from(&mut p);
            (p, t)
        })
        .collect();
    let cfg = bus_file(dir, 2, watchdogs);
    let (mut m, mut ml) = master(&bus.link_str(0), &cfg);
    ml.wait("every slave in data exchange", status_all_dx);
    for (a, _) in watchdogs {
        send(
            &mut m,
            &format!(r#"{{"slave": {a}, "outputs": "12 34 56 78"}}"#),
        );
    }
    ml.wait("outputs echoed", |v| {
        status_all_dx(v)
            && watchdogs
                .iter()
                .all(|(a, _)| slave_of(v, *a)["inputs"] == "12 34 56 78")
    });
    (slaves, m, ml)
}

#[test]
fn a_killed_master_leaves_each_slave_safe_within_its_watchdog() {
    let dir = TempDir::new("scn-master");
    let pcap = dir.path("bus.pcapng");
    let bus = Bus::start(3, &["--pcap", pcap.to_str().unwrap()]);
    let watchdogs = [(10u8, 500u64), (11, 1500)];
    let (mut slaves, mut m, _ml) = slaves_echoing_outputs(&bus, &dir, &watchdogs);
    m.signal(9);
    m.wait(Duration::from_secs(10));
    let mut expiries = vec![];
    for ((_, lines), (a, wd)) in slaves.iter_mut().zip(watchdogs) {
        let (_, w) = lines.wait("the watchdog", |v| v["event"] == "watchdog");
        assert_eq!(w["after_ms"], wd);
        lines.wait("outputs in the safe state", |v| {
            v["event"] == "outputs_cleared"
        });
        lines.wait("back in Wait_Prm", |v| {
            v["event"] == "state" && v["to"] == "Wait_Prm"
        });
        expiries.push((a, wd, w["t"].as_f64().unwrap() + lines.offset()));
    }
    bus.stop();
    let seen = read_pcap(&pcap);
    for (a, wd, expiry) in expiries {
        let last = seen
            .iter()
            .filter(|s| s.sa == 2 && s.request && (s.da == a || s.da == 127))
            .map(|s| s.t)
            .fold(f64::NAN, f64::max);
        let measured = (expiry - last) * 1e3;
        eprintln!(
            "MEASURED master killed: slave {a} (watchdog {wd} ms) safe after {measured:.1} ms"
        );
        let tol = wd as f64 * 0.1;
        assert!(
            (measured - wd as f64).abs() <= tol,
            "slave {a}: {measured:.1} ms, watchdog {wd} ms ± 10 %"
        );
    }
    drop(slaves);
}

/// SIGTERM (and Ctrl-C) to `dpctl master`: before it exits it sends
/// Global_Control with Clear_Data and a cycle of zero outputs, so each
/// slave is in its safe state at once, seconds before its watchdog
/// (5 s here) would have put it there; the master exits with status 0
/// within the farewell's bound.
#[test]
fn a_terminated_master_clears_its_slaves_before_it_exits() {
    let dir = TempDir::new("scn-farewell");
    let bus = Bus::start(3, &[]);
    let watchdogs = [(10u8, 5000u64), (11, 5000)];
    let (mut slaves, mut m, _ml) = slaves_echoing_outputs(&bus, &dir, &watchdogs);
    for (_, lines) in &mut slaves {
        lines.skip_to_end();
    }
    let asked = wall();
    m.signal(15);
    let status = m.wait(Duration::from_secs(10));
    let ended = wall();
    assert!(status.success(), "{status}");
    assert!(
        ended - asked < 3.0,
        "the master took {:.2} s",
        ended - asked
    );
    for (_, lines) in &mut slaves {
        // The slave clears its outputs, then reports the Global_Control.
        let (_, c) = lines.wait("outputs in the safe state", |v| {
            v["event"] == "outputs_cleared" || v["event"] == "watchdog"
        });
        assert_eq!(
            c["event"], "outputs_cleared",
            "the watchdog came first: {c}"
        );
        assert_eq!(c["reason"], "Global_Control Clear_Data", "{c}");
        let (_, g) = lines.wait("Global_Control Clear_Data", |v| {
            v["event"] == "global_control"
                && v["command"].as_str().is_some_and(|c| c.contains("Clear"))
        });
        assert_eq!(g["master"], 2, "{g}");
        // Cleared while the master still ran (the slave's clock against
        // the wall clock: reading its lines only adds delay).
        let at = c["t"].as_f64().unwrap() + lines.offset();
        assert!(
            at <= ended + 0.05,
            "cleared {:.3} s after the master ended",
            at - ended
        );
    }
    bus.stop();
}

/// CPU time (user + system, s) of process `pid`.
fn cpu_time(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // Fields after the command name (which may contain spaces).
    let rest = stat.rsplit_once(')').map(|x| x.1).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11).and_then(|s| s.parse().ok()).unwrap_or(0.0)
        + f.get(12).and_then(|s| s.parse().ok()).unwrap_or(0.0);
    ticks / 100.0
}

/// The pty under a running `dpctl slave` / `dpctl master` disappears
/// (socat killed): the process exits with a one-line error, or keeps
/// waiting for the device without a busy loop (under 10 % of a core).
#[test]
fn the_pty_under_a_running_slave_or_master_disappears() {
    let dir = TempDir::new("scn-pty");
    for what in ["slave", "master"] {
        let a = dir.path(&format!("{what}-a"));
        let b = dir.path(&format!("{what}-b"));
        let mut socat = common::pty_pair(&a, &b);
        let cfg = bus_file(&dir, 2, &[(10, 1000)]);
        let mut cmd = Command::new(dpctl());
        match what {
            "slave" => cmd
                .args([
                    "slave",
                    "--port",
                    a.to_str().unwrap(),
                    "--addr",
                    "10",
                    "--baud",
                    "1.5M",
                ])
                .arg("--gsd")
                .arg(gen_gsd())
                .args(["--module", "2 words in/out"]),
            _ => cmd
                .args([
                    "master",
                    "--json",
                    "--port",
                    a.to_str().unwrap(),
                    "--config",
                ])
                .arg(&cfg),
        };
        let mut p = Proc::spawn_captured(cmd);
        // Wait until it has the pty open.
        common::wait_for("the pty opened", WAIT, || {
            let fds = std::fs::read_dir(format!("/proc/{}/fd", p.pid())).unwrap();
            fds.filter_map(Result::ok).any(|e| {
                std::fs::read_link(e.path())
                    .map(|l| l.to_string_lossy().starts_with("/dev/pts/"))
                    .unwrap_or(false)
            })
        });
        socat.signal(9);
        socat.wait(Duration::from_secs(10));
        // Either it ends with a clean error …
        let end = Instant::now() + Duration::from_secs(5);
        let cpu0 = cpu_time(p.pid());
        let t0 = Instant::now();
        while Instant::now() < end && !p.exited() {
            std::thread::sleep(Duration::from_millis(50));
        }
        if p.exited() {
            let out = p.finish(Duration::from_secs(5));
            eprintln!(
                "MEASURED pty gone under dpctl {what}: exit {:?}: {}",
                out.status.code(),
                out.stderr.trim()
            );
            assert_eq!(out.status.code(), Some(1), "{what}: {}", out.stderr);
            let last = out.stderr.lines().last().unwrap_or_default();
            assert!(last.starts_with("dpctl: "), "{what}: {}", out.stderr);
            // Each cause once (issue 18: "port closed: port closed").
            let parts: Vec<&str> = last.split(": ").collect();
            assert!(
                parts.windows(2).all(|w| w[0] != w[1]),
                "{what}: a cause printed twice: {last}"
            );
        } else {
            // … or it waits for the device to come back without spinning.
            let cpu = cpu_time(p.pid()) - cpu0;
            let secs = t0.elapsed().as_secs_f64();
            eprintln!(
                "MEASURED pty gone under dpctl {what}: still running, {:.0} % CPU",
                cpu / secs * 100.0
            );
            assert!(
                cpu / secs < 0.1,
                "{what}: busy loop: {cpu:.2} s CPU in {secs:.1} s"
            );
            p.terminate(Duration::from_secs(10));
        }
    }
}

/// The token holder of a 3-master ring on `dpctl bus` is killed: the
/// survivors claim the token after the token-lost timeout and pass it on
/// (measured on the bus's pcap). Master 2 probes a slave that is not
/// there, holding the token for the slot time plus its latency allowance;
/// it is killed as soon as a sniffer on the bus shows such a probe. The
/// pcap tells whether it held the token; a kill that missed is repeated.
#[test]
fn the_token_holder_of_a_three_master_ring_is_killed() {
    const LATENCY_MS: f64 = 50.0;
    for attempt in 1..=10 {
        let dir = TempDir::new("scn-ring");
        let pcap = dir.path("bus.pcapng");
        let bus = Bus::start(4, &["--pcap", pcap.to_str().unwrap()]);
        // A sniffer on the 4th link shows when master 2 probes its
        // missing slave: it then holds the token for the slot time plus
        // its latency allowance, twice (one retry).
        let mut sniff = Proc::spawn(
            "dpctl sniff",
            Command::new(dpctl())
                .args([
                    "sniff",
                    "--json",
                    "--baud",
                    "1.5M",
                    "--port",
                    &bus.link_str(3),
                ])
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .stderr(Stdio::null()),
        );
        let mut sniffed = Timed::from(&mut sniff);
        let mut masters = vec![];
        for (i, a) in [2u8, 3, 4].into_iter().enumerate() {
            // Master 2 has a slave that never answers; 3 and 4 none.
            let slaves: &[(u8, u64)] = if a == 2 { &[(50, 1000)] } else { &[] };
            let cfg = bus_file(&dir, a, slaves);
            let mut p = Proc::spawn(
                &format!("dpctl master {a}"),
                Command::new(dpctl())
                    .args(["master", "--json", "--interval", "100"])
                    .args([
                        "--latency",
                        &LATENCY_MS.to_string(),
                        "--port",
                        &bus.link_str(i),
                    ])
                    .arg("--config")
                    .arg(&cfg)
                    .stdin(Stdio::null())
                    .stdout(Stdio::piped())
                    .stderr(Stdio::null()),
            );
            let lines = Timed::from(&mut p);
            masters.push((a, p, lines));
        }
        // The ring is formed when every master is in it and cycling.
        for (a, _, lines) in masters.iter_mut() {
            lines.wait(&format!("master {a} in the ring"), |v| {
                v["event"] == "ring" && v["what"] == "in the token ring"
            });
            let c = lines.wait("a status", |v| v["event"] == "status").1["cycles"]
                .as_u64()
                .unwrap();
            lines.wait("cycles", |v| {
                v["event"] == "status" && v["cycles"].as_u64().unwrap() > c + 3
            });
        }
        sniffed.skip_to_end();
        sniffed.wait("master 2 probing slave 50", |v| {
            v["sa"] == 2 && v["da"] == 50
        });
        let killed = wall();
        masters[0].1.signal(9);
        masters[0].1.wait(Duration::from_secs(10));
        // Both survivors keep getting the token: the ring works again
        // (whoever held the token; the pcap tells below).
        for (a, _, lines) in masters.iter_mut().skip(1) {
            let c = lines.wait("a status", |v| v["event"] == "status").1["cycles"]
                .as_u64()
                .unwrap();
            lines.wait(&format!("master {a} cycling after the kill"), |v| {
                v["event"] == "status" && v["cycles"].as_u64().unwrap() > c + 20
            });
        }
        let stopping = wall();
        for (_, p, _) in masters.iter_mut().skip(1) {
            p.terminate(Duration::from_secs(10));
        }
        sniff.terminate(Duration::from_secs(10));
        bus.stop();

        let seen = read_pcap(&pcap);
        let before: Vec<&Seen> = seen.iter().filter(|s| s.t <= killed).collect();
        let mut holder = before.iter().rev().find(|s| s.token).map(|s| s.da);
        // A pass of master 2 stamped by the hub after the kill: it had
        // passed the token on.
        if seen.iter().any(|s| s.t > killed && s.token && s.sa == 2) {
            holder = None;
        }
        if holder != Some(2) {
            eprintln!("attempt {attempt}: master {holder:?} held the token at the kill; again");
            continue;
        }
        // The last telegram before the silence, the claim (token to
        // itself) and the first pass to the other survivor.
        let Some(claim) = seen
            .iter()
            .position(|s| s.t > killed && s.token && s.sa == s.da)
        else {
            // The time stamps did not settle who held the token (the hub
            // stamps a telegram when it has relayed it).
            let around: Vec<String> = seen
                .iter()
                .filter(|s| s.t > killed - 0.3 && s.t < killed + 0.5)
                .map(|s| {
                    format!(
                        "{:.4} {}→{}{}",
                        s.t - killed,
                        s.sa,
                        s.da,
                        if s.token { " token" } else { "" }
                    )
                })
                .collect();
            eprintln!("attempt {attempt}: no claim after the kill; again: {around:?}");
            continue;
        };
        let last = seen[..claim].last().expect("activity before the claim").t;
        let passed = seen[claim..]
            .iter()
            .find(|s| s.token && s.sa != s.da && s.sa != 2 && s.da != 2)
            .expect("a token pass between the survivors");
        let claimer = seen[claim].sa;
        let mut cfg = ActiveConfig::new(claimer, BusParams::defaults(Baud::B1500000));
        cfg.latency_allowance = Duration::from_secs_f64(LATENCY_MS / 1e3);
        // As `dpctl master` on a pty (`Port::whole_telegrams`).
        cfg.whole_telegrams = true;
        let tto_ms = cfg.token_lost_timeout().as_secs_f64() * 1e3;
        let silence_ms = (seen[claim].t - last) * 1e3;
        let back_ms = (passed.t - last) * 1e3;
        eprintln!(
            "MEASURED ring: holder 2 killed, master {claimer} claimed after {silence_ms:.1} ms of silence \
             (token-lost timeout {tto_ms:.1} ms incl. 3 + {claimer} latency allowances), ring back after {back_ms:.1} ms"
        );
        // Master 3, the lowest survivor, claims: its token-lost timeout is
        // one latency allowance (and 2 slot times) shorter than master
        // 4's, and its claim reaches master 4 within that allowance.
        // Before issue 18's fix the step was 2 slot times (0.4 ms) and
        // master 4 claimed too in about a third of the runs.
        assert_eq!(claimer, 3, "the lowest survivor claims");
        let claims: Vec<u8> = seen[claim..]
            .iter()
            .filter(|s| s.t < stopping && s.token && s.sa == s.da)
            .map(|s| s.sa)
            .collect();
        assert!(
            claims.iter().all(|&a| a == 3),
            "only master 3 claims: {claims:?}"
        );
        assert!(
            silence_ms >= tto_ms - 5.0,
            "claimed early: {silence_ms:.1} ms"
        );
        // One claim: two tokens to itself, then the pass (plus scheduling
        // of processes on a loaded machine).
        assert!(back_ms <= tto_ms + 100.0, "ring back after {back_ms:.1} ms");
        return;
    }
    panic!("in 10 attempts the kill never hit the token holder");
}
