//! Scale-out: N gateways × M slaves on one mosquitto.
//!
//! `cargo bench -p profibus-gateway --bench scale -- N M SECONDS MODE [sparkplug]`
//! (defaults 16 32 20 change:100; MODE `change:MS` or `interval:MS`;
//! `sparkplug`: each gateway a Sparkplug B edge node `scale/segG`, and
//! the DDATA messages are counted).
//!
//! Each gateway runs as `dpctl gateway --sim` does in its own process: a
//! thread with a simulated bus at 1.5 Mbit/s paced on the wall clock by
//! the library's `Pacer` with M generic echo slaves (2 words in/out), the
//! gateway stepped after every turn, and its MQTT client on a
//! single-threaded tokio runtime of its own, publishing to a mosquitto
//! started here. `change:MS`: every MS ms the application
//! writes new outputs to every slave (its inputs echo them), images are
//! published on change, so each slave yields 2 messages per MS.
//! `interval:MS`: no writes, every image published every MS. A `mosquitto_sub` process counts what the
//! broker delivers. Measured over SECONDS after a warm-up: messages per
//! second, CPU seconds of this process (buses + gateways + MQTT clients),
//! of the time spent in the gateway's own work (step and publish) and in
//! the bus simulation, of the broker and of the subscriber, bus cycles
//! per second against the rate the simulated bus should reach, and the
//! load average.

mod support;

use profibus_gateway::link;
use profibus_gateway::{sparkplug, EdgeNode, MqttLink, Session, SparkplugId};
use profibus_io::pace::Pacer;
use profibus_plant::Plant;
use std::io::BufRead;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use support::{run_gateway, run_session, Broker};

/// User + system CPU seconds of a process (`/proc/PID/stat`).
fn cpu_s(pid: &str) -> f64 {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let rest = s.rsplit_once(')').map(|(_, r)| r).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let t = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // Fields 14 and 15 (utime, stime) are 11 and 12 after the ')'.
    (t(11) + t(12)) / 100.0
}

fn bus_file(m: usize, mode: &str, g: usize) -> String {
    let mut s = String::from("[master]\naddress = 1\nbaud = \"1.5M\"\n\n");
    for i in 0..m {
        s += &format!(
            "[[slave]]\naddress = {}\ngsd = \"DPCTL_GEN.GSD\"\nmodules = [\"2 words in/out\"]\n\n",
            3 + i
        );
    }
    s += &format!("[mqtt]\nbus = \"seg{g}\"\nprefix = \"scale\"\nclient_id = \"scale-{g}\"\n");
    match mode.strip_prefix("interval:") {
        Some(ms) => s += &format!("publish = \"interval\"\ninterval_ms = {ms}\n"),
        // Every change (the rate the bench sets): no minimum interval.
        None => s += "publish = \"change\"\nmin_interval_ms = 0\n",
    }
    s
}

#[derive(Default)]
struct Counters {
    sim_ns: AtomicU64,
    gw_ns: AtomicU64,
    cycles: AtomicU64,
}

fn gateway(
    port: u16,
    text: String,
    write: Option<Duration>,
    sparkplug_node: Option<SparkplugId>,
    stop: Arc<AtomicBool>,
    c: Arc<Counters>,
) {
    match sparkplug_node {
        None => run_gateway(&text, port, |plant, pacer, gw, link| {
            drive(plant, pacer, gw, link, write, &stop, &c)
        }),
        Some(id) => run_session(
            &text,
            port,
            |p, s| EdgeNode::new(s, id, sparkplug::devices(p).unwrap()),
            |plant, pacer, gw, link| drive(plant, pacer, gw, link, write, &stop, &c),
        ),
    }
}

