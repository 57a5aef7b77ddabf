//! The RFID client does not allocate while it runs commands: `VER` and
//! `GT` against the reader's side of the handshake, every call of
//! `RfidClient::poll` counted by a global allocator.

use profibus::devices::rfid::client::RfidClient;
use profibus::devices::rfid::commands::VERSION;
use profibus::devices::rfid::link::{Line, ReaderLink};
use profibus::fdl::Instant;
use std::time::Duration;

use profibus_io::alloc_count;

#[global_allocator]
static GLOBAL: alloc_count::Counting = alloc_count::Counting;

#[test]
fn a_command_runs_without_allocating() {
    // The reader's side of the handshake answers; only the client's calls
    // are counted.
    let mut link = ReaderLink::new();
    let mut c = RfidClient::new(Duration::from_secs(1));
    let (mut out, mut inp) = ([0u8; 16], [0u8; 16]);
    let mut answer = Vec::with_capacity(64);
    let mut allocs = 0;
    let t0 = Instant::ZERO;
    for cmd in [&b"VER"[..], b"GT"] {
        c.start(t0, cmd).unwrap();
        for cycle in 0..1000u64 {
            let now = t0 + Duration::from_millis(cycle);
            let before = alloc_count::allocations();
            let r = c.poll(now, cycle, &inp, &mut out);
            let done = r.map(|r| {
                let a = r.unwrap();
                answer.clear();
                answer.extend_from_slice(a);
            });
            allocs += alloc_count::allocations() - before;
            if done.is_some() {
                break;
            }
            // One Data_Exchange: the reader answers VER as the manual does.
            link.request(&out, false);
            while let Some(l) = link.take_command() {
                let a: &[u8] = match l {
                    Line::Text(t) if t == b"VER" => VERSION,
                    _ => b"E004015012345678\r",
                };
                link.push_answer(a);
            }
            link.response(&mut inp);
        }
        if cmd == b"VER" {
            assert_eq!(answer, VERSION);
        }
    }
    assert_eq!(answer, b"E004015012345678\r");
    assert_eq!(allocs, 0, "allocations in RfidClient::poll");
}
