//! From a slave's real configuration back to GSD modules: which module
//! selection of a GSD file gives exactly the identifier bytes a slave
//! returned in Get_Cfg (commissioning: `dpctl scan --write-config`).
//!
//! A modular station's Get_Cfg is the concatenation of its modules'
//! `Module` identifier bytes, in slot order (IEC 61158-6-3 Chk_Cfg; GSD
//! specification: a module's configuration is sent as written). The
//! search splits the bytes into modules of the file, respecting
//! `Max_Module`, the `SlotDefinition` rules (slot numbers from
//! `Modul_Offset`), `Fix_Preset_Modules` with the `Preset` modules first,
//! and the file's length limits ([`Gsd::check_selection`]). A compact
//! station matches one of its modules (or all of them in file order, as
//! some files mean them).
//!
//! Where several selections fit, the simplest comes first: the fewest
//! modules, then the modules declared earliest. Modules with the same
//! bytes are told apart by nothing on the wire: each position lists
//! every candidate ([`Fit::alternatives`]) and the first is chosen.

use crate::config::gsd::Gsd;
use crate::pdu::cfg;

/// Longest search (steps) before giving up on listing more fits; the best
/// fit is found by a breadth-first pass that does not depend on it.
const SEARCH_BUDGET: usize = 200_000;
/// Most alternative fits listed.
pub const MAX_OTHER_FITS: usize = 8;

/// One module selection that gives the bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fit {
    /// The chosen module per slot (indices into `Gsd::modules`).
    pub modules: Vec<usize>,
    /// Per slot, every module that fits there with the same bytes
    /// (the chosen one first).
    pub alternatives: Vec<Vec<usize>>,
}

impl Fit {
    /// The chosen modules' names, as the bus file's `modules` key wants
    /// them.
    pub fn names<'g>(&self, gsd: &'g Gsd) -> Vec<&'g str> {
        self.modules
            .iter()
            .map(|i| gsd.modules[*i].name.as_str())
            .collect()
    }

    /// Whether some slot could hold another module with the same bytes.
    pub fn is_ambiguous(&self) -> bool {
        self.alternatives.iter().any(|a| a.len() > 1)
    }
}

/// The result of [`modules_for_cfg`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CfgMatch {
    /// At least one selection fits: the simplest, and up to
    /// [`MAX_OTHER_FITS`] others.
    Found {
        /// The simplest fit.
        best: Fit,
        /// Other fits, simplest first.
        others: Vec<Fit>,
    },
    /// No selection fits.
    NoFit(Nearest),
}

/// Why nothing fits, for the message: how far the bytes match modules of
/// the file, and the first identifier no module explains.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Nearest {
    /// Bytes from the start that a sequence of modules reproduces.
    pub matched_bytes: usize,
    /// Modules of that longest partial fit.
    pub modules: Vec<usize>,
    /// The first identifier after it, as bytes (empty when all bytes
    /// matched but a rule such as `Max_Module` refused the selection).
    pub unmatched: Vec<u8>,
    /// The rule that refused an otherwise matching selection.
    pub refused: Option<String>,
    /// A module whose I/O lengths equal the unmatched identifier's (its
    /// bytes are a different encoding of the same data), if any.
    pub same_size: Option<usize>,
}

impl Nearest {
    /// In words: "the modules A, B match the first 3 byte(s); identifier
    /// 13 matches no module (`C` has the same I/O size with other
    /// bytes)".
    pub fn describe(&self, gsd: &Gsd) -> String {
        let names: Vec<&str> = self
            .modules
            .iter()
            .map(|i| gsd.modules[*i].name.trim())
            .collect();
        let mut s = if self.matched_bytes == 0 {
            "no module of the file matches the first identifier".to_string()
        } else {
            format!(
                "the modules {} match the first {} byte(s)",
                names.join(", "),
                self.matched_bytes
            )
        };
        if let Some(r) = &self.refused {
            s.push_str(&format!(", but {r}"));
        }
        if !self.unmatched.is_empty() {
            let hex: Vec<String> = self.unmatched.iter().map(|b| format!("{b:02X}")).collect();
            s.push_str(&format!("; identifier {} matches no module", hex.join(" ")));
            if let Some(m) = self.same_size {
                s.push_str(&format!(
                    " (`{}` has the same I/O size with other bytes)",
                    gsd.modules[m].name.trim()
                ));
            }
        }
        s
    }
}

