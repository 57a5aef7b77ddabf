//! `dpctl gateway --sim` speaking MQTT 5 (`[mqtt] version = 5`) to a
//! real mosquitto: requests answered on their Response Topic with their
//! Correlation Data, units as user properties, message expiry on values
//! published without retain; Debian's `mosquitto_sub` / `mosquitto_pub`
//! with `-V mqttv5` as the clients. Fails (never skips) when mosquitto
//! is missing: run `scripts/setup-test-env`.

mod common;

use common::mqtt::{self, broker, free_port, write_bus, GATEWAY_SLAVES};
use common::{dpctl, Lines, Proc, TempDir};
use std::process::Command;
use std::time::{Duration, Instant};

const T: Duration = Duration::from_secs(30);

/// The output format of the subscriber: topic, correlation data, message
/// expiry interval, user properties, retain flag, payload; `|` between.
const FORMAT: &str = "%t|%D|%E|%P|%r|%p";

/// One message as [`FORMAT`] prints it.
#[derive(Debug)]
struct Msg {
    topic: String,
    correlation: String,
    expiry: Option<u32>,
    user: String,
    retained: bool,
    payload: serde_json::Value,
}

fn parse(line: &str) -> Option<Msg> {
    let mut f = line.splitn(6, '|');
    let (topic, correlation, expiry, user, retained, payload) = (
        f.next()?,
        f.next()?,
        f.next()?,
        f.next()?,
        f.next()?,
        f.next()?,
    );
    Some(Msg {
        topic: topic.into(),
        correlation: correlation.into(),
        expiry: expiry.parse().ok(),
        user: user.into(),
        retained: retained == "1",
        payload: serde_json::from_str(payload).ok()?,
    })
}

/// The first message (seen or to come) that `want` accepts.
fn expect(lines: &mut Lines, what: &str, want: impl Fn(&Msg) -> bool) -> Msg {
    let hit = |l: &str| parse(l).filter(|m| want(m));
    if let Some(m) = lines.1.iter().find_map(|l| hit(l)) {
        return m;
    }
    let end = Instant::now() + T;
    while let Some(l) = lines.next_line(end.saturating_duration_since(Instant::now())) {
        if let Some(m) = hit(&l) {
            return m;
        }
    }
    panic!("no message {what}; got:\n{}", lines.1.join("\n"));
}

/// `mosquitto_pub -V mqttv5` of `payload` to `topic` with `extra`
/// arguments (the properties).
fn publish5(port: u16, topic: &str, payload: &str, extra: &[&str]) {
    common::require("mosquitto_pub");
    let ok = Command::new("mosquitto_pub")
        .args(["-V", "mqttv5", "-h", "127.0.0.1", "-p", &port.to_string()])
        .args(["-q", "1", "-t", topic, "-m", payload])
        .args(extra)
        .status()
        .expect("mosquitto_pub")
        .success();
    assert!(ok, "mosquitto_pub to {topic} failed");
}

const BUS: &str = r#"
[[slave]]
address = 15
name = "coupler"
device = "bk3000"
terminals = ["KL1104", "KL2134", "KL3102", "KL4002", "KL9010"]

[mqtt]
prefix = "profibus"
bus = "line"
version = 5
writable = [3]
retain_values = false
message_expiry_s = 7
"#;

