//! `dpctl gateway --sim --opcua` against an independent OPC UA client:
//! Python `asyncua` (tests/data/opcua_client.py) from the repository's
//! .venv. Fails (never skips) when asyncua is missing: run
//! `scripts/setup-test-env`.

mod common;

use common::mqtt::{free_port, write_bus, GATEWAY_SLAVES};
use common::{dpctl, need, repo, Proc, TempDir};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

const T: Duration = Duration::from_secs(120);

/// The gateway tests' slaves ([`GATEWAY_SLAVES`]: generic GSD slaves 3
/// `echo`, DP-V1 and writable, and 4 `locked`, not writable; an Omega
/// drive at 25, here following its setpoint, only `setpoint1` writable)
/// and a BK3000 strip (15).
fn slaves() -> String {
    format!(
        r#"{GATEWAY_SLAVES}drive_enable = "auto"

[[slave]]
address = 15
name = "coupler"
device = "bk3000"
terminals = ["KL1104", "KL2134", "KL3102", "KL4002", "KL9010"]
"#
    )
}

const MQTT: &str = r#"
[mqtt]
bus = "line"
writable = [3, { address = 25, channels = ["setpoint1"] }]
"#;

/// The venv's Python with asyncua importable.
fn python() -> PathBuf {
    let py = repo().join(".venv/bin/python");
    let ok = Command::new(&py)
        .args(["-c", "import asyncua"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        need("asyncua in .venv (python OPC UA client)");
    }
    py
}

fn script() -> PathBuf {
    repo().join("crates/cli/tests/data/opcua_client.py")
}

/// `dpctl gateway --sim --opcua` on a free port with `extra` arguments;
/// returns once the port takes connections.
fn gateway(dir: &TempDir, table: &str, extra: &[&str]) -> (Proc, String) {
    let bus = write_bus(dir, &format!("{}{MQTT}{table}", slaves()));
    let port = free_port();
    let url = format!("opc.tcp://127.0.0.1:{port}");
    let mut cmd = Command::new(dpctl());
    cmd.arg("gateway")
        .arg("--config")
        .arg(&bus)
        .arg("--sim")
        .args(["--opcua", &url])
        .args(extra)
        .env("XDG_DATA_HOME", dir.path("xdg"));
    let mut gw = Proc::spawn_captured(cmd);
    common::wait_for("the OPC UA port", T, || {
        assert!(!gw.exited(), "dpctl gateway ended early");
        std::net::TcpStream::connect(("127.0.0.1", port)).is_ok()
    });
    (gw, url)
}

/// Run the client's `scenario`; its JSON output.
fn client(url: &str, args: &[&str]) -> serde_json::Value {
    let mut cmd = Command::new(python());
    cmd.arg(script()).arg(url).args(args);
    let out = Proc::spawn_captured(cmd).finish(T);
    assert!(
        out.status.success(),
        "opcua_client.py {args:?} failed:\n{}\n{}",
        out.stdout,
        out.stderr
    );
    let last = out.stdout.lines().last().unwrap_or("");
    serde_json::from_str(last).unwrap_or_else(|e| panic!("{e}: {}", out.stdout))
}

#[test]
fn opcua_client_browses_reads_subscribes_writes_and_calls() {
    let dir = TempDir::new("opcua");
    let (gw, url) = gateway(&dir, "[opcua]\nanonymous = true\n", &["--opcua-insecure"]);
    let v = client(&url, &["check"]);
    let slaves: Vec<&str> = v["slaves"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap())
        .collect();
    assert_eq!(slaves.len(), 4, "{v}");
    assert!(
        slaves.contains(&"3 echo") && slaves.contains(&"15 coupler"),
        "{v}"
    );
    assert_eq!(v["master"], "operate");
    assert_eq!(v["bk3000_state"], "data_exchange");
    // A scaled BK3000 channel: Double, with its unit as EUInformation.
    assert_eq!(v["bk3000_analog"]["type"], "Double", "{v}");
    assert_eq!(v["bk3000_analog"]["source_ts"], true);
    assert_eq!(v["bk3000_unit"]["display"], "V");
    assert_eq!(v["bk3000_unit"]["unit_id"], 0x564c54, "UNECE VLT");
    // The drive's actual value follows the setpoint written over OPC UA.
    let seen: Vec<i64> = (v["subscribed"].as_array().unwrap().iter())
        .filter_map(|x| x.as_i64())
        .collect();
    assert!(seen.contains(&1500) && seen.last() == Some(&1600), "{v}");
    // Absolute deadband 1000: no notification for a change below it.
    let banded: Vec<i64> = (v["deadband"].as_array().unwrap().iter())
        .filter_map(|x| x.as_i64())
        .collect();
    assert!(!banded.is_empty() && !banded.contains(&1600), "{v}");
    for w in banded.windows(2) {
        assert!((w[1] - w[0]).abs() > 1000, "deadband: {banded:?}");
    }
    // Not writable: slave 4 is not in `writable` (its outputs are not
    // even offered for writing); 25 only lets setpoint1 be written.
    assert_eq!(v["locked_access"], 1, "CurrentRead only");
    assert_eq!(v["refused_locked"], "BadUserAccessDenied", "{v}");
    assert_eq!(v["refused_control"], "BadUserAccessDenied", "{v}");
    // DP-V1 through the gateway core's MSAC_C1 jobs.
    assert_eq!(v["read_record"], "cafe");
    assert_eq!(v["ident_number"], 0x0dce, "{v}");
    assert_eq!(v["manufacturer"], "profibus-rs", "{v}");
    assert_eq!(v["echo_modules"], serde_json::json!(["0 2 words in/out"]));
    assert!(v["echo_stats"].as_u64().unwrap() > 0, "{v}");
    let out = gw.stop();
    assert!(!out.stderr.contains("panicked"), "{}", out.stderr);
}

#[test]
fn opcua_survives_a_client_killed_mid_subscription_and_50_clients() {
    let dir = TempDir::new("opcua-load");
    let (gw, url) = gateway(&dir, "[opcua]\nanonymous = true\n", &["--opcua-insecure"]);
    let mut cmd = Command::new(python());
    cmd.arg(script()).arg(&url).arg("hold");
    let mut holder = Proc::spawn_captured(cmd);
    let line = holder.stdout_line(T);
    assert_eq!(line.as_deref(), Some("subscribed"));
    holder.signal(9);
    holder.wait(T);
    let rss = |pid: u32| {
        let s = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
        let l = s
            .lines()
            .find(|l| l.starts_with("VmRSS:"))
            .unwrap()
            .to_string();
        l.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap()
    };
    let cpu = |pid: u32| {
        let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
        let f: Vec<&str> = s.rsplit_once(')').unwrap().1.split_whitespace().collect();
        f[11].parse::<u64>().unwrap() + f[12].parse::<u64>().unwrap()
    };
    let pid = gw.pid();
    let (rss0, cpu0, t0) = (rss(pid), cpu(pid), std::time::Instant::now());
    let v = client(&url, &["many", "50"]);
    assert_eq!(v["ok"], 50, "{v}");
    let (rss1, cpu1) = (rss(pid), cpu(pid));
    let ticks = 100.0; // USER_HZ on Linux
    eprintln!(
        "50 clients: RSS {rss0} -> {rss1} KiB, CPU {:.2} s in {:.2} s wall",
        (cpu1 - cpu0) as f64 / ticks,
        t0.elapsed().as_secs_f64()
    );
    // Still serving after all that.
    let v = client(&url, &["many", "1"]);
    assert_eq!(v["ok"], 1, "{v}");
    let out = gw.stop();
    assert!(!out.stderr.contains("panicked"), "{}", out.stderr);
}

/// A self-signed client certificate and its key for asyncua, made in
/// `dir`.
fn client_cert(dir: &TempDir) -> (PathBuf, PathBuf) {
    let cert = dir.path("client.der");
    let key = dir.path("client.pem");
    let gen = Command::new(python())
        .arg("-c")
        .arg(
            "import sys, asyncio\n\
             from asyncua.crypto.cert_gen import setup_self_signed_certificate\n\
             from cryptography.x509.oid import ExtendedKeyUsageOID\n\
             from pathlib import Path\n\
             asyncio.run(setup_self_signed_certificate(Path(sys.argv[2]), Path(sys.argv[1]), \
             'urn:profibus:dpctl:test-client', 'localhost', [ExtendedKeyUsageOID.CLIENT_AUTH], \
             {'countryName': 'DE', 'organizationName': 'test', 'commonName': 'test'}))",
        )
        .arg(&cert)
        .arg(&key)
        .status()
        .unwrap();
    assert!(gen.success(), "client certificate");
    (cert, key)
}

/// Under the default settings a client certificate the server does not
/// know is refused (and kept in `rejected/`); moved to `trusted/`, as
/// docs/opcua.md says, it is accepted without a
/// restart.
#[test]
fn opcua_refuses_an_untrusted_client_certificate_until_it_is_trusted() {
    let dir = TempDir::new("opcua-untrusted");
    let (cert, key) = client_cert(&dir);
    let (gw, url) = gateway(&dir, "[opcua]\nanonymous = true\n", &[]);
    let args = ["cert", cert.to_str().unwrap(), key.to_str().unwrap()];
    let v = client(&url, &args);
    assert_ne!(v["result"], "accepted", "{v}");
    let pki = dir.path("xdg/dpctl/opcua/pki");
    let rejected: Vec<PathBuf> = std::fs::read_dir(pki.join("rejected"))
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    assert_eq!(
        rejected.len(),
        1,
        "the refused certificate is kept: {rejected:?}"
    );
    let trusted = pki.join("trusted");
    std::fs::create_dir_all(&trusted).unwrap();
    let name = rejected[0].file_name().unwrap();
    std::fs::rename(&rejected[0], trusted.join(name)).unwrap();
    let v = client(&url, &args);
    assert_eq!(v["result"], "accepted", "{v}");
    let out = gw.stop();
    assert!(!out.stderr.contains("panicked"), "{}", out.stderr);
}

#[test]
fn opcua_default_security_takes_users_and_refuses_anonymous_and_none() {
    let dir = TempDir::new("opcua-secure");
    std::fs::write(dir.path("users"), "operator:s3cret\n").unwrap();
    // A client certificate of its own: the server trusts client
    // certificates only when told to (`trust_client_certs`).
    let (cert, key) = client_cert(&dir);
    let (gw, url) = gateway(
        &dir,
        "[opcua]\nusers_file = \"users\"\ntrust_client_certs = true\n",
        &[],
    );
    let v = client(
        &url,
        &[
            "secure",
            "operator",
            "s3cret",
            cert.to_str().unwrap(),
            key.to_str().unwrap(),
        ],
    );
    assert_eq!(v["master"], "operate", "{v}");
    assert_ne!(v["anonymous"], "accepted", "{v}");
    assert_ne!(v["no_security"], "accepted", "{v}");
    // The certificate made on first start, where docs/opcua.md says.
    assert!(dir.path("xdg/dpctl/opcua/pki/own/cert.der").is_file());
    assert!(dir
        .path("xdg/dpctl/opcua/pki/private/private.pem")
        .is_file());
    drop(gw);
}

#[test]
fn opcua_refuses_bad_settings_with_one_line() {
    let dir = TempDir::new("opcua-bad");
    for (table, args, want) in [
        (
            "[opcua]\nsecurity = [\"none\"]\nanonymous = true\n",
            vec![],
            "[opcua]: `security` `none` is only taken from the command line (--opcua-insecure)",
        ),
        (
            "[opcua]\n",
            vec![],
            "[opcua]: no way to log in: give `users_file` or `anonymous = true`",
        ),
        (
            "",
            vec!["--opcua", "http://x:1"],
            "OPC UA endpoint `http://x:1` is not opc.tcp://HOST[:PORT]",
        ),
    ] {
        let bus = write_bus(&dir, &format!("{}{MQTT}{table}", slaves()));
        let mut cmd = Command::new(dpctl());
        cmd.args(["gateway", "--sim", "--config"])
            .arg(&bus)
            .args(&args);
        let out = Proc::spawn_captured(cmd).finish(T);
        assert!(!out.status.success());
        assert!(out.stderr.contains(want), "{want}\n{}", out.stderr);
    }
}

/// A DP-V1 slave on `dpctl bus` (`dpctl slave` with the alarm GSD and an
/// I&M0 serial number) under `dpctl gateway --port --opcua`: its
/// identity shows I&M0 once it is in Data_Exchange, and a plug alarm it
/// raises reaches a client subscribed to the slave's events (and, once,
/// one subscribed to the Server object's) as a `DpAlarmEventType` event
/// with its fields.
#[test]
fn opcua_alarm_events_and_im0_identity_of_a_dpv1_slave() {
    let dir = TempDir::new("opcua-alarm");
    let line = common::Bus::start(2, &[]);
    let gsd = repo().join("crates/cli/tests/data/DPCTL_ALM.GSD");
    let mut slave = Proc::spawn(
        "dpctl slave 9",
        Command::new(dpctl())
            .args(["slave", "--port"])
            .arg(line.link(1))
            .args(["--addr", "9", "--baud", "1.5M", "--gsd"])
            .arg(&gsd)
            .args(["--module", "2 words in/out"])
            .args(["--device-opt", "serial_number=SN-4711"])
            .args(["--control", "-"])
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    let bus = dir.path("bus.toml");
    std::fs::write(
        &bus,
        format!(
            "[master]\naddress = 1\nbaud = \"1.5M\"\n[[slave]]\naddress = 9\nname = \"io\"\n\
             gsd = \"{}\"\nmodules = [\"2 words in/out\"]\n[mqtt]\nbus = \"line\"\n\
             [opcua]\nanonymous = true\n",
            gsd.display()
        ),
    )
    .unwrap();
    let port = free_port();
    let url = format!("opc.tcp://127.0.0.1:{port}");
    let mut cmd = Command::new(dpctl());
    cmd.arg("gateway")
        .arg("--config")
        .arg(&bus)
        .args(["--port", &line.link_str(0)])
        .args(["--opcua", &url, "--opcua-insecure"])
        .env("XDG_DATA_HOME", dir.path("xdg"));
    let mut gw = Proc::spawn_captured(cmd);
    common::wait_for("the OPC UA port", T, || {
        assert!(!gw.exited(), "dpctl gateway ended early");
        std::net::TcpStream::connect(("127.0.0.1", port)).is_ok()
    });
    let mut cmd = Command::new(python());
    cmd.arg(script()).arg(&url).args(["events", "9"]);
    let client = Proc::spawn_captured(cmd);
    if client.stdout_line(T).as_deref() != Some("subscribed") {
        let out = client.finish(T);
        panic!(
            "the client did not subscribe:\n{}\n{}",
            out.stdout, out.stderr
        );
    }
    common::send(&mut slave, "alarm plug 3 appears");
    let out = client.finish(T);
    assert!(out.status.success(), "{}\n{}", out.stdout, out.stderr);
    let v: serde_json::Value =
        serde_json::from_str(out.stdout.lines().last().unwrap_or("")).unwrap();
    // I&M0 in the identity (the GSD has no serial number).
    assert_eq!(v["serial_number"], "SN-4711", "{v}");
    assert_eq!(v["RevisionCounter"], 0, "{v}");
    assert_eq!(v["Manufacturer"], "profibus-rs", "the GSD's vendor: {v}");
    assert_eq!(v["event_notifier"], 1, "SubscribeToEvents: {v}");
    let e = &v["event"];
    assert_eq!(e["source_node"], v["slave_node"], "{v}");
    assert_eq!(e["source_name"], "9 io", "{v}");
    assert_eq!(e["alarm_type"], "plug", "{v}");
    assert_eq!(e["slot"], 3, "{v}");
    assert_eq!(e["specifier"], "appears", "{v}");
    assert_eq!(e["severity"], 400, "plug: {v}");
    assert_eq!(e["acknowledged"], true, "{v}");
    assert!(e["sequence_number"].as_u64().unwrap() < 32, "{v}");
    let msg = e["message"].as_str().unwrap();
    assert!(msg.contains("plug") && msg.contains("slot 3"), "{v}");
    assert!(e["event_type"]
        .as_str()
        .unwrap()
        .contains("DpAlarmEventType"));
    assert_eq!(v["server_events"], 1, "once on the Server object: {v}");
    let out = gw.stop();
    assert!(!out.stderr.contains("panicked"), "{}", out.stderr);
    slave.terminate(T);
}

/// Before: the Omega's `setpoint1` writable, `control1` not. Then the
/// bus file's `writable` names `control1` instead and the gateway gets
/// SIGHUP: access levels and writes follow. Returns the new bus text.
fn reload_writable_and_check(dir: &TempDir, gw: &Proc, url: &str) -> String {
    let before = client(url, &["access", "25", "setpoint1", "control1"]);
    assert_eq!(before["setpoint1"]["access_level"], 3, "{before}");
    assert_eq!(before["setpoint1"]["user_access_level"], 3, "{before}");
    assert_eq!(before["setpoint1"]["write"], "Good", "{before}");
    assert_eq!(before["control1"]["access_level"], 1, "{before}");
    assert_ne!(before["control1"]["write"], "Good", "{before}");
    let bus = dir.path("bus.toml");
    let text = std::fs::read_to_string(&bus)
        .unwrap()
        .replace(r#"channels = ["setpoint1"]"#, r#"channels = ["control1"]"#);
    assert!(text.contains(r#"channels = ["control1"]"#));
    std::fs::write(&bus, &text).unwrap();
    gw.signal(1);
    let mut after = serde_json::Value::Null;
    common::wait_for("the access levels after SIGHUP", T, || {
        after = client(url, &["access", "25", "setpoint1", "control1"]);
        after["control1"]["access_level"] == 3
    });
    assert_eq!(after["control1"]["user_access_level"], 3, "{after}");
    assert_eq!(after["control1"]["write"], "Good", "{after}");
    assert_eq!(after["setpoint1"]["access_level"], 1, "{after}");
    assert_eq!(after["setpoint1"]["user_access_level"], 1, "{after}");
    assert_ne!(after["setpoint1"]["write"], "Good", "{after}");
    text
}

/// SIGHUP with a changed `[mqtt] writable` (here beside MQTT, where the
/// gateway reloads): the access levels of the Omega's output variables
/// follow, and so do the writes.
#[test]
fn opcua_access_levels_follow_a_reload_of_writable() {
    let dir = TempDir::new("opcua-hup");
    let mqtt_port = free_port();
    let _mosq = common::mqtt::broker(&dir, mqtt_port);
    let (gw, url) = gateway(
        &dir,
        "[opcua]\nanonymous = true\n",
        &[
            "--opcua-insecure",
            "--mqtt",
            &format!("mqtt://127.0.0.1:{mqtt_port}"),
        ],
    );
    reload_writable_and_check(&dir, &gw, &url);
    let out = gw.stop();
    assert!(!out.stderr.contains("panicked"), "{}", out.stderr);
}

/// The same reload without a broker (`--opcua` alone): SIGHUP reads the
/// bus file again, a changed `[mqtt] writable` turns the Omega's
/// `control1` writable and `setpoint1` read-only, and the writes follow;
/// a changed `[opcua]` table is refused in one line (it needs a restart)
/// and the gateway runs on. Before, only a gateway with `--mqtt` reloaded.
#[test]
fn opcua_alone_reloads_writable_on_sighup() {
    let dir = TempDir::new("opcua-hup-alone");
    let (gw, url) = gateway(&dir, "[opcua]\nanonymous = true\n", &["--opcua-insecure"]);
    let text = reload_writable_and_check(&dir, &gw, &url);
    // `[opcua]` is the server's set-up: not taken while running.
    let bus = dir.path("bus.toml");
    std::fs::write(&bus, format!("{text}trust_client_certs = true\n")).unwrap();
    gw.signal(1);
    let mut refused = String::new();
    common::wait_for("the refused [opcua] reload", T, || {
        let line = gw.stderr_line(T).unwrap_or_default();
        let hit = line.contains("[opcua] only changes with a restart");
        if hit {
            refused = line;
        }
        hit
    });
    assert!(refused.contains("SIGHUP: not reloaded"), "{refused}");
    let still = client(&url, &["access", "25", "control1"]);
    assert_eq!(still["control1"]["access_level"], 3, "{still}");
    let out = gw.stop();
    assert!(!out.stderr.contains("panicked"), "{}", out.stderr);
    assert!(
        out.stderr.contains("reloaded [mqtt]: writable:"),
        "{}",
        out.stderr
    );
}
