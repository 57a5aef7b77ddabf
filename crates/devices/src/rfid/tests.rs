use super::client::{RfidClient, RfidError, Stage, StartError};
use super::commands::{NO_READ, VERSION};
use super::tags::TagField;
use super::*;
use std::time::Duration;

fn ms(n: u64) -> Instant {
    Instant::ZERO + Duration::from_millis(n)
}

/// Hex bytes with the rest of the 16 bytes 0.
fn tg(hex: &str) -> [u8; 16] {
    let mut t = [0u8; 16];
    for (i, b) in hex.split_whitespace().enumerate() {
        t[i] = u8::from_str_radix(b, 16).unwrap();
    }
    t
}

/// One Data_Exchange: the request, then the response.
fn dx(d: &mut Rfid, now: Instant, req: &[u8; 16]) -> [u8; 16] {
    d.write_outputs(now, req);
    let mut out = [0u8; 16];
    d.read_inputs(now, &mut out);
    out
}

fn reader_with_tag() -> Rfid {
    let mut f = TagField::parse(
        "[reader]\ntor = 5\nuid_ms = 10\nblock_ms = 20\n\n[[tag]]\nuid = \"E004015012345678\"\nin_field = true\ndata = [\"00112233\", \"44556677\"]",
    )
    .unwrap();
    f.timing.tor = 5;
    Rfid::new(f)
}

#[test]
fn the_manuals_ver_exchange_byte_for_byte() {
    let mut d = Rfid::new(TagField::new());
    assert_eq!(d.check_cfg(&[0x3F]).unwrap().inputs, 16);
    let resp: Vec<[u8; 16]> = MANUAL_RESPONSES.iter().map(|h| tg(h)).collect();
    // Step 1-3: the command; the flag is set, nothing delivered.
    assert_eq!(dx(&mut d, ms(0), &tg(MANUAL_REQUESTS[0])), resp[0]);
    assert_eq!(dx(&mut d, ms(1), &tg(MANUAL_REQUESTS[0])), resp[0]);
    for (i, req) in MANUAL_REQUESTS[1..].iter().enumerate() {
        // The response of the Data_Exchange carrying the change of R
        // still shows the previous one (L86) ...
        assert_eq!(dx(&mut d, ms(2), &tg(req)), resp[i], "request {req}");
        // ... the next one carries the fragment, and repeats it.
        assert_eq!(dx(&mut d, ms(3), &tg(req)), resp[i + 1], "request {req}");
        assert_eq!(dx(&mut d, ms(4), &tg(req)), resp[i + 1], "request {req}");
    }
    assert!(!d.link().data_waiting());
}

#[test]
fn ver_rejects_configurations_and_parameters_the_gsd_does_not_have() {
    let mut d = Rfid::new(TagField::new());
    assert!(d.check_cfg(&[0x2F, 0x1F]).is_err());
    assert!(d.check_cfg(&[0x3F]).is_ok());
    assert_eq!(d.ident_number(), 0x0DC4);
    let g = crate::gsd_files::parse(GSD).unwrap();
    assert_eq!(g.ident_number, IDENT);
    assert_eq!(g.chk_cfg(&g.default_selection()).unwrap(), CFG);
    assert_eq!(g.max_diag_data_len, Some(d.features().max_diag_len));
}

/// Client and reader in lockstep. Each step: the client sees the images
/// (the master's callback), then one Data_Exchange carries the output
/// image to the reader. Returns the result, the distinct (request,
/// response) pairs in order, and the cycles used.
struct Bench {
    d: Rfid,
    c: RfidClient,
    out: [u8; 16],
    inp: [u8; 16],
    cycle: u64,
    now: Instant,
    pairs: Vec<([u8; 16], [u8; 16])>,
}

impl Bench {
    fn new(d: Rfid) -> Bench {
        Bench {
            d,
            c: RfidClient::new(Duration::from_millis(2000)),
            out: [0; 16],
            inp: [0; 16],
            cycle: 0,
            now: ms(0),
            pairs: vec![],
        }
    }

