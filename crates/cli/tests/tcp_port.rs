//! `--port tcp://HOST:PORT`: a DP master reaches a slave through a serial
//! device server in raw TCP mode. socat plays the server: it listens on
//! 127.0.0.1 and relays the connection's bytes to a pty, the server's
//! "serial line", where a `dpctl slave` runs. `dpctl master --port
//! tcp://…` must bring the slave into Data_Exchange and exchange data;
//! `dpctl sniff` and `dpctl scan` take the same ports. The test fails when
//! socat is missing.

mod common;

use common::{dpctl, generic_slave, repo, require, Lines, Proc, TempDir};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

const WAIT: Duration = Duration::from_secs(60);

/// A TCP port on 127.0.0.1 that was free a moment ago.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// `socat` relaying one TCP connection on 127.0.0.1:`port` to a new pty
/// at `link`; returns once it listens.
fn serial_server(link: &Path, port: u16) -> Proc {
    require("socat");
    let mut p = Proc::spawn(
        "socat",
        Command::new("socat")
            .args(["-d", "-d"])
            .arg(format!("PTY,link={},raw,echo=0", link.display()))
            .arg(format!("TCP-LISTEN:{port},bind=127.0.0.1,reuseaddr"))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped()),
    );
    // socat logs to stderr: read it as lines.
    let err = p.child.as_mut().unwrap().stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for l in std::io::BufReader::new(err).lines().map_while(Result::ok) {
            if tx.send(l).is_err() {
                break;
            }
        }
    });
    let end = std::time::Instant::now() + WAIT;
    loop {
        let left = end.saturating_duration_since(std::time::Instant::now());
        match rx.recv_timeout(left) {
            Ok(l) if l.contains("listening on") => break,
            Ok(_) => {}
            Err(_) => panic!("socat does not listen on {port}"),
        }
    }
    assert!(link.exists(), "socat made no pty at {}", link.display());
    // Keep draining socat's log so that it never blocks on a full pipe.
    std::thread::spawn(move || while rx.recv().is_ok() {});
    p
}

fn slave(link: &Path, addr: u8) -> Proc {
    Proc::spawn(
        "dpctl slave",
        generic_slave(link, addr, "19200", &["2 words in/out"]).stderr(Stdio::null()),
    )
}

#[test]
fn master_reaches_data_exchange_through_a_serial_device_server() {
    let dir = TempDir::new("tcp-port");
    let link = dir.path("server-line");
    let port = free_port();
    let mut server = serial_server(&link, port);
    let mut s = slave(&link, 10);
    let config = dir.path("bus.toml");
    std::fs::write(
        &config,
        format!(
            "[master]\naddress = 2\nbaud = \"19200\"\n[[slave]]\naddress = 10\ngsd = \"{}\"\n\
             modules = [\"2 words in/out\"]\nwatchdog_ms = 5000\ninitial_outputs = [1, 2, 3, 4]\n",
            repo().join("crates/devices/gsd/DPCTL_GEN.GSD").display()
        ),
    )
    .unwrap();
    let url = format!("tcp://127.0.0.1:{port}");
    let mut m = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--exchanges", "20", "--timeout", "60"])
            .args(["--port", &url, "--config"])
            .arg(&config)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    let mut lines = Lines::from(&mut m);
    // The echoing generic slave returns the master's outputs as inputs.
    assert!(
        lines.wait_for(r#""inputs":"01 02 03 04""#, WAIT),
        "no echoed inputs through {url}: {:#?}",
        lines.1
    );
    let status = m.wait(WAIT);
    assert!(status.success(), "dpctl master: {status:?} {:#?}", lines.1);
    let dx = lines
        .1
        .iter()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["event"] == "status")
        .filter_map(|v| {
            v["slaves"]
                .as_array()?
                .iter()
                .find(|s| s["address"] == 10)
                .cloned()
        })
        .any(|s| s["state"] == "data_exchange");
    assert!(dx, "slave 10 never in Data_Exchange: {:#?}", lines.1);
    s.terminate(Duration::from_secs(10));
    server.terminate(Duration::from_secs(10));
}

#[test]
fn a_refused_connection_is_a_one_line_error() {
    let port = free_port();
    let url = format!("tcp://127.0.0.1:{port}");
    let out = common::run_dpctl(&["scan", "--port", &url]);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let err = out.stderr.trim();
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains(&url), "{err}");
}
