//! The master side of the RFID reader's handshake (`RfidClient`) fed
//! arbitrary 16-byte input images: any command line, fragments of any
//! content, flags and sequence numbers at any cycle, restarts. Checks: no
//! panic; an answer is never longer than the client's capacity; a
//! command ends (answer or error) at the latest one cycle after its
//! timeout; the output image keeps its length.
//!
//! Input: byte 0 = capacity / 4 (0: the default); then records `op` and
//! 16 bytes of inputs: `op & 3 == 0` starts a command (the 16 bytes are
//! the command line) when the client is idle, `op & 3 == 1` restarts,
//! otherwise the bytes are the reader's inputs; `op >> 2` is the time step
//! in ms.
//!
//! Run: `cd fuzz && cargo +nightly fuzz run rfid_client`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_devices::rfid::client::{RfidClient, DEFAULT_ANSWER_CAPACITY};
use profibus_devices::rfid::TELEGRAM_LEN;
use profibus_fdl::Instant;
use std::time::Duration;

const TIMEOUT: Duration = Duration::from_millis(300);

fuzz_target!(|data: &[u8]| {
    let Some((&cap, mut rest)) = data.split_first() else {
        return;
    };
    let capacity = if cap == 0 {
        DEFAULT_ANSWER_CAPACITY
    } else {
        cap as usize * 4
    };
    let mut client = RfidClient::with_capacity(TIMEOUT, capacity);
    let mut now = Instant::ZERO;
    let mut cycle = 0u64;
    let mut outputs = [0u8; TELEGRAM_LEN];
    let mut started: Option<Instant> = None;
    while rest.len() > TELEGRAM_LEN {
        let (rec, tail) = rest.split_at(TELEGRAM_LEN + 1);
        rest = tail;
        let (op, bytes) = (rec[0], &rec[1..]);
        now += Duration::from_millis((op >> 2) as u64);
        cycle += 1;
        match op & 3 {
            0 => {
                if client.is_idle() && client.start(now, bytes).is_ok() {
                    started = Some(now);
                }
                continue;
            }
            1 => {
                client.restart(&mut outputs);
                continue;
            }
            _ => {}
        }
        match client.poll(now, cycle, bytes, &mut outputs) {
            Some(Ok(answer)) => {
                assert!(
                    answer.len() <= capacity,
                    "{} bytes > {capacity}",
                    answer.len()
                );
                assert!(started.take().is_some(), "an answer without a command");
            }
            Some(Err(_)) => assert!(started.take().is_some(), "an error without a command"),
            None => {
                if let Some(t) = started {
                    assert!(
                        now.saturating_duration_since(t) <= TIMEOUT + Duration::from_millis(63),
                        "command running {:?} after a timeout of {TIMEOUT:?}",
                        now.saturating_duration_since(t)
                    );
                }
            }
        }
        assert!(
            client.is_idle() == started.is_none(),
            "idle state and command disagree"
        );
    }
});