    fn exchange(&mut self) {
        self.now += Duration::from_millis(1);
        self.d.handle_timeout(self.now);
        self.d.write_outputs(self.now, &self.out);
        self.d.read_inputs(self.now, &mut self.inp);
        self.cycle += 1;
        let p = (self.out, self.inp);
        if self.pairs.last() != Some(&p) {
            self.pairs.push(p);
        }
    }

    fn run(&mut self, cmd: &[u8]) -> Result<Vec<u8>, RfidError> {
        self.pairs.clear();
        self.c.start(self.now, cmd).unwrap();
        for _ in 0..100_000 {
            if let Some(r) = self.c.poll(self.now, self.cycle, &self.inp, &mut self.out) {
                return r.map(|a| a.to_vec());
            }
            self.exchange();
        }
        panic!("no result");
    }
}

#[test]
fn the_client_runs_the_manuals_exchange() {
    let mut b = Bench::new(Rfid::new(TagField::new()));
    let a = b.run(b"VER").unwrap();
    assert_eq!(a, VERSION);
    assert_eq!(
        String::from_utf8(a).unwrap(),
        "AEG ID - PFB V1.26\rAEG ID - A9 /PFB V1.28\r"
    );
    // Every request and response of the manual in order; between them
    // only the Data_Exchange that follows each change of R (its response
    // is the previous one).
    let mut expect = vec![];
    for i in 0..5 {
        if i > 0 {
            expect.push((tg(MANUAL_REQUESTS[i]), tg(MANUAL_RESPONSES[i - 1])));
        }
        expect.push((tg(MANUAL_REQUESTS[i]), tg(MANUAL_RESPONSES[i])));
    }
    assert_eq!(b.pairs, expect);
}

#[test]
fn long_commands_and_long_answers() {
    let mut b = Bench::new(reader_with_tag());
    // 34 bytes with CR: three send jobs.
    let a = b.run(b"WD 2 AABBCCDD0102030405060708").unwrap();
    assert_eq!(a, b"AABBCCDD0102030405060708\r");
    let jobs: Vec<u8> = b.pairs.iter().map(|(r, _)| r[1]).collect();
    let mut distinct = jobs.clone();
    distinct.dedup();
    assert_eq!(distinct.len(), 3, "three values of S: {jobs:?}");
    assert_eq!(b.d.link().stats().jobs, 3);
    // 16 blocks: 129 bytes, ten fragments.
    let a = b.run(b"RD 0 F").unwrap();
    assert_eq!(a.len(), 129);
    assert_eq!(&a[..32], b"0011223344556677AABBCCDD01020304");
    assert_eq!(b.d.link().stats().fragments, 2 + 10);
    assert_eq!(b.d.reader().field().tags[0].blocks[4], [5, 6, 7, 8]);
    // A command ending with CR is sent as it is; errors are answers.
    assert_eq!(b.run(b"HELLO\r").unwrap(), b"NAK #00\r");
    assert_eq!(b.run(b"RD 0 10").unwrap(), b"NAK #02\r");
    assert_eq!(b.run(&[b'A'; 300]).unwrap(), b"NAK #05\r");
    assert_eq!(b.run(b"GT").unwrap(), b"E004015012345678\r");
}

#[test]
fn a_slow_command_takes_many_cycles() {
    let mut b = Bench::new(reader_with_tag());
    let c0 = b.cycle;
    let a = b.run(b"RD 0 F").unwrap();
    assert_eq!(a.len(), 129);
    // 16 blocks × 20 ms at 1 ms per cycle.
    assert!(b.cycle - c0 >= 320, "{} cycles", b.cycle - c0);
    // While it ran, the flag stayed 0 and E unchanged.
    let before: Vec<_> = b
        .pairs
        .iter()
        .take_while(|(_, r)| r[0] & DATA_FLAG == 0)
        .collect();
    assert!(before.iter().all(|(_, r)| r[1] == 0 && r[2] == 0));
}

