//! Scan to bus file, the decoding half: for every GSD file of the project
//! and the corpus, module selections the file allows are turned into
//! their Chk_Cfg bytes and back (`config::discover::modules_for_cfg`);
//! the fit found must give the same bytes and be a selection the file
//! accepts, and it is never longer than the selection that made the
//! bytes.

use profibus_dp::config::discover::{modules_for_cfg, CfgMatch};
use profibus_dp::config::gsd::{Gsd, ParseOptions};

mod common;
use common::gsd_files;

/// A small deterministic generator (xorshift), so the selections are the
/// same on every run.
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: usize) -> usize {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 % n as u64) as usize
    }
}

fn cfg_of(g: &Gsd, sel: &[usize]) -> Vec<u8> {
    sel.iter().flat_map(|i| g.modules[*i].cfg.clone()).collect()
}

#[test]
fn selections_of_every_file_come_back_from_their_bytes() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let (mut files, mut checked) = (0, 0);
    for path in gsd_files() {
        let Ok(parsed) = Gsd::from_file(&path, ParseOptions::LENIENT) else {
            continue;
        };
        let g = parsed.gsd;
        if g.modules.is_empty() {
            continue;
        }
        files += 1;
        for _ in 0..60 {
            let sel: Vec<usize> = if g.modular_station {
                let max = usize::from(g.max_module.unwrap_or(4)).clamp(1, 6);
                // Fixed preset modules come first, as a configurator puts them.
                let presets =
                    (0..g.modules.len()).filter(|i| g.fix_preset_modules && g.modules[*i].preset);
                presets
                    .chain((0..1 + rng.below(max)).map(|_| rng.below(g.modules.len())))
                    .collect()
            } else {
                vec![rng.below(g.modules.len())]
            };
            if !g.check_selection(&sel).is_empty() || cfg_of(&g, &sel).is_empty() {
                continue;
            }
            let bytes = cfg_of(&g, &sel);
            match modules_for_cfg(&g, &bytes) {
                CfgMatch::Found { best, others } => {
                    for fit in std::iter::once(&best).chain(&others) {
                        assert_eq!(cfg_of(&g, &fit.modules), bytes, "{}", path.display());
                    }
                    assert!(best.modules.len() <= sel.len(), "{}", path.display());
                    checked += 1;
                }
                CfgMatch::NoFit(n) => {
                    // Slot rules may refuse what check_selection allows;
                    // nothing else may.
                    assert!(
                        !g.slots.is_empty(),
                        "{}: {:?} → {:02X?}: {}",
                        path.display(),
                        sel,
                        bytes,
                        n.describe(&g)
                    );
                }
            }
        }
    }
    assert!(files >= 30, "only {files} GSD files with modules");
    eprintln!("{files} files, {checked} selections");
    assert!(checked >= 1500, "only {checked} selections checked");
}
