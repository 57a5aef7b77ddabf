use super::*;
use crate::pdu::sap;
use profibus_fdl::codec::CodecStats;
use profibus_fdl::wire::{DataTelegram, RequestKind, ResponseStatus};
use profibus_fdl::Instant;
use proptest::prelude::*;

const M: u8 = 2;
const S: u8 = 8;

fn parse(s: &str) -> Trigger {
    Trigger::parse(s).unwrap_or_else(|e| panic!("{s}: {e}"))
}

fn err(s: &str) -> String {
    Trigger::parse(s).unwrap_err().to_string()
}

#[test]
fn parses_and_prints_in_canonical_form() {
    for (src, canon) in [
        ("cfg_fault", "cfg_fault"),
        ("ADDR==5", "addr == 5"),
        ("addr == 0x05", "addr == 5"),
        ("service == Set_Prm", "service == set_prm"),
    ] {
        assert_eq!(parse(src).to_string(), canon);
    }
    // `and` binds tighter than `or`; parentheses are kept where needed.
    assert_eq!(
        parse("fcs or retry and addr == 5").to_string(),
        "fcs or retry and addr == 5"
    );
    assert_eq!(
        parse("(fcs or retry) and not (addr == 5)").to_string(),
        "(fcs or retry) and not addr == 5"
    );
    assert_eq!(
        parse("not (fcs or retry)").to_string(),
        "not (fcs or retry)"
    );
    assert_eq!(parse("t >= 1.5s").to_string(), "t >= 1.5s");
    assert_eq!(parse("fc == SRD_high").to_string(), "fc == srd_high");
    assert_eq!(
        parse("state == data_exchange").to_string(),
        "state == data_exchange"
    );
}

/// Found by the `trigger` fuzz target: the parser groups `or` and `and`
/// to the left, so a right operand of the same operator must keep its
/// parentheses or the canonical form parses to another tree.
#[test]
fn right_nested_operands_keep_their_parentheses() {
    for (src, canon) in [
        ("diag or (fcs or retry)", "diag or (fcs or retry)"),
        ("diag and (fcs and retry)", "diag and (fcs and retry)"),
        ("(diag or fcs) or retry", "diag or fcs or retry"),
        (
            "(not((diag)or((diag)or deactivated)or deactivated)or diag)",
            "not (diag or (diag or deactivated) or deactivated) or diag",
        ),
    ] {
        let t = parse(src);
        assert_eq!(t.to_string(), canon);
        assert_eq!(parse(canon), t, "{canon}");
    }
}

#[test]
fn errors_name_the_column_and_the_closest_name() {
    assert_eq!(
        err("addr == 5 and cfg_falt"),
        "column 15: unknown name `cfg_falt`; did you mean `cfg_fault`?"
    );
    assert_eq!(
        err("service == set_pram"),
        "column 12: unknown service `set_pram`; did you mean `set_prm`?"
    );
    assert_eq!(
        err("adr == 5"),
        "column 1: unknown name `adr`; did you mean `addr`?"
    );
    assert_eq!(
        err("addr == 300"),
        "column 9: `addr` takes a number 0..=127, not `300`"
    );
    assert_eq!(
        err("t > 10"),
        "column 5: `10` is no time; write a number with s, ms or us (`10s`, `250ms`)"
    );
    assert_eq!(
        err("(fcs or retry"),
        "column 14: `(` at column 1 is never closed"
    );
    assert_eq!(err("fcs retry"), "column 5: unexpected `retry`");
    assert_eq!(err(""), "column 1: expected a name or `(` at the end");
    assert_eq!(
        err("fcs and"),
        "column 8: expected a name or `(` at the end"
    );
    assert_eq!(
        err("addr = 5"),
        "column 6: `=` compares nothing; write `==`"
    );
    assert_eq!(
        err("cfg_fault == 1"),
        "column 11: `cfg_fault` is a flag, true or false on its own; it compares with nothing"
    );
    assert_eq!(
        err("service > set_prm"),
        "column 11: `service` is a name; compare it with == or !="
    );
    assert_eq!(
        err("addr 5"),
        "column 6: expected a comparison (== != < <= > >=) after `addr`, found `5`"
    );
    assert_eq!(
        err("state == runing").split(';').next(),
        Some("column 10: unknown state `runing`")
    );
    assert!(err(&"(".repeat(100)).contains("nested deeper than 64 levels"));
}

fn obs() -> Observation {
    Observation {
        t: Duration::from_secs(12),
        src: Some(M),
        dst: Some(S),
        dsap: Some(sap::SET_PRM),
        ssap: Some(sap::MASTER),
        fc: Some((0xD, true)),
        len: Some(10),
        service: Some("Set_Prm"),
        request: true,
        ..Observation::default()
    }
}