/// The module selections of `gsd` whose identifier bytes are exactly
/// `cfg` (a slave's Get_Cfg answer).
pub fn modules_for_cfg(gsd: &Gsd, cfg: &[u8]) -> CfgMatch {
    if !gsd.modular_station {
        return compact(gsd, cfg);
    }
    let mut search = Search {
        gsd,
        cfg,
        first_slot: first_slot(gsd),
        steps: 0,
        fits: Vec::new(),
        refused: None,
        longest: (0, Vec::new()),
        path: Vec::new(),
        longest_module: gsd.modules.iter().map(|m| m.cfg.len()).max().unwrap_or(0),
    };
    let max = gsd.max_module.map_or(usize::MAX, usize::from);
    // Iterative deepening: fits with n modules before fits with n + 1,
    // so the first fit found is the simplest.
    let most = cfg.len().min(max).max(1);
    for depth in 1..=most {
        search.dfs(0, depth);
        if search.fits.len() > MAX_OTHER_FITS || search.steps > SEARCH_BUDGET {
            break;
        }
    }
    if search.fits.is_empty() {
        let (matched_bytes, modules) = search.longest.clone();
        let rest = &cfg[matched_bytes.min(cfg.len())..];
        let unmatched = first_identifier(rest);
        let same_size = same_size_module(gsd, &unmatched);
        return CfgMatch::NoFit(Nearest {
            matched_bytes,
            modules,
            unmatched,
            refused: search.refused,
            same_size,
        });
    }
    let mut fits = search.fits;
    let best = fits.remove(0);
    fits.truncate(MAX_OTHER_FITS);
    CfgMatch::Found { best, others: fits }
}

/// The slot number of the first module: `Modul_Offset`, else the lowest
/// `SlotDefinition` slot, else 0.
fn first_slot(gsd: &Gsd) -> u32 {
    gsd.modul_offset
        .map(u32::from)
        .or_else(|| gsd.slots.iter().map(|s| u32::from(s.number)).min())
        .unwrap_or(0)
}

fn first_identifier(rest: &[u8]) -> Vec<u8> {
    match cfg::identifiers(rest).next() {
        Some(Ok(id)) => id.raw.to_vec(),
        _ => rest.iter().take(1).copied().collect(),
    }
}

fn same_size_module(gsd: &Gsd, id: &[u8]) -> Option<usize> {
    let want = match cfg::identifiers(id).next() {
        Some(Ok(id)) => (id.input_bytes(), id.output_bytes()),
        _ => return None,
    };
    if want == (0, 0) {
        return None;
    }
    gsd.modules.iter().position(|m| {
        m.io()
            .is_ok_and(|t| (t.input_bytes, t.output_bytes) == want)
    })
}

fn compact(gsd: &Gsd, cfg: &[u8]) -> CfgMatch {
    let same: Vec<usize> = (0..gsd.modules.len())
        .filter(|i| gsd.modules[*i].cfg == cfg)
        .collect();
    if let Some(&first) = same.first() {
        return CfgMatch::Found {
            best: Fit {
                modules: vec![first],
                alternatives: vec![same],
            },
            others: vec![],
        };
    }
    // Some files mean all their modules together, in file order.
    let all: Vec<u8> = gsd.modules.iter().flat_map(|m| m.cfg.clone()).collect();
    if gsd.modules.len() > 1 && all == cfg {
        let every: Vec<usize> = (0..gsd.modules.len()).collect();
        return CfgMatch::Found {
            best: Fit {
                alternatives: every.iter().map(|i| vec![*i]).collect(),
                modules: every,
            },
            others: vec![],
        };
    }
    let unmatched = first_identifier(cfg);
    CfgMatch::NoFit(Nearest {
        matched_bytes: 0,
        modules: vec![],
        same_size: same_size_module(gsd, cfg).or_else(|| same_size_module(gsd, &unmatched)),
        unmatched: cfg.to_vec(),
        refused: None,
    })
}

struct Search<'a> {
    gsd: &'a Gsd,
    cfg: &'a [u8],
    first_slot: u32,
    steps: usize,
    fits: Vec<Fit>,
    refused: Option<String>,
    longest: (usize, Vec<usize>),
    /// Per placed slot, the candidates (the chosen one first).
    path: Vec<Vec<usize>>,
    /// Bytes of the longest module: prunes splits that cannot finish.
    longest_module: usize,
}

