//! [`GsdSummary`]: what a GSD file describes, for people (`Display`) and
//! for scripts (`Serialize`, feature `serde`) — the output of
//! `dpctl gsd show`; [`GsdCheck`]: what is wrong with it, the output of
//! `dpctl gsd check`.

use super::{
    Allowed, Diagnostic, FileDiagnostic, Gsd, Module, ParamInstance, ParseOptions, Parsed,
};
use profibus_fdl::wire::Hex;
use profibus_fdl::Baud;
use std::fmt;
use std::path::Path;

/// A parsed GSD file with its path: identity, services, limits, baud
/// rates with MaxTsdr, user parameters with defaults and ranges, modules
/// with their decoded I/O, unit diagnosis texts. `Display` gives the text
/// form; with the feature `serde` it serialises as one object (the
/// warnings of the parse included).
#[derive(Debug, Clone, Copy)]
pub struct GsdSummary<'a> {
    /// The file it was read from.
    pub file: &'a Path,
    /// The parse result.
    pub parsed: &'a Parsed,
}

/// `v` or `-`.
struct Opt<T>(Option<T>);

impl<T: fmt::Display> fmt::Display for Opt<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.0 {
            Some(v) => v.fmt(f),
            None => f.write_str("-"),
        }
    }
}

fn yes(v: bool) -> &'static str {
    if v {
        "yes"
    } else {
        "no"
    }
}

/// One parameter as a line: its byte offset from `base`, name, type,
/// default (with its text), allowed values and value texts.
struct ParamLine<'a>(&'a Gsd, &'a ParamInstance<'a>, usize);

impl fmt::Display for ParamLine<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (g, p) = (self.0, self.1);
        let d = p.definition;
        let at = if p.position.is_some() {
            "module byte"
        } else {
            "byte"
        };
        let (offset, ty) = (p.offset - self.2, d.data_type.gsd_name());
        write!(
            f,
            "{at} {offset}: \"{}\" {ty} default {}",
            d.name, d.default
        )?;
        if let Some(t) = g.value_text(d, d.default) {
            write!(f, " ({t})")?;
        }
        if d.allowed != Allowed::Any {
            write!(f, ", allowed {}", d.allowed)?;
        }
        if let Some(t) = d.prm_text_ref.and_then(|r| g.prm_text(r)) {
            f.write_str("; ")?;
            for (i, v) in t.texts.iter().enumerate() {
                let sep = if i == 0 { "" } else { ", " };
                write!(f, "{sep}{} = {}", v.value, v.text)?;
            }
        }
        Ok(())
    }
}

impl GsdSummary<'_> {
    /// The baud rates the file names (supported or with a MaxTsdr).
    fn bauds(&self) -> impl Iterator<Item = Baud> + '_ {
        let g = &self.parsed.gsd;
        Baud::ALL
            .into_iter()
            .filter(|&b| g.supports_baud(b) || g.max_tsdr(b).is_some())
    }

    /// The module parameters of module `i`, offsets from the module's
    /// first byte after the station's User_Prm_Data.
    fn module_params(&self, i: usize) -> Vec<ParamInstance<'_>> {
        let g = &self.parsed.gsd;
        g.parameters(&[i]).map_or_else(
            |_| vec![],
            |ps| ps.into_iter().filter(|p| p.position.is_some()).collect(),
        )
    }

    /// Length of the station's own User_Prm_Data.
    fn base(&self) -> usize {
        self.parsed
            .gsd
            .user_prm_data(&[], &[])
            .map_or(0, |d| d.len())
    }
}

fn module_line(f: &mut fmt::Formatter<'_>, i: usize, m: &Module) -> fmt::Result {
    let name = format!("\"{}\"", m.name);
    let cfg = Hex(&m.cfg).to_string();
    match m.io() {
        Ok(t) => {
            let io = format!("{} in / {} out", t.input_bytes, t.output_bytes);
            writeln!(f, "  {i:>3} {name:<40} {cfg:<24} {io}")?;
            for id in m.identifiers().filter_map(Result::ok) {
                writeln!(f, "        {id}")?;
            }
        }
        Err(e) => writeln!(f, "  {i:>3} {name:<40} {cfg:<24} undecodable\n        {e}")?,
    }
    Ok(())
}