#[test]
fn evaluates_fields_flags_and_combinations() {
    let o = obs();
    for (expr, want) in [
        ("addr == 8", true),
        ("addr == 2", true),
        ("addr == 9", false),
        ("addr != 9", true),
        ("addr != 8", false),
        ("src == 2 and dst == 8", true),
        ("dst < 8", false),
        ("dst <= 8", true),
        ("sap == 61", true),
        ("sap == 62", true),
        ("dsap == 62", false),
        ("service == set_prm", true),
        ("service != set_prm", false),
        ("service == chk_cfg", false),
        ("fc == 13", true),
        ("fc == srd_high", true),
        ("fc == sda_high", false),
        ("len > 7", true),
        ("t > 10s", true),
        ("t > 12001ms", false),
        ("request and not response", true),
        ("cfg_fault or retry", false),
        ("not (cfg_fault or retry)", true),
        ("state_change", false),
    ] {
        assert_eq!(parse(expr).matches(&o), want, "{expr}");
    }
    let diag = Observation {
        diag: vec!["Cfg_Fault".into(), "Ext_Diag".into()],
        service: Some("Slave_Diag"),
        response: true,
        request: false,
        ..obs()
    };
    assert!(parse("cfg_fault and ext_diag and diag").matches(&diag));
    assert!(!parse("prm_fault").matches(&diag));
    let states = Observation {
        states: vec![SlaveState::DataExchange],
        ..obs()
    };
    assert!(parse("state == data_exchange").matches(&states));
    assert!(!parse("state == offline").matches(&states));
    assert!(parse("state_change").matches(&states));
}

/// Bytes of a data telegram.
fn data(da: u8, sa: u8, fc: FunctionCode, saps: Option<(u8, u8)>, du: &[u8]) -> Vec<u8> {
    let (dsap, ssap) = saps.unzip();
    let t = DataTelegram::new(da, sa, fc, du).with_saps(dsap, ssap);
    Telegram::Data(t).to_vec().unwrap()
}

fn req(sap: Option<u8>, fcb: bool, du: &[u8]) -> Vec<u8> {
    let fc = FunctionCode::Request {
        kind: RequestKind::SrdHigh,
        fcb,
        fcv: true,
    };
    data(S, M, fc, sap.map(|s| (s, sap::MASTER)), du)
}

fn resp(sap: Option<u8>, du: &[u8]) -> Vec<u8> {
    let fc = FunctionCode::slave_response(ResponseStatus::Dl);
    data(M, S, fc, sap.map(|s| (sap::MASTER, s)), du)
}

/// Observations of `telegrams`, 1 ms apart.
fn watch(w: &mut Watch, t0: u64, telegrams: &[Vec<u8>]) -> Vec<Observation> {
    telegrams
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let at = Instant::from_nanos((t0 + i as u64) * 1_000_000);
            w.hear(&TapEvent::Telegram {
                at,
                bytes: b.clone(),
            })
            .0
        })
        .collect()
}

#[test]
fn watch_reads_a_cfg_fault_from_the_diagnosis_answer() {
    let mut w = Watch::default();
    // Chk_Cfg (one identifier), acknowledged; Slave_Diag answered with
    // Cfg_Fault.
    let diag_du = [0x04, 0x04, 0x00, M, 0x0D, 0xCE];
    let o = watch(
        &mut w,
        0,
        &[
            req(Some(sap::CHK_CFG), true, &[0x71]),
            vec![0xE5],
            req(Some(sap::SLAVE_DIAG), false, &[]),
            resp(Some(sap::SLAVE_DIAG), &diag_du),
        ],
    );
    let t = parse("cfg_fault");
    let fired: Vec<bool> = o.iter().map(|o| t.matches(o)).collect();
    assert_eq!(fired, [false, false, false, true]);
    // The short acknowledge is read by its request.
    assert!(parse("service == chk_cfg and response").matches(&o[1]));
    assert_eq!(o[3].t, Duration::from_millis(3));
}

#[test]
fn watch_sees_retries_missing_answers_corrupt_bytes_and_restarts() {
    let mut w = Watch::default();
    let dx = |fcb| req(None, fcb, &[1]);
    let ans = resp(None, &[2]);
    let token = Telegram::Token { da: M, sa: M }.to_vec().unwrap();
    let o = watch(
        &mut w,
        0,
        &[
            dx(true),
            ans.clone(),
            dx(false),
            token.clone(),
            dx(false),
            ans.clone(),
        ],
    );
    // The token after an unanswered request reveals it; the request
    // repeated with the same FCB is a retry.
    let flags: Vec<(bool, bool)> = o.iter().map(|o| (o.no_answer, o.retry)).collect();
    assert_eq!(
        flags,
        [
            (false, false),
            (false, false),
            (false, false),
            (true, false),
            (false, true),
            (false, false)
        ]
    );
    let skipped = w
        .hear(&TapEvent::Skipped {
            at: Instant::from_nanos(7_000_000),
            bytes: vec![0x68, 0x01],
            errors: CodecStats {
                bad_fcs: 1,
                ..CodecStats::default()
            },
        })
        .0;
    assert!(parse("fcs and corrupt").matches(&skipped));
    assert_eq!(skipped.src, None);
    // A start-up to Data_Exchange, then parameterised again: a restart.
    let mut w = Watch::default();
    let prm = req(Some(sap::SET_PRM), true, &[0x88, 1, 0, 0x0B, 0x0D, 0xCE, 0]);
    let o = watch(
        &mut w,
        10,
        &[
            prm.clone(),
            vec![0xE5],
            req(Some(sap::CHK_CFG), false, &[0x71]),
            vec![0xE5],
            req(Some(sap::SLAVE_DIAG), true, &[]),
            resp(Some(sap::SLAVE_DIAG), &[0x00, 0x04, 0x00, M, 0x0D, 0xCE]),
            dx(false),
            ans.clone(),
            dx(true),
            ans.clone(),
            prm,
            vec![0xE5],
        ],
    );
    let entered = |state: &str| {
        let t = parse(&format!("state == {state}"));
        o.iter().position(|o| t.matches(o))
    };
    assert!(entered("data_exchange").is_some(), "{o:#?}");
    assert!(entered("data_exchange") < o.iter().rposition(|o| o.restart));
    let restarts: Vec<bool> = o.iter().map(|o| parse("restart").matches(o)).collect();
    assert_eq!(restarts.iter().filter(|r| **r).count(), 1, "{o:#?}");
}

