//! `dpctl gateway` on MQTT 5 against a real mosquitto: every message
//! carries the Content Type `application/json` and the Payload Format
//! Indicator 1, and a request whose Content Type is not JSON is refused
//! on its response topic (`mosquitto_pub -V mqttv5 -D publish
//! content-type …`). Fails (never skips) when mosquitto or its clients
//! are missing: run `scripts/setup-test-env`.

mod common;

use common::mqtt::{self, broker, free_port, write_bus, GATEWAY_SLAVES};
use common::{Lines, Proc, TempDir};
use std::process::Command;
use std::time::Duration;

const T: Duration = Duration::from_secs(30);

/// The next line (topic, content type, payload format, payload) on
/// `topic` whose payload contains `needle`.
fn expect(lines: &mut Lines, topic: &str, needle: &str) -> Vec<String> {
    let mut seen = 0;
    loop {
        while seen < lines.1.len() {
            let f: Vec<String> = lines.1[seen].splitn(4, '|').map(Into::into).collect();
            seen += 1;
            if f.len() == 4 && f[0] == topic && f[3].contains(needle) {
                return f;
            }
        }
        assert!(
            lines.next_line(T).is_some(),
            "nothing on {topic} with {needle}:\n{}",
            lines.1.join("\n")
        );
    }
}

fn publish5(port: u16, topic: &str, payload: &str, content_type: &str) {
    let ok = Command::new("mosquitto_pub")
        .args(["-V", "mqttv5", "-h", "127.0.0.1", "-p", &port.to_string()])
        .args(["-q", "1", "-t", topic, "-m", payload])
        .args(["-D", "publish", "response-topic", "client/ct"])
        .args(["-D", "publish", "content-type", content_type])
        .status()
        .expect("mosquitto_pub")
        .success();
    assert!(ok, "mosquitto_pub to {topic} failed");
}

#[test]
fn mqtt5_messages_are_json_and_requests_of_another_content_type_are_refused() {
    let dir = TempDir::new("gateway-mqtt5-ct");
    let mqtt = "\n[mqtt]\nbus = \"line\"\nversion = 5\nwritable = [3]\n";
    let bus = write_bus(&dir, &format!("{GATEWAY_SLAVES}{mqtt}"));
    let port = free_port();
    let _mosq = broker(&dir, port);
    let _gw = Proc::spawn("dpctl gateway", &mut mqtt::sim_gateway(&[], &bus, port));
    let (_sub, mut lines) = mqtt::subscribe(
        port,
        &[
            "-V",
            "mqttv5",
            "-F",
            "%t|%C|%F|%p",
            "-t",
            "profibus/line/#",
            "-t",
            "client/#",
        ],
        &[],
        "client/probe",
    );
    // Retained status and values: JSON, UTF-8.
    let status = expect(&mut lines, "profibus/line/status", "online");
    assert_eq!(
        (status[1].as_str(), status[2].as_str()),
        ("application/json", "1")
    );

    // text/plain: refused on the response topic, nothing written.
    let set = "profibus/line/3/outputs/set";
    publish5(port, set, r#"{"hex": "12345678"}"#, "text/plain");
    let a = expect(&mut lines, "client/ct", "content type");
    assert!(a[3].contains(r#""ok":false"#), "{a:?}");
    assert!(a[3].contains("`text/plain` is not JSON"), "{a:?}");
    assert_eq!(a[1], "application/json");
    // application/json; charset=utf-8: taken, the echo follows.
    publish5(
        port,
        set,
        r#"{"hex": "12345678"}"#,
        "application/json; charset=utf-8",
    );
    let a = expect(&mut lines, "client/ct", r#""ok":true"#);
    assert_eq!((a[1].as_str(), a[2].as_str()), ("application/json", "1"));
    let echo = expect(&mut lines, "profibus/line/3/inputs", "12345678");
    assert_eq!(
        (echo[1].as_str(), echo[2].as_str()),
        ("application/json", "1")
    );
}
