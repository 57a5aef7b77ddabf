//! `dpctl gsd show FILE` and `dpctl gsd check FILE`: what a GSD file
//! describes, and what is wrong with it.

use crate::describe::hex;
use anyhow::bail;
use profibus_dp::cfg::IoLen;
use profibus_dp::gsd::{
    Allowed, Diagnostic, FileDiagnostic, Gsd, GsdError, Module, ParamInstance, ParseOptions, Parsed,
};
use profibus_fdl::timing::Baud;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Show or check a GSD file.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(clap::Subcommand)]
enum Cmd {
    /// Show identity, baud rates with MaxTsdr, limits, modules with their
    /// decoded I/O sizes, and user parameters with defaults and ranges.
    Show(ShowArgs),
    /// Check a GSD file: print its errors and warnings with
    /// file:line:col; exit status 1 when it has errors.
    Check(CheckArgs),
}

#[derive(clap::Args)]
struct ShowArgs {
    /// The GSD file (Latin-1 text; `.gsd` or a localised `.gse`, `.gsg`, …).
    file: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Accept known vendor quirks with a warning on stderr (the default).
    #[arg(long, conflicts_with = "strict")]
    lenient: bool,
    /// Treat vendor quirks as errors.
    #[arg(long)]
    strict: bool,
}

#[derive(clap::Args)]
struct CheckArgs {
    /// The GSD file (Latin-1 text; `.gsd` or a localised `.gse`, `.gsg`, …).
    file: PathBuf,
    /// Treat vendor quirks (e.g. `MaxTsd_`, `Modules=`, a commented-out
    /// `#Profibus_DP`) as errors instead of warnings.
    #[arg(long)]
    strict: bool,
    /// Print one JSON object per error or warning.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.cmd {
        Cmd::Show(a) => show(a),
        Cmd::Check(a) => check(a),
    }
}

fn opts(strict: bool) -> ParseOptions {
    ParseOptions { lenient: !strict }
}

/// `d` of `file` as `gsd check` prints it.
fn located<'a>(file: &'a Path, severity: &'static str, d: &'a Diagnostic) -> FileDiagnostic<'a> {
    FileDiagnostic {
        file,
        severity,
        diagnostic: d,
    }
}

fn diag_json(file: &Path, severity: &'static str, d: &Diagnostic) -> Value {
    serde_json::to_value(located(file, severity, d)).unwrap_or(Value::Null)
}

fn fail(file: &Path, e: &GsdError) -> anyhow::Error {
    let n = e.errors.len();
    anyhow::anyhow!(
        "{}: {n} error{}; first: {}",
        file.display(),
        if n == 1 { "" } else { "s" },
        e.first()
    )
}

fn show(a: ShowArgs) -> anyhow::Result<()> {
    let parsed = match Gsd::from_file(&a.file, opts(a.strict)) {
        Ok(p) => p,
        Err(e) => {
            for d in &e.errors {
                eprintln!("{}", located(&a.file, "error", d));
            }
            return Err(fail(&a.file, &e));
        }
    };
    for w in &parsed.warnings {
        eprintln!("{}", located(&a.file, "warning", w));
    }
    if a.json {
        println!("{}", show_json(&a.file, &parsed));
    } else {
        print!("{}", show_text(&a.file, &parsed.gsd));
    }
    Ok(())
}

fn opt<T: ToString>(v: Option<T>) -> String {
    v.map_or_else(|| "-".into(), |v| v.to_string())
}

fn yes(v: bool) -> &'static str {
    if v {
        "yes"
    } else {
        "no"
    }
}

fn baud_name(b: Baud) -> String {
    b.to_string()
}

