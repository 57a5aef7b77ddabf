//! GSD parser: arbitrary bytes (read as Latin-1, like a file) never make
//! the parser or the semantic API panic, in strict or lenient mode, and
//! whatever parses survives write → parse unchanged.
//!
//! Run: `cargo +nightly fuzz run gsd_parse fuzz/corpus/gsd_parse gsd gsd/corpus -- -dict=fuzz/gsd.dict`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::gsd::{decode_latin1, Gsd, ParseOptions};

fuzz_target!(|data: &[u8]| {
    let text = decode_latin1(data);
    for opts in [ParseOptions::LENIENT, ParseOptions::STRICT] {
        let Ok(p) = Gsd::parse(&text, opts) else {
            continue;
        };
        let g = &p.gsd;
        let all: Vec<usize> = (0..g.modules.len()).collect();
        for sel in [g.default_selection(), all] {
            let _ = g.chk_cfg(&sel);
            let _ = g.user_prm_data(&sel, &[]);
            let _ = g.parameters(&sel);
            let _ = g.check_selection(&sel);
        }
        for m in &g.modules {
            let _ = g.find_module(&m.name);
        }
        if g.is_writable() {
            let written = g.write();
            let again = Gsd::parse(&written, ParseOptions::LENIENT)
                .unwrap_or_else(|e| panic!("written text does not parse: {e}\n{written}"));
            assert_eq!(&again.gsd, g, "round trip\n{written}");
        }
    }
});
