//! Telegram decode+verify and encode throughput, ours next to profirust's
//! telegram parser on the same bytes (issue: ≥ 10 M small telegrams/s per
//! core, at least as fast as profirust).
//!
//! Run: `cargo bench -p profibus-fdl --bench wire`
// `criterion_main!` defines an undocumented `pub fn main`.
#![allow(missing_docs)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use profibus_fdl::wire::Telegram;
use std::hint::black_box;

mod support;

fn data_exchange(len: usize) -> Vec<u8> {
    let data: Vec<u8> = (0..len as u8).collect();
    support::data_exchange(&data).to_vec().unwrap()
}

fn decode(c: &mut Criterion) {
    let mut g = c.benchmark_group("decode");
    for len in [2usize, 244] {
        let bytes = data_exchange(len);
        g.throughput(Throughput::Elements(1));
        g.bench_with_input(BenchmarkId::new("profibus-fdl", len), &bytes, |b, bytes| {
            b.iter(|| {
                let (t, n) = Telegram::parse(black_box(bytes)).unwrap();
                black_box((t, n))
            })
        });
        g.bench_with_input(BenchmarkId::new("profirust", len), &bytes, |b, bytes| {
            b.iter(|| {
                let r = profirust::fdl::Telegram::deserialize(black_box(bytes))
                    .unwrap()
                    .unwrap();
                black_box(r)
            })
        });
    }
    g.finish();
}

fn encode(c: &mut Criterion) {
    let mut g = c.benchmark_group("encode");
    for len in [2usize, 244] {
        let data: Vec<u8> = (0..len as u8).collect();
        g.throughput(Throughput::Elements(1));
        g.bench_with_input(BenchmarkId::new("profibus-fdl", len), &data, |b, data| {
            let mut buf = [0u8; 255];
            b.iter(|| {
                let t = support::data_exchange(black_box(data));
                black_box(t.emit(&mut buf).unwrap())
            })
        });
        g.bench_with_input(BenchmarkId::new("profirust", len), &data, |b, data| {
            let mut buf = [0u8; 255];
            let h = support::profirust_data_exchange();
            b.iter(|| {
                let d = black_box(data);
                black_box(h.serialize(&mut buf, d.len(), |pdu| pdu.copy_from_slice(d)))
            })
        });
    }
    g.finish();
}

criterion_group!(benches, decode, encode);
criterion_main!(benches);
