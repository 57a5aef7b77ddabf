//! The plain JSON core on the simulated plant of `dpctl gateway --sim`:
//! DP-V1, PKW and RFID requests answered by emulated slaves, decoded
//! images and diagnoses. No broker.

use profibus_devices::bus::ProfiledBus;
use profibus_dp::master::SlaveState;
use profibus_gateway::{slave_infos, Gateway, MqttSettings, WriteAccess};
use profibus_plant::Plant;

type Msgs = Vec<(String, serde_json::Value, bool)>;

fn drain(g: &mut Gateway) -> Msgs {
    std::iter::from_fn(|| g.poll_publish())
        .map(|p| {
            (
                p.topic,
                serde_json::from_slice(&p.payload).unwrap(),
                p.retain,
            )
        })
        .collect()
}

fn find<'a>(msgs: &'a Msgs, topic: &str) -> Option<&'a serde_json::Value> {
    msgs.iter().find(|(t, _, _)| t == topic).map(|(_, v, _)| v)
}

/// A simulated plant: a generic DP-V1 slave (3), an Omega drive with
/// PKW (25) and an RFID reader (30), all writable but the reader.
fn plant() -> (Gateway, Plant, ProfiledBus) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../devices/gsd/plant.toml");
    let text = "[master]\naddress = 1\nbaud = \"1.5M\"\n\n\
        [[slave]]\naddress = 3\ngsd = \"DPCTL_GEN.GSD\"\nmodules = [\"2 words in/out\"]\n\n\
        [[slave]]\naddress = 25\ndevice = \"omega\"\n\n\
        [[slave]]\naddress = 30\ndevice = \"rfid\"\n\n\
        [[slave]]\naddress = 40\ndevice = \"bk3000\"\nterminals = [\"KL3102\", \"KL9010\"]\n\n\
        [[slave]]\naddress = 26\ndevice = \"bm4\"\nexample = true\nvariables = [\"ud_MyReadVar1\"]\n\n\
        [mqtt]\nbus = \"p\"\nwritable = [3, 25]\n";
    let bus = ProfiledBus::parse(&dir, text).unwrap();
    let s = MqttSettings::from_table(bus.file.mqtt.as_ref(), "p").unwrap();
    let g = Gateway::new(s, slave_infos(&bus).unwrap());
    let plant = Plant::from_bus(&bus).unwrap();
    (g, plant, bus)
}

/// Run the plant 1 ms at a time until a message on `topic` (at most
/// 2 s of bus time).
fn run_until(g: &mut Gateway, p: &mut Plant, topic: &str) -> serde_json::Value {
    for _ in 0..2000 {
        let t = p.now() + std::time::Duration::from_millis(1);
        p.run_until(t);
        let ms = p.now().as_nanos() / 1_000_000;
        g.step(p.master(), t, ms);
        if let Some(v) = find(&drain(g), topic) {
            return v.clone();
        }
    }
    panic!("no message on {topic}");
}

