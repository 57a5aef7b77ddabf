//! `dpctl gateway --sim` against a real MQTT broker: mosquitto started
//! on a free localhost port, Debian's `mosquitto_sub` / `mosquitto_pub`
//! as the clients. Fails (never skips) when mosquitto is missing: run
//! `scripts/setup-test-env`.

mod common;

use common::mqtt::{
    self, broker, broker_with, echo_bus_text, echo_slave, free_port, write_bus, GATEWAY_SLAVES,
};
use common::{dpctl, Lines, Proc, TempDir};
use std::process::Command;
use std::time::Duration;

const T: Duration = Duration::from_secs(30);

/// `mosquitto_sub -v` on the gateway's topics and `client/#` (answers
/// sent to a request's `reply_to`), subscribed when this returns, its
/// lines collected.
fn subscribe(port: u16) -> (Proc, Lines) {
    subscribe_with(port, &[])
}

/// [`subscribe`] with extra `mosquitto_sub` arguments (TLS, user).
fn subscribe_with(port: u16, auth: &[&str]) -> (Proc, Lines) {
    let topics = ["-v", "-t", "profibus/line/#", "-t", "client/#"];
    mqtt::subscribe(port, &topics, auth, "client/probe")
}

fn publish(port: u16, topic: &str, payload: &str) {
    publish_with(port, topic, payload, &[])
}

/// [`publish`] with extra `mosquitto_pub` arguments (TLS, user).
fn publish_with(port: u16, topic: &str, payload: &str, extra: &[&str]) {
    common::require("mosquitto_pub");
    let ok = Command::new("mosquitto_pub")
        .args([
            "-h",
            "127.0.0.1",
            "-p",
            &port.to_string(),
            "-q",
            "1",
            "-t",
            topic,
            "-m",
            payload,
        ])
        .args(extra)
        .status()
        .expect("mosquitto_pub")
        .success();
    assert!(ok, "mosquitto_pub to {topic} failed");
}

/// Wait for a line on `topic` whose payload contains every needle; the
/// payload as JSON.
fn expect(lines: &mut Lines, topic: &str, needles: &[&str]) -> serde_json::Value {
    let hit = |l: &str| {
        l.split_once(' ')
            .is_some_and(|(t, p)| t == topic && needles.iter().all(|n| p.contains(n)))
    };
    if let Some(l) = lines.1.iter().find(|l| hit(l)) {
        return serde_json::from_str(l.split_once(' ').unwrap().1).unwrap();
    }
    let end = std::time::Instant::now() + T;
    while let Some(l) = lines.next_line(end.saturating_duration_since(std::time::Instant::now())) {
        if hit(&l) {
            return serde_json::from_str(l.split_once(' ').unwrap().1).unwrap();
        }
    }
    panic!(
        "no message on {topic} with {needles:?}; got:\n{}",
        lines.1.join("\n")
    );
}

/// Slaves of profiles with named channels, after [`GATEWAY_SLAVES`]: a
/// BM4 module (the manual's example variables) and a BK3000 strip.
const PROFILED: &str = r#"
[[slave]]
address = 6
name = "plc"
device = "bm4"
example = true

[[slave]]
address = 15
name = "coupler"
device = "bk3000"
terminals = ["KL1104", "KL2134", "KL3102", "KL4002", "KL9010"]
"#;

/// The `[mqtt]` table of the bus file of [`GATEWAY_SLAVES`].
const MQTT: &str = r#"prefix = "profibus"
bus = "line"
writable = [3, { address = 25, channels = ["setpoint1"] }, { address = 15, channels = ["4.KL4002.1"] }]
outputs_timeout_ms = 300
safe_state = "zero"
"#;

