//! Commissioning a BK3000 from its configuration (`dpctl scan
//! --write-config`): the terminal strips whose Chk_Cfg is a coupler's
//! Get_Cfg answer.
//!
//! The configuration tells the strip only in part (manual pages 48-50,
//! auto configuration): each complex terminal in plug order with the
//! identifier bytes of its format, then the digital terminals' bits
//! packed into bytes (`0x1n` inputs, `0x2n` outputs, `0x3n` both). So a
//! strip found here has the complex terminals in plug order, each the
//! first catalogue terminal that sends its bytes (the others that do are
//! named in [`notes`]), then the digital data as 8-bit terminals
//! (`KL1408`, `KL2408`), then the end terminal. Where the digital
//! terminals sat between the complex ones, how many bits each had, and
//! passive terminals (power feeds) are not on the bus.

use super::catalogue::{Class, Mapping, TerminalType, Variant, CATALOGUE, END_TERMINAL};

/// The digital terminals written for each byte of digital data.
const DIGITAL_IN: &str = "KL1408";
const DIGITAL_OUT: &str = "KL2408";
/// Most candidate strips tried.
const MAX_STRIPS: usize = 8;

/// A complex terminal's format that a terminal list can name: its
/// terminal, the mapping suffix needed (`None`: the default format).
struct Form {
    ty: &'static TerminalType,
    variant: &'static Variant,
    suffix: Option<Mapping>,
}

/// Every format a terminal list can ask for, catalogue order.
fn forms() -> Vec<Form> {
    let mut out = vec![];
    for ty in CATALOGUE.iter().filter(|t| t.class == Class::Complex) {
        for v in ty.variants {
            // `KL3102:compact` names the first compact format only.
            if ty.variant(v.mapping).is_some_and(|f| std::ptr::eq(f, v)) {
                let default = ty.default_variant().is_some_and(|d| std::ptr::eq(d, v));
                out.push(Form {
                    ty,
                    variant: v,
                    suffix: (!default).then_some(v.mapping),
                });
            }
        }
    }
    out
}

/// The simplest form for each distinct identifier string: a terminal's
/// default format before a named one, then catalogue order.
fn simplest(forms: &[Form]) -> Vec<&Form> {
    let mut out: Vec<&Form> = vec![];
    for pass in [true, false] {
        for f in forms.iter().filter(|f| f.suffix.is_none() == pass) {
            if !out.iter().any(|o| o.variant.cfg == f.variant.cfg) {
                out.push(f);
            }
        }
    }
    // Longest identifiers first: one 2-channel terminal before two
    // 1-channel ones.
    out.sort_by_key(|f| std::cmp::Reverse(f.variant.cfg.len()));
    out
}

fn name(f: &Form) -> String {
    match f.suffix {
        Some(m) => format!("{}:{}", f.ty.name, m.as_str()),
        None => f.ty.name.to_string(),
    }
}

/// Digital input and output bytes of identifiers that are all digital
/// (`0x1n`, `0x2n`, `0x3n`).
fn digital(cfg: &[u8]) -> Option<(usize, usize)> {
    let (mut i, mut o) = (0, 0);
    for &b in cfg {
        let n = usize::from(b & 0x0F) + 1;
        match b & 0xF0 {
            0x10 => i += n,
            0x20 => o += n,
            0x30 => (i, o) = (i + n, o + n),
            _ => return None,
        }
    }
    Some((i, o))
}

/// Terminal strips (names in plug order, end terminal last) whose
/// configuration may be `cfg`, simplest first; see the module docs.
pub fn strips_for_cfg(cfg: &[u8]) -> Vec<Vec<String>> {
    let forms = forms();
    let simple = simplest(&forms);
    let mut out = vec![];
    let mut path = vec![];
    search(cfg, &simple, &mut path, &mut out);
    out
}

fn search(rest: &[u8], forms: &[&Form], path: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    if out.len() >= MAX_STRIPS || path.len() > 64 {
        return;
    }
    if let Some((i, o)) = digital(rest) {
        let mut strip = path.clone();
        strip.extend(std::iter::repeat_n(DIGITAL_IN.to_string(), i));
        strip.extend(std::iter::repeat_n(DIGITAL_OUT.to_string(), o));
        strip.push(END_TERMINAL.to_string());
        out.push(strip);
    }
    for f in forms {
        if let Some(tail) = rest.strip_prefix(f.variant.cfg) {
            path.push(name(f));
            search(tail, forms, path, out);
            path.pop();
        }
    }
}

/// What a configuration leaves open about `terminals` (a strip of
/// [`strips_for_cfg`]): per complex terminal, the other catalogue
/// terminals that send the same bytes; the digital terminals' bits.
pub fn notes(terminals: &[String]) -> Vec<String> {
    let forms = forms();
    let mut out = vec![];
    for (k, t) in terminals.iter().enumerate() {
        let (n, mapping) = match t.split_once(':') {
            Some((n, m)) => (n, Some(m)),
            None => (t.as_str(), None),
        };
        let Some(f) = forms
            .iter()
            .find(|f| f.ty.name == n && f.suffix.map(Mapping::as_str) == mapping)
        else {
            continue;
        };
        let same: Vec<String> = forms
            .iter()
            .filter(|g| g.variant.cfg == f.variant.cfg && !std::ptr::eq(g.ty, f.ty))
            .map(name)
            .collect();
        if !same.is_empty() {
            out.push(format!(
                "terminal {} ({t}): {} send(s) the same bytes",
                k + 1,
                same.join(", ")
            ));
        }
    }
    let (i, o) = (
        terminals.iter().filter(|t| *t == DIGITAL_IN).count(),
        terminals.iter().filter(|t| *t == DIGITAL_OUT).count(),
    );
    if i + o > 0 {
        out.push(format!(
            "digital data: {i} input and {o} output byte(s), written as {DIGITAL_IN}/{DIGITAL_OUT}; \
             any digital terminals with as many bytes of bits give the same configuration, \
             and passive terminals (power feeds) are not on the bus"
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bk3000::image::Strip;

    fn cfg_of(list: &str) -> Vec<u8> {
        Strip::parse(list)
            .unwrap()
            .default_image(Default::default())
            .cfg
    }

    #[test]
    fn a_strip_is_found_again_as_far_as_its_configuration_tells() {
        let cfg = cfg_of("KL1104,KL2134,KL3102,KL4002,KL9010");
        assert_eq!(cfg, [0x50, 0x50, 0x60, 0x60, 0x10, 0x20]);
        let strips = strips_for_cfg(&cfg);
        assert_eq!(
            strips[0],
            ["KL3002", "KL4002", "KL1408", "KL2408", "KL9010"],
            "{strips:?}"
        );
        // Every candidate gives the same configuration.
        for s in &strips {
            assert_eq!(cfg_of(&s.join(",")), cfg, "{s:?}");
        }
        let notes = notes(&strips[0]);
        assert!(
            notes[0].starts_with("terminal 1 (KL3002): KL3102, KL3202")
                && notes[0].ends_with(" send(s) the same bytes"),
            "{notes:?}"
        );
        assert!(notes
            .last()
            .unwrap()
            .starts_with("digital data: 1 input and 1 output byte(s)"));
    }

    #[test]
    fn named_formats_and_no_fit() {
        let cfg = cfg_of("KL3102:complete,KL1501,KL9010");
        let s = &strips_for_cfg(&cfg)[0];
        assert_eq!(cfg_of(&s.join(",")), cfg, "{s:?}");
        // Bytes no terminal sends: no strip.
        assert!(strips_for_cfg(&[0x57]).is_empty());
    }
}