impl fmt::Display for GsdSummary<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let g = &self.parsed.gsd;
        let o = |v: &Option<String>| Opt(v.clone());
        writeln!(f, "File:          {}", self.file.display())?;
        let (vendor, model, rev) = (o(&g.vendor_name), o(&g.model_name), o(&g.revision));
        writeln!(f, "Device:        {vendor} / {model} / {rev}")?;
        let ident = g.ident_number;
        writeln!(
            f,
            "Ident number:  0x{ident:04X}   GSD revision {}",
            Opt(g.gsd_revision)
        )?;
        let (hw, sw) = (o(&g.hardware_release), o(&g.software_release));
        write!(f, "Releases:      hardware {hw}, software {sw}")?;
        match &g.order_number {
            Some(n) => writeln!(f, ", order number {n}")?,
            None => writeln!(f)?,
        }
        if let Some(t) = &g.implementation_type {
            writeln!(f, "Chip:          {t}")?;
        }
        writeln!(
            f,
            "Services:      freeze {}, sync {}, auto-baud {}, Set_Slave_Add {}, fail-safe {}",
            yes(g.freeze_mode_supp),
            yes(g.sync_mode_supp),
            yes(g.auto_baud_supp),
            yes(g.set_slave_add_supp),
            yes(g.fail_safe)
        )?;
        if g.dpv1_slave {
            writeln!(
                f,
                "DP-V1:         yes; C1 read/write {}, C1_Max_Data_Len {}, C1_Response_Timeout {} (x 10 ms)",
                yes(g.c1_read_write_supp),
                Opt(g.c1_max_data_len),
                Opt(g.c1_response_timeout)
            )?;
        } else {
            writeln!(f, "DP-V1:         no")?;
        }
        writeln!(
            f,
            "Timing:        Min_Slave_Intervall {} (x 100 us), Max_Diag_Data_Len {}",
            Opt(g.min_slave_intervall),
            Opt(g.max_diag_data_len)
        )?;
        writeln!(
            f,
            "Limits:        {} station, Max_Module {}, Max_Input_Len {}, Max_Output_Len {}, Max_Data_Len {}, Max_User_Prm_Data_Len {}",
            if g.modular_station { "modular" } else { "compact" },
            Opt(g.max_module),
            Opt(g.max_input_len),
            Opt(g.max_output_len),
            Opt(g.max_data_len),
            Opt(g.max_user_prm_data_len)
        )?;
        if !g.other.is_empty() {
            writeln!(
                f,
                "Kept as text:  {} line(s) of keywords not interpreted here (DP-V2, I&M, …; --json lists them)",
                g.other.len()
            )?;
        }
        writeln!(f, "Baud rates:    (MaxTsdr in bit times)")?;
        for b in self.bauds() {
            let unsupported = if g.supports_baud(b) {
                ""
            } else {
                "   (not supported)"
            };
            let name = b.to_string();
            writeln!(f, "  {name:<14} {:>5}{unsupported}", Opt(g.max_tsdr(b)))?;
        }
        match g.user_prm_data(&[], &[]) {
            Ok(d) => writeln!(
                f,
                "User_Prm_Data: {} byte(s) for the station: {}",
                d.len(),
                Hex(&d)
            )?,
            Err(e) => writeln!(f, "User_Prm_Data: {e}")?,
        }
        for p in &g.parameters(&[]).unwrap_or_default() {
            writeln!(f, "  {}", ParamLine(g, p, 0))?;
        }
        writeln!(f, "Modules:       {}", g.modules.len())?;
        let base = self.base();
        for (i, m) in g.modules.iter().enumerate() {
            module_line(f, i, m)?;
            for p in &self.module_params(i) {
                writeln!(f, "        parameter at {}", ParamLine(g, p, base))?;
            }
        }
        for t in &g.unit_diag_bits {
            writeln!(f, "Diag bit {:>4} set:   {}", t.bit, t.text)?;
        }
        for t in &g.unit_diag_not_bits {
            writeln!(f, "Diag bit {:>4} clear: {}", t.bit, t.text)?;
        }
        for a in &g.unit_diag_areas {
            let n = a.values.len();
            writeln!(f, "Diag bits {}-{}: {n} texts", a.first, a.last)?;
        }
        Ok(())
    }
}

#[cfg(feature = "serde")]
mod ser {
    use super::{Allowed, GsdSummary, Hex, ParamInstance};
    use crate::config::gsd::{FileDiagnostic, Gsd, PrmTextValue, UnitDiagText};
    use crate::pdu::cfg::IoLen;
    use serde::{Serialize, Serializer};

    #[derive(Serialize)]
    struct Len {
        units: u8,
        words: bool,
        consistent: bool,
        bytes: usize,
    }

    fn len(l: Option<IoLen>) -> Option<Len> {
        l.map(|l| Len {
            units: l.units,
            words: l.words,
            consistent: l.consistent,
            bytes: l.bytes(),
        })
    }