#[test]
fn gateway_publishes_takes_writes_and_survives_a_broker_restart() {
    let dir = TempDir::new("gateway");
    let bus = write_bus(&dir, &format!("{GATEWAY_SLAVES}{PROFILED}\n[mqtt]\n{MQTT}"));
    let port = free_port();
    let mut mosq = broker(&dir, port);
    // The gateway's log (stderr) read as it comes: `exec` keeps the pid
    // for the signals.
    let mut gw = Proc::spawn("dpctl gateway", &mut mqtt::sim_gateway(&[], &bus, port));
    let mut log = Lines::from(&mut gw);

    // Every slave reaches Data_Exchange; a late subscriber gets the
    // retained status and states.
    let (sub0, mut early) = subscribe(port);
    for a in [3, 4, 6, 15, 25] {
        expect(
            &mut early,
            &format!("profibus/line/{a}/state"),
            &["data_exchange"],
        );
    }
    drop(sub0);
    let (_sub, mut lines) = subscribe(port);
    let status = expect(&mut lines, "profibus/line/status", &["online"]);
    assert_eq!(status["writable"], serde_json::json!([3, 25, 15]));
    let st = expect(&mut lines, "profibus/line/3/state", &["data_exchange"]);
    assert_eq!(st["name"], "echo");
    // The Omega drive's inputs decoded into its named channels.
    let omega = expect(&mut lines, "profibus/line/25/inputs", &["values"]);
    assert!(omega["values"].get("status1").is_some(), "{omega}");
    // The BM4 module's variables and the BK3000's terminal channels by
    // name, the analog ones with their unit.
    let plc = expect(&mut lines, "profibus/line/6/inputs", &["values"]);
    assert!(plc["values"].get("ud_MyReadVar1").is_some(), "{plc}");
    let strip = expect(&mut lines, "profibus/line/15/inputs", &["values"]);
    assert!(strip["values"].get("1.KL1104.2").is_some(), "{strip}");
    assert_eq!(strip["units"]["3.KL3102.1"], "V", "{strip}");

    // A write of the whole image: the echo slave's inputs follow it.
    publish(
        port,
        "profibus/line/3/outputs/set",
        r#"{"hex": "12345678", "id": "w1"}"#,
    );
    let r = expect(&mut lines, "profibus/line/3/outputs/response", &["w1"]);
    assert_eq!(r["ok"], true, "{r}");
    expect(&mut lines, "profibus/line/3/outputs", &["\"12345678\""]);
    expect(&mut lines, "profibus/line/3/inputs", &["\"12345678\""]);

    // Named channels of a profiled slave.
    publish(
        port,
        "profibus/line/25/outputs/set",
        r#"{"channels": {"setpoint1": 4321}, "id": 7}"#,
    );
    let r = expect(
        &mut lines,
        "profibus/line/25/outputs/response",
        &["\"id\":7"],
    );
    assert_eq!(r["ok"], true, "{r}");
    let o = expect(
        &mut lines,
        "profibus/line/25/outputs",
        &["\"setpoint1\":4321"],
    );
    assert!(o["hex"].as_str().unwrap().contains("10e1"), "{o}");

    // An analog output of the BK3000 strip by name, in volts.
    publish(
        port,
        "profibus/line/15/outputs/set",
        r#"{"channels": {"4.KL4002.1": 5.0}, "id": "kl"}"#,
    );
    let r = expect(&mut lines, "profibus/line/15/outputs/response", &["\"kl\""]);
    assert_eq!(r["ok"], true, "{r}");
    let o = expect(
        &mut lines,
        "profibus/line/15/outputs",
        &["\"4.KL4002.1\":5"],
    );
    assert_eq!(o["units"]["4.KL4002.1"], "V", "{o}");

    // A PKW job on the drive, answered on the topic the request names.
    publish(
        port,
        "profibus/line/25/pkw/request",
        r#"{"op": "read", "pnu": 126, "id": "p1", "reply_to": "client/7/pkw"}"#,
    );
    let r = expect(&mut lines, "client/7/pkw", &["\"p1\""]);
    assert_eq!(r["ok"], true, "{r}");

    // Refused: a slave not in `writable`, a malformed payload, a wrong
    // length, an unknown channel, a channel `writable` does not list, a
    // PKW write to a slave with channel access only. None changes
    // anything.
    publish(
        port,
        "profibus/line/4/outputs/set",
        r#"{"hex": "00000001", "id": "u"}"#,
    );
    let r = expect(&mut lines, "profibus/line/4/outputs/response", &["\"u\""]);
    assert_eq!(r["ok"], false);
    assert!(r["error"].as_str().unwrap().contains("not writable"), "{r}");
    publish(port, "profibus/line/3/outputs/set", "not hex");
    let r = expect(
        &mut lines,
        "profibus/line/3/outputs/response",
        &["malformed"],
    );
    assert_eq!(r["ok"], false);
    publish(
        port,
        "profibus/line/3/outputs/set",
        r#"{"hex": "0102", "id": "len"}"#,
    );
    let r = expect(&mut lines, "profibus/line/3/outputs/response", &["\"len\""]);
    assert!(
        r["error"].as_str().unwrap().contains("4 output bytes"),
        "{r}"
    );
    publish(
        port,
        "profibus/line/25/outputs/set",
        r#"{"channels": {"nope": 1}, "id": "ch"}"#,
    );
    let r = expect(&mut lines, "profibus/line/25/outputs/response", &["\"ch\""]);
    assert_eq!(r["ok"], false);
    // Not writable: the drive's input channels, and its PKW channel.
    for (topic, request, id) in [
        (
            "outputs/set",
            r#"{"channels": {"control1": 1}, "id": "cw"}"#,
            "cw",
        ),
        (
            "pkw/request",
            r#"{"op": "write", "pnu": 1000, "value": 1, "id": "pw"}"#,
            "pw",
        ),
    ] {
        publish(port, &format!("profibus/line/25/{topic}"), request);
        let service = topic.split('/').next().unwrap();
        let response = format!("profibus/line/25/{service}/response");
        let r = expect(&mut lines, &response, &[&format!("\"{id}\"")]);
        let error = r["error"].as_str().unwrap();
        assert!(error.contains("only the output channels"), "{r}");
    }
    // A later good write goes through; by then nothing of the refused
    // ones reached an image.
    publish(port, "profibus/line/3/outputs/set", "cafe0001");
    expect(&mut lines, "profibus/line/3/inputs", &["\"cafe0001\""]);
    for l in &lines.1 {
        assert!(
            !(l.starts_with("profibus/line/4/outputs ") && l.contains("00000001")),
            "{l}"
        );
        assert!(
            !(l.starts_with("profibus/line/3/outputs ") && l.contains("\"0102\"")),
            "{l}"
        );
    }

    // The broker dies: after `outputs_timeout_ms` the gateway zeroes
    // the outputs of the writable slaves (logged). It comes back: the
    // gateway reconnects, reports the safe state in its status and
    // publishes its retained topics again; the bus kept running (the
    // echo slave echoes the zeroed outputs, then answers writes).
    mosq.signal(9);
    mosq.wait(T);
    assert!(
        log.wait_for("outputs to the safe state", T),
        "no safe state in the log:\n{}",
        log.1.join("\n")
    );
    let _mosq = broker(&dir, port);
    let (_sub2, mut again) = subscribe(port);
    let st = expect(&mut again, "profibus/line/status", &["online"]);
    assert_eq!(st["outputs_timeout"]["safe_state"], "zero", "{st}");
    let st = expect(&mut again, "profibus/line/3/state", &["data_exchange"]);
    assert!(st["cycle"].as_u64().unwrap() > 0);
    expect(&mut again, "profibus/line/3/outputs", &["\"00000000\""]);
    expect(&mut again, "profibus/line/3/inputs", &["\"00000000\""]);
    publish(port, "profibus/line/3/outputs/set", "0badf00d");
    expect(&mut again, "profibus/line/3/inputs", &["\"0badf00d\""]);

    // SIGTERM: a clean stop that leaves the status offline.
    gw.signal(15);
    expect(&mut again, "profibus/line/status", &["offline"]);
    assert!(
        gw.wait(T).success(),
        "gateway failed:\n{}",
        log.rest().join("\n")
    );
}