#[test]
fn a_tag_arriving_during_a_read_is_read() {
    let mut b = Bench::new(reader_with_tag());
    b.d.tag_leaves(b.now);
    b.c.start(b.now, b"RD 0 1").unwrap();
    let uid = b.d.reader().field().tags[0].uid.clone();
    let mut result = None;
    for i in 0..2000 {
        if i == 100 {
            b.d.tag_enters(b.now, &uid);
        }
        if let Some(r) = b.c.poll(b.now, b.cycle, &b.inp, &mut b.out) {
            result = Some(r.map(|a| a.to_vec()));
            break;
        }
        b.exchange();
    }
    assert_eq!(result.unwrap().unwrap(), b"0011223344556677\r");
    // A tag that leaves for good: no read after TOR.
    b.c.start(b.now, b"RD 0 1").unwrap();
    let mut result = None;
    for i in 0..2000 {
        if i == 10 {
            b.d.tag_leaves(b.now);
        }
        if let Some(r) = b.c.poll(b.now, b.cycle, &b.inp, &mut b.out) {
            result = Some(r.map(|a| a.to_vec()));
            break;
        }
        b.exchange();
    }
    assert_eq!(result.unwrap().unwrap(), NO_READ);
}

#[test]
fn a_job_while_the_flag_is_set_is_ignored() {
    let mut d = Rfid::new(TagField::new());
    dx(&mut d, ms(0), &tg("00 01 04 56 45 52 0D"));
    // A second command without fetching the answer.
    let r = dx(&mut d, ms(1), &tg("00 02 03 47 54 0D"));
    assert_eq!(r[0], DATA_FLAG);
    assert_eq!(d.link().stats().ignored_jobs, 1);
    assert_eq!(d.link().pending_answer(), VERSION);
    let mut texts = vec![];
    while let Some(e) = d.poll_event() {
        texts.push(e.text);
    }
    assert!(texts.iter().any(|t| t.contains("ignored")), "{texts:?}");
}

#[test]
fn the_client_drains_a_left_over_answer_and_times_out_cleanly() {
    let mut b = Bench::new(reader_with_tag());
    // A command sent by someone else, its answer never fetched.
    b.out = tg("00 01 03 47 54 0D");
    for _ in 0..50 {
        b.exchange();
    }
    assert!(b.d.link().data_waiting());
    assert_eq!(b.run(b"VER").unwrap(), VERSION);
    assert_eq!(b.c.drained(), 17);
    // A reader that never answers (a master alone on its outputs).
    let mut c = RfidClient::new(Duration::from_millis(50));
    let (inp, mut out) = ([0u8; 16], [0u8; 16]);
    c.start(ms(0), b"VER").unwrap();
    assert_eq!(c.start(ms(0), b"VER"), Err(StartError::Busy));
    let mut res = None;
    for cycle in 0..100u64 {
        if let Some(r) = c.poll(ms(cycle), cycle, &inp, &mut out) {
            res = Some(r.map(|a| a.to_vec()));
            break;
        }
    }
    let e = res.unwrap().unwrap_err();
    assert_eq!(
        e,
        RfidError::Timeout {
            after: Duration::from_millis(50),
            stage: Stage::Answer
        }
    );
    assert!(e.to_string().contains("waiting for the data flag"));
    assert!(c.is_idle());
    assert_eq!(out[..3], [0, 1, 0], "S kept, L and payload 0");
    assert_eq!(out[3..], [0; 13]);
    assert_eq!(c.start(ms(0), b"A\rB"), Err(StartError::EmbeddedCr));
}

#[test]
fn the_answer_buffer_is_bounded() {
    let mut b = Bench::new(reader_with_tag());
    b.c = RfidClient::with_capacity(Duration::from_millis(2000), 20);
    assert_eq!(b.run(b"RD 0 F"), Err(RfidError::AnswerTooLong(20)));
}

#[test]
fn leaving_data_exchange_starts_the_handshake_afresh() {
    let mut d = Rfid::new(TagField::new());
    dx(&mut d, ms(0), &tg("00 01 04 56 45 52 0D"));
    assert!(d.link().data_waiting());
    d.clear_outputs(ms(1), ClearReason::LeftDataExchange);
    assert!(!d.link().data_waiting());
    // The master's image still says S = 1 with L = 0: a job without bytes.
    let r = dx(&mut d, ms(2), &tg("00 01"));
    assert_eq!(r, [0; 16]);
}

