//! A real MQTT broker for the gateway tests: Debian's mosquitto on a free
//! localhost port. Fails (never skips) when it is missing.

use super::{need, wait_for, Proc, TempDir};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

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

/// A localhost TCP port nobody listens on now.
pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
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
/// returns.
pub fn broker_with(conf: &Path, port: u16) -> Proc {
    let p = Proc::spawn(
        "mosquitto",
        Command::new(mosquitto())
            .arg("-c")
            .arg(conf)
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    wait_for("mosquitto to listen", Duration::from_secs(30), || {
        TcpStream::connect(("127.0.0.1", port)).is_ok()
    });
    p
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
    let gsd = super::repo().join("gsd/DPCTL_GEN.GSD");
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
            .arg(super::repo().join("gsd/DPCTL_GEN.GSD"))
            .args(["--module", "2 words in/out"])
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
}