/// The gateway as a master on a line: `dpctl bus` with a `dpctl slave`
/// process (a generic echo slave).
#[test]
fn gateway_on_a_line_with_a_slave_process() {
    let dir = TempDir::new("gateway-line");
    let port = free_port();
    let _mosq = broker(&dir, port);
    let line = common::Bus::start(2, &[]);
    let _slave = echo_slave(&line.link(1));
    let bus = write_bus(&dir, &echo_bus_text("bus = \"line\"\nwritable = [3]\n"));
    let (_sub, mut lines) = subscribe(port);
    let gw = Proc::spawn_captured({
        let mut c = Command::new(dpctl());
        c.arg("gateway")
            .arg("--config")
            .arg(&bus)
            .arg("--port")
            .arg(line.link(0))
            .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")]);
        c
    });
    expect(&mut lines, "profibus/line/3/state", &["data_exchange"]);
    publish(port, "profibus/line/3/outputs/set", "a5a50102");
    expect(&mut lines, "profibus/line/3/inputs", &["\"a5a50102\""]);
    // DP-V1 (MSAC_C1) over the line: write a record, read it back.
    let r = dpv1_on_a_line(
        port,
        &mut lines,
        r#""op": "write", "slot": 1, "index": 4, "hex": "0b0c0d""#,
        "dw",
    );
    assert_eq!(r["ok"], true, "{r}");
    let r = dpv1_on_a_line(
        port,
        &mut lines,
        r#""op": "read", "slot": 1, "index": 4"#,
        "dr",
    );
    assert_eq!(r["hex"], "0b0c0d", "{r}");
    // A malformed request is answered, and changes nothing.
    publish(
        port,
        "profibus/line/3/outputs/set",
        r#"{"hex": "zz", "id": "bad"}"#,
    );
    let r = expect(&mut lines, "profibus/line/3/outputs/response", &["\"bad\""]);
    assert!(r["error"].as_str().unwrap().contains("malformed"), "{r}");
    gw.signal(15);
    expect(&mut lines, "profibus/line/status", &["offline"]);
    let out = gw.finish(T);
    assert!(out.status.success(), "gateway failed: {}", out.stderr);
}

