//! `dpctl decode` of FMS telegrams (issue 35): telegrams written by hand
//! from the encodings of docs/fms.md (not by our encoder) print the FDL
//! header and the LLI/FMS meaning like `dpctl sniff`; and every telegram
//! of a real FMS exchange heard by `dpctl sniff` decodes to the very same
//! text and JSON.

mod common;
mod fms_capture;

use common::run_dpctl;
use serde_json::Value;

/// Read.req, invoke ID 3, index 2020, from station 3 (SSAP 41) to the
/// server 5 (DSAP 40), SRD low: SD2 with both SAPs (address bit 7 set),
/// data unit = PDU type 1 (confirmed request), invoke ID, service 2
/// (Read), index big-endian.
const READ_REQ: &str = "68 0A 0A 68 85 83 4C 28 29 01 03 02 07 E4 96 16";
/// Its answer: PDU type 2 (confirmed response), invoke ID 3, service 2,
/// the value 00 CB 03 (status byte, then the word).
const READ_RES: &str = "68 0B 0B 68 83 85 08 29 28 02 03 02 00 CB 03 36 16";
/// An empty SRD on the connection (the client polls for the answer).
const POLL: &str = "68 05 05 68 85 83 4C 28 29 A5 16";
/// LLI Abort (0x12), reason 0 (user), detail 0.
const ABORT: &str = "68 08 08 68 85 83 4C 28 29 12 00 00 B7 16";

fn decode(args: &[&str]) -> Vec<String> {
    let mut all = vec!["decode"];
    all.extend_from_slice(args);
    let out = run_dpctl(&all);
    assert!(out.status.success(), "{out:?}");
    out.stdout.lines().map(str::to_string).collect()
}

#[test]
fn hand_written_fms_telegrams_decode_to_their_meaning() {
    let lines = decode(&[READ_REQ, READ_RES, POLL, "E5", ABORT]);
    assert_eq!(
        lines,
        [
            "SD2 3→5 SRD_low DSAP=40 (FMS) SSAP=41 DU[5]=01 03 02 07 E4 FCS ok | FMS Read.req invoke 3 index 2020",
            "SD2 5→3 DL (passive) DSAP=41 SSAP=40 (FMS) DU[6]=02 03 02 00 CB 03 FCS ok | FMS Read.resp invoke 3 data 00 CB 03",
            "SD2 3→5 SRD_low DSAP=40 (FMS) SSAP=41 FCS ok | LLI poll",
            "SC short acknowledge | LLI no data",
            "SD2 3→5 SRD_low DSAP=40 (FMS) SSAP=41 DU[3]=12 00 00 FCS ok | LLI Abort reason 0 detail 0: released by the user",
        ]
    );
    let json: Vec<Value> = decode(&["--json", READ_REQ, READ_RES, ABORT])
        .iter()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(json.len(), 3);
    for j in &json {
        assert_eq!(j["service_sap"], "FMS", "{j}");
    }
    assert_eq!(
        json[0]["fms"],
        serde_json::json!({"lli": "data", "pdu": "read_req", "service": "Read", "invoke_id": 3, "index": 2020})
    );
    assert_eq!(
        json[1]["fms"],
        serde_json::json!({"lli": "data", "pdu": "read_resp", "service": "Read", "invoke_id": 3, "data": "00 CB 03"})
    );
    assert_eq!(
        json[2]["fms"],
        serde_json::json!({"lli": "abort", "reason": 0, "detail": 0, "error": "released by the user"})
    );
    // Alone, an empty SRD on SAP 40 is no FMS (no connection seen), and
    // DP telegrams print as before.
    assert_eq!(
        decode(&[POLL]),
        ["SD2 3→5 SRD_low DSAP=40 (MSAC_C2) SSAP=41 FCS ok"]
    );
    assert_eq!(
        decode(&["10 02 08 00 0A 16"]),
        ["SD1 8→2 OK (passive) FCS ok"]
    );
    let dp: Value = serde_json::from_str(&decode(&["--json", "10 02 08 00 0A 16"])[0]).unwrap();
    assert!(dp.get("fms").is_none(), "{dp}");
    // A garbled FMS PDU is flagged, never a panic: Read.req cut after
    // the service octet (FCS 0xAB).
    let cut = decode(&["68 08 08 68 85 83 4C 28 29 01 03 02 AB 16"]);
    assert_eq!(cut.len(), 1);
    assert!(cut[0].contains("| FMS malformed: "), "{cut:?}");
}

#[test]
fn every_telegram_of_a_sniffed_fms_exchange_decodes_like_the_sniffer() {
    let cap = fms_capture::record();
    let heard: Vec<&Value> = cap.json.iter().filter(|l| l.get("raw").is_some()).collect();
    let raws: Vec<&str> = heard.iter().map(|l| l["raw"].as_str().unwrap()).collect();
    let mut args = vec!["--json"];
    args.extend(&raws);
    let decoded: Vec<Value> = decode(&args)
        .iter()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(decoded.len(), heard.len());
    let mut fms = 0;
    for (s, d) in heard.iter().zip(&decoded) {
        // Sniff's line without its time and DP layer is decode's line.
        let mut s = (*s).clone();
        let o = s.as_object_mut().unwrap();
        o.remove("t_us");
        o.remove("dp");
        assert_eq!(&s, d);
        fms += usize::from(d.get("fms").is_some());
    }
    assert!(fms >= 15, "{decoded:#?}");
    // The text lines: sniff's `TIME TELEGRAM | FMS …` without the time.
    let sniffed: Vec<&str> = cap
        .plain
        .iter()
        .filter_map(|l| l.trim_start().split_once(' ').map(|(_, rest)| rest))
        .filter(|l| l.contains("| FMS") || l.contains("| LLI"))
        .collect();
    let lines = decode(&raws);
    let ours: Vec<&str> = lines
        .iter()
        .map(String::as_str)
        .filter(|l| l.contains("| FMS") || l.contains("| LLI"))
        .collect();
    assert_eq!(ours, sniffed);
    assert!(ours.len() >= 15, "{ours:#?}");
}