fn param_text(g: &Gsd, p: &ParamInstance<'_>, base: usize) -> String {
    let d = p.definition;
    let mut s = format!(
        "{} {}: \"{}\" {} default {}",
        if p.position.is_some() {
            "module byte"
        } else {
            "byte"
        },
        p.offset - base,
        d.name,
        d.data_type.gsd_name(),
        d.default
    );
    if let Some(t) = g.value_text(d, d.default) {
        s.push_str(&format!(" ({t})"));
    }
    if d.allowed != Allowed::Any {
        s.push_str(&format!(", allowed {}", d.allowed));
    }
    if let Some(t) = d.prm_text_ref.and_then(|r| g.prm_text(r)) {
        let texts: Vec<String> = t
            .texts
            .iter()
            .map(|v| format!("{} = {}", v.value, v.text))
            .collect();
        s.push_str(&format!("; {}", texts.join(", ")));
    }
    s
}

fn module_io(m: &Module) -> (String, Vec<String>) {
    match m.io() {
        Ok(t) => (
            format!("{} in / {} out", t.input_bytes, t.output_bytes),
            m.identifiers()
                .filter_map(Result::ok)
                .map(|id| id.to_string())
                .collect(),
        ),
        Err(e) => ("undecodable".into(), vec![e.to_string()]),
    }
}

fn show_text(file: &Path, g: &Gsd) -> String {
    let mut o = String::new();
    let mut line = |s: String| {
        o.push_str(&s);
        o.push('\n');
    };
    line(format!("File:          {}", file.display()));
    line(format!(
        "Device:        {} / {} / {}",
        opt(g.vendor_name.as_deref()),
        opt(g.model_name.as_deref()),
        opt(g.revision.as_deref())
    ));
    line(format!(
        "Ident number:  0x{:04X}   GSD revision {}",
        g.ident_number,
        opt(g.gsd_revision)
    ));
    line(format!(
        "Releases:      hardware {}, software {}{}",
        opt(g.hardware_release.as_deref()),
        opt(g.software_release.as_deref()),
        g.order_number
            .as_ref()
            .map(|o| format!(", order number {o}"))
            .unwrap_or_default()
    ));
    if let Some(t) = &g.implementation_type {
        line(format!("Chip:          {t}"));
    }
    line(format!(
        "Services:      freeze {}, sync {}, auto-baud {}, Set_Slave_Add {}, fail-safe {}",
        yes(g.freeze_mode_supp),
        yes(g.sync_mode_supp),
        yes(g.auto_baud_supp),
        yes(g.set_slave_add_supp),
        yes(g.fail_safe)
    ));
    if g.dpv1_slave {
        line(format!(
            "DP-V1:         yes; C1 read/write {}, C1_Max_Data_Len {}, C1_Response_Timeout {} (x 10 ms)",
            yes(g.c1_read_write_supp),
            opt(g.c1_max_data_len),
            opt(g.c1_response_timeout)
        ));
    } else {
        line("DP-V1:         no".into());
    }
    line(format!(
        "Timing:        Min_Slave_Intervall {} (x 100 us), Max_Diag_Data_Len {}",
        opt(g.min_slave_intervall),
        opt(g.max_diag_data_len)
    ));
    line(format!(
        "Limits:        {} station, Max_Module {}, Max_Input_Len {}, Max_Output_Len {}, Max_Data_Len {}, Max_User_Prm_Data_Len {}",
        if g.modular_station { "modular" } else { "compact" },
        opt(g.max_module),
        opt(g.max_input_len),
        opt(g.max_output_len),
        opt(g.max_data_len),
        opt(g.max_user_prm_data_len)
    ));
    if !g.other.is_empty() {
        line(format!(
            "Kept as text:  {} line(s) of keywords not interpreted here (DP-V2, I&M, …; --json lists them)",
            g.other.len()
        ));
    }
    line("Baud rates:    (MaxTsdr in bit times)".into());
    for b in Baud::ALL {
        if g.supports_baud(b) || g.max_tsdr(b).is_some() {
            line(format!(
                "  {:<14} {:>5}{}",
                baud_name(b),
                opt(g.max_tsdr(b)),
                if g.supports_baud(b) {
                    ""
                } else {
                    "   (not supported)"
                }
            ));
        }
    }
    match g.user_prm_data(&[], &[]) {
        Ok(d) => line(format!(
            "User_Prm_Data: {} byte(s) for the station: {}",
            d.len(),
            hex(&d)
        )),
        Err(e) => line(format!("User_Prm_Data: {e}")),
    }
    if let Ok(params) = g.parameters(&[]) {
        for p in &params {
            line(format!("  {}", param_text(g, p, 0)));
        }
    }
    line(format!("Modules:       {}", g.modules.len()));
    for (i, m) in g.modules.iter().enumerate() {
        let (io, ids) = module_io(m);
        line(format!(
            "  {:>3} {:<40} {:<24} {}",
            i,
            format!("\"{}\"", m.name),
            hex(&m.cfg),
            io
        ));
        for id in ids {
            line(format!("        {id}"));
        }
        let base = g.user_prm_data(&[], &[]).map_or(0, |d| d.len());
        if let Ok(params) = g.parameters(&[i]) {
            for p in params.iter().filter(|p| p.position.is_some()) {
                line(format!("        parameter at {}", param_text(g, p, base)));
            }
        }
    }
    for t in &g.unit_diag_bits {
        line(format!("Diag bit {:>4} set:   {}", t.bit, t.text));
    }
    for t in &g.unit_diag_not_bits {
        line(format!("Diag bit {:>4} clear: {}", t.bit, t.text));
    }
    for a in &g.unit_diag_areas {
        line(format!(
            "Diag bits {}-{}: {} texts",
            a.first,
            a.last,
            a.values.len()
        ));
    }
    o
}

