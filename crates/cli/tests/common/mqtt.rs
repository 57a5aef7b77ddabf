//! A real MQTT broker for the gateway tests: Debian's mosquitto on a free
//! localhost port. Fails (never skips) when it is missing.

use super::{dpctl, need, require, wait_for, Lines, Proc, TempDir};
use std::collections::BTreeSet;
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The mosquitto broker binary (Debian puts it in /usr/sbin).
pub fn mosquitto() -> PathBuf {
    let on_path = std::env::var_os("PATH").and_then(|p| {
        std::env::split_paths(&p)
            .map(|d| d.join("mosquitto"))
            .find(|f| f.is_file())
    });
    match on_path {
        Some(p) => p,
        None if std::path::Path::new("/usr/sbin/mosquitto").is_file() => {
            "/usr/sbin/mosquitto".into()
        }
        None => need("mosquitto (Debian package mosquitto)"),
    }
}

/// A localhost TCP port nobody listens on now, and never handed out
/// before in this test process (the tests of a binary run in parallel:
/// two brokers on one port would leave one test talking to the other's
/// broker).
pub fn free_port() -> u16 {
    static GIVEN: Mutex<BTreeSet<u16>> = Mutex::new(BTreeSet::new());
    let mut given = GIVEN.lock().unwrap_or_else(|e| e.into_inner());
    loop {
        let port = TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        if given.insert(port) {
            return port;
        }
    }
}

/// A broker on `port` (its config in `dir`), accepting connections when
/// this returns.
pub fn broker(dir: &TempDir, port: u16) -> Proc {
    let conf = dir.path("mosquitto.conf");
    std::fs::write(
        &conf,
        format!("listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n"),
    )
    .unwrap();
    broker_with(&conf, port)
}

/// A broker with the configuration `conf`, listening on `port` when this
/// returns; its log (stderr) is `mosquitto-<port>.log` beside `conf`.
/// Fails, with the log, when the broker exits before or just after the
/// port accepts (a port somebody else took, a bad certificate).
pub fn broker_with(conf: &Path, port: u16) -> Proc {
    let log = conf.with_file_name(format!("mosquitto-{port}.log"));
    let mut p = Proc::spawn(
        "mosquitto",
        Command::new(mosquitto())
            .arg("-c")
            .arg(conf)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap()),
    );
    let dead = |p: &mut Proc| {
        if p.exited() {
            let log = std::fs::read_to_string(&log).unwrap_or_default();
            panic!("mosquitto on port {port} exited:\n{log}");
        }
    };
    wait_for("mosquitto to listen", Duration::from_secs(30), || {
        dead(&mut p);
        TcpStream::connect(("127.0.0.1", port)).is_ok()
    });
    dead(&mut p);
    p
}

/// `mosquitto_sub` on `port` with `args` (its topics and output format)
/// and `auth` (TLS and user options, given to the probe's
/// `mosquitto_pub` too); its stdout and stderr as [`Lines`] (an error
/// of the client shows in a failing test's output). Returns once the
/// subscription is in place: an empty message published to `probe`, a
/// topic that `args` subscribe to, came back (it is in the lines).
pub fn subscribe(port: u16, args: &[&str], auth: &[&str], probe: &str) -> (Proc, Lines) {
    require("mosquitto_sub");
    require("mosquitto_pub");
    let port = port.to_string();
    let mut p = Proc::spawn(
        "mosquitto_sub",
        Command::new("sh")
            .args(["-c", "exec mosquitto_sub \"$@\" 2>&1", "mosquitto_sub"])
            .args(["-h", "127.0.0.1", "-p", &port])
            .args(args)
            .args(auth)
            .stdin(Stdio::null())
            .stdout(Stdio::piped()),
    );
    let mut lines = Lines::from(&mut p);
    let end = Instant::now() + Duration::from_secs(30);
    loop {
        let published = Command::new("mosquitto_pub")
            .args(["-h", "127.0.0.1", "-p", &port])
            .args(auth)
            .args(["-t", probe, "-n"])
            .stderr(Stdio::null())
            .status()
            .expect("mosquitto_pub")
            .success();
        // The wait is the pause between tries.
        if lines.wait_for(probe, Duration::from_millis(500)) {
            return (p, lines);
        }
        assert!(
            !p.exited() && Instant::now() < end,
            "mosquitto_sub never subscribed (last probe published: {published}); it printed:\n{}",
            lines.1.join("\n")
        );
    }
}

