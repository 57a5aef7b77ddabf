//! The master side of the PKW handshake (`PkwClient`) in the BM4 and
//! Omega dialects, fed arbitrary input images: jobs of any command on any
//! parameter, replies of any content at any cycle, timeouts. Checks: no
//! panic; the output image keeps its length and only the 8 PKW bytes
//! change; a job ends (answer, refusal, bad response or timeout) at the
//! latest one cycle after its timeout, and the client is idle again
//! after the reset it sends.
//!
//! Input: byte 0 selects the dialect; then records `op, a, b, c, d`
//! followed by 8 bytes of the slave's PKW input words: `op & 1` starts a
//! job (`a` the command, `b c` the PNU, `d` the value) when the client is
//! idle; `op >> 1` is the time step in ms.
//!
//! Run: `cd fuzz && cargo +nightly fuzz run pkw_client`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_devices::pkw::client::PkwClient;
use profibus_devices::pkw::{Command, PKW_LEN};
use profibus_fdl::Instant;
use std::time::Duration;

const TIMEOUT: Duration = Duration::from_millis(200);

fuzz_target!(|data: &[u8]| {
    let Some((&sel, mut rest)) = data.split_first() else {
        return;
    };
    let dialects: Vec<_> = profibus_devices::PROFILES
        .iter()
        .filter_map(|p| p.pkw)
        .collect();
    let dialect = dialects[sel as usize % dialects.len()];
    let mut client = PkwClient::new(dialect, TIMEOUT);
    let mut now = Instant::ZERO;
    let mut cycle = 0u64;
    let mut inputs = [0u8; 12];
    let mut outputs = [0x5Au8; 12];
    let mut started: Option<Instant> = None;
    while rest.len() >= 13 {
        let (rec, tail) = rest.split_at(13);
        rest = tail;
        let [op, a, b, c, d, pkw @ ..] = rec else {
            unreachable!()
        };
        now += Duration::from_millis((op >> 1) as u64);
        cycle += 1;
        if op & 1 != 0 && client.is_idle() {
            let pnu = u16::from_be_bytes([*b, *c]);
            let v = *d as u16 * 257;
            let cmd = match a % 8 {
                0 => Command::Read,
                1 => Command::WriteWord(v),
                2 => Command::WriteDword((v as u32).wrapping_mul(65539)),
                3 => Command::Describe(*d as u16),
                4 => Command::ReadElement(*d as u16),
                5 => Command::WriteElementWord {
                    index: *d as u16,
                    value: v,
                },
                6 => Command::WriteElementDword {
                    index: *d as u16,
                    value: v as u32,
                },
                _ => Command::Unsupported(*d),
            };
            if client.start(now, pnu, cmd).is_ok() {
                started = Some(now);
            }
        }
        inputs[..PKW_LEN].copy_from_slice(pkw);
        let result = client.poll(now, cycle, &inputs, &mut outputs);
        assert_eq!(
            &outputs[PKW_LEN..],
            &[0x5A; 4],
            "bytes after the PKW words written"
        );
        if result.is_some() {
            assert!(started.take().is_some(), "a result without a job");
        } else if let Some(t) = started {
            assert!(
                now.saturating_duration_since(t) <= TIMEOUT + Duration::from_millis(127),
                "job running {:?} after a timeout of {TIMEOUT:?}",
                now.saturating_duration_since(t)
            );
        }
    }
    // Whatever state it is in, a few quiet cycles make it idle.
    for _ in 0..8 {
        now += TIMEOUT;
        cycle += 1;
        let _ = client.poll(now, cycle, &[0u8; PKW_LEN], &mut outputs);
    }
    assert!(client.is_idle(), "not idle after its timeout and reset");
});