fn run(r: &mut Recorder<u32>, items: &[(u32, bool)]) -> Vec<Output<u32>> {
    let mut out = vec![];
    for &(i, f) in items {
        r.push(i, f, |o| out.push(o));
    }
    r.finish(|o| out.push(o));
    out
}

fn rec(record: u32, fired: bool) -> Output<u32> {
    Output::Record { record, fired }
}

#[test]
fn recorder_keeps_pre_and_post_records_and_merges_overlaps() {
    let mut r = Recorder::new(2, 2);
    let items: Vec<(u32, bool)> = (1..=20).map(|i| (i, [5, 6, 12, 20].contains(&i))).collect();
    let out = run(&mut r, &items);
    use Output::{End, Start};
    assert_eq!(
        out,
        [
            Start { segment: 1 },
            rec(3, false),
            rec(4, false),
            rec(5, true),
            rec(6, true),
            rec(7, false),
            rec(8, false),
            End { segment: 1 },
            Start { segment: 2 },
            rec(10, false),
            rec(11, false),
            rec(12, true),
            rec(13, false),
            rec(14, false),
            End { segment: 2 },
            Start { segment: 3 },
            rec(18, false),
            rec(19, false),
            rec(20, true),
            End { segment: 3 },
        ]
    );
    // No pre/post: the firing alone.
    let mut r = Recorder::new(0, 0);
    assert_eq!(
        run(&mut r, &[(1, false), (2, true)]),
        [Start { segment: 1 }, rec(2, true), End { segment: 1 }]
    );
    // A segment whose window starts before the first record.
    let mut r = Recorder::new(5, 1);
    assert_eq!(
        run(&mut r, &[(1, false), (2, true), (3, false), (4, false)]),
        [
            Start { segment: 1 },
            rec(1, false),
            rec(2, true),
            rec(3, false),
            End { segment: 1 }
        ]
    );
}

proptest! {
    /// Any text: an error or a trigger, never a panic; a trigger prints
    /// as an expression that parses to itself.
    #[test]
    fn parser_never_panics_and_round_trips(s in "[a-z_ ()=!<>0-9.]{0,40}") {
        if let Ok(t) = Trigger::parse(&s) {
            let again = Trigger::parse(&t.to_string()).unwrap();
            prop_assert_eq!(again.to_string(), t.to_string());
        }
    }

    #[test]
    fn words_of_the_language_never_panic(words in proptest::collection::vec(
        prop_oneof![
            Just("addr"), Just("=="), Just("5"), Just("and"), Just("or"), Just("not"),
            Just("("), Just(")"), Just("cfg_fault"), Just("t"), Just(">"), Just("10s"),
            Just("service"), Just("set_prm"), Just("!="), Just("fc"), Just("dh"),
        ], 0..20)) {
        let s = words.join(" ");
        if let Ok(t) = Trigger::parse(&s) {
            prop_assert_eq!(Trigger::parse(&t.to_string()).unwrap(), t.clone());
            let _ = t.matches(&obs());
        }
    }

    /// Every record is handed out at most once, in order, and every
    /// firing record is handed out.
    #[test]
    fn recorder_hands_out_records_in_order(pre in 0usize..5, post in 0usize..5,
        fires in proptest::collection::vec(any::<bool>(), 0..60)) {
        let mut r = Recorder::new(pre, post);
        let items: Vec<(u32, bool)> = fires.iter().enumerate().map(|(i, f)| (i as u32, *f)).collect();
        let out = run(&mut r, &items);
        let recs: Vec<u32> = out.iter().filter_map(|o| match o { Output::Record { record, .. } => Some(*record), _ => None }).collect();
        prop_assert!(recs.windows(2).all(|w| w[0] < w[1]));
        for (i, f) in &items {
            if *f { prop_assert!(recs.contains(i)); }
        }
        let starts = out.iter().filter(|o| matches!(o, Output::Start { .. })).count();
        let ends = out.iter().filter(|o| matches!(o, Output::End { .. })).count();
        prop_assert_eq!(starts, ends);
    }
}