fn io_len_json(l: Option<IoLen>) -> Value {
    match l {
        None => Value::Null,
        Some(l) => {
            json!({"units": l.units, "words": l.words, "consistent": l.consistent, "bytes": l.bytes()})
        }
    }
}

fn param_json(g: &Gsd, p: &ParamInstance<'_>, base: usize) -> Value {
    let d = p.definition;
    let allowed = match &d.allowed {
        Allowed::Any => Value::Null,
        Allowed::Range(a, b) => json!({"min": a, "max": b}),
        Allowed::Values(v) => json!(v),
    };
    let texts: Vec<Value> = d
        .prm_text_ref
        .and_then(|r| g.prm_text(r))
        .map(|t| {
            t.texts
                .iter()
                .map(|v| json!({"value": v.value, "text": v.text}))
                .collect()
        })
        .unwrap_or_default();
    json!({
        "offset": p.offset - base,
        "name": d.name,
        "reference": d.reference,
        "type": d.data_type.gsd_name(),
        "default": d.default,
        "allowed": allowed,
        "texts": texts,
    })
}

fn show_json(file: &Path, parsed: &Parsed) -> Value {
    let g = &parsed.gsd;
    let station_prm = g.user_prm_data(&[], &[]).ok();
    let base = station_prm.as_ref().map_or(0, Vec::len);
    let bauds: Vec<Value> = Baud::ALL
        .iter()
        .filter(|&&b| g.supports_baud(b) || g.max_tsdr(b).is_some())
        .map(|&b| json!({"baud": b.bps(), "name": b.gsd_suffix(), "supported": g.supports_baud(b), "max_tsdr": g.max_tsdr(b)}))
        .collect();
    let modules: Vec<Value> = g
        .modules
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let ids: Vec<Value> = m
                .identifiers()
                .filter_map(Result::ok)
                .map(|id| {
                    json!({
                        "raw": hex(id.raw),
                        "input": io_len_json(id.input),
                        "output": io_len_json(id.output),
                        "manufacturer": hex(id.manufacturer),
                        "text": id.to_string(),
                    })
                })
                .collect();
            let io = m.io().ok();
            let params: Vec<Value> = g
                .parameters(&[i])
                .map(|ps| {
                    ps.iter()
                        .filter(|p| p.position.is_some())
                        .map(|p| param_json(g, p, base))
                        .collect()
                })
                .unwrap_or_default();
            json!({
                "index": i,
                "name": m.name,
                "cfg": hex(&m.cfg),
                "reference": m.reference,
                "input_bytes": io.map(|t| t.input_bytes),
                "output_bytes": io.map(|t| t.output_bytes),
                "identifiers": ids,
                "preset": m.preset,
                "ext_module_prm_data_len": m.ext_module_prm_data_len,
                "parameters": params,
            })
        })
        .collect();
    let params: Vec<Value> = g
        .parameters(&[])
        .map(|ps| ps.iter().map(|p| param_json(g, p, 0)).collect())
        .unwrap_or_default();
    let diag_texts = |v: &[profibus_dp::gsd::UnitDiagText]| -> Vec<Value> {
        v.iter()
            .map(|t| json!({"bit": t.bit, "text": t.text}))
            .collect()
    };
    json!({
        "file": file.display().to_string(),
        "gsd_revision": g.gsd_revision,
        "vendor_name": g.vendor_name,
        "model_name": g.model_name,
        "revision": g.revision,
        "ident_number": g.ident_number,
        "ident": format!("0x{:04X}", g.ident_number),
        "hardware_release": g.hardware_release,
        "software_release": g.software_release,
        "order_number": g.order_number,
        "implementation_type": g.implementation_type,
        "bauds": bauds,
        "freeze_mode_supp": g.freeze_mode_supp,
        "sync_mode_supp": g.sync_mode_supp,
        "auto_baud_supp": g.auto_baud_supp,
        "set_slave_add_supp": g.set_slave_add_supp,
        "fail_safe": g.fail_safe,
        "dpv1_slave": g.dpv1_slave,
        "c1_read_write_supp": g.c1_read_write_supp,
        "c1_max_data_len": g.c1_max_data_len,
        "c1_response_timeout": g.c1_response_timeout,
        "min_slave_intervall": g.min_slave_intervall,
        "max_diag_data_len": g.max_diag_data_len,
        "modular_station": g.modular_station,
        "max_module": g.max_module,
        "max_input_len": g.max_input_len,
        "max_output_len": g.max_output_len,
        "max_data_len": g.max_data_len,
        "max_user_prm_data_len": g.max_user_prm_data_len,
        "user_prm_data": station_prm.map(|d| hex(&d)),
        "parameters": params,
        "modules": modules,
        "unit_diag_bits": diag_texts(&g.unit_diag_bits),
        "unit_diag_not_bits": diag_texts(&g.unit_diag_not_bits),
        "other": g.other,
        "warnings": parsed.warnings.iter().map(|w| diag_json(file, "warning", w)).collect::<Vec<_>>(),
    })
}