#[test]
fn dpv1_pkw_and_rfid_requests_are_answered() {
    let (mut g, mut p, bus) = plant();
    g.connected(0);
    let mut seen = vec![];
    for _ in 0..2000 {
        let t = p.now() + std::time::Duration::from_millis(1);
        p.run_until(t);
        g.step(p.master(), t, 0);
        seen.extend(drain(&mut g));
        let m = p.master();
        if [3, 25, 26, 30, 40]
            .iter()
            .all(|&a| m.slave_state(a) == Some(SlaveState::DataExchange))
        {
            break;
        }
    }
    // Decoded values next to the hex: GSD module bytes of the generic
    // slave, the Omega's profile channels.
    let v = &find(&seen, "profibus/p/3/outputs").unwrap()["values"];
    assert_eq!(v["2 words in/out[0]"], 0, "{v}");
    let v = &find(&seen, "profibus/p/25/inputs").unwrap()["values"];
    assert!(v.get("status1").is_some() && v.get("pke").is_some(), "{v}");
    // Units where the profile scales a channel: the BK3000's KL3102
    // (±10 V); the diagnosis decoded by its standard bytes.
    let last = |topic: &str| {
        seen.iter()
            .rev()
            .find(|(t, _, _)| t == topic)
            .map(|(_, v, _)| v.clone())
            .unwrap()
    };
    let bk = last("profibus/p/40/inputs");
    assert_eq!(bk["units"]["1.KL3102.1"], "V", "{bk}");
    assert!(bk["values"]["1.KL3102.1"].is_f64(), "{bk}");
    let d = last("profibus/p/3/diag");
    assert_eq!(d["master"], 1, "{d}");
    assert_eq!(d["station_status"], "WD_On", "{d}");
    assert!(d["ident_number"].is_u64() && d["text"].is_array(), "{d}");
    // DP-V1: write a record, read it back.
    g.handle_message(
        "profibus/p/3/dpv1/request",
        br#"{"op": "write", "slot": 1, "index": 7, "hex": "cafe", "id": 1}"#,
        0,
    );
    let r = run_until(&mut g, &mut p, "profibus/p/3/dpv1/response");
    assert_eq!(
        (r["ok"].as_bool(), r["id"].as_i64()),
        (Some(true), Some(1)),
        "{r}"
    );
    g.handle_message(
        "profibus/p/3/dpv1/request",
        br#"{"op": "read", "slot": 1, "index": 7, "id": 2}"#,
        0,
    );
    let r = run_until(&mut g, &mut p, "profibus/p/3/dpv1/response");
    assert_eq!(r["hex"], "cafe", "{r}");
    g.handle_message(
        "profibus/p/3/dpv1/request",
        br#"{"op": "read", "slot": 1, "index": 99, "id": 3}"#,
        0,
    );
    let r = run_until(&mut g, &mut p, "profibus/p/3/dpv1/response");
    assert_eq!(r["ok"], false, "{r}");
    // PKW: two jobs queued at once run one after the other.
    g.handle_message(
        "profibus/p/25/pkw/request",
        br#"{"op": "write", "pnu": 1000, "value": 305419896, "id": "w"}"#,
        0,
    );
    g.handle_message(
        "profibus/p/25/pkw/request",
        br#"{"op": "read", "pnu": 1000, "id": "r", "reply_to": "me/pkw"}"#,
        0,
    );
    let r = run_until(&mut g, &mut p, "profibus/p/25/pkw/response");
    assert_eq!(
        (r["ok"].as_bool(), r["id"].as_str()),
        (Some(true), Some("w")),
        "{r}"
    );
    let r = run_until(&mut g, &mut p, "me/pkw");
    assert_eq!(r["value"], 0x1234_5678, "{r}");
    assert_eq!(r["response"], "23e8000012345678", "{r}");
    // PKW by name: a BM4 variable module of the GSD is its parameter
    // (`di_MyReadVar3`: PNU 4); an unknown name is refused.
    g.handle_message(
        "profibus/p/26/pkw/request",
        br#"{"op": "read", "pnu": "di_MyReadVar3", "id": "n"}"#,
        0,
    );
    let r = run_until(&mut g, &mut p, "profibus/p/26/pkw/response");
    assert_eq!(
        (r["ok"].as_bool(), r["id"].as_str()),
        (Some(true), Some("n")),
        "{r}"
    );
    assert_eq!(&r["request"].as_str().unwrap()[..4], "1004", "{r}");
    g.handle_message(
        "profibus/p/26/pkw/request",
        br#"{"op": "read", "pnu": "nope"}"#,
        0,
    );
    let r = run_until(&mut g, &mut p, "profibus/p/26/pkw/response");
    assert_eq!(r["error"], "slave 26 has no parameter named `nope`", "{r}");
    // RFID: the reader is not writable; a read-only request would be
    // answered, a command is refused.
    g.handle_message("profibus/p/30/rfid/request", br#"{"command": "VER"}"#, 0);
    let r = run_until(&mut g, &mut p, "profibus/p/30/rfid/response");
    assert!(r["error"].as_str().unwrap().contains("not writable"), "{r}");
    let mut s = g.settings().clone();
    s.writable.push(WriteAccess::full(30));
    let mut g = Gateway::new(s, slave_infos(&bus).unwrap());
    g.connected(0);
    g.handle_message(
        "profibus/p/30/rfid/request",
        br#"{"command": "VER", "id": 5}"#,
        0,
    );
    let r = run_until(&mut g, &mut p, "profibus/p/30/rfid/response");
    assert_eq!(r["ok"], true, "{r}");
    assert!(!r["answer"].as_str().unwrap().is_empty(), "{r}");
}
