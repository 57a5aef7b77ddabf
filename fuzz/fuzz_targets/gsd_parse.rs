//! GSD parser: arbitrary bytes (read as Latin-1, like a file) never make
//! the parser or the semantic API panic, in strict or lenient mode, and
//! whatever parses survives write → parse unchanged.
//!
//! Run: `cargo +nightly fuzz run gsd_parse fuzz/corpus/gsd_parse gsd gsd/corpus -- -dict=fuzz/gsd.dict`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::gsd::{decode_latin1, Gsd, ParseOptions};

/// Whether every string of the model can be written (no `"`).
fn representable(g: &Gsd) -> bool {
    let mut s: Vec<&str> = [
        &g.vendor_name,
        &g.model_name,
        &g.revision,
        &g.hardware_release,
        &g.software_release,
        &g.order_number,
        &g.info_text,
        &g.implementation_type,
        &g.bitmap_device,
        &g.bitmap_diag,
        &g.bitmap_sf,
    ]
    .iter()
    .filter_map(|o| o.as_deref())
    .collect();
    for m in &g.modules {
        s.push(&m.name);
        s.extend(m.info_text.as_deref());
    }
    s.extend(g.ext_user_prm_data.iter().map(|p| p.name.as_str()));
    s.extend(
        g.prm_texts
            .iter()
            .flat_map(|t| t.texts.iter().map(|v| v.text.as_str())),
    );
    s.extend(g.slots.iter().map(|x| x.name.as_str()));
    s.extend(
        g.unit_diag_bits
            .iter()
            .chain(&g.unit_diag_not_bits)
            .map(|t| t.text.as_str()),
    );
    s.extend(
        g.unit_diag_areas
            .iter()
            .flat_map(|a| a.values.iter().map(|v| v.text.as_str())),
    );
    s.extend(
        g.slave_family
            .iter()
            .flat_map(|f| f.sub.iter().map(String::as_str)),
    );
    s.iter().all(|x| !x.contains('"'))
}

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
        if representable(g) {
            let written = g.write();
            let again = Gsd::parse(&written, ParseOptions::LENIENT)
                .unwrap_or_else(|e| panic!("written text does not parse: {e}\n{written}"));
            assert_eq!(&again.gsd, g, "round trip\n{written}");
        }
    }
});
