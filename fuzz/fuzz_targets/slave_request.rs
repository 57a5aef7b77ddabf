//! Arbitrary request telegrams into the DP slave core (`DpSlave` with the
//! generic device, every optional feature on or off), and the same bytes
//! as a raw byte stream into `PassiveStation<DpSlave>`.
//!
//! Input layout: byte 0 selects the features; then records
//! `kind, dt, da, sa, fc, dsap, ssap, len, data[len]`, where `kind` 0 and
//! 1 insert a valid Set_Prm / Chk_Cfg (so the fuzzer reaches Data_Exch
//! quickly), 2 a Data_Exchange with the right output length, and anything
//! else the record's own telegram. Checks: no panic, no response beyond
//! 244 bytes of data, no broadcast answered, outputs never left set
//! outside Data_Exch.

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_devices::generic::{GenericDevice, InputPattern};
use profibus_dp::slave::{Device, DpSlave, Features, SlaveState};
use profibus_fdl::station::passive::{PassiveStation, Reply, Responder};
use profibus_fdl::station::Station;
use profibus_fdl::{Baud, BusParams, DataTelegram, FunctionCode, Instant};
use std::time::Duration;

const CFG: [u8; 4] = [0x21, 0x13, 0x42, 0x41];
const IDENT: u16 = 0x0DCE;

fn device(sel: u8) -> GenericDevice {
    let all = sel & 1 != 0;
    let f = Features {
        sync: all,
        freeze: all,
        set_slave_add: all,
        dpv1: sel & 2 != 0,
        c1_read_write: sel & 2 != 0,
        alarms: false,
        fail_safe: sel & 4 != 0,
        max_diag_len: 6 + (sel >> 3),
        c1_max_data_len: if sel & 0x20 != 0 { 16 } else { 240 },
        // Class 2 and I&M with DP-V1, so requests on SAPs 0..=49 and
        // index 255 reach the resource manager and the I&M store.
        c2_read_write: sel & 2 != 0,
        c2_max_data_len: if sel & 0x20 != 0 { 16 } else { 240 },
        c2_max_count_channels: 2,
        max_initiate_pdu_length: 52,
        im: sel & 2 != 0,
    };
    let pattern = if sel & 0x80 != 0 {
        InputPattern::Counter
    } else {
        InputPattern::Echo
    };
    let dev = GenericDevice::new("fuzz", IDENT, CFG.to_vec(), f).with_inputs(pattern);
    if sel & 0x40 != 0 {
        dev.with_user_prm(if f.dpv1 { 4 } else { 1 }, vec![])
    } else {
        dev
    }
}

fn good_prm(dpv1: bool) -> Vec<u8> {
    let mut p = vec![0xB8, 20, 1, 11, (IDENT >> 8) as u8, IDENT as u8, 1];
    if dpv1 {
        p.extend([0xC0, 0x00, 0x00]);
    }
    p.push(0);
    p
}

fuzz_target!(|data: &[u8]| {
    let Some((&sel, mut rest)) = data.split_first() else {
        return;
    };
    let dev = device(sel);
    let dpv1 = dev.features().dpv1;
    let outputs_len = 2 + 2;
    let mut slave = DpSlave::new(dev, 8);
    let mut now = Instant::ZERO;
    while rest.len() >= 8 {
        let (head, tail) = rest.split_at(8);
        let [kind, dt, da, sa, fc, dsap, ssap, len] = head.try_into().unwrap();
        let n = (len as usize).min(tail.len());
        let (body, tail) = tail.split_at(n);
        rest = tail;
        now += Duration::from_millis(dt as u64);
        if slave.poll_timeout().is_some_and(|t| t <= now) {
            slave.handle_timeout(now);
        }
        let prm;
        let (da, sa, fc, dsap, ssap, body): (u8, u8, u8, Option<u8>, Option<u8>, &[u8]) = match kind
        {
            0 => {
                prm = good_prm(dpv1);
                (8, 2, 0x6D, Some(61), Some(62), &prm)
            }
            1 => (8, 2, 0x5D, Some(62), Some(62), &CFG),
            2 => (8, 2, 0x7D, None, None, &body[..body.len().min(outputs_len)]),
            _ => (
                da & 0x7F,
                sa & 0x7F,
                fc,
                (dsap != 0xFF).then_some(dsap),
                (ssap != 0xFF).then_some(ssap),
                body,
            ),
        };
        let req = DataTelegram {
            da,
            sa,
            fc: FunctionCode::from_byte(fc),
            dsap,
            ssap,
            data: body,
            format: None,
        };
        let FunctionCode::Request { kind, .. } = req.fc else {
            continue;
        };
        let silent = da == 127 || !kind.expects_reply();
        let mut buf = [0u8; 246];
        let out: &mut [u8] = if silent { &mut [] } else { &mut buf };
        match slave.on_request(now, &req, out) {
            Reply::Data { len, .. } => {
                assert!(!silent, "answered a broadcast/SDN");
                assert!(len <= 244, "{len} bytes of response data");
            }
            Reply::ShortAck => assert!(!silent, "acknowledged a broadcast/SDN"),
            Reply::Silence => {}
        }
        if slave.state() != SlaveState::DataExch {
            assert!(slave.outputs().iter().all(|&b| b == 0), "stale outputs");
            assert!(
                slave.device().outputs().iter().all(|&b| b == 0),
                "stale device outputs"
            );
        }
        while slave.poll_event().is_some() {}
    }

    // The same bytes as a line: framing, FCB rule, then the slave.
    let mut st = PassiveStation::new(
        DpSlave::new(device(sel), 8),
        BusParams::defaults(Baud::B19200),
    );
    let mut t = Instant::ZERO;
    for chunk in data[1..].chunks(37) {
        t += Duration::from_micros(300);
        st.handle_rx(t, chunk);
        while let Some(d) = st.poll_timeout() {
            if d > t {
                break;
            }
            st.handle_timeout(d);
            if let Some(b) = st.poll_transmit(d) {
                assert!(b.len() <= 255);
            }
        }
    }
});
