//! GSD parser: arbitrary bytes (read as Latin-1, like a file) never make
//! the parser or the semantic API panic, in strict or lenient mode; what
//! parses strictly parses leniently to the same model (strict mode only
//! turns quirks into errors); and whatever parses survives write → parse
//! unchanged.
//!
//! Run: `cargo +nightly fuzz run gsd_parse fuzz/corpus/gsd_parse crates/devices/gsd crates/devices/gsd/corpus -- -dict=fuzz/gsd.dict`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::config::gsd::{decode_latin1, Gsd, ParseOptions};

fuzz_target!(|data: &[u8]| {
    let text = decode_latin1(data);
    let lenient = Gsd::parse(&text, ParseOptions::LENIENT);
    let strict = Gsd::parse(&text, ParseOptions::STRICT);
    if let Ok(s) = &strict {
        let l = lenient
            .as_ref()
            .unwrap_or_else(|e| panic!("parses strictly but not leniently: {e}"));
        assert_eq!(l.gsd, s.gsd, "strict and lenient models differ");
    }
    // Both modes give the same model: the semantic API and the writer
    // see it once.
    let Ok(p) = &lenient else {
        return;
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
});