fn check(a: CheckArgs) -> anyhow::Result<()> {
    let emit = |severity: &'static str, d: &Diagnostic| {
        let fd = located(&a.file, severity, d);
        if a.json {
            println!("{}", crate::common::json_line(&fd));
        } else {
            println!("{fd}");
        }
    };
    match Gsd::from_file(&a.file, opts(a.strict)) {
        Ok(parsed) => {
            let mut warnings = parsed.warnings.clone();
            warnings.extend(parsed.gsd.module_problems());
            for w in &warnings {
                emit("warning", w);
            }
            if !a.json {
                println!(
                    "{}: ok, {} module(s), {} warning(s)",
                    a.file.display(),
                    parsed.gsd.modules.len(),
                    warnings.len()
                );
            }
            Ok(())
        }
        Err(e) => {
            let mut all: Vec<(&'static str, &Diagnostic)> = e
                .errors
                .iter()
                .map(|d| ("error", d))
                .chain(e.warnings.iter().map(|d| ("warning", d)))
                .collect();
            all.sort_by_key(|(_, d)| d.pos);
            for (s, d) in all {
                emit(s, d);
            }
            bail!(
                "{}: {} error(s), {} warning(s)",
                a.file.display(),
                e.errors.len(),
                e.warnings.len()
            )
        }
    }
}
