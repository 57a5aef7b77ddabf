//! `dpctl demo` and `dpctl decode` as a user runs them.

use serde_json::Value;
mod common;

use common::run_dpctl as dpctl;

#[test]
fn demo_brings_every_slave_to_data_exchange_and_data_moves() {
    let o = dpctl(&["demo", "--fast", "--cycles", "3000", "--json"]);
    assert!(o.status.success(), "{}", o.stderr);
    let lines: Vec<Value> = o
        .stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect();
    let status = lines
        .iter()
        .rev()
        .find(|v| v["event"] == "status")
        .expect("a status line");
    assert!(status["cycles"].as_u64().unwrap() >= 500);
    for s in status["slaves"].as_array().unwrap() {
        assert_eq!(s["state"], "data_exchange", "{s}");
        assert_eq!(s["errors"], 0);
    }
    // The echo slave returns the master's outputs.
    let echo = &status["slaves"][0];
    let out = echo["outputs"].as_str().unwrap();
    assert!(echo["inputs"].as_str().unwrap().starts_with(out));
    assert_ne!(out, "00 00 00 00", "the demo application writes outputs");
    // The counter slave counts.
    let counter = &status["slaves"][1];
    assert_ne!(counter["inputs"], "00 00 00 00");
    // The parameter channels of the BM4 PLC module and the Omega drive:
    // the manual's example value di_MyReadVar3 = 3000, written values read
    // back.
    let pkw: Vec<&Value> = lines.iter().filter(|v| v["event"] == "pkw").collect();
    assert!(
        pkw.iter()
            .any(|v| v["name"] == "di_MyReadVar3" && v["value"] == 3000),
        "{pkw:?}"
    );
    assert!(pkw.iter().any(|v| v["slave"] == 25 && v["name"] == "P003"));
    assert!(pkw.iter().all(|v| v["error"].is_null()), "{pkw:?}");
    // The RFID reader: the manual's VER answer; its tag comes and goes, so
    // GT reads the UID and, with the tag away, the no-read code.
    let rfid: Vec<&Value> = lines.iter().filter(|v| v["event"] == "rfid").collect();
    assert!(rfid
        .iter()
        .any(|v| v["command"] == "VER"
            && v["answer"] == "AEG ID - PFB V1.26\rAEG ID - A9 /PFB V1.28\r"));
    for answer in ["E004015012345678\r", "XXXXXXXX\r"] {
        assert!(
            rfid.iter()
                .any(|v| v["command"] == "GT" && v["answer"] == answer),
            "{rfid:?}"
        );
    }
    assert!(rfid.iter().all(|v| v["error"].is_null()), "{rfid:?}");
    // The JX2-PROFI1's PLC program: input word 0 counts, word 1 echoes
    // output word 0.
    let jx2 = status["slaves"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["address"] == 7)
        .expect("the JX2-PROFI1");
    let (i, o) = (
        jx2["inputs"].as_str().unwrap(),
        jx2["outputs"].as_str().unwrap(),
    );
    assert_ne!(&i[..5], "00 00", "{jx2}");
    assert_ne!(&o[..5], "00 00", "{jx2}");
    let summary = lines.last().unwrap();
    assert_eq!(summary["event"], "summary");
    assert!(summary["telegrams"].as_u64().unwrap() > 1000);
}

/// `dpctl decode --json TELEGRAMS…`: it succeeds, every line is JSON.
fn decode_json(telegrams: &[&str]) -> Vec<Value> {
    let o = dpctl(&[&["decode", "--json"], telegrams].concat());
    assert!(o.status.success());
    o.stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn decode_reports_malformed_telegrams_with_exit_1() {
    let o = dpctl(&["decode", "10", "02", "08", "00", "0B", "16"]);
    assert_eq!(o.status.code(), Some(1));
    let err = o.stderr;
    assert!(err.contains("FCS mismatch"), "{err}");
    let v = decode_json(&["10 02 08 00 0A 16", "E5"]);
    assert_eq!(v[0]["status"], "OK");
    assert_eq!(v[0]["sa"], 8);
    assert_eq!(v[1]["type"], "short_ack");
    let o = dpctl(&["decode"]);
    assert_eq!(o.status.code(), Some(2), "usage error");
}

#[test]
fn decode_shows_the_start_delimiter_received() {
    // The same 6-byte Slave_Diag answer as SD2 (as real devices send it)
    // and as SD3: each is labelled as received.
    let v = decode_json(&[
        "680b0b68828b083e3c020900ff002bc416",
        "a2828b083e3c020900ff002bc416",
    ]);
    assert_eq!(v[0]["format"], "SD2");
    assert_eq!(v[1]["format"], "SD3");
    assert_eq!(v[0]["data"], v[1]["data"]);
    let o = dpctl(&["decode", "680b0b68828b083e3c020900ff002bc416"]);
    let text = o.stdout;
    assert!(text.starts_with("SD2 "), "{text}");
}