/// The DP-V1 request `fields` (JSON members without the id) to slave 3
/// of the line, and its answer. A request that failed on the line itself
/// ("no response", "timeout", the slave out of Data_Exchange for a
/// moment: a station process descheduled past the slot time on a loaded
/// machine) is sent again once the slave is back in Data_Exchange, as a
/// client would, at most four times, each with its own id (`id-1`, …);
/// any other answer is returned as it is.
fn dpv1_on_a_line(port: u16, lines: &mut Lines, fields: &str, id: &str) -> serde_json::Value {
    let transient = ["no response", "timeout", "not in data exchange"];
    let mut answers = vec![];
    for attempt in 1..=4 {
        let id = format!("{id}-{attempt}");
        publish(
            port,
            "profibus/line/3/dpv1/request",
            &format!(r#"{{{fields}, "id": "{id}"}}"#),
        );
        let r = expect(
            lines,
            "profibus/line/3/dpv1/response",
            &[&format!("\"{id}\"")],
        );
        let error = r["error"].as_str().unwrap_or_default();
        if r["ok"] == true || !transient.iter().any(|t| error.contains(t)) {
            return r;
        }
        eprintln!("DP-V1 request {id} failed on the line ({error}); sent again");
        answers.push(r);
        // The newest state, not any earlier one, must be Data_Exchange.
        let end = std::time::Instant::now() + T;
        let in_dx = |l: &String| l.contains("data_exchange");
        while !lines
            .1
            .iter()
            .rev()
            .find(|l| l.starts_with("profibus/line/3/state "))
            .is_some_and(in_dx)
        {
            let left = end.saturating_duration_since(std::time::Instant::now());
            assert!(
                lines.next_line(left).is_some(),
                "slave 3 not back in Data_Exchange"
            );
        }
    }
    panic!("DP-V1 request failed four times on the line: {answers:?}");
}

/// Run `program` with `args` in `dir`; it must succeed.
fn run_in(dir: &TempDir, program: &str, args: &[&str]) {
    common::require(program);
    let out = Command::new(program)
        .args(args)
        .current_dir(&dir.0)
        .output()
        .unwrap_or_else(|e| panic!("{program}: {e}"));
    assert!(
        out.status.success(),
        "{program} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `mqtts://` with a CA made here (openssl), a server certificate for
/// 127.0.0.1 and a password file: the gateway connects with the
/// bus file's `ca_file`, `username` and `password_file`, publishes and
/// takes a write; a client without the password sees nothing.
#[test]
fn gateway_over_tls_with_a_password() {
    let dir = TempDir::new("gateway-tls");
    // A new P-256 key and a request for it (with -x509: a certificate).
    let new_key = [
        "req",
        "-newkey",
        "ec",
        "-pkeyopt",
        "ec_paramgen_curve:prime256v1",
        "-nodes",
    ];
    let ca = ["-x509", "-keyout", "ca.key", "-out", "ca.crt", "-days", "2"];
    let ca = [&new_key[..], &ca, &["-subj", "/CN=dpctl test CA"]].concat();
    run_in(&dir, "openssl", &ca);
    let server = [
        "-keyout",
        "server.key",
        "-out",
        "server.csr",
        "-subj",
        "/CN=127.0.0.1",
    ];
    run_in(&dir, "openssl", &[&new_key[..], &server].concat());
    std::fs::write(
        dir.path("ext.cnf"),
        "subjectAltName=IP:127.0.0.1,DNS:localhost\nbasicConstraints=CA:FALSE\n",
    )
    .unwrap();
    run_in(
        &dir,
        "openssl",
        &[
            "x509",
            "-req",
            "-in",
            "server.csr",
            "-CA",
            "ca.crt",
            "-CAkey",
            "ca.key",
            "-CAcreateserial",
            "-out",
            "server.crt",
            "-days",
            "2",
            "-extfile",
            "ext.cnf",
        ],
    );
    run_in(
        &dir,
        "mosquitto_passwd",
        &["-b", "-c", "passwd", "gw", "s3cret"],
    );
    for f in ["ca.crt", "server.crt", "server.key", "passwd"] {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(dir.path(f), std::fs::Permissions::from_mode(0o644)).unwrap();
    }
    let port = free_port();
    let conf = dir.path("mosquitto.conf");
    std::fs::write(
        &conf,
        format!(
            "listener {port} 127.0.0.1\ncafile {d}/ca.crt\ncertfile {d}/server.crt\nkeyfile {d}/server.key\nallow_anonymous false\npassword_file {d}/passwd\npersistence false\n",
            d = dir.0.display()
        ),
    )
    .unwrap();
    let _mosq = broker_with(&conf, port);
    std::fs::write(dir.path("pw.txt"), "s3cret\n").unwrap();
    let mqtt = "bus = \"line\"\nwritable = [3]\nusername = \"gw\"\npassword_file = \"pw.txt\"\nca_file = \"ca.crt\"\n";
    let bus = write_bus(&dir, &echo_bus_text(mqtt));
    let ca = dir.path("ca.crt");
    let ca = ca.to_str().unwrap();
    let tls = ["--cafile", ca, "-u", "gw", "-P", "s3cret"];
    let (_sub, mut lines) = subscribe_with(port, &tls);
    let gw = Proc::spawn_captured({
        let mut c = Command::new(dpctl());
        c.arg("gateway")
            .arg("--config")
            .arg(&bus)
            .arg("--sim")
            .args(["--mqtt", &format!("mqtts://127.0.0.1:{port}")]);
        c
    });
    expect(&mut lines, "profibus/line/status", &["online"]);
    expect(&mut lines, "profibus/line/3/state", &["data_exchange"]);
    publish_with(port, "profibus/line/3/outputs/set", "5aa50102", &tls);
    expect(&mut lines, "profibus/line/3/inputs", &["\"5aa50102\""]);
    // Without the password the broker refuses the client.
    let refused = Command::new("mosquitto_pub")
        .args(["-h", "127.0.0.1", "-p", &port.to_string(), "--cafile", ca])
        .args([
            "-u",
            "gw",
            "-P",
            "wrong",
            "-t",
            "profibus/line/3/outputs/set",
            "-m",
            "00000000",
        ])
        .output()
        .unwrap();
    assert!(!refused.status.success(), "a wrong password was taken");
    gw.signal(15);
    expect(&mut lines, "profibus/line/status", &["offline"]);
    let out = gw.finish(T);
    assert!(out.status.success(), "gateway failed: {}", out.stderr);
}

/// The gateway's own log at the default level: one line at the start,
/// one on connecting and one on reconnecting after the broker came back
/// (each with the broker's URL), one for the loss; SIGTERM ends it
/// within a bound and logs no loss of the connection it closes.
#[test]
fn gateway_logs_its_connections_and_stops_promptly_on_sigterm() {
    let dir = TempDir::new("gateway-log");
    let bus = write_bus(&dir, &echo_bus_text(""));
    let port = free_port();
    let url = format!("mqtt://127.0.0.1:{port}");
    let mut mosq = broker(&dir, port);
    let mut gw = Proc::spawn(
        "dpctl gateway",
        mqtt::sim_gateway(&[], &bus, port).env_remove("NO_COLOR"),
    );
    let mut log = Lines::from(&mut gw);
    let seen = |log: &mut Lines, what: &str| {
        assert!(
            log.wait_for(what, T),
            "no `{what}` in the log:\n{}",
            log.1.join("\n")
        );
    };
    seen(&mut log, &format!("MQTT gateway starting: broker {url}"));
    seen(&mut log, &format!("connected to the MQTT broker {url}"));
    // The broker goes away and comes back.
    mosq.signal(9);
    mosq.wait(T);
    seen(&mut log, &format!("MQTT connection to {url} lost"));
    let _mosq = broker(&dir, port);
    seen(&mut log, &format!("reconnected to the MQTT broker {url}"));

    gw.signal(15);
    let status = gw.wait(Duration::from_secs(10));
    let lines = log.rest().to_vec();
    assert!(status.success(), "{status}:\n{}", lines.join("\n"));
    let count = |needle: &str| lines.iter().filter(|l| l.contains(needle)).count();
    for (needle, n) in [
        ("MQTT gateway starting", 1),
        ("connected to the MQTT broker", 2),
        ("reconnected to the MQTT broker", 1),
        ("lost", 1),
    ] {
        assert_eq!(count(needle), n, "`{needle}`:\n{}", lines.join("\n"));
    }
    assert!(
        !lines.iter().any(|l| l.contains('\x1b')),
        "colour codes in a pipe:\n{}",
        lines.join("\n")
    );
}

/// The `ts` of every message on `topic` in `lines` so far, once there
/// are `n` of them.
fn wait_ts(lines: &mut Lines, topic: &str, n: usize) -> Vec<u64> {
    let ts = |lines: &Lines| -> Vec<u64> {
        (lines.1.iter())
            .filter_map(|l| l.split_once(' ').filter(|(t, _)| *t == topic))
            .map(|(_, p)| {
                serde_json::from_str::<serde_json::Value>(p).unwrap()["ts"]
                    .as_u64()
                    .unwrap()
            })
            .collect()
    };
    let end = std::time::Instant::now() + T;
    while ts(lines).len() < n {
        if lines
            .next_line(end.saturating_duration_since(std::time::Instant::now()))
            .is_none()
        {
            panic!("only {} messages on {topic}", ts(lines).len());
        }
    }
    ts(lines)
}

/// A BK3000 with four analog inputs (the simulation's sine waves change
/// in every cycle) through a real broker: with the defaults its inputs
/// come at most every 250 ms (4/s, not 1 000/s); with `[[mqtt.slave]]
/// min_interval_ms = 600` at most every 600 ms.
#[test]
fn gateway_bounds_the_messages_of_a_noisy_analog_slave() {
    for (extra, min) in [
        ("", 250),
        ("[[mqtt.slave]]\naddress = 40\nmin_interval_ms = 600\n", 600),
    ] {
        let dir = TempDir::new("gateway-traffic");
        let bus = write_bus(
            &dir,
            &format!(
                "[master]\naddress = 1\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 40\ndevice = \"bk3000\"\n\
                 terminals = [\"KL3102\", \"KL3102\", \"KL9010\"]\n\n[mqtt]\nbus = \"line\"\n{extra}"
            ),
        );
        let port = free_port();
        let _mosq = broker(&dir, port);
        let (_sub, mut lines) = subscribe(port);
        let mut c = Command::new(dpctl());
        c.args(["gateway", "--sim", "--config"])
            .arg(&bus)
            .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")]);
        let _gw = Proc::spawn_captured(c);
        let topic = "profibus/line/40/inputs";
        let ts = wait_ts(&mut lines, topic, 6);
        // After the first (the slave's start-up image), never closer than
        // the minimum interval: the payload's `ts` is the publish time.
        let gaps: Vec<u64> = ts.windows(2).skip(1).map(|w| w[1] - w[0]).collect();
        assert!(gaps.iter().all(|g| *g >= min), "{min} ms: {gaps:?}");
        // ... and the values keep coming: the sine moves more than the
        // deadband (0.2 V) in every interval.
        assert!(gaps.iter().all(|g| *g < 4 * min), "{min} ms: {gaps:?}");
    }
}
