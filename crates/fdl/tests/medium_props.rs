//! Tests of the RS-485 line model (`profibus_fdl::line::medium`) together with
//! the codec: pacing, serialisation, fault injection and its detection.

use profibus_fdl::codec::{Framed, Framer};
use profibus_fdl::line::medium::{Collisions, Delivery, Medium, MediumConfig, MediumStats};
use profibus_fdl::rng::Rng;
use profibus_fdl::wire::{DataTelegram, FunctionCode, Telegram};
use profibus_fdl::{Baud, Instant};
use proptest::prelude::*;
use std::time::Duration;

/// A random valid telegram (all five formats), emitted.
fn random_telegram(r: &mut Rng) -> Vec<u8> {
    let mut buf = [0u8; 255];
    let kind = r.range_inclusive(0, 9);
    let t = match kind {
        0 => Telegram::ShortAck,
        1 => Telegram::Token {
            da: r.range_inclusive(0, 126) as u8,
            sa: r.range_inclusive(0, 126) as u8,
        },
        _ => {
            let len = match kind {
                2..=4 => 0,
                5 | 6 => 8,
                _ => r.range_inclusive(0, 244) as usize,
            };
            let data: Vec<u8> = (0..len).map(|_| r.next_u8()).collect();
            let sap = r.chance(0.5);
            let fc = FunctionCode::from_byte(r.next_u8() & 0x7F);
            let n = Telegram::Data(DataTelegram {
                da: r.range_inclusive(0, 127) as u8,
                sa: r.range_inclusive(0, 126) as u8,
                fc,
                dsap: sap.then_some(r.range_inclusive(0, 63) as u8),
                ssap: sap.then_some(r.range_inclusive(0, 63) as u8),
                data: &data,
                format: None,
            })
            .emit(&mut buf)
            .unwrap();
            return buf[..n].to_vec();
        }
    };
    let n = t.emit(&mut buf).unwrap();
    buf[..n].to_vec()
}

/// Frames a received byte stream; returns the telegrams.
#[derive(Default)]
struct Receiver {
    framer: Framer,
    buf: Vec<u8>,
    out: Vec<Vec<u8>>,
}

impl Receiver {
    fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
        loop {
            let framed = self.framer.frame(&self.buf);
            if !self.take(framed) {
                break;
            }
        }
    }

    /// The line went idle: give up incomplete candidates.
    fn idle(&mut self) {
        while !self.buf.is_empty() {
            let framed = self.framer.line_idle(&self.buf);
            self.take(framed);
            self.push(&[]);
        }
    }

    /// Take what the framer found off the buffer; whether it was a
    /// telegram.
    fn take(&mut self, framed: Framed) -> bool {
        match framed {
            Framed::Telegram { skip, len } => {
                self.out.push(self.buf[skip..skip + len].to_vec());
                self.buf.drain(..skip + len);
                true
            }
            Framed::NeedMore { skip } => {
                self.buf.drain(..skip);
                false
            }
        }
    }
}

/// Everything due up to `limit`.
fn drain_until(m: &mut Medium, limit: Instant) -> Vec<Delivery> {
    let mut out = vec![];
    while let Some(t) = m.poll_timeout().filter(|&t| t <= limit) {
        let mut any = false;
        while let Some(d) = m.poll_delivery(t) {
            out.push(d);
            any = true;
        }
        if !any && m.poll_timeout() == Some(t) {
            break;
        }
    }
    out
}

/// Everything pending on a line without noise.
fn drain_all(m: &mut Medium) -> Vec<Delivery> {
    drain_until(m, Instant::NEVER)
}

/// Sends `n` random telegrams from alternating stations, one after the
/// other (each starts when the line is free), and returns what a
/// receiving station framed plus the medium's and codec's counters.
fn run(
    n: usize,
    cfg: MediumConfig,
    seed: u64,
) -> (Vec<Vec<u8>>, Vec<Vec<u8>>, MediumStats, Receiver) {
    let mut r = Rng::new(seed);
    let mut m = Medium::new(3, cfg);
    let mut rx = Receiver::default();
    let mut sent = Vec::with_capacity(n);
    let mut now = Instant::ZERO;
    for i in 0..n {
        let t = random_telegram(&mut r);
        // Stations 0 and 1 talk; station 2 listens.
        m.transmit(now, i % 2, &t);
        sent.push(t);
        // The next one starts after an idle gap.
        let next = m.busy_until().max(now) + Duration::from_micros(100);
        for d in drain_until(&mut m, next) {
            assert!(d.reaches(2));
            rx.push(&d.bytes);
        }
        now = next;
        if (i + 1) % 16 == 0 {
            rx.idle();
        }
    }
    rx.idle();
    let out = std::mem::take(&mut rx.out);
    (sent, out, m.stats(), rx)
}