#[test]
fn control_commands_and_state_events() {
    let f = TagField::parse("[[tag]]\nuid = \"01020304\"\nblocks = 2\n").unwrap();
    let mut d = Rfid::new(f).with_state_events(true);
    let state = |d: &mut Rfid| {
        let mut last = None;
        while let Some(e) = d.poll_event() {
            if e.kind == crate::STATE_EVENT {
                last = Some(TagField::parse(&e.text).unwrap());
            }
        }
        last
    };
    assert!(d.control(ms(0), "enter 01020304").is_ok());
    assert!(d.control(ms(0), "tags").unwrap().contains("in the field"));
    assert!(d.control(ms(0), "fly away").is_err());
    assert!(d.control(ms(0), "enter XY").is_err());
    let saved = state(&mut d).expect("a state event");
    assert_eq!(saved.in_field().unwrap().uid, [1, 2, 3, 4]);
    // A write is reported.
    let mut b = Bench::new(d);
    assert_eq!(b.run(b"WD 1 CAFEF00D").unwrap(), b"CAFEF00D\r");
    let saved = state(&mut b.d).expect("a state event");
    assert_eq!(saved.tags[0].blocks[1], [0xCA, 0xFE, 0xF0, 0x0D]);
    assert!(b.d.control(ms(0), "leave").unwrap().contains("left"));
    assert!(b.d.control(ms(0), "status").unwrap().contains("none"));
    assert!(state(&mut b.d).unwrap().in_field().is_none());
    // Without state events nothing is reported.
    let mut d = Rfid::new(TagField::new());
    d.control(ms(0), "enter 0A").unwrap();
    assert!(state(&mut d).is_none());
}

#[test]
fn a_restart_of_the_reader_mid_command_sends_the_command_again() {
    let mut b = Bench::new(reader_with_tag());
    let cmd = b"WD 2 AABBCCDD0102030405060708";
    b.c.start(b.now, cmd).unwrap();
    let mut restarted = false;
    let mut result = None;
    for _ in 0..5000 {
        if let Some(r) = b.c.poll(b.now, b.cycle, &b.inp, &mut b.out) {
            result = Some(r.map(|a| a.to_vec()));
            break;
        }
        // The reader restarts once the second fragment has arrived: it
        // drops both; the master's image still holds the second with
        // S = 2, which would differ from the reader's new reference.
        if !restarted && b.d.link().stats().jobs == 2 {
            b.d.clear_outputs(b.now, ClearReason::LeftDataExchange);
            b.c.restart(&mut b.out);
            restarted = true;
        }
        b.exchange();
    }
    assert!(restarted);
    assert_eq!(result.unwrap().unwrap(), b"AABBCCDD0102030405060708\r");
    assert_eq!(b.d.reader().field().tags[0].blocks[3], [1, 2, 3, 4]);
}

#[test]
fn a_users_command_set_with_answers_and_delays() {
    // Only VER is from the manual (L97); a user loads their reader's
    // commands: answers and delays, the modelled ones dropped.
    let set = crate::rfid::custom::CommandSet::parse(
        "builtin = false\n[[command]]\ncommand = \"SN\"\nanswer = \"A9-0042\\r\"\ndelay_ms = 40\n",
    )
    .unwrap();
    let mut b = Bench::new(reader_with_tag().with_commands(set));
    let c0 = b.cycle;
    assert_eq!(b.run(b"sn").unwrap(), b"A9-0042\r");
    assert!(b.cycle - c0 >= 40, "{} cycles: the delay", b.cycle - c0);
    assert_eq!(b.run(b"VER").unwrap(), crate::rfid::commands::VERSION);
    assert_eq!(
        b.run(b"GT").unwrap(),
        b"NAK #00\r",
        "GT is modelled, not kept"
    );
    // With the modelled commands kept, GT still reads the tag.
    let set = crate::rfid::custom::CommandSet::parse(
        "unknown = \"?\\r\"\n[[command]]\ncommand = \"SN\"\nanswer = \"1\\r\"\n",
    )
    .unwrap();
    let mut b = Bench::new(reader_with_tag().with_commands(set));
    assert_eq!(b.run(b"SN").unwrap(), b"1\r");
    assert_ne!(b.run(b"GT").unwrap(), b"?\r");
    assert_eq!(b.run(b"XYZ").unwrap(), b"?\r");
}
