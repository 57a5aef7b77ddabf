//! What the gateway benches share: a mosquitto on a free localhost port,
//! and a gateway whose MQTT client runs on a tokio runtime thread of its
//! own while its simulated plant runs on the calling thread, paced by
//! [`Pacer`] as in `dpctl gateway --sim`.

#![allow(dead_code)]

use profibus_devices::bus::ProfiledBus;
use profibus_gateway::sim::slave_infos;
use profibus_gateway::{Broker as BrokerUrl, Connection, Gateway, MqttLink, MqttSettings, Session};
use profibus_io::pace::Pacer;
use profibus_plant::Plant;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// A mosquitto started for the bench; killed when dropped.
pub struct Broker {
    /// Its localhost port.
    pub port: u16,
    child: Child,
    /// Holds the broker's configuration; removed on drop.
    _dir: tempfile::TempDir,
}

fn mosquitto() -> String {
    for p in ["mosquitto", "/usr/sbin/mosquitto"] {
        let found = Command::new(p)
            .arg("-h")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok();
        if found {
            return p.into();
        }
    }
    panic!("mosquitto is missing: run scripts/setup-test-env");
}

impl Broker {
    /// Start mosquitto on a free port with `extra` configuration lines;
    /// returns once it takes connections.
    pub fn start(name: &str, extra: &str) -> Broker {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let dir = tempfile::Builder::new()
            .prefix(&format!("gw-{name}-"))
            .tempdir()
            .unwrap();
        let conf = dir.path().join("mosquitto.conf");
        let text = format!("listener {port} 127.0.0.1\nallow_anonymous true\n{extra}");
        std::fs::write(&conf, text).unwrap();
        let child = Command::new(mosquitto())
            .arg("-c")
            .arg(&conf)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            std::thread::sleep(Duration::from_millis(5));
        }
        Broker {
            port,
            child,
            _dir: dir,
        }
    }

    /// The broker's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A bus file's text, parsed as if it were in `crates/devices/gsd/` (for its GSDs).
pub fn bus(text: &str) -> ProfiledBus {
    let path = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../devices/gsd/bus.toml"
    ));
    ProfiledBus::parse(path, text).unwrap()
}

/// Run the plain JSON gateway of the bus file `text` against the broker
/// on `port`: [`run_session`].
pub fn run_gateway<R>(
    text: &str,
    port: u16,
    turns: impl FnOnce(&mut Plant, &Pacer, &mut Gateway, &mut MqttLink) -> R,
) -> R {
    let make = |p: &ProfiledBus, s| Gateway::new(s, slave_infos(p).unwrap());
    run_session(text, port, make, turns)
}

/// Run the gateway core `make` builds for the bus file `text` against
/// the broker on `port`: its MQTT client on a current-thread runtime of
/// its own (as `dpctl gateway` has), the plant and the core on this
/// thread in `turns` (which paces them with the given [`Pacer`]) until it
/// returns.
pub fn run_session<S: Session, R>(
    text: &str,
    port: u16,
    make: impl FnOnce(&ProfiledBus, MqttSettings) -> S,
    turns: impl FnOnce(&mut Plant, &Pacer, &mut S, &mut MqttLink) -> R,
) -> R {
    let profiled = bus(text);
    let settings = MqttSettings::from_table(profiled.file.mqtt.as_ref(), "bench").unwrap();
    let mut gw = make(&profiled, settings);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let conn = Connection::plain(BrokerUrl {
        host: "127.0.0.1".into(),
        port,
        tls: false,
    });
    let mut link = {
        let _in = rt.enter();
        MqttLink::connect(&conn, &gw)
    };
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let client = std::thread::spawn(move || {
        let _ = rt.block_on(stopped);
    });
    let mut plant = Plant::from_bus(&profiled).unwrap();
    let r = turns(&mut plant, &Pacer::new(), &mut gw, &mut link);
    let _ = stop.send(());
    let _ = client.join();
    r
}

/// The `p` quantile of `v` (sorts it).
pub fn pct(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}