#[test]
fn zero_faults_is_identity_over_100000_telegrams() {
    for baud in [None, Some(Baud::B12000000), Some(Baud::B19200)] {
        let cfg = MediumConfig {
            baud,
            drop: 0.0,
            flip_ber: 0.0,
            seed: 1234,
            ..MediumConfig::default()
        };
        let (sent, got, stats, rx) = run(100_000, cfg, 5);
        assert_eq!(got.len(), sent.len(), "{baud:?}");
        assert!(got == sent, "{baud:?}: telegrams differ");
        assert_eq!(rx.framer.stats().errors(), 0);
        assert_eq!(rx.framer.stats().garbage_bytes, 0);
        assert_eq!(stats.dropped + stats.bits_flipped + stats.collisions, 0);
        assert_eq!(
            stats.chars,
            sent.iter().map(|t| t.len() as u64).sum::<u64>()
        );
    }
}

#[test]
fn fault_counts_are_reproducible_per_seed() {
    let cfg = |seed| MediumConfig {
        baud: Some(Baud::B1500000),
        drop: 0.002,
        flip_ber: 0.0005,
        noise_rate: 50.0,
        seed,
        collisions: Collisions::Garble,
    };
    let (_, got_a, a, rxa) = run(5_000, cfg(7), 1);
    let (_, got_b, b, rxb) = run(5_000, cfg(7), 1);
    let (_, _, c, _) = run(5_000, cfg(8), 1);
    assert_eq!(a, b);
    assert_eq!(got_a, got_b);
    assert_eq!(rxa.framer.stats(), rxb.framer.stats());
    assert_ne!(a, c);
    assert!(
        a.dropped > 0 && a.bits_flipped > 0 && a.noise_bursts > 0,
        "{a}"
    );
    // Plausible rates: chars × P within ±6σ.
    let expect = a.chars as f64 * 0.002;
    assert!(
        (a.dropped as f64 - expect).abs() < 6.0 * expect.sqrt() + 1.0,
        "{a}"
    );
    let expect = a.chars as f64 * 8.0 * 0.0005;
    assert!(
        (a.bits_flipped as f64 - expect).abs() < 6.0 * expect.sqrt() + 1.0,
        "{a}"
    );
}

#[test]
fn drop_and_flip_counts_do_not_depend_on_timing_or_write_splitting() {
    let data: Vec<u8> = (0..20_000u32).map(|i| (i * 31) as u8).collect();
    let cfg = |baud| MediumConfig {
        baud,
        drop: 0.01,
        flip_ber: 0.001,
        seed: 99,
        ..MediumConfig::default()
    };
    let mut whole = Medium::new(2, cfg(None));
    whole.transmit(Instant::ZERO, 0, &data);
    let mut pieces = Medium::new(2, cfg(Some(Baud::B500000)));
    for (i, c) in data.chunks(7).enumerate() {
        pieces.transmit(Instant::from_nanos(i as u64 * 1_000_000), i % 2, c);
    }
    let (a, b) = (whole.stats(), pieces.stats());
    assert_eq!((a.dropped, a.bits_flipped), (b.dropped, b.bits_flipped));
    assert!(a.dropped > 100 && a.bits_flipped > 100);
}

