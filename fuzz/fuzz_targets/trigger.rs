//! Trigger expressions (`profibus_dp::monitor::trigger`): arbitrary text
//! never panics the parser; an expression that parses prints in a
//! canonical form that parses to the same expression, and evaluates on
//! any observation without panicking.
//!
//! Run: `cargo +nightly fuzz run trigger`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::monitor::trigger::{Observation, Trigger};
use std::time::Duration;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let Ok(t) = Trigger::parse(&text) else {
        return;
    };
    let canon = t.to_string();
    let again = Trigger::parse(&canon).expect("the canonical form parses");
    assert_eq!(again, t, "{canon}");
    // An observation from the input's first bytes.
    let b = |i: usize| data.get(i).copied().unwrap_or(0);
    let o = Observation {
        t: Duration::from_millis(u64::from(b(0)) * 100),
        src: Some(b(1) & 0x7F),
        dst: Some(b(2) & 0x7F),
        dsap: (b(3) & 0x40 != 0).then_some(b(3) & 0x3F),
        ssap: (b(4) & 0x40 != 0).then_some(b(4) & 0x3F),
        fc: Some((b(5) & 0x0F, b(5) & 0x40 != 0)),
        len: Some(usize::from(b(6))),
        service: Some("Slave_Diag"),
        request: b(7) & 1 != 0,
        response: b(7) & 1 == 0,
        diag: vec!["Cfg_Fault".into()],
        retry: b(7) & 2 != 0,
        ..Observation::default()
    };
    let _ = t.matches(&o);
    assert_eq!(t.matches(&o), again.matches(&o));
});
