//! Instructions per telegram encode, ours next to profirust's, counted by
//! valgrind (callgrind) instead of timed: the count does not move with the
//! load of a shared machine.
//!
//! Run: `scripts/bench-encode-instructions` (builds this target, runs it
//! under `valgrind --tool=callgrind` once per case and once with an empty
//! loop, and prints instructions per encode). By hand: `WIRE_CASE=ours-2
//! valgrind --tool=callgrind target/release/deps/wire_instructions-*`.
//!
//! Cases (`WIRE_CASE`): `none` (the loop alone), `ours-2`, `ours-244`,
//! `profirust-2`, `profirust-244`: a Data_Exchange request (SRD high, FCB
//! and FCV set, no SAPs) with a 2- or 244-byte data unit, encoded
//! [`ITERATIONS`] times into a stack buffer.

use std::hint::black_box;

mod support;

/// Encodes per run.
const ITERATIONS: usize = 100_000;

/// An encoder under test: data unit in, bytes written out.
type Encode = fn(&[u8], &mut [u8; 255]) -> usize;

fn ours(data: &[u8], buf: &mut [u8; 255]) -> usize {
    support::data_exchange(data).emit(buf).unwrap()
}

fn profirust(data: &[u8], buf: &mut [u8; 255]) -> usize {
    support::profirust_data_exchange().serialize(buf, data.len(), |pdu| pdu.copy_from_slice(data))
}

fn main() {
    // `cargo bench` runs every bench target with `--bench`: do nothing
    // then unless a case is chosen.
    let Ok(case) = std::env::var("WIRE_CASE") else {
        return;
    };
    let (f, len): (Encode, usize) = match case.as_str() {
        "none" => (|d, _| d.len(), 2),
        "ours-2" => (ours, 2),
        "ours-244" => (ours, 244),
        "profirust-2" => (profirust, 2),
        "profirust-244" => (profirust, 244),
        other => panic!("unknown WIRE_CASE {other}"),
    };
    let data: Vec<u8> = (0..len as u8).collect();
    let mut buf = [0u8; 255];
    let mut sum = 0usize;
    for _ in 0..ITERATIONS {
        sum += f(black_box(&data), black_box(&mut buf));
        black_box(&buf);
    }
    black_box(sum);
}
