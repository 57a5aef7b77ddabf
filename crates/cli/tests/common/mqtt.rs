//! A real MQTT broker for the gateway tests: Debian's mosquitto on a free
//! localhost port. Fails (never skips) when it is missing.

use super::{need, wait_for, Proc, TempDir};
use std::net::{TcpListener, TcpStream};
use std::path::PathBuf;
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
    let p = Proc::spawn(
        "mosquitto",
        Command::new(mosquitto())
            .arg("-c")
            .arg(&conf)
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    wait_for("mosquitto to listen", Duration::from_secs(30), || {
        TcpStream::connect(("127.0.0.1", port)).is_ok()
    });
    p
}
