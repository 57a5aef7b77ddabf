//! The RS-485 line model and the tap: arbitrary configurations and
//! sequences of writes never panic; deliveries come in time order, never
//! empty and never to their sender; the tap accounts for every delivered
//! byte exactly once; a fault-free serialising line delivers every
//! station's bytes unchanged.
//!
//! Run: `cargo +nightly fuzz run medium_tap`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_fdl::line::medium::{Collisions, Medium, MediumConfig};
use profibus_fdl::line::tap::{Tap, TapEvent};
use profibus_fdl::{Baud, Instant};

fuzz_target!(|data: &[u8]| {
    if data.len() < 4 {
        return;
    }
    let (head, mut ops) = data.split_at(4);
    let stations = 2 + (head[0] % 6) as usize;
    let baud = match head[1] % 12 {
        11 => None,
        i => Some(Baud::ALL[i as usize]),
    };
    let faults = head[2] & 0x80 != 0;
    let cfg = MediumConfig {
        baud,
        drop: if faults {
            (head[2] & 0x0F) as f64 / 64.0
        } else {
            0.0
        },
        flip_ber: if faults {
            ((head[2] >> 4) & 0x07) as f64 / 256.0
        } else {
            0.0
        },
        noise_rate: if faults { head[3] as f64 * 10.0 } else { 0.0 },
        seed: head[3] as u64,
        collisions: if head[2] & 0x40 != 0 {
            Collisions::Serialize
        } else {
            Collisions::Garble
        },
    };
    let clean = !faults && cfg.collisions == Collisions::Serialize;
    let mut m = Medium::new(stations, cfg);
    let mut tap = Tap::new();
    let mut now = Instant::ZERO;
    let mut last_at = Instant::ZERO;
    let mut sent = vec![Vec::new(); stations];
    let mut got = vec![Vec::new(); stations];
    let mut delivered = Vec::new();
    let mut tapped = Vec::new();
    let deliver = |m: &mut Medium,
                   t: Instant,
                   tap: &mut Tap,
                   last_at: &mut Instant,
                   got: &mut Vec<Vec<u8>>,
                   delivered: &mut Vec<u8>| {
        while let Some(d) = m.poll_delivery(t) {
            assert!(!d.bytes.is_empty());
            assert!(d.at >= *last_at && d.at <= t);
            *last_at = d.at;
            if let Some(f) = d.from {
                assert!(!d.reaches(f));
                got[f].extend_from_slice(&d.bytes);
            }
            delivered.extend_from_slice(&d.bytes);
            tap.push(d.at, &d.bytes);
        }
    };
    // Ops: [station, dt (µs), len, bytes…]
    while ops.len() >= 3 {
        let from = ops[0] as usize % stations;
        let dt = ops[1] as u64 * 1000;
        let len = (ops[2] as usize).min(ops.len() - 3);
        let bytes = &ops[3..3 + len];
        ops = &ops[3 + len..];
        let t = now + std::time::Duration::from_nanos(dt);
        // Deliver what is due before the write, as a driver would.
        while let Some(e) = m.poll_timeout().filter(|&e| e <= t) {
            deliver(&mut m, e, &mut tap, &mut last_at, &mut got, &mut delivered);
        }
        now = t;
        m.transmit(now, from, bytes);
        sent[from].extend_from_slice(bytes);
        deliver(
            &mut m,
            now,
            &mut tap,
            &mut last_at,
            &mut got,
            &mut delivered,
        );
        while let Some(ev) = tap.poll() {
            match ev {
                TapEvent::Telegram { bytes, .. } | TapEvent::Skipped { bytes, .. } => {
                    tapped.extend_from_slice(&bytes)
                }
            }
        }
    }
    // Drain what is still on the line (bounded: noise never stops).
    let end = m.busy_until();
    while let Some(e) = m.poll_timeout().filter(|&e| e <= end) {
        deliver(&mut m, e, &mut tap, &mut last_at, &mut got, &mut delivered);
    }
    tap.line_idle();
    while let Some(ev) = tap.poll() {
        match ev {
            TapEvent::Telegram { bytes, .. } | TapEvent::Skipped { bytes, .. } => {
                tapped.extend_from_slice(&bytes)
            }
        }
    }
    assert_eq!(tapped, delivered);
    let s = m.stats();
    assert_eq!(s.chars, sent.iter().map(|v| v.len() as u64).sum::<u64>());
    if clean {
        assert_eq!(got, sent);
        assert_eq!(s.collisions + s.dropped + s.bits_flipped + s.noise_chars, 0);
    }
});