/// The slaves of the gateway tests' bus file (master 1 at 1.5 Mbit/s):
/// a GSD echo at 3 (`echo`), a GSD slave at 4 (`locked`) and an Omega
/// drive at 25 with one setpoint and one actual value; the drive's table
/// is last, so its further options may follow.
pub const GATEWAY_SLAVES: &str = r#"[master]
address = 1
baud = "1.5M"

[[slave]]
address = 3
name = "echo"
gsd = "DPCTL_GEN.GSD"
modules = ["2 words in/out"]

[[slave]]
address = 4
name = "locked"
gsd = "DPCTL_GEN.GSD"
modules = ["2 words in/out"]

[[slave]]
address = 25
device = "omega"
setpoints = 1
actual_values = 1
"#;

/// A bus file with the generic echo slave at 3 ("2 words in/out"),
/// then `mqtt` (the `[mqtt]` table's lines).
pub fn echo_bus_text(mqtt: &str) -> String {
    let slave = "[[slave]]\naddress = 3\ngsd = \"DPCTL_GEN.GSD\"\nmodules = [\"2 words in/out\"]";
    format!("[master]\naddress = 1\nbaud = \"1.5M\"\n\n{slave}\n\n[mqtt]\n{mqtt}")
}

/// `bus.toml` with `text` in `dir`, beside a copy of DPCTL_GEN.GSD (the
/// GSD file the bus files of these tests name).
pub fn write_bus(dir: &TempDir, text: &str) -> PathBuf {
    let gsd = super::repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    std::fs::copy(gsd, dir.path("DPCTL_GEN.GSD")).unwrap();
    let bus = dir.path("bus.toml");
    std::fs::write(&bus, text).unwrap();
    bus
}

/// `dpctl slave`: the generic echo at 3 ("2 words in/out") on `port`
/// at 1.5 Mbit/s.
pub fn echo_slave(port: &Path) -> Proc {
    Proc::spawn(
        "dpctl slave",
        Command::new(super::dpctl())
            .args(["slave", "--port"])
            .arg(port)
            .args(["--addr", "3", "--baud", "1.5M", "--gsd"])
            .arg(super::repo().join("crates/devices/gsd/DPCTL_GEN.GSD"))
            .args(["--module", "2 words in/out"])
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
}

/// `dpctl GLOBAL… gateway --config BUS --sim --mqtt mqtt://127.0.0.1:PORT`
/// with stderr joined to stdout (piped) and `DPCTL_LOG` unset; add
/// arguments or environment to the returned command before spawning.
pub fn sim_gateway(global: &[&str], bus: &Path, port: u16) -> Command {
    let mut cmd = Command::new("sh");
    cmd.args(["-c", "exec \"$0\" \"$@\" 2>&1"])
        .arg(dpctl())
        .args(global)
        .args(["gateway", "--config"])
        .arg(bus)
        .arg("--sim")
        .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")])
        .env_remove("DPCTL_LOG")
        .stdout(Stdio::piped());
    cmd
}

/// Run `protoc` with `mode` (`--decode=…` / `--encode=…`) on `input`
/// against the Sparkplug B specification's `sparkplug_b.proto` (the
/// independent payload decoder of the Sparkplug tests); fails (never
/// skips) when protoc is missing.
pub fn protoc(mode: &str, input: &[u8]) -> Vec<u8> {
    use std::io::Write;
    require("protoc");
    let mut p = Command::new("protoc")
        .arg("-I")
        .arg(super::repo().join("crates/gateway/proto"))
        .arg(mode)
        .arg("sparkplug_b.proto")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("protoc");
    p.stdin.take().unwrap().write_all(input).unwrap();
    let out = p.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "protoc {mode} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// Run the Python `script` in the venv with pysparkplug (the independent
/// Sparkplug implementation of the tests) on `input` as stdin; its
/// stdout's JSON lines. Fails (never skips) when pysparkplug is missing.
pub fn pysparkplug(script: &str, input: &str) -> Vec<serde_json::Value> {
    use std::io::Write;
    let py = super::python();
    let ok = Command::new(&py)
        .args(["-c", "import pysparkplug"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        need("pysparkplug in .venv (scripts/setup-test-env)");
    }
    let mut p = Command::new(&py)
        .args(["-c", script])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python");
    p.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
    let out = p.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "pysparkplug: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    super::json_lines(String::from_utf8(out.stdout).unwrap().lines())
}