/// The loop of one gateway: the plant paced, new outputs every `write`,
/// the core stepped after every turn; timed into `c`.
fn drive(
    plant: &mut Plant,
    pacer: &Pacer,
    gw: &mut impl Session,
    link: &mut MqttLink,
    write: Option<Duration>,
    stop: &AtomicBool,
    c: &Counters,
) {
    let mut last_cycles = 0;
    let mut next_write = Instant::now();
    let mut value: u32 = 0;
    let addresses: Vec<u8> = plant.master().slave_addresses().collect();
    while !stop.load(Ordering::Relaxed) {
        let t0 = Instant::now();
        let pause = pacer.turn(plant.now(), |t| plant.run_until(t));
        if let Some(w) = write.filter(|_| t0 >= next_write) {
            next_write = t0 + w;
            value = value.wrapping_add(1);
            for &a in &addresses {
                plant.master().set_outputs(a, &value.to_be_bytes());
            }
        }
        let t1 = Instant::now();
        let now = plant.now();
        link::step(link, gw, plant.master(), now);
        let t2 = Instant::now();
        c.sim_ns
            .fetch_add((t1 - t0).as_nanos() as u64, Ordering::Relaxed);
        c.gw_ns
            .fetch_add((t2 - t1).as_nanos() as u64, Ordering::Relaxed);
        let cycles = plant.master().cycle_stats().cycles;
        c.cycles.fetch_add(cycles - last_cycles, Ordering::Relaxed);
        last_cycles = cycles;
        std::thread::sleep(pause);
    }
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let n: usize = args.first().and_then(|a| a.parse().ok()).unwrap_or(16);
    let m: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(32);
    let secs: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(20);
    let mode = args.get(3).cloned().unwrap_or_else(|| "change:100".into());
    let spb = args.get(4).map(String::as_str) == Some("sparkplug");
    let write = mode
        .strip_prefix("change:")
        .map(|ms| Duration::from_millis(ms.parse().expect("change:MS")));
    let broker = Broker::start("scale", "persistence false\nmax_queued_messages 100000\n");
    let port = broker.port;
    let mut sub = Command::new("mosquitto_sub")
        .args(["-h", "127.0.0.1", "-p", &port.to_string(), "-q", "0"])
        .args(match spb {
            // One line per message: the topic (the payload is protobuf).
            true => vec!["-t", "spBv1.0/scale/DDATA/+/+", "-F", "%t"],
            false => vec!["-t", "scale/+/+/inputs", "-t", "scale/+/+/outputs"],
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("mosquitto_sub (Debian package mosquitto-clients)");
    let received = Arc::new(AtomicU64::new(0));
    {
        let out = sub.stdout.take().unwrap();
        let received = received.clone();
        std::thread::spawn(move || {
            for _ in std::io::BufReader::new(out).lines().map_while(Result::ok) {
                received.fetch_add(1, Ordering::Relaxed);
            }
        });
    }
    let stop = Arc::new(AtomicBool::new(false));
    let counters = Arc::new(Counters::default());
    let threads: Vec<_> = (0..n)
        .map(|g| {
            let (stop, c, text) = (stop.clone(), counters.clone(), bus_file(m, &mode, g));
            let id = spb.then(|| format!("scale/seg{g}").parse().unwrap());
            std::thread::spawn(move || gateway(port, text, write, id, stop, c))
        })
        .collect();
    // Warm-up: connections, start-up of every slave.
    std::thread::sleep(Duration::from_secs(5));
    let (bpid, spid) = (broker.pid().to_string(), sub.id().to_string());
    let snap = |c: &Counters| {
        (
            cpu_s("self"),
            cpu_s(&bpid),
            cpu_s(&spid),
            received.load(Ordering::Relaxed),
            c.sim_ns.load(Ordering::Relaxed),
            c.gw_ns.load(Ordering::Relaxed),
            c.cycles.load(Ordering::Relaxed),
            Instant::now(),
        )
    };
    let a = snap(&counters);
    std::thread::sleep(Duration::from_secs(secs));
    let b = snap(&counters);
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        let _ = t.join();
    }
    let _ = sub.kill();
    let _ = sub.wait();
    drop(broker);

    let wall = (b.7 - a.7).as_secs_f64();
    let msgs = (b.3 - a.3) as f64;
    let per_msg_us = |cpu: f64| {
        if msgs > 0.0 {
            cpu / msgs * 1e6
        } else {
            f64::NAN
        }
    };
    let (proc_cpu, broker_cpu, sub_cpu) = (b.0 - a.0, b.1 - a.1, b.2 - a.2);
    let sim = (b.4 - a.4) as f64 / 1e9;
    let gw = (b.5 - a.5) as f64 / 1e9;
    let cycles = (b.6 - a.6) as f64 / wall / n as f64;
    let kind = if spb {
        "Sparkplug B DDATA"
    } else {
        "JSON inputs+outputs"
    };
    println!("{n} gateways x {m} slaves, publish {mode}, {secs} s measured, counting {kind}");
    println!(
        "messages received by the subscriber: {msgs:.0} ({:.0}/s)",
        msgs / wall
    );
    println!(
        "CPU: gateway process {proc_cpu:.2} s ({:.0}% of one core; {:.1} us/msg), of which wall time in gateway step+publish {gw:.2} s ({:.1} us/msg) and in the bus simulation {sim:.2} s",
        proc_cpu / wall * 100.0,
        per_msg_us(proc_cpu),
        per_msg_us(gw)
    );
    println!(
        "CPU: mosquitto {broker_cpu:.2} s ({:.0}% of one core; {:.1} us/msg), mosquitto_sub {sub_cpu:.2} s",
        broker_cpu / wall * 100.0,
        per_msg_us(broker_cpu)
    );
    println!("bus cycles per gateway: {cycles:.0}/s");
    println!("load average: {}", load.trim());
}