    #[derive(Serialize)]
    struct Ident<'a> {
        raw: Hex<'a>,
        input: Option<Len>,
        output: Option<Len>,
        manufacturer: Hex<'a>,
        text: String,
    }

    #[derive(Serialize)]
    #[serde(untagged)]
    enum AllowedJson<'a> {
        Range { min: i64, max: i64 },
        Values(&'a [i64]),
    }

    #[derive(Serialize)]
    struct Param<'a> {
        offset: usize,
        name: &'a str,
        reference: u16,
        #[serde(rename = "type")]
        data_type: String,
        default: i64,
        allowed: Option<AllowedJson<'a>>,
        texts: &'a [PrmTextValue],
    }

    fn param<'a>(g: &'a Gsd, p: &ParamInstance<'a>, base: usize) -> Param<'a> {
        let d = p.definition;
        Param {
            offset: p.offset - base,
            name: &d.name,
            reference: d.reference,
            data_type: d.data_type.gsd_name(),
            default: d.default,
            allowed: match &d.allowed {
                Allowed::Any => None,
                Allowed::Range(a, b) => Some(AllowedJson::Range { min: *a, max: *b }),
                Allowed::Values(v) => Some(AllowedJson::Values(v)),
            },
            texts: d
                .prm_text_ref
                .and_then(|r| g.prm_text(r))
                .map_or(&[], |t| &t.texts[..]),
        }
    }

    #[derive(Serialize)]
    struct Baud {
        baud: u32,
        name: &'static str,
        supported: bool,
        max_tsdr: Option<u32>,
    }

    #[derive(Serialize)]
    struct Module<'a> {
        index: usize,
        name: &'a str,
        cfg: Hex<'a>,
        reference: Option<u32>,
        input_bytes: Option<usize>,
        output_bytes: Option<usize>,
        identifiers: Vec<Ident<'a>>,
        preset: bool,
        ext_module_prm_data_len: Option<u8>,
        parameters: Vec<Param<'a>>,
    }

    /// The object; keys in the order `dpctl` has always printed them
    /// after sorting (scripts read them by name).
    #[derive(Serialize)]
    struct Summary<'a> {
        file: String,
        gsd_revision: Option<u8>,
        vendor_name: &'a Option<String>,
        model_name: &'a Option<String>,
        revision: &'a Option<String>,
        ident_number: u16,
        ident: String,
        hardware_release: &'a Option<String>,
        software_release: &'a Option<String>,
        order_number: &'a Option<String>,
        implementation_type: &'a Option<String>,
        bauds: Vec<Baud>,
        freeze_mode_supp: bool,
        sync_mode_supp: bool,
        auto_baud_supp: bool,
        set_slave_add_supp: bool,
        fail_safe: bool,
        dpv1_slave: bool,
        c1_read_write_supp: bool,
        c1_max_data_len: Option<u8>,
        c1_response_timeout: Option<u16>,
        min_slave_intervall: Option<u16>,
        max_diag_data_len: Option<u8>,
        modular_station: bool,
        max_module: Option<u8>,
        max_input_len: Option<u8>,
        max_output_len: Option<u8>,
        max_data_len: Option<u16>,
        max_user_prm_data_len: Option<u8>,
        #[serde(serialize_with = "profibus_fdl::ser::opt_hex")]
        user_prm_data: Option<Vec<u8>>,
        parameters: Vec<Param<'a>>,
        modules: Vec<Module<'a>>,
        unit_diag_bits: &'a [UnitDiagText],
        unit_diag_not_bits: &'a [UnitDiagText],
        other: &'a [String],
        warnings: Vec<FileDiagnostic<'a>>,
    }

    impl Serialize for GsdSummary<'_> {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            let g = &self.parsed.gsd;
            let base = self.base();
            let modules = g.modules.iter().enumerate().map(|(i, m)| {
                let io = m.io().ok();
                let identifiers = m.identifiers().filter_map(Result::ok).map(|id| Ident {
                    raw: Hex(id.raw),
                    input: len(id.input),
                    output: len(id.output),
                    manufacturer: Hex(id.manufacturer),
                    text: id.to_string(),
                });
                Module {
                    index: i,
                    name: &m.name,
                    cfg: Hex(&m.cfg),
                    reference: m.reference,
                    input_bytes: io.map(|t| t.input_bytes),
                    output_bytes: io.map(|t| t.output_bytes),
                    identifiers: identifiers.collect(),
                    preset: m.preset,
                    ext_module_prm_data_len: m.ext_module_prm_data_len,
                    parameters: (self.module_params(i).iter())
                        .map(|p| param(g, p, base))
                        .collect(),
                }
            });
            let bauds = self.bauds().map(|b| Baud {
                baud: b.bps(),
                name: b.gsd_suffix(),
                supported: g.supports_baud(b),
                max_tsdr: g.max_tsdr(b),
            });
            let located = |d| FileDiagnostic::new(self.file, "warning", d);
            Summary {
                file: self.file.display().to_string(),
                gsd_revision: g.gsd_revision,
                vendor_name: &g.vendor_name,
                model_name: &g.model_name,
                revision: &g.revision,
                ident_number: g.ident_number,
                ident: format!("0x{:04X}", g.ident_number),
                hardware_release: &g.hardware_release,
                software_release: &g.software_release,
                order_number: &g.order_number,
                implementation_type: &g.implementation_type,
                bauds: bauds.collect(),
                freeze_mode_supp: g.freeze_mode_supp,
                sync_mode_supp: g.sync_mode_supp,
                auto_baud_supp: g.auto_baud_supp,
                set_slave_add_supp: g.set_slave_add_supp,
                fail_safe: g.fail_safe,
                dpv1_slave: g.dpv1_slave,
                c1_read_write_supp: g.c1_read_write_supp,
                c1_max_data_len: g.c1_max_data_len,
                c1_response_timeout: g.c1_response_timeout,
                min_slave_intervall: g.min_slave_intervall,
                max_diag_data_len: g.max_diag_data_len,
                modular_station: g.modular_station,
                max_module: g.max_module,
                max_input_len: g.max_input_len,
                max_output_len: g.max_output_len,
                max_data_len: g.max_data_len,
                max_user_prm_data_len: g.max_user_prm_data_len,
                user_prm_data: g.user_prm_data(&[], &[]).ok(),
                parameters: (g.parameters(&[]).unwrap_or_default().iter())
                    .map(|p| param(g, p, 0))
                    .collect(),
                modules: modules.collect(),
                unit_diag_bits: &g.unit_diag_bits,
                unit_diag_not_bits: &g.unit_diag_not_bits,
                other: &g.other,
                warnings: self.parsed.warnings.iter().map(located).collect(),
            }
            .serialize(s)
        }
    }
}

