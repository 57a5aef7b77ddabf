//! `dpctl sniff` decodes FMS (issue 35): an FMS client talks to a
//! `dpctl slave --device bk3000 --device-opt fms=mixed` on a `dpctl bus`
//! (fms_capture/mod.rs) and the sniffer's `--json` lines carry each
//! telegram's LLI and FMS PDUs in `"fms"`, its plain lines say them in
//! words. Needs nothing beyond dpctl.

mod common;
mod fms_capture;

use fms_capture::{CLIENT, CLIENT_LSAP, SERVER, SERVER_LSAP};
use serde_json::Value;

/// The `"fms"` objects of the telegrams of the connection, in order, with
/// each telegram's direction (`request`/`response`).
fn fms_objects(json: &[Value]) -> Vec<(String, Value)> {
    json.iter()
        .filter_map(|l| {
            let fms = l.get("fms")?.clone();
            let kind = l["type"].as_str().unwrap_or("").to_string();
            let (client, server) = if kind == "request" {
                (l["sa"].as_u64(), l["da"].as_u64())
            } else {
                (l["da"].as_u64(), l["sa"].as_u64())
            };
            assert_eq!(
                (client, server),
                (Some(CLIENT.into()), Some(SERVER.into())),
                "{l}"
            );
            if kind == "request" {
                assert_eq!(l["dsap"], SERVER_LSAP, "{l}");
                assert_eq!(l["ssap"], CLIENT_LSAP, "{l}");
            }
            assert_eq!(l["service_sap"], "FMS", "{l}");
            assert!(
                l.get("dp").is_none(),
                "an FMS telegram has no DP layer: {l}"
            );
            Some((kind, fms))
        })
        .collect()
}

fn find<'a>(objects: &'a [(String, Value)], kind: &str, pdu: &str) -> &'a Value {
    objects
        .iter()
        .find(|(k, o)| k == kind && o["pdu"] == pdu)
        .map(|(_, o)| o)
        .unwrap_or_else(|| panic!("no {kind} {pdu} in {objects:#?}"))
}

#[test]
fn sniff_decodes_an_fms_exchange_with_a_bk3000() {
    let cap = fms_capture::record();
    let objects = fms_objects(&cap.json);

    let a = find(&objects, "request", "initiate_req");
    assert_eq!(
        (&a["lli"], &a["monitoring_ms"]),
        (&"associate".into(), &2000.into())
    );
    assert_eq!(a["max_pdu"], serde_json::json!([0, 241, 0, 241]));
    let a = find(&objects, "response", "initiate_resp");
    assert_eq!(a["lli"], "associate_res");

    let i = find(&objects, "response", "identify_resp");
    assert_eq!(
        (&i["invoke_id"], &i["vendor"]),
        (&1.into(), &"Beckhoff".into())
    );
    assert_eq!(i["model"], "BK3000");

    let r = find(&objects, "request", "read_req");
    assert_eq!((&r["invoke_id"], &r["index"]), (&2.into(), &2020.into()));
    assert_eq!((&r["lli"], &r["service"]), (&"data".into(), &"Read".into()));
    let r = find(&objects, "response", "read_resp");
    assert_eq!(r["invoke_id"], 2);
    // KL3102 channel 1: status byte and a 16-bit value.
    assert_eq!(r["data"].as_str().unwrap().split(' ').count(), 3, "{r}");

    let w = find(&objects, "request", "write_req");
    assert_eq!(
        (&w["invoke_id"], &w["index"], &w["data"]),
        (&3.into(), &2041.into(), &"00 20 00".into())
    );
    assert_eq!(find(&objects, "response", "write_resp")["invoke_id"], 3);

    let e = find(&objects, "response", "error");
    assert_eq!(
        (&e["invoke_id"], &e["service"]),
        (&4.into(), &"Read".into())
    );
    assert_eq!(e["error"], "object does not exist");
    assert!(e["error_class"].is_u64() && e["error_code"].is_u64(), "{e}");

    let g = find(&objects, "request", "get_od_req");
    assert_eq!(
        (&g["index"], &g["long_form"], &g["from_index"]),
        (&2020.into(), &false.into(), &false.into())
    );
    let g = find(&objects, "response", "get_od_resp");
    assert_eq!(g["descriptions"].as_array().map(Vec::len), Some(1), "{g}");

    // The garbled request is flagged, and the server's Reject decoded.
    let bad = objects
        .iter()
        .find(|(k, o)| k == "request" && o["lli"] == "malformed")
        .expect("the garbled request");
    assert_eq!(
        bad.1["error"],
        "unknown FMS service 9 in a confirmed request PDU"
    );
    let rej = find(&objects, "response", "reject");
    assert_eq!(
        (&rej["original_invoke_id"], &rej["rejected_pdu_type"]),
        (&0.into(), &1.into())
    );

    assert!(objects
        .iter()
        .any(|(k, o)| k == "request" && o["lli"] == "poll"));
    let abort = objects
        .iter()
        .find(|(_, o)| o["lli"] == "abort")
        .expect("the Abort");
    assert_eq!(
        (&abort.1["reason"], &abort.1["error"]),
        (&0.into(), &"released by the user".into())
    );

    // The plain lines: the telegram, then the FMS layer in words.
    let line = |needle: &str| {
        cap.plain
            .iter()
            .find(|l| l.contains(needle))
            .unwrap_or_else(|| panic!("no line with {needle:?} in {:#?}", cap.plain))
    };
    let l = line("| FMS Read.req invoke 2 index 2020");
    assert!(
        l.contains("3→5 SRD_low ") && l.contains(" DSAP=40 (FMS) SSAP=33 "),
        "{l}"
    );
    assert!(line("| FMS Read.resp invoke 2 data ").contains("DSAP=33 SSAP=40 (FMS)"));
    line("| LLI Associate (monitoring 2000 ms): FMS Initiate.req OD version 0");
    line("| FMS Write.req invoke 3 index 2041 data 00 20 00");
    line("| FMS Error invoke 4 (Read) class ");
    line("| FMS Identify.resp invoke 1: vendor \"Beckhoff\" model \"BK3000\"");
    line("| FMS Get-OD.req invoke 5 index 2020, short form");
    line("| FMS malformed: unknown FMS service 9 in a confirmed request PDU");
    line("| LLI poll");
    line("| LLI Abort reason 0 detail 0: released by the user");
}