impl Search<'_> {
    /// The modules that may stand in slot position `k` with the bytes at
    /// `at`, grouped by their byte length (each group: same bytes).
    fn candidates(&mut self, at: usize, k: usize) -> Vec<(usize, Vec<usize>)> {
        let gsd = self.gsd;
        let slot_no = self.first_slot + k as u32;
        let slot = gsd.slots.iter().find(|s| u32::from(s.number) == slot_no);
        let presets: Vec<usize> = (0..gsd.modules.len())
            .filter(|i| gsd.modules[*i].preset)
            .collect();
        let mut groups: Vec<(usize, Vec<usize>)> = Vec::new();
        for (i, m) in gsd.modules.iter().enumerate() {
            let n = m.cfg.len();
            if n == 0 || self.cfg.get(at..at + n) != Some(m.cfg.as_slice()) {
                continue;
            }
            if let Some(s) = slot {
                let allowed = m
                    .reference
                    .is_some_and(|r| s.allowed.contains(i64::from(r)) || r == s.default_module);
                if !allowed {
                    continue;
                }
            }
            if gsd.fix_preset_modules && k < presets.len() && presets[k] != i {
                self.refused.get_or_insert_with(|| {
                    format!(
                        "the file fixes the preset module `{}` at position {}",
                        gsd.modules[presets[k]].name.trim(),
                        k + 1
                    )
                });
                continue;
            }
            match groups.iter_mut().find(|(len, _)| *len == n) {
                Some((_, g)) => g.push(i),
                None => groups.push((n, vec![i])),
            }
        }
        groups
    }

    fn dfs(&mut self, at: usize, depth_left: usize) {
        self.steps += 1;
        if self.fits.len() > MAX_OTHER_FITS {
            return;
        }
        if at > self.longest.0 {
            self.longest = (at, self.path.iter().map(|c| c[0]).collect());
        }
        if self.steps > SEARCH_BUDGET {
            return;
        }
        if at == self.cfg.len() {
            if depth_left == 0 {
                self.accept();
            }
            return;
        }
        let rest = self.cfg.len() - at;
        if depth_left == 0 || rest > depth_left * self.longest_module {
            return;
        }
        let k = self.path.len();
        for (len, group) in self.candidates(at, k) {
            self.path.push(group);
            self.dfs(at + len, depth_left - 1);
            self.path.pop();
        }
    }

    fn accept(&mut self) {
        let modules: Vec<usize> = self.path.iter().map(|c| c[0]).collect();
        let gsd = self.gsd;
        let preset_count = gsd.modules.iter().filter(|m| m.preset).count();
        if gsd.fix_preset_modules && modules.len() < preset_count {
            self.refused
                .get_or_insert_with(|| format!("the {preset_count} preset modules are fixed"));
            return;
        }
        let problems = gsd.check_selection(&modules);
        if let Some(p) = problems.first() {
            self.refused.get_or_insert_with(|| p.to_string());
            return;
        }
        if self.fits.iter().any(|f| f.modules == modules) {
            return;
        }
        self.fits.push(Fit {
            modules,
            alternatives: self.path.clone(),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::gsd::{Gsd, ParseOptions};

    fn gsd(body: &str) -> Gsd {
        let text = format!(
            "#Profibus_DP\nGSD_Revision = 3\nVendor_Name = \"T\"\nModel_Name = \"M\"\n\
             Ident_Number = 0x1234\nProtocol_Ident = 0\nStation_Type = 0\n\
             9.6_supp = 1\n{body}\n"
        );
        Gsd::parse(&text, ParseOptions::default()).unwrap().gsd
    }

    const MODULAR: &str = "Modular_Station = 1\nMax_Module = 4\n\
        Max_Input_Len = 100\nMax_Output_Len = 100\nMax_Data_Len = 200\n\
        Module = \"8 DI\" 0x10\nEndModule\n\
        Module = \"16 DI\" 0x11\nEndModule\n\
        Module = \"8 DI twin\" 0x10\nEndModule\n\
        Module = \"2x8 DI\" 0x10,0x10\nEndModule\n\
        Module = \"8 DO\" 0x20\nEndModule\n";

    #[test]
    fn simplest_fit_first_and_the_others_listed() {
        let g = gsd(MODULAR);
        let CfgMatch::Found { best, others } = modules_for_cfg(&g, &[0x10, 0x10, 0x20]) else {
            panic!()
        };
        assert_eq!(best.names(&g), ["2x8 DI", "8 DO"]);
        assert!(!best.is_ambiguous());
        assert_eq!(others.len(), 1);
        assert_eq!(others[0].names(&g), ["8 DI", "8 DI", "8 DO"]);
        // "8 DI" and "8 DI twin" send the same byte.
        assert_eq!(others[0].alternatives[0], vec![0, 2]);
        assert!(others[0].is_ambiguous());
    }

    #[test]
    fn max_module_and_unknown_identifiers() {
        let g = gsd(MODULAR);
        // Five single modules: Max_Module 4 refuses, no other split.
        let CfgMatch::NoFit(n) = modules_for_cfg(&g, &[0x11, 0x11, 0x11, 0x11, 0x11]) else {
            panic!()
        };
        assert_eq!(n.matched_bytes, 4);
        assert!(n.unmatched == [0x11] || n.refused.is_some());
        // An identifier no module has: 1 word in (0x50) after 8 DO.
        let CfgMatch::NoFit(n) = modules_for_cfg(&g, &[0x20, 0x50]) else {
            panic!()
        };
        assert_eq!(n.matched_bytes, 1);
        assert_eq!(n.unmatched, [0x50]);
        assert_eq!(
            n.describe(&g),
            "the modules 8 DO match the first 1 byte(s); identifier 50 matches no module \
             (`16 DI` has the same I/O size with other bytes)"
        );
        // Special format for 1 byte in (0x40 0x00): same size as "8 DI".
        let CfgMatch::NoFit(n) = modules_for_cfg(&g, &[0x40, 0x00]) else {
            panic!()
        };
        assert_eq!(n.same_size, Some(0));
    }

    #[test]
    fn slot_definition_restricts_slots() {
        let g = gsd("Modular_Station = 1\nMax_Module = 2\nModul_Offset = 1\n\
             Max_Input_Len = 10\nMax_Output_Len = 10\nMax_Data_Len = 20\n\
             Module = \"DI\" 0x10\n1\nEndModule\n\
             Module = \"DI alt\" 0x10\n2\nEndModule\n\
             SlotDefinition\nSlot(1) = \"first\" 2 2\nSlot(2) = \"second\" 1 1,2\n\
             EndSlotDefinition");
        let CfgMatch::Found { best, .. } = modules_for_cfg(&g, &[0x10, 0x10]) else {
            panic!()
        };
        // Slot 1 allows only module 2 ("DI alt"); slot 2 both.
        assert_eq!(best.names(&g), ["DI alt", "DI"]);
        assert_eq!(best.alternatives, vec![vec![1], vec![0, 1]]);
    }

    #[test]
    fn compact_station() {
        let g =
            gsd("Module = \"PPO 1\" 0xF3,0xF1\nEndModule\nModule = \"PPO 2\" 0xF3,0xF5\nEndModule");
        let CfgMatch::Found { best, .. } = modules_for_cfg(&g, &[0xF3, 0xF5]) else {
            panic!()
        };
        assert_eq!(best.names(&g), ["PPO 2"]);
        assert!(matches!(
            modules_for_cfg(&g, &[0xF3]),
            CfgMatch::NoFit(Nearest {
                matched_bytes: 0,
                ..
            })
        ));
    }

    #[test]
    fn many_identical_modules_stay_fast() {
        // 32 one-byte modules of the same kind, 4 module kinds that
        // produce the byte: the search must not enumerate 4^32 splits.
        let mut body = String::from("Modular_Station = 1\nMax_Module = 64\n");
        body.push_str("Max_Input_Len = 244\nMax_Output_Len = 244\nMax_Data_Len = 488\n");
        for n in 0..4 {
            body.push_str(&format!("Module = \"DI {n}\" 0x10\nEndModule\n"));
        }
        body.push_str("Module = \"DI pair\" 0x10,0x10\nEndModule\n");
        let g = gsd(&body);
        let cfg = [0x10; 32];
        let CfgMatch::Found { best, others } = modules_for_cfg(&g, &cfg) else {
            panic!()
        };
        assert_eq!(best.modules.len(), 16);
        assert!(others.len() <= MAX_OTHER_FITS);
    }
}