/// What `dpctl gsd check` reports about a GSD file: every error and
/// warning with its severity (the problems of single modules among the
/// warnings of a file that parses). `Display` is the verdict line,
/// `FILE: ok, N module(s), W warning(s)` or `FILE: E error(s), W
/// warning(s)`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GsdCheck {
    /// The file checked.
    pub file: std::path::PathBuf,
    /// The modules of a file that parses; `None` when it has errors.
    pub modules: Option<usize>,
    /// Errors and warnings with their severity (`error`, `warning`): in
    /// file order when the file has errors; else the parser's warnings in
    /// file order, then those of the modules.
    pub diagnostics: Vec<(&'static str, Diagnostic)>,
}

impl GsdCheck {
    /// Parse and check `file`.
    pub fn of_file(file: &Path, opts: ParseOptions) -> GsdCheck {
        let (modules, diagnostics) = match Gsd::from_file(file, opts) {
            Ok(parsed) => {
                let warnings = parsed.warnings.into_iter();
                let all = warnings.chain(parsed.gsd.module_problems());
                let modules = parsed.gsd.modules.len();
                (Some(modules), all.map(|d| ("warning", d)).collect())
            }
            Err(e) => {
                let errors = e.errors.into_iter().map(|d| ("error", d));
                let mut all: Vec<_> = errors
                    .chain(e.warnings.into_iter().map(|d| ("warning", d)))
                    .collect();
                all.sort_by_key(|(_, d)| d.pos);
                (None, all)
            }
        };
        GsdCheck {
            file: file.to_path_buf(),
            modules,
            diagnostics,
        }
    }

    /// Each diagnostic with the file, as printed.
    pub fn lines(&self) -> impl Iterator<Item = FileDiagnostic<'_>> {
        (self.diagnostics.iter()).map(|(severity, d)| FileDiagnostic::new(&self.file, severity, d))
    }

    /// How many diagnostics are of `severity`.
    pub fn count(&self, severity: &str) -> usize {
        self.diagnostics
            .iter()
            .filter(|(s, _)| *s == severity)
            .count()
    }

    /// Whether the file has no errors.
    pub fn ok(&self) -> bool {
        self.modules.is_some()
    }
}

impl fmt::Display for GsdCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (file, warnings) = (self.file.display(), self.count("warning"));
        match self.modules {
            Some(n) => write!(f, "{file}: ok, {n} module(s), {warnings} warning(s)"),
            None => {
                let errors = self.count("error");
                write!(f, "{file}: {errors} error(s), {warnings} warning(s)")
            }
        }
    }
}