#[test]
fn flipped_bits_are_caught_by_fcs_and_framing() {
    // Data telegrams (SD1/SD2/SD3) carry an FCS; send each through the
    // medium alone and frame it with a fresh framer.
    let mut r = Rng::new(3);
    let cfg = MediumConfig {
        flip_ber: 0.002,
        seed: 11,
        ..MediumConfig::default()
    };
    let mut m = Medium::new(2, cfg);
    let (mut corrupted, mut single, mut caught, mut undetected) = (0, 0, 0, 0);
    let mut total = Framer::new().stats();
    for _ in 0..20_000 {
        let t = loop {
            let t = random_telegram(&mut r);
            if t.len() > 3 {
                break t;
            }
        };
        m.transmit(Instant::ZERO, 0, &t);
        let d = m.poll_delivery(Instant::ZERO).unwrap();
        let flips: u32 = t
            .iter()
            .zip(d.bytes.iter())
            .map(|(a, b)| (a ^ b).count_ones())
            .sum();
        let mut rx = Receiver::default();
        rx.push(&d.bytes);
        rx.idle();
        let s = rx.framer.stats();
        total.telegrams += s.telegrams;
        total.bad_fcs += s.bad_fcs;
        total.bad_length += s.bad_length;
        total.bad_end_delimiter += s.bad_end_delimiter;
        total.truncated += s.truncated;
        if flips == 0 {
            assert_eq!(rx.out, vec![t.clone()]);
            continue;
        }
        corrupted += 1;
        // The corrupted telegram itself must not be accepted (later bytes
        // of its data unit may happen to form a valid short telegram).
        let accepted_whole = rx.out.iter().any(|o| o.len() == t.len());
        if flips == 1 {
            single += 1;
            assert!(
                !accepted_whole,
                "single bit flip not detected: {:02X?}",
                &d.bytes[..]
            );
        }
        if accepted_whole {
            undetected += 1;
        } else {
            caught += 1;
            assert!(
                s.errors() + s.garbage_bytes > 0,
                "the codec counted nothing"
            );
        }
    }
    let s = m.stats();
    assert!(single > 1000 && corrupted > single, "{single} {corrupted}");
    assert_eq!(caught + undetected, corrupted);
    // Two flips of the same bit position in opposite directions cancel in
    // the FCS, an arithmetic sum (on a real line the parity bit of each
    // character catches them; a pty carries none): about 1/16 of the
    // telegrams with two or more flips pass.
    assert!(undetected * 20 < corrupted, "{undetected} of {corrupted}");
    eprintln!(
        "{corrupted} corrupted telegrams ({single} with one flipped bit), {undetected} undetected"
    );
    assert!(total.bad_fcs > 0 && total.bad_length + total.bad_end_delimiter > 0);
    assert!(s.bits_flipped >= corrupted);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// However a transmission is split into writes made while the line is
    /// still busy, its characters end at the exact wire time.
    #[test]
    fn pacing_is_exact_for_any_split(
        baud in proptest::sample::select(Baud::ALL.to_vec()),
        start in 0u64..1_000_000_000,
        pieces in proptest::collection::vec(1usize..50, 1..40),
    ) {
        let mut m = Medium::new(2, MediumConfig::paced(baud));
        let origin = Instant::from_nanos(start);
        let total: usize = pieces.iter().sum();
        let mut sent = 0;
        let mut got: Vec<Delivery> = vec![];
        for (i, p) in pieces.iter().enumerate() {
            // Write piece i while character `sent - 1` is still on the line.
            let now = if i == 0 { origin } else {
                origin + baud.chars_to_duration(sent as u64 - 1)
            };
            while let Some(d) = m.poll_delivery(now) { got.push(d); }
            let bytes: Vec<u8> = (sent..sent + p).map(|x| x as u8).collect();
            m.transmit(now, 0, &bytes);
            sent += p;
        }
        got.extend(drain_all(&mut m));
        // Chunks touch: chunk i ends at the end of character (count so far),
        // so no idle gap appears inside the transmission.
        let mut count = 0u64;
        for d in &got {
            count += d.bytes.len() as u64;
            prop_assert_eq!(d.at, origin + baud.chars_to_duration(count));
        }
        prop_assert_eq!(got.last().unwrap().at, origin + baud.chars_to_duration(total as u64));
        let bytes: Vec<u8> = got.iter().flat_map(|d| d.bytes.to_vec()).collect();
        prop_assert_eq!(bytes, (0..total).map(|x| x as u8).collect::<Vec<_>>());
        prop_assert_eq!(m.stats().transmissions, 1);
    }

    /// Concurrent writers on a serialising line: every station's bytes
    /// arrive intact and contiguous, back to back, and the line is busy for
    /// exactly the sum of all characters.
    #[test]
    fn serialize_keeps_transmissions_intact(
        baud in proptest::sample::select(Baud::ALL.to_vec()),
        writes in proptest::collection::vec((0usize..4, 1usize..30), 1..20),
    ) {
        let cfg = MediumConfig { collisions: Collisions::Serialize, ..MediumConfig::paced(baud) };
        let mut m = Medium::new(4, cfg);
        let mut expect: Vec<(usize, Vec<u8>)> = vec![];
        for (n, &(from, len)) in writes.iter().enumerate() {
            let bytes = vec![n as u8; len];
            m.transmit(Instant::ZERO, from, &bytes);
            match expect.iter_mut().find(|(f, _)| *f == from) {
                Some((_, v)) => v.extend_from_slice(&bytes),
                None => expect.push((from, bytes)),
            }
        }
        let total: usize = writes.iter().map(|w| w.1).sum();
        prop_assert_eq!(m.busy_until(), Instant::ZERO + baud.chars_to_duration(total as u64));
        let got = drain_all(&mut m);
        let mut merged: Vec<(usize, Vec<u8>)> = vec![];
        for d in &got {
            let f = d.from.unwrap();
            match merged.last_mut() {
                Some((lf, v)) if *lf == f => v.extend_from_slice(&d.bytes),
                _ => merged.push((f, d.bytes.to_vec())),
            }
        }
        prop_assert_eq!(merged, expect);
        prop_assert!(got.windows(2).all(|w| w[0].at <= w[1].at));
        prop_assert_eq!(got.last().unwrap().at, Instant::ZERO + baud.chars_to_duration(total as u64));
        prop_assert_eq!(m.stats().collisions, 0);
    }
}
