//! Arbitrary bytes at arbitrary times into an FDL active station running
//! the DP master core: requests from other masters, tokens, garbage,
//! replies at odd moments. Nothing panics; time always advances.
#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams};
use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
use profibus_fdl::station::Station;
use profibus_fdl::{Baud, BusParams, Instant};

fuzz_target!(|data: &[u8]| {
    let params = BusParams::defaults(Baud::B1500000);
    let cfg = MasterConfig {
        address: 2,
        params,
        slaves: vec![
            SlaveParams::new(8, 0x0DCE, vec![0x11, 0x21]),
            SlaveParams::new(9, 0x0008, vec![0x42, 0xC1, 0x02, 0x04]),
        ],
        options: MasterOptions::default(),
    };
    let mut st = ActiveStation::new(ActiveConfig::new(2, params), DpMaster::new(&cfg).unwrap());
    let mut now = Instant::ZERO;
    // Records: [delay µs, len, bytes…].
    let mut rest = data;
    while let [delay, len, tail @ ..] = rest {
        let n = (*len as usize).min(tail.len());
        now += std::time::Duration::from_micros(*delay as u64 * 8);
        if let Some(t) = st.poll_timeout() {
            if t <= now {
                st.handle_timeout(now);
            }
        }
        while st.poll_transmit(now).is_some() {}
        st.handle_rx(now, &tail[..n]);
        while st.poll_transmit(now).is_some() {}
        rest = &tail[n..];
    }
    // Let it run on for a while with silence: every deadline it asks for
    // must lead somewhere (no deadline that stays due without progress).
    let mut stuck = 0;
    for _ in 0..500 {
        let Some(t) = st.poll_timeout() else { break };
        if t <= now {
            stuck += 1;
            assert!(stuck < 100, "deadline {t} stays due at {now}");
        } else {
            stuck = 0;
        }
        now = now.max(t);
        st.handle_timeout(now);
        while st.poll_transmit(now).is_some() {}
    }
});