#[test]
fn mqtt5_answers_on_the_response_topic_with_the_correlation_data() {
    let dir = TempDir::new("gateway-mqtt5");
    let bus = write_bus(&dir, &format!("{GATEWAY_SLAVES}{BUS}"));
    let port = free_port();
    let url = format!("mqtt://127.0.0.1:{port}");
    let _mosq = broker(&dir, port);
    let mut gw = Proc::spawn("dpctl gateway", &mut mqtt::sim_gateway(&[], &bus, port));
    let mut log = Lines::from(&mut gw);
    let (_sub, mut lines) = mqtt::subscribe(
        port,
        &[
            "-V",
            "mqttv5",
            "-F",
            FORMAT,
            "-t",
            "profibus/line/#",
            "-t",
            "client/#",
        ],
        &[],
        "client/probe",
    );
    let connected = format!("connected to the MQTT broker {url} (MQTT 5, clean session)");
    assert!(
        log.wait_for(&connected, T),
        "no `{connected}`:\n{}",
        log.1.join("\n")
    );

    // A value message: the unit of the analog channel as a user
    // property, not retained (`retain_values = false`), expiring after
    // `message_expiry_s`.
    let strip = expect(&mut lines, "from the BK3000 with a unit", |m| {
        m.topic == "profibus/line/15/inputs" && m.user.contains("unit:")
    });
    assert!(strip.user.contains("unit:3.KL3102.1=V"), "{strip:?}");
    assert!(!strip.retained, "{strip:?}");
    assert!(
        strip.expiry.is_some_and(|e| (1..=7).contains(&e)),
        "{strip:?}"
    );
    // Retained topics never expire.
    let state = expect(&mut lines, "state of 3 in data exchange", |m| {
        m.topic == "profibus/line/3/state" && m.payload["state"] == "data_exchange"
    });
    assert_eq!(state.expiry, None, "{state:?}");

    // The issue's check: a request with Response Topic and Correlation
    // Data, no `id` or `reply_to` in the payload.
    publish5(
        port,
        "profibus/line/3/outputs/set",
        r#"{"hex": "12345678"}"#,
        &[
            "-D",
            "publish",
            "response-topic",
            "client/rt",
            "-D",
            "publish",
            "correlation-data",
            "cd-4711",
        ],
    );
    let a = expect(&mut lines, "on client/rt", |m| m.topic == "client/rt");
    assert_eq!(a.correlation, "cd-4711", "{a:?}");
    assert_eq!(a.payload["ok"], true, "{a:?}");
    assert!(a.payload.get("id").is_none(), "{a:?}");
    assert!(a.expiry.is_some(), "{a:?}");
    expect(&mut lines, "the echo's inputs", |m| {
        m.topic == "profibus/line/3/inputs" && m.payload["hex"] == "12345678"
    });
    // Refused (slave 4 is not writable): answered the same way.
    publish5(
        port,
        "profibus/line/4/outputs/set",
        r#"{"hex": "0102"}"#,
        &[
            "-D",
            "publish",
            "response-topic",
            "client/rt4",
            "-D",
            "publish",
            "correlation-data",
            "cd-4",
        ],
    );
    let a = expect(&mut lines, "on client/rt4", |m| m.topic == "client/rt4");
    assert_eq!(
        (a.correlation.as_str(), &a.payload["ok"]),
        ("cd-4", &false.into())
    );
    // A 3.1.1-style request (payload fields, no properties) as before.
    publish5(
        port,
        "profibus/line/3/outputs/set",
        r#"{"hex": "0a0b0c0d", "id": "w2"}"#,
        &[],
    );
    let a = expect(&mut lines, "on the response topic with w2", |m| {
        m.topic == "profibus/line/3/outputs/response" && m.payload["id"] == "w2"
    });
    assert_eq!(
        (a.correlation.as_str(), &a.payload["ok"]),
        ("", &true.into())
    );
    assert!(!gw.exited(), "the gateway stopped:\n{}", log.1.join("\n"));
}

#[test]
fn bad_versions_and_sparkplug_on_mqtt5_are_one_line_each() {
    let dir = TempDir::new("gateway-mqtt5-bad");
    for (table, args, want) in [
        (
            "version = 3",
            vec![],
            "[mqtt]: `version` must be 4 (MQTT 3.1.1, the default) or 5 (MQTT 5)",
        ),
        (
            "version = 5\nsparkplug = \"plant/edge\"",
            vec![],
            "[mqtt]: Sparkplug B needs MQTT 3.1.1 (`version = 4`, the default), not `version = 5`",
        ),
        (
            "",
            vec!["--mqtt-version", "5", "--sparkplug", "plant/edge"],
            "[mqtt]: Sparkplug B needs MQTT 3.1.1 (`version = 4`, the default), not `version = 5`",
        ),
        (
            "",
            vec!["--mqtt-version", "3"],
            "invalid value '3' for '--mqtt-version <4|5>': must be 4 (MQTT 3.1.1) or 5 (MQTT 5)",
        ),
    ] {
        let bus = write_bus(&dir, &mqtt::echo_bus_text(table));
        let mut cmd = Command::new(dpctl());
        cmd.args([
            "gateway",
            "--sim",
            "--mqtt",
            "mqtt://127.0.0.1:1",
            "--config",
        ])
        .arg(&bus)
        .args(&args);
        let out = Proc::spawn_captured(cmd).finish(T);
        assert!(!out.status.success(), "{table} {args:?}");
        let lines: Vec<&str> = out
            .stderr
            .lines()
            .filter(|l| !l.trim().is_empty())
            .collect();
        assert!(lines[0].contains(want), "{want}\n{}", out.stderr);
    }
}
