//! The GSD statement parser: logical lines of the `#Profibus_DP` section
//! → [`Gsd`].
//!
//! The parser is line-oriented and recovers after an error (the next line
//! starts a new statement), so one run reports every error of a file. A
//! block (`Module`, `ExtUserPrmData`, `PrmText`, `SlotDefinition`,
//! `Unit_Diag_Area`) is open until its `End…` line; blocks of later GSD
//! revisions the model does not interpret are copied verbatim into
//! `other`.

use super::keywords;
use super::lexer::{
    strip_comment, strip_comment_from, Cursor, LogicalLine, PhysicalLines, ScanError,
};
use super::model::*;
use super::{DiagKind, Diagnostic, ParseOptions, Parsed, Pos, Quirk, MAX_LINE_LEN};
use crate::pdu::cfg;
use profibus_fdl::timing::Baud;
use std::collections::HashMap;

/// Errors and warnings of a failed parse.
pub(crate) type Failure = (Vec<Diagnostic>, Vec<Diagnostic>);

/// Parse the text of a GSD file.
pub(crate) fn parse(text: &str, opts: ParseOptions) -> Result<Parsed, Failure> {
    let mut p = Parser::new(opts);
    p.run(text);
    p.finish()
}

/// Blocks whose content the model keeps verbatim: (opening keyword,
/// closing keyword), lower case.
const RAW_BLOCKS: &[(&str, &str)] = &[
    ("unitdiagtype", "endunitdiagtype"),
    ("x_unit_diag_area", "x_unit_diag_area_end"),
    ("version_firmware_download", "end_version_firmware_download"),
    ("physical_interface", "end_physical_interface"),
    ("data_area_beg", "data_area_end"),
];

/// Warnings kept per quirk before the rest are folded into one.
const QUIRK_REPEATS: usize = 3;

/// The `(index)` after a keyword: its value and byte offset.
type Index = Option<(i64, usize)>;

/// A statement head: keyword, index, whether `=` follows.
type Head<'t> = (&'t str, Index, bool);

/// A block of value texts: `PrmText` (its `Text(v)` lines) or
/// `Unit_Diag_Area` (its `Value(v)` lines).
struct TextBlock {
    /// The block in words, for messages.
    name: &'static str,
    /// The keyword that closes it.
    end: &'static str,
    /// The key of its text lines.
    item: &'static str,
}

const PRM_TEXT: TextBlock = TextBlock {
    name: "`PrmText` block",
    end: "EndPrmText",
    item: "Text",
};

const DIAG_AREA: TextBlock = TextBlock {
    name: "`Unit_Diag_Area` block",
    end: "Unit_Diag_Area_End",
    item: "Value",
};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Owner {
    Global,
    Module(usize),
}

/// An `ExtUserPrmData` block being read.
#[derive(Debug)]
struct PendingPrm {
    start: Pos,
    reference: u16,
    name: String,
    data_type: Option<(PrmDataType, i64, Allowed)>,
    prm_text_ref: Option<(u16, Pos)>,
    changeable: Option<bool>,
    visible: Option<bool>,
}

#[derive(Debug)]
enum State {
    Global,
    Module {
        index: usize,
        start: Pos,
    },
    ExtPrm(Box<PendingPrm>),
    PrmText {
        index: usize,
        start: Pos,
    },
    Slots {
        start: Pos,
    },
    DiagArea {
        index: usize,
        start: Pos,
    },
    Raw {
        end: &'static str,
        owner: Owner,
        start: Pos,
    },
}

struct Parser {
    lenient: bool,
    gsd: Gsd,
    errors: Vec<Diagnostic>,
    warnings: Vec<Diagnostic>,
    state: State,
    ident_seen: bool,
    /// Simple keywords seen, with their first line.
    seen: HashMap<String, u32, KeyHasher>,
    /// Positions of `Ext_User_Prm_Data_Ref` lines.
    prm_refs: Vec<(Pos, u16)>,
    /// Positions of `Prm_Text_Ref` lines.
    text_refs: Vec<(Pos, u16)>,
    /// Position of each module's `Module` line.
    module_pos: Vec<Pos>,
}

fn scan_pos(ll: &LogicalLine<'_>, e: &ScanError) -> Pos {
    ll.pos(e.at)
}

fn baud_by_suffix(suffix: &str) -> Option<usize> {
    Baud::ALL
        .iter()
        .position(|b| b.gsd_suffix().eq_ignore_ascii_case(suffix))
}

impl Parser {
    fn new(opts: ParseOptions) -> Parser {
        Parser {
            lenient: opts.lenient,
            gsd: Gsd::default(),
            errors: Vec::new(),
            warnings: Vec::new(),
            state: State::Global,
            ident_seen: false,
            // Room for the simple keywords of a large file: no rehashing
            // while parsing.
            seen: HashMap::with_capacity_and_hasher(32, KeyHasher),
            prm_refs: Vec::new(),
            text_refs: Vec::new(),
            module_pos: Vec::new(),
        }
    }

    // ---- diagnostics ----

    fn error(&mut self, pos: Pos, kind: DiagKind, message: String) {
        push_capped(&mut self.errors, Diagnostic { pos, kind, message });
    }

    fn warn(&mut self, pos: Pos, kind: DiagKind, message: String) {
        push_capped(&mut self.warnings, Diagnostic { pos, kind, message });
    }

    /// A quirk: a warning when lenient, an error when strict.
    fn quirk(&mut self, pos: Pos, quirk: Quirk, message: String) {
        let d = Diagnostic {
            pos,
            kind: DiagKind::Quirk(quirk),
            message,
        };
        if self.lenient {
            push_capped(&mut self.warnings, d);
        } else {
            push_capped(&mut self.errors, d);
        }
    }

    fn syntax(&mut self, ll: &LogicalLine<'_>, e: ScanError) {
        let pos = scan_pos(ll, &e);
        self.error(pos, DiagKind::Syntax, e.msg);
    }

    // ---- driver ----

    fn run(&mut self, text: &str) {
        let text = text
            .strip_prefix('\u{FEFF}')
            .or_else(|| text.strip_prefix("\u{EF}\u{BB}\u{BF}"))
            .unwrap_or(text);
        let Some(start) = self.find_section(text) else {
            return;
        };
        let mut current: Option<LogicalLine<'_>> = None;
        let mut continued = false;
        // The quote of a string still open at the end of the last line.
        let mut open: Option<u8> = None;
        for item in PhysicalLines::new(text) {
            let (n, raw) = match item {
                Ok(l) => l,
                Err(n) => {
                    self.line_too_long(n);
                    return;
                }
            };
            if n < start {
                continue;
            }
            // A continuation line starts inside the string the line
            // before left open.
            let (content, quote) = strip_comment_from(raw, if continued { open } else { None });
            let content = content.trim_end();
            let (content, cont) = match content.strip_suffix('\\') {
                Some(c) => (c, true),
                None => (content, false),
            };
            open = quote;
            if continued {
                let ll = current.as_mut().expect("a line is being continued");
                ll.push(n, content);
                if ll.text.len() > MAX_LINE_LEN {
                    self.line_too_long(ll.line());
                    return;
                }
            } else {
                if content.trim_start().starts_with('#') {
                    if self.section_header(content.trim(), n) {
                        break;
                    }
                    continue;
                }
                current = Some(LogicalLine::new(n, content));
            }
            continued = cont;
            if !cont {
                let mut ll = current.take().expect("a line was started");
                ll.trim();
                // A `#` line reached through a continuation (`\` on an
                // otherwise empty line) is a section header too: kept as a
                // statement, it would be written back as a line of its own
                // and read as a header then.
                if ll.text.starts_with('#') {
                    if self.section_header(&ll.text, ll.pos(0).line) {
                        break;
                    }
                } else if !ll.text.is_empty() {
                    self.statement(&ll);
                }
            }
        }
        if let Some(mut ll) = current.take() {
            ll.trim();
            if ll.text.starts_with('#') {
                self.section_header(&ll.text, ll.pos(0).line);
            } else if !ll.text.is_empty() {
                self.statement(&ll);
            }
        }
        self.close_at_eof();
    }

    /// A `#` line (`header`, trimmed) on line `n` inside the section: a
    /// second `#Profibus_DP` is ignored, any other header ends the
    /// section. Whether it ends it.
    fn section_header(&mut self, header: &str, n: u32) -> bool {
        if header.eq_ignore_ascii_case("#Profibus_DP") {
            self.warn(
                Pos { line: n, col: 1 },
                DiagKind::Semantic,
                "a second `#Profibus_DP` line; ignored".into(),
            );
            return false;
        }
        self.warn(
            Pos { line: n, col: 1 },
            DiagKind::Semantic,
            format!("`{header}` starts another section; the rest of the file is not read"),
        );
        true
    }

    fn line_too_long(&mut self, n: u32) {
        self.error(
            Pos { line: n, col: 1 },
            DiagKind::TooLarge,
            format!("line {n} is longer than {MAX_LINE_LEN} bytes; this is not a GSD file"),
        );
    }

    /// The first line of the `#Profibus_DP` section, or `None` after an
    /// error that stops parsing.
    fn find_section(&mut self, text: &str) -> Option<u32> {
        let mut commented: Option<u32> = None;
        for item in PhysicalLines::new(text) {
            let (n, raw) = match item {
                Ok(l) => l,
                Err(n) => {
                    self.line_too_long(n);
                    return None;
                }
            };
            // The header line, commented out or not, has a `#`; most
            // lines have none and need no closer look.
            if !raw.as_bytes().contains(&b'#') {
                continue;
            }
            let t = raw.trim();
            if strip_comment(t).trim().eq_ignore_ascii_case("#Profibus_DP") {
                return Some(n + 1);
            }
            if commented.is_none() {
                if let Some(rest) = t.strip_prefix(';') {
                    if rest.trim().eq_ignore_ascii_case("#Profibus_DP") {
                        commented = Some(n);
                    }
                }
            }
        }
        match commented {
            Some(n) => {
                self.quirk(
                    Pos { line: n, col: 1 },
                    Quirk::CommentedSectionHeader,
                    "expected a `#Profibus_DP` line; found it commented out as `;#Profibus_DP`"
                        .into(),
                );
                Some(n + 1)
            }
            None => {
                self.quirk(
                    Pos { line: 1, col: 1 },
                    Quirk::MissingSectionHeader,
                    "expected a `#Profibus_DP` line starting the section; the file has none".into(),
                );
                Some(1)
            }
        }
    }

    fn finish(mut self) -> Result<Parsed, Failure> {
        self.validate();
        // File order; remarks about the file as a whole (line 0) last.
        self.errors.sort_by_key(|d| (d.pos.line == 0, d.pos));
        self.warnings.sort_by_key(|d| (d.pos.line == 0, d.pos));
        self.fold_repeated_quirks();
        if self.errors.is_empty() {
            Ok(Parsed {
                gsd: self.gsd,
                warnings: self.warnings,
            })
        } else {
            Err((self.errors, self.warnings))
        }
    }

    /// Keep the first [`QUIRK_REPEATS`] warnings of each quirk and fold
    /// the rest into one warning listing their lines (a vendor file
    /// repeats its quirk on every line of a kind).
    fn fold_repeated_quirks(&mut self) {
        let mut counts: HashMap<Quirk, Vec<usize>> = HashMap::new();
        for (i, w) in self.warnings.iter().enumerate() {
            if let DiagKind::Quirk(q) = w.kind {
                counts.entry(q).or_default().push(i);
            }
        }
        let mut drop = vec![false; self.warnings.len()];
        let mut summaries = Vec::new();
        for (q, idx) in counts {
            if idx.len() <= QUIRK_REPEATS {
                continue;
            }
            let rest = &idx[QUIRK_REPEATS..];
            let lines: Vec<String> = rest
                .iter()
                .map(|&i| self.warnings[i].pos.line.to_string())
                .collect();
            for &i in rest {
                drop[i] = true;
            }
            summaries.push(Diagnostic {
                pos: self.warnings[rest[0]].pos,
                kind: DiagKind::Quirk(q),
                message: format!(
                    "the same quirk ({}) on {} more line(s): {}",
                    self.warnings[idx[0]].message,
                    rest.len(),
                    lines.join(", ")
                ),
            });
        }
        let mut i = 0;
        self.warnings.retain(|_| {
            i += 1;
            !drop[i - 1]
        });
        self.warnings.extend(summaries);
        self.warnings.sort_by_key(|d| (d.pos.line == 0, d.pos));
    }

    // ---- statements ----

    fn statement(&mut self, ll: &LogicalLine<'_>) {
        let state = std::mem::replace(&mut self.state, State::Global);
        match state {
            State::Global => self.global(ll),
            State::Module { index, start } => {
                self.state = State::Module { index, start };
                self.module_line(ll, index, start);
            }
            State::ExtPrm(p) => self.ext_prm_line(ll, p),
            State::PrmText { index, start } => {
                self.state = State::PrmText { index, start };
                self.prm_text_line(ll, index, start);
            }
            State::Slots { start } => {
                self.state = State::Slots { start };
                self.slot_line(ll, start);
            }
            State::DiagArea { index, start } => {
                self.state = State::DiagArea { index, start };
                self.diag_area_line(ll, index, start);
            }
            State::Raw { end, owner, start } => {
                let text = ll.text.to_string();
                let closes = Cursor::new(&ll.text)
                    .word()
                    .is_some_and(|w| w.eq_ignore_ascii_case(end));
                self.push_other(owner, text);
                self.state = match (closes, owner) {
                    (false, _) => State::Raw { end, owner, start },
                    (true, Owner::Global) => State::Global,
                    (true, Owner::Module(index)) => State::Module {
                        index,
                        start: self.module_pos[index],
                    },
                };
            }
        }
    }

    fn push_other(&mut self, owner: Owner, text: String) {
        match owner {
            Owner::Global => self.gsd.other.push(text),
            Owner::Module(i) => self.gsd.modules[i].other.push(text),
        }
    }

    /// A block was not closed before `ll`: report, then read `ll` as a
    /// station-level statement.
    fn missing_end(&mut self, ll: &LogicalLine<'_>, block: &str, start: Pos, end: &str) {
        self.quirk(
            ll.pos(0),
            Quirk::MissingEnd,
            format!(
                "expected `{end}` closing the {block} opened on line {}",
                start.line
            ),
        );
        self.state = State::Global;
        self.global(ll);
    }

    /// Key, optional `(index)` and whether `=` follows.
    fn head<'t>(&mut self, ll: &LogicalLine<'_>, c: &mut Cursor<'t>) -> Option<Head<'t>> {
        let Some(word) = c.word() else {
            let found = c.found();
            self.quirk(
                ll.pos(c.at()),
                Quirk::StrayText,
                format!("expected a keyword, found {found}; the line is ignored"),
            );
            return None;
        };
        let mut index = None;
        if c.peek() == Some('(') {
            c.eat('(');
            let at = {
                c.ws();
                c.at()
            };
            match c
                .int("an index")
                .and_then(|v| c.expect(')', "`)`").map(|_| v))
            {
                Ok(v) => index = Some((v, at)),
                Err(e) => {
                    self.syntax(ll, e);
                    return None;
                }
            }
        }
        let eq = c.eat('=');
        Some((word, index, eq))
    }

    fn global(&mut self, ll: &LogicalLine<'_>) {
        let mut c = Cursor::new(&ll.text);
        let Some((word, index, eq)) = self.head(ll, &mut c) else {
            return;
        };
        let key = word.to_ascii_lowercase();
        if let Some(&(_, end)) = RAW_BLOCKS.iter().find(|(b, _)| *b == key) {
            if key != "data_area_beg" {
                self.gsd.other.push(ll.text.to_string());
                self.state = State::Raw {
                    end,
                    owner: Owner::Global,
                    start: ll.pos(0),
                };
                return;
            }
        }
        if !eq {
            self.bare_word(ll, &mut c, word, &key);
            return;
        }
        let r = self.global_keyword(ll, &mut c, word, &key, index);
        if let Err(e) = r {
            self.syntax(ll, e);
        }
    }

    /// A line with a word and no `=`.
    fn bare_word(&mut self, ll: &LogicalLine<'_>, c: &mut Cursor<'_>, word: &str, key: &str) {
        match key {
            "endmodule" | "endextuserprmdata" | "endprmtext" | "endslotdefinition"
            | "unit_diag_area_end" => {
                self.quirk(
                    ll.pos(0),
                    Quirk::UnmatchedEnd,
                    format!("`{word}` closes no open block"),
                );
            }
            "slotdefinition" => {
                if let Err(e) = c.end("`SlotDefinition`") {
                    self.syntax(ll, e);
                }
                self.state = State::Slots { start: ll.pos(0) };
            }
            _ if c.at_end() => {
                self.warn(
                    ll.pos(0),
                    DiagKind::UnknownKeyword,
                    format!("unknown keyword `{word}` without a value; kept, not interpreted"),
                );
                self.gsd.other.push(ll.text.to_string());
            }
            _ => {
                let found = c.found();
                self.quirk(
                    ll.pos(c.at()),
                    Quirk::StrayText,
                    format!("expected `=` after `{word}`, found {found}; the line is ignored"),
                );
            }
        }
    }

    fn no_index(&self, word: &str, index: Index) -> Result<(), ScanError> {
        match index {
            None => Ok(()),
            Some((_, at)) => Err(ScanError {
                at,
                msg: format!("`{word}` takes no index"),
            }),
        }
    }

    fn need_index(&self, word: &str, index: Index, lo: i64, hi: i64) -> Result<i64, ScanError> {
        match index {
            None => Err(ScanError {
                at: word.len(),
                msg: format!("expected `(` and an index after `{word}`"),
            }),
            Some((v, at)) if v < lo || v > hi => Err(ScanError {
                at,
                msg: format!("the index of `{word}` is {v}, outside {lo}..={hi}"),
            }),
            Some((v, _)) => Ok(v),
        }
    }

    /// Note a simple keyword; warn when it was given before.
    fn seen(&mut self, ll: &LogicalLine<'_>, key: &str, word: &str) {
        let line = ll.line();
        // The key is allocated only the first time it is seen.
        let earlier = match self.seen.get_mut(key) {
            Some(first) => Some(std::mem::replace(first, line)),
            None => {
                self.seen.insert(key.to_string(), line);
                None
            }
        };
        if let Some(first) = earlier {
            self.warn(
                ll.pos(0),
                DiagKind::Semantic,
                format!("`{word}` was already given on line {first}; this later value counts"),
            );
        }
    }

    fn int_value(
        &mut self,
        ll: &LogicalLine<'_>,
        c: &mut Cursor<'_>,
        word: &str,
        key: &str,
        lo: i64,
        hi: i64,
    ) -> Result<i64, ScanError> {
        let v = c.int_in(format_args!("a number for `{word}`"), lo, hi)?;
        c.end(format_args!("the value of `{word}`"))?;
        self.seen(ll, key, word);
        Ok(v)
    }

    fn bool_value(
        &mut self,
        ll: &LogicalLine<'_>,
        c: &mut Cursor<'_>,
        word: &str,
        key: &str,
    ) -> Result<bool, ScanError> {
        c.ws();
        let at = c.at();
        let v = c.int(format_args!("0 or 1 for `{word}`"))?;
        c.end(format_args!("the value of `{word}`"))?;
        self.seen(ll, key, word);
        if v != 0 && v != 1 {
            self.quirk(
                ll.pos(at),
                Quirk::BadBoolean,
                format!("expected 0 or 1 for `{word}`, found {v}; read as 1"),
            );
        }
        Ok(v != 0)
    }

    /// A quoted string (single quotes and no quotes are quirks).
    fn string_value(
        &mut self,
        ll: &LogicalLine<'_>,
        c: &mut Cursor<'_>,
        what: impl std::fmt::Display,
        to_end: bool,
    ) -> Result<String, ScanError> {
        match c.peek() {
            Some('"') => Ok(c.string(&what, false)?.text.to_string()),
            Some('\'') => {
                let q = c.string(&what, true)?;
                self.quirk(
                    ll.pos(q.at),
                    Quirk::SingleQuotes,
                    format!("expected {what} in double quotes, found single quotes"),
                );
                Ok(q.text.to_string())
            }
            Some(_) if to_end => {
                let at = c.at();
                let text = c.take_rest().to_string();
                self.quirk(
                    ll.pos(at),
                    Quirk::UnquotedString,
                    format!("expected {what} in double quotes, found `{text}` without quotes"),
                );
                Ok(text)
            }
            _ => {
                let found = c.found();
                Err(c.error(format!("expected {what} in double quotes, found {found}")))
            }
        }
    }

    fn string_field(
        &mut self,
        ll: &LogicalLine<'_>,
        c: &mut Cursor<'_>,
        word: &str,
        key: &str,
    ) -> Result<String, ScanError> {
        let s = self.string_value(ll, c, format_args!("the text of `{word}`"), true)?;
        c.end(format_args!("the text of `{word}`"))?;
        self.seen(ll, key, word);
        Ok(s)
    }

    fn global_keyword(
        &mut self,
        ll: &LogicalLine<'_>,
        c: &mut Cursor<'_>,
        word: &str,
        key: &str,
        index: Index,
    ) -> Result<(), ScanError> {
        macro_rules! int {
            ($field:ident, $t:ty) => {{
                self.no_index(word, index)?;
                let v = self.int_value(ll, c, word, key, <$t>::MIN as i64, <$t>::MAX as i64)?;
                self.gsd.$field = Some(v as $t);
            }};
        }
        macro_rules! flag {
            ($field:ident) => {{
                self.no_index(word, index)?;
                self.gsd.$field = self.bool_value(ll, c, word, key)?;
            }};
        }
        macro_rules! text {
            ($field:ident) => {{
                self.no_index(word, index)?;
                self.gsd.$field = Some(self.string_field(ll, c, word, key)?);
            }};
        }
        match key {
            "gsd_revision" => int!(gsd_revision, u8),
            "vendor_name" => text!(vendor_name),
            "model_name" => text!(model_name),
            "revision" => text!(revision),
            "revision_number" => int!(revision_number, u8),
            "ident_number" => {
                self.ident_seen = true;
                self.no_index(word, index)?;
                let v = self.int_value(ll, c, word, key, 0, 0xFFFF)?;
                self.gsd.ident_number = v as u16;
            }
            "protocol_ident" => {
                self.no_index(word, index)?;
                self.gsd.protocol_ident = self.int_value(ll, c, word, key, 0, 255)? as u8;
            }
            "station_type" => {
                self.no_index(word, index)?;
                self.gsd.station_type = self.int_value(ll, c, word, key, 0, 255)? as u8;
            }
            "fms_supp" => flag!(fms_supp),
            "hardware_release" => text!(hardware_release),
            "software_release" => text!(software_release),
            "ordernumber" | "order_number" => text!(order_number),
            "info_text" => text!(info_text),
            "redundancy" => flag!(redundancy),
            "repeater_ctrl_sig" => int!(repeater_ctrl_sig, u8),
            "24v_pins" => int!(pins_24v, u8),
            "implementation_type" => text!(implementation_type),
            "bitmap_device" => text!(bitmap_device),
            "bitmap_diag" => text!(bitmap_diag),
            "bitmap_sf" => text!(bitmap_sf),
            "freeze_mode_supp" => flag!(freeze_mode_supp),
            "sync_mode_supp" => flag!(sync_mode_supp),
            "auto_baud_supp" => flag!(auto_baud_supp),
            "set_slave_add_supp" => flag!(set_slave_add_supp),
            "fail_safe" => flag!(fail_safe),
            "min_slave_intervall" => int!(min_slave_intervall, u16),
            "max_diag_data_len" => int!(max_diag_data_len, u8),
            "modular_station" => flag!(modular_station),
            "max_module" => int!(max_module, u8),
            "max_input_len" => int!(max_input_len, u8),
            "max_output_len" => int!(max_output_len, u8),
            "max_data_len" => int!(max_data_len, u16),
            "modul_offset" => int!(modul_offset, u8),
            "fixpresetmodules" => flag!(fix_preset_modules),
            "user_prm_data_len" => int!(user_prm_data_len, u8),
            "max_user_prm_data_len" => int!(max_user_prm_data_len, u8),
            "dpv1_slave" => flag!(dpv1_slave),
            "c1_read_write_supp" => flag!(c1_read_write_supp),
            "c1_read_write_required" => flag!(c1_read_write_required),
            "c1_max_data_len" => int!(c1_max_data_len, u8),
            "c1_response_timeout" => int!(c1_response_timeout, u16),
            "c2_read_write_supp" => flag!(c2_read_write_supp),
            "c2_max_data_len" => int!(c2_max_data_len, u8),
            "c2_response_timeout" => int!(c2_response_timeout, u16),
            "c2_max_count_channels" => int!(c2_max_count_channels, u8),
            "max_initiate_pdu_length" => int!(max_initiate_pdu_length, u8),
            "wd_base_1ms_supp" => flag!(wd_base_1ms_supp),
            "check_cfg_mode" => flag!(check_cfg_mode),
            "diagnostic_alarm_supp" => flag!(diagnostic_alarm_supp),
            "process_alarm_supp" => flag!(process_alarm_supp),
            "pull_plug_alarm_supp" => flag!(pull_plug_alarm_supp),
            "status_alarm_supp" => flag!(status_alarm_supp),
            "update_alarm_supp" => flag!(update_alarm_supp),
            "manufacturer_specific_alarm_supp" => flag!(manufacturer_specific_alarm_supp),
            "alarm_type_mode_supp" => flag!(alarm_type_mode_supp),
            "alarm_sequence_mode_count" => int!(alarm_sequence_mode_count, u8),
            "slave_family" => {
                self.no_index(word, index)?;
                c.ws();
                let at = c.at();
                let rest = c.take_rest();
                let mut parts = rest.split('@');
                let main = parts.next().unwrap_or("").trim();
                let mut mc = Cursor::new(main);
                let main = mc
                    .int_in("the family number of `Slave_Family`", 0, 255)
                    .and_then(|v| mc.end("the family number").map(|_| v))
                    .map_err(|e| ScanError {
                        at: at + e.at,
                        msg: e.msg,
                    })?;
                let sub = parts.map(|s| s.trim().to_string()).collect();
                self.seen(ll, key, word);
                self.gsd.slave_family = Some(SlaveFamily {
                    main: main as u8,
                    sub,
                });
            }
            "user_prm_data" => {
                self.no_index(word, index)?;
                let v = c.bytes("a byte of `User_Prm_Data`")?;
                c.end("the bytes of `User_Prm_Data`")?;
                self.seen(ll, key, word);
                self.gsd.user_prm_data = Some(v);
            }
            "ext_user_prm_data_const" => {
                let offset = self.need_index(word, index, 0, 0xFFFF)? as u16;
                let data = c.bytes("a byte of `Ext_User_Prm_Data_Const`")?;
                c.end("the bytes of `Ext_User_Prm_Data_Const`")?;
                self.gsd
                    .ext_user_prm_data_const
                    .push(PrmConst { offset, data });
            }
            "ext_user_prm_data_ref" => {
                let offset = self.need_index(word, index, 0, 0xFFFF)? as u16;
                c.ws();
                let at = c.at();
                let reference = c.int_in("a reference number", 0, 0xFFFF)? as u16;
                c.end("the reference number")?;
                self.prm_refs.push((ll.pos(at), reference));
                self.gsd
                    .ext_user_prm_data_ref
                    .push(PrmRef { offset, reference });
            }
            "module" | "modules" => {
                self.no_index(word, index)?;
                if key == "modules" {
                    self.quirk(
                        ll.pos(0),
                        Quirk::ModulesKeyword,
                        format!("expected `Module`, found `{word}`"),
                    );
                }
                if self.gsd.modules.len() >= MAX_MODULES {
                    return Err(c.error(format!(
                        "more than {MAX_MODULES} modules; a GSD file may define at most {MAX_MODULES}"
                    )));
                }
                let name = self.string_value(ll, c, "the module name", false)?;
                let cfg = c.bytes("an identifier byte of the module")?;
                c.end("the identifier bytes")?;
                let start = ll.pos(0);
                self.gsd.modules.push(Module {
                    name,
                    cfg,
                    ..Module::default()
                });
                self.module_pos.push(start);
                self.state = State::Module {
                    index: self.gsd.modules.len() - 1,
                    start,
                };
            }
            "extuserprmdata" => {
                self.no_index(word, index)?;
                let reference = c.int_in("a reference number", 0, 0xFFFF)? as u16;
                let name = self.string_value(ll, c, "the parameter name", false)?;
                c.end("the parameter name")?;
                self.state = State::ExtPrm(Box::new(PendingPrm {
                    start: ll.pos(0),
                    reference,
                    name,
                    data_type: None,
                    prm_text_ref: None,
                    changeable: None,
                    visible: None,
                }));
            }
            "prmtext" => {
                self.no_index(word, index)?;
                let reference = c.int_in("a reference number", 0, 0xFFFF)? as u16;
                c.end("the reference number")?;
                self.gsd.prm_texts.push(PrmText {
                    reference,
                    texts: Vec::new(),
                });
                self.state = State::PrmText {
                    index: self.gsd.prm_texts.len() - 1,
                    start: ll.pos(0),
                };
            }
            "unit_diag_bit" | "unit_diag_not_bit" => {
                let bit = self.need_index(word, index, 0, u32::MAX as i64)? as u32;
                let text = self.string_value(ll, c, "the diagnosis text", true)?;
                c.end("the diagnosis text")?;
                let t = UnitDiagText { bit, text };
                if key == "unit_diag_bit" {
                    self.gsd.unit_diag_bits.push(t);
                } else {
                    self.gsd.unit_diag_not_bits.push(t);
                }
            }
            "unit_diag_area" => {
                self.no_index(word, index)?;
                let first = c.int_in("the first bit", 0, u32::MAX as i64)? as u32;
                c.expect('-', "`-` between the first and last bit")?;
                let last = c.int_in("the last bit", first as i64, u32::MAX as i64)? as u32;
                c.end("the bit range")?;
                self.gsd.unit_diag_areas.push(UnitDiagArea {
                    first,
                    last,
                    values: Vec::new(),
                });
                self.state = State::DiagArea {
                    index: self.gsd.unit_diag_areas.len() - 1,
                    start: ll.pos(0),
                };
            }
            _ => {
                if let Some(i) = key.strip_suffix("_supp").and_then(baud_by_suffix) {
                    self.no_index(word, index)?;
                    self.gsd.baud_rates[i].supported = self.bool_value(ll, c, word, key)?;
                } else if let Some((i, quirk)) = key
                    .strip_prefix("maxtsdr_")
                    .map(|s| (s, false))
                    .or_else(|| key.strip_prefix("maxtsd_").map(|s| (s, true)))
                    .and_then(|(s, q)| baud_by_suffix(s).map(|i| (i, q)))
                {
                    self.no_index(word, index)?;
                    if quirk {
                        self.quirk(
                            ll.pos(0),
                            Quirk::MaxTsdSpelling,
                            format!("expected `MaxTsdr_…`, found `{word}`"),
                        );
                    }
                    let canonical = format!("maxtsdr_{}", &key[key.find('_').unwrap_or(0) + 1..]);
                    let v = self.int_value(ll, c, word, &canonical, 0, 0xFFFF)?;
                    self.gsd.baud_rates[i].max_tsdr = Some(v as u16);
                } else {
                    if !keywords::known_station(key) {
                        self.warn(
                            ll.pos(0),
                            DiagKind::UnknownKeyword,
                            format!("unknown keyword `{word}`; kept, not interpreted"),
                        );
                    }
                    self.gsd.other.push(ll.text.to_string());
                }
            }
        }
        Ok(())
    }

    /// Whether `key` is a station-level keyword the parser handles (used
    /// to detect a block that lacks its `End…` line).
    fn is_global_keyword(key: &str) -> bool {
        matches!(
            key,
            "gsd_revision"
                | "vendor_name"
                | "model_name"
                | "revision"
                | "ident_number"
                | "protocol_ident"
                | "station_type"
                | "hardware_release"
                | "software_release"
                | "freeze_mode_supp"
                | "sync_mode_supp"
                | "auto_baud_supp"
                | "set_slave_add_supp"
                | "min_slave_intervall"
                | "max_diag_data_len"
                | "modular_station"
                | "max_module"
                | "max_input_len"
                | "max_output_len"
                | "max_data_len"
                | "user_prm_data_len"
                | "user_prm_data"
                | "max_user_prm_data_len"
                | "module"
                | "modules"
                | "extuserprmdata"
                | "prmtext"
                | "slotdefinition"
                | "unit_diag_bit"
                | "unit_diag_not_bit"
                | "unit_diag_area"
                | "dpv1_slave"
                | "slave_family"
        ) || key.starts_with("maxtsd")
            || key.ends_with("_supp")
    }

    // ---- Module body ----

    fn module_line(&mut self, ll: &LogicalLine<'_>, index: usize, start: Pos) {
        if ll.text.starts_with(|ch: char| ch.is_ascii_digit()) {
            let mut c = Cursor::new(&ll.text);
            let r = c
                .int_in("a module reference number", 0, u32::MAX as i64)
                .and_then(|v| c.end("the module reference number").map(|_| v));
            match r {
                Ok(v) => {
                    let m = &mut self.gsd.modules[index];
                    if m.reference.is_some() {
                        self.warn(
                            ll.pos(0),
                            DiagKind::Semantic,
                            "a second module reference number; this later one counts".into(),
                        );
                    }
                    self.gsd.modules[index].reference = Some(v as u32);
                }
                Err(e) => self.syntax(ll, e),
            }
            return;
        }
        let mut c = Cursor::new(&ll.text);
        let Some((word, idx, eq)) = self.head(ll, &mut c) else {
            return;
        };
        let key = word.to_ascii_lowercase();
        if key == "endmodule" {
            if let Err(e) = c.end("`EndModule`") {
                self.syntax(ll, e);
            }
            self.state = State::Global;
            return;
        }
        if key == "data_area_beg" {
            self.gsd.modules[index].other.push(ll.text.to_string());
            self.state = State::Raw {
                end: "data_area_end",
                owner: Owner::Module(index),
                start: ll.pos(0),
            };
            return;
        }
        if !eq || key == "module" || key == "modules" {
            if Self::is_global_keyword(&key) || key.starts_with("end") {
                self.missing_end(ll, "module", start, "EndModule");
            } else if c.at_end() {
                self.warn(
                    ll.pos(0),
                    DiagKind::UnknownKeyword,
                    format!("unknown keyword `{word}` in a module; kept, not interpreted"),
                );
                self.gsd.modules[index].other.push(ll.text.to_string());
            } else {
                let found = c.found();
                self.quirk(
                    ll.pos(c.at()),
                    Quirk::StrayText,
                    format!("expected `=` after `{word}`, found {found}; the line is ignored"),
                );
            }
            return;
        }
        let r: Result<(), ScanError> = (|| {
            match key.as_str() {
                "ext_module_prm_data_len" => {
                    self.no_index(word, idx)?;
                    let v = c.int_in("a length", 0, 255)?;
                    c.end("the length")?;
                    self.gsd.modules[index].ext_module_prm_data_len = Some(v as u8);
                }
                "ext_user_prm_data_const" => {
                    let offset = self.need_index(word, idx, 0, 0xFFFF)? as u16;
                    let data = c.bytes("a byte of `Ext_User_Prm_Data_Const`")?;
                    c.end("the bytes of `Ext_User_Prm_Data_Const`")?;
                    self.gsd.modules[index]
                        .ext_user_prm_data_const
                        .push(PrmConst { offset, data });
                }
                "ext_user_prm_data_ref" => {
                    let offset = self.need_index(word, idx, 0, 0xFFFF)? as u16;
                    c.ws();
                    let at = c.at();
                    let reference = c.int_in("a reference number", 0, 0xFFFF)? as u16;
                    c.end("the reference number")?;
                    self.prm_refs.push((ll.pos(at), reference));
                    self.gsd.modules[index]
                        .ext_user_prm_data_ref
                        .push(PrmRef { offset, reference });
                }
                "preset" => {
                    self.no_index(word, idx)?;
                    c.ws();
                    let v = c.int_in("0 or 1 for `Preset`", 0, 1)?;
                    c.end("the value of `Preset`")?;
                    self.gsd.modules[index].preset = v == 1;
                }
                "info_text" => {
                    self.no_index(word, idx)?;
                    let s = self.string_value(ll, &mut c, "the text of `Info_Text`", true)?;
                    c.end("the text of `Info_Text`")?;
                    self.gsd.modules[index].info_text = Some(s);
                }
                k if Self::is_global_keyword(k) => {
                    self.missing_end(ll, "module", start, "EndModule");
                }
                k => {
                    if !keywords::known_module(k) {
                        self.warn(
                            ll.pos(0),
                            DiagKind::UnknownKeyword,
                            format!("unknown keyword `{word}` in a module; kept, not interpreted"),
                        );
                    }
                    self.gsd.modules[index].other.push(ll.text.to_string());
                }
            }
            Ok(())
        })();
        if let Err(e) = r {
            self.syntax(ll, e);
        }
    }

    // ---- ExtUserPrmData body ----

    fn ext_prm_line(&mut self, ll: &LogicalLine<'_>, mut p: Box<PendingPrm>) {
        let mut c = Cursor::new(&ll.text);
        let Some(word) = c.clone().word() else {
            self.state = State::ExtPrm(p);
            let found = c.found();
            self.quirk(
                ll.pos(0),
                Quirk::StrayText,
                format!("expected a data type or `EndExtUserPrmData`, found {found}"),
            );
            return;
        };
        let key = word.to_ascii_lowercase();
        let data_type = match key.as_str() {
            "unsigned8" => Some(PrmDataType::Unsigned8),
            "unsigned16" => Some(PrmDataType::Unsigned16),
            "unsigned32" => Some(PrmDataType::Unsigned32),
            "signed8" => Some(PrmDataType::Signed8),
            "signed16" => Some(PrmDataType::Signed16),
            "signed32" => Some(PrmDataType::Signed32),
            "bit" | "bitarea" => Some(PrmDataType::Bit(0)),
            _ => None,
        };
        if data_type.is_some() {
            c.word();
            match self.prm_type_line(&mut c, &key) {
                Ok((t, default, allowed)) => {
                    if p.data_type.is_some() {
                        self.warn(
                            ll.pos(0),
                            DiagKind::Semantic,
                            format!(
                                "a second data type line in `ExtUserPrmData` {}; this later one counts",
                                p.reference
                            ),
                        );
                    }
                    let (lo, hi) = t.limits();
                    if default < lo || default > hi {
                        self.quirk(
                            ll.pos(0),
                            Quirk::BadParameter,
                            format!(
                                "the default {default} of parameter `{}` does not fit {} ({lo}..={hi}); the parameter is ignored",
                                p.name,
                                t.gsd_name()
                            ),
                        );
                    } else {
                        if !allowed.contains(default) {
                            self.warn(
                                ll.pos(0),
                                DiagKind::Semantic,
                                format!(
                                    "the default {default} of parameter `{}` is not among its allowed values ({allowed})",
                                    p.name
                                ),
                            );
                        }
                        p.data_type = Some((t, default, allowed));
                    }
                }
                Err(e) => self.syntax(ll, e),
            }
            self.state = State::ExtPrm(p);
            return;
        }
        let Some((word, idx, eq)) = self.head(ll, &mut c) else {
            self.state = State::ExtPrm(p);
            return;
        };
        if key == "endextuserprmdata" {
            if let Err(e) = c.end("`EndExtUserPrmData`") {
                self.syntax(ll, e);
            }
            self.finish_prm(*p);
            return;
        }
        let r: Result<(), ScanError> = match key.as_str() {
            "prm_text_ref" if eq => (|| {
                self.no_index(word, idx)?;
                c.ws();
                let at = c.at();
                let v = c.int_in("a reference number", 0, 0xFFFF)? as u16;
                c.end("the reference number")?;
                p.prm_text_ref = Some((v, ll.pos(at)));
                Ok(())
            })(),
            "changeable" | "visible" if eq => (|| {
                self.no_index(word, idx)?;
                c.ws();
                let v = c.int_in("0 or 1", 0, 1)? == 1;
                c.end("the value")?;
                if key == "changeable" {
                    p.changeable = Some(v);
                } else {
                    p.visible = Some(v);
                }
                Ok(())
            })(),
            k if Self::is_global_keyword(k) || k.starts_with("end") => {
                let start = p.start;
                self.finish_prm(*p);
                self.missing_end(ll, "`ExtUserPrmData` block", start, "EndExtUserPrmData");
                return;
            }
            _ => {
                self.quirk(
                    ll.pos(0),
                    Quirk::BadParameter,
                    format!(
                        "expected a data type (Unsigned8/16/32, Signed8/16/32, Bit(n), BitArea(a-b)), `Prm_Text_Ref` or `EndExtUserPrmData`, found `{word}`"
                    ),
                );
                Ok(())
            }
        };
        if let Err(e) = r {
            self.syntax(ll, e);
        }
        self.state = State::ExtPrm(p);
    }

    /// `Type[(args)] Default [Min-Max | a,b,c]` after the type word.
    fn prm_type_line(
        &mut self,
        c: &mut Cursor<'_>,
        key: &str,
    ) -> Result<(PrmDataType, i64, Allowed), ScanError> {
        let t = match key {
            "unsigned8" => PrmDataType::Unsigned8,
            "unsigned16" => PrmDataType::Unsigned16,
            "unsigned32" => PrmDataType::Unsigned32,
            "signed8" => PrmDataType::Signed8,
            "signed16" => PrmDataType::Signed16,
            "signed32" => PrmDataType::Signed32,
            "bit" => {
                c.expect('(', "`(` and a bit number after `Bit`")?;
                let n = c.int_in("a bit number", 0, 7)? as u8;
                c.expect(')', "`)`")?;
                PrmDataType::Bit(n)
            }
            _ => {
                c.expect('(', "`(` and a bit range after `BitArea`")?;
                let a = c.int_in("the first bit", 0, 7)? as u8;
                c.expect('-', "`-` between the first and last bit")?;
                let b = c.int_in("the last bit", a as i64, 7)? as u8;
                c.expect(')', "`)`")?;
                PrmDataType::BitArea(a, b)
            }
        };
        let default = c.int("a default value")?;
        let allowed = if c.at_end() {
            Allowed::Any
        } else {
            let at = c.at();
            let a = c.int("the allowed values (`min-max` or `a,b,c`)")?;
            if c.eat('-') {
                let b = c.int("the maximum")?;
                if b < a {
                    return Err(ScanError {
                        at,
                        msg: format!("the range {a}-{b} is empty"),
                    });
                }
                Allowed::Range(a, b)
            } else {
                let mut v = vec![a];
                while c.eat(',') {
                    v.push(c.int("an allowed value")?);
                }
                Allowed::Values(v)
            }
        };
        c.end("the parameter definition")?;
        Ok((t, default, allowed))
    }

    fn finish_prm(&mut self, p: PendingPrm) {
        self.state = State::Global;
        let Some((data_type, default, allowed)) = p.data_type else {
            self.quirk(
                p.start,
                Quirk::BadParameter,
                format!(
                    "`ExtUserPrmData` {} (`{}`) has no usable data type line; the parameter is ignored",
                    p.reference, p.name
                ),
            );
            return;
        };
        if let Some((r, pos)) = p.prm_text_ref {
            self.text_refs.push((pos, r));
        }
        self.gsd.ext_user_prm_data.push(ExtUserPrmData {
            reference: p.reference,
            name: p.name,
            data_type,
            default,
            allowed,
            prm_text_ref: p.prm_text_ref.map(|(r, _)| r),
            changeable: p.changeable,
            visible: p.visible,
        });
    }

    // ---- PrmText, SlotDefinition, Unit_Diag_Area bodies ----

    /// `Text(v) = "…"` or `Value(v) = "…"`: the value and text.
    fn value_text(
        &mut self,
        ll: &LogicalLine<'_>,
        c: &mut Cursor<'_>,
        word: &str,
        idx: Index,
    ) -> Result<PrmTextValue, ScanError> {
        let value = self.need_index(word, idx, i64::MIN, i64::MAX)?;
        let text = self.string_value(ll, c, "the text", true)?;
        c.end("the text")?;
        Ok(PrmTextValue { value, text })
    }

    fn prm_text_line(&mut self, ll: &LogicalLine<'_>, index: usize, start: Pos) {
        if let Some(t) = self.text_block_line(ll, &PRM_TEXT, start) {
            self.gsd.prm_texts[index].texts.push(t);
        }
    }

    /// A line inside a block of value texts: its end keyword closes the
    /// block, an `item(value) = "text"` line gives a text (returned).
    fn text_block_line(
        &mut self,
        ll: &LogicalLine<'_>,
        block: &TextBlock,
        start: Pos,
    ) -> Option<PrmTextValue> {
        let mut c = Cursor::new(&ll.text);
        let (word, idx, eq) = self.head(ll, &mut c)?;
        if word.eq_ignore_ascii_case(block.end) {
            if let Err(e) = c.end(format_args!("`{}`", block.end)) {
                self.syntax(ll, e);
            }
            self.state = State::Global;
        } else if eq && word.eq_ignore_ascii_case(block.item) {
            match self.value_text(ll, &mut c, word, idx) {
                Ok(t) => return Some(t),
                Err(e) => self.syntax(ll, e),
            }
        } else {
            self.missing_end(ll, block.name, start, block.end);
        }
        None
    }

    fn slot_line(&mut self, ll: &LogicalLine<'_>, start: Pos) {
        let mut c = Cursor::new(&ll.text);
        let Some((word, idx, eq)) = self.head(ll, &mut c) else {
            return;
        };
        let key = word.to_ascii_lowercase();
        match key.as_str() {
            "endslotdefinition" => {
                if let Err(e) = c.end("`EndSlotDefinition`") {
                    self.syntax(ll, e);
                }
                self.state = State::Global;
            }
            "slot" if eq => {
                let r: Result<Slot, ScanError> = (|| {
                    let number = self.need_index(word, idx, 0, 255)? as u8;
                    let name = self.string_value(ll, &mut c, "the slot name", false)?;
                    let default_module =
                        c.int_in("the default module reference", 0, u32::MAX as i64)? as u32;
                    let a = c.int_in("the allowed module references", 0, u32::MAX as i64)?;
                    let allowed = if c.eat('-') {
                        let b = c.int_in("the last module reference", a, u32::MAX as i64)?;
                        Allowed::Range(a, b)
                    } else {
                        let mut v = vec![a];
                        while c.eat(',') {
                            v.push(c.int_in("a module reference", 0, u32::MAX as i64)?);
                        }
                        Allowed::Values(v)
                    };
                    c.end("the slot definition")?;
                    Ok(Slot {
                        number,
                        name,
                        default_module,
                        allowed,
                    })
                })();
                match r {
                    Ok(s) => self.gsd.slots.push(s),
                    Err(e) => self.syntax(ll, e),
                }
            }
            _ => self.missing_end(ll, "`SlotDefinition` block", start, "EndSlotDefinition"),
        }
    }

    fn diag_area_line(&mut self, ll: &LogicalLine<'_>, index: usize, start: Pos) {
        if let Some(t) = self.text_block_line(ll, &DIAG_AREA, start) {
            self.gsd.unit_diag_areas[index].values.push(t);
        }
    }

    fn close_at_eof(&mut self) {
        let state = std::mem::replace(&mut self.state, State::Global);
        let (what, start, end) = match state {
            State::Global => return,
            State::Module { start, .. } => ("module", start, "EndModule"),
            State::ExtPrm(p) => {
                let start = p.start;
                self.finish_prm(*p);
                ("`ExtUserPrmData` block", start, "EndExtUserPrmData")
            }
            State::PrmText { start, .. } => ("`PrmText` block", start, "EndPrmText"),
            State::Slots { start } => ("`SlotDefinition` block", start, "EndSlotDefinition"),
            State::DiagArea { start, .. } => {
                ("`Unit_Diag_Area` block", start, "Unit_Diag_Area_End")
            }
            State::Raw { end, start, owner } => {
                // Close the copied block so that writing `other` back
                // keeps it apart from what follows.
                self.push_other(owner, end.to_string());
                ("block", start, end)
            }
        };
        self.quirk(
            start,
            Quirk::MissingEnd,
            format!(
                "expected `{end}` closing the {what} opened on line {}, found the end of the file",
                start.line
            ),
        );
    }

    // ---- checks after parsing ----

    fn validate(&mut self) {
        if self.errors.iter().any(|d| d.kind == DiagKind::TooLarge) {
            return;
        }
        let g = &self.gsd;
        let mut notes: Vec<(Pos, DiagKind, String, bool)> = Vec::new();
        let mut note = |pos: Pos, kind: DiagKind, msg: String, is_err: bool| {
            notes.push((pos, kind, msg, is_err));
        };
        if !self.ident_seen {
            note(
                Pos::default(),
                DiagKind::Syntax,
                "the file has no `Ident_Number`".into(),
                true,
            );
        }
        for (key, present) in [
            ("GSD_Revision", g.gsd_revision.is_some()),
            ("Vendor_Name", g.vendor_name.is_some()),
            ("Model_Name", g.model_name.is_some()),
        ] {
            if !present {
                note(
                    Pos::default(),
                    DiagKind::Semantic,
                    format!("the file has no `{key}`"),
                    false,
                );
            }
        }
        // Sets of the defined reference numbers: a hostile file with
        // tens of thousands of references and definitions must not cost
        // their product.
        let mut prm_defined = RefSet::new();
        let mut duplicates = Vec::new();
        for p in &g.ext_user_prm_data {
            if !prm_defined.insert(p.reference) {
                duplicates.push(p.reference);
            }
        }
        let mut text_defined = RefSet::new();
        for t in &g.prm_texts {
            text_defined.insert(t.reference);
        }
        for (pos, r) in &self.prm_refs {
            if !prm_defined.contains(*r) {
                note(
                    *pos,
                    DiagKind::Quirk(Quirk::DanglingReference),
                    format!("`Ext_User_Prm_Data_Ref` names `ExtUserPrmData` {r}, which the file does not define"),
                    !self.lenient,
                );
            }
        }
        for (pos, r) in &self.text_refs {
            if !text_defined.contains(*r) {
                note(
                    *pos,
                    DiagKind::Quirk(Quirk::DanglingReference),
                    format!("`Prm_Text_Ref` names `PrmText` {r}, which the file does not define"),
                    !self.lenient,
                );
            }
        }
        for reference in duplicates {
            note(
                Pos::default(),
                DiagKind::Semantic,
                format!(
                    "`ExtUserPrmData` {reference} is defined twice; the first definition counts"
                ),
                false,
            );
        }
        for (m, pos) in g.modules.iter().zip(&self.module_pos) {
            if let Some(Err(e)) = cfg::identifiers(&m.cfg).find(|r| r.is_err()) {
                note(
                    *pos,
                    DiagKind::Quirk(Quirk::BadIdentifier),
                    format!(
                        "module `{}`: its identifier bytes do not decode: {e}",
                        m.name
                    ),
                    !self.lenient,
                );
            }
        }
        for (i, b) in g.baud_rates.iter().enumerate() {
            if b.supported && b.max_tsdr.is_none() {
                note(
                    Pos::default(),
                    DiagKind::Semantic,
                    format!(
                        "`{}_supp` is set but `MaxTsdr_{}` is missing",
                        Baud::ALL[i].gsd_suffix(),
                        Baud::ALL[i].gsd_suffix()
                    ),
                    false,
                );
            }
        }
        for (key, v) in [
            ("Max_Input_Len", g.max_input_len),
            ("Max_Output_Len", g.max_output_len),
            ("Max_Diag_Data_Len", g.max_diag_data_len),
        ] {
            if let Some(v) = v.filter(|&v| v > 244) {
                note(
                    Pos::default(),
                    DiagKind::Semantic,
                    format!("`{key}` is {v}, more than the 244 bytes a DP telegram carries"),
                    false,
                );
            }
        }
        let line_of = |key: &str| Pos {
            line: self.seen.get(key).copied().unwrap_or(0),
            col: 1,
        };
        // A modular station's limits without `Modular_Station = 1`: the
        // file contradicts itself, and the station is read as compact.
        if !g.modular_station && g.modules.len() > 1 {
            if let Some(n) = g.max_module {
                let modular = if self.seen.contains_key("modular_station") {
                    "`Modular_Station = 0`"
                } else {
                    "no `Modular_Station = 1`"
                };
                note(
                    line_of("max_module"),
                    DiagKind::Semantic,
                    format!(
                        "`Max_Module = {n}` describes a modular station, but the file has {modular}: \
                         it is read as a compact station, configured with exactly one of its {} modules; \
                         if the device takes several modules at once, the file lacks `Modular_Station = 1`",
                        g.modules.len()
                    ),
                    false,
                );
            }
        }
        // The legacy User_Prm_Data is sent padded or cut to its length.
        let legacy = g.ext_user_prm_data_const.is_empty() && g.ext_user_prm_data_ref.is_empty();
        if let Some(len) = g.user_prm_data_len.map(usize::from) {
            let given = g.user_prm_data.as_ref().map_or(0, Vec::len);
            let used = if legacy {
                ""
            } else {
                "; the file's `Ext_User_Prm_Data_Const`/`Ext_User_Prm_Data_Ref` lines define the bytes instead"
            };
            let pos = line_of("user_prm_data_len");
            if g.user_prm_data.is_some() && given < len {
                let what = if legacy {
                    format!("; the other {} byte(s) are sent as 0", len - given)
                } else {
                    used.to_string()
                };
                note(
                    pos,
                    DiagKind::Semantic,
                    format!("`User_Prm_Data_Len = {len}` but `User_Prm_Data` gives only {given} byte(s){what}"),
                    false,
                );
            } else if given > len {
                let what = if legacy {
                    format!("; only the first {len} are sent")
                } else {
                    used.to_string()
                };
                note(
                    pos,
                    DiagKind::Semantic,
                    format!("`User_Prm_Data` gives {given} bytes, more than `User_Prm_Data_Len = {len}`{what}"),
                    false,
                );
            } else if g.user_prm_data.is_none() && len > 0 && legacy {
                note(
                    pos,
                    DiagKind::Semantic,
                    format!("`User_Prm_Data_Len = {len}` but the file gives no `User_Prm_Data`; {len} zero byte(s) are sent"),
                    false,
                );
            }
        }
        if let Some(v) = g.c1_max_data_len.filter(|&v| v > 240) {
            note(
                Pos::default(),
                DiagKind::Semantic,
                format!("`C1_Max_Data_Len` is {v}, more than the 240 bytes of a DP-V1 read/write"),
                false,
            );
        }
        for (pos, kind, message, is_err) in notes {
            let d = Diagnostic { pos, kind, message };
            if is_err {
                push_capped(&mut self.errors, d);
            } else {
                push_capped(&mut self.warnings, d);
            }
        }
    }
}

/// Modules a GSD file may define (real files define a few hundred at
/// most; each costs a few hundred bytes).
pub(crate) const MAX_MODULES: usize = 4096;

/// Errors or warnings kept per list: a hostile file (a quarter of a
/// million unclosed modules) must not cost a diagnostic per line. The
/// last one kept says that more were left out.
pub(crate) const MAX_DIAGNOSTICS: usize = 1000;

/// FNV-1a for the keyword table: the keys are the parser's own keywords
/// (a fixed set of a few dozen), so a hash resisting chosen collisions is
/// not needed, and SipHash costs more than the rest of a short line.
#[derive(Clone, Copy, Default)]
struct KeyHasher;

struct Fnv(u64);

impl std::hash::BuildHasher for KeyHasher {
    type Hasher = Fnv;

    fn build_hasher(&self) -> Fnv {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl std::hash::Hasher for Fnv {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
}

/// A set of 16-bit reference numbers, one bit each; it allocates its
/// 8 KiB only when the first number goes in.
struct RefSet(Vec<u64>);

impl RefSet {
    fn new() -> RefSet {
        RefSet(Vec::new())
    }

    /// Add `r`; whether it was not in the set yet.
    fn insert(&mut self, r: u16) -> bool {
        if self.0.is_empty() {
            self.0 = vec![0; 1 << 10];
        }
        let (word, bit) = (usize::from(r >> 6), 1u64 << (r & 63));
        let new = self.0[word] & bit == 0;
        self.0[word] |= bit;
        new
    }

    fn contains(&self, r: u16) -> bool {
        self.0
            .get(usize::from(r >> 6))
            .is_some_and(|w| w & (1u64 << (r & 63)) != 0)
    }
}

fn push_capped(list: &mut Vec<Diagnostic>, d: Diagnostic) {
    match list.len() {
        n if n + 1 < MAX_DIAGNOSTICS => list.push(d),
        n if n + 1 == MAX_DIAGNOSTICS => list.push(Diagnostic {
            message: format!("{} (further diagnostics left out)", d.message),
            ..d
        }),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lenient(text: &str) -> Parsed {
        parse(text, ParseOptions::LENIENT).unwrap_or_else(|e| panic!("{e:?}"))
    }

    #[test]
    fn a_header_reached_through_a_continuation_ends_the_section() {
        // Found by gsd_parse (third session), minimised: a `#` line after
        // a lone `\` was copied into the open `UnitDiagType` block, written
        // back as a line of its own and read as a section header then, so
        // the round trip lost the rest of the block.
        let p = lenient("Ident_Number=0\nUnitDiagType\n\\\n#");
        assert_eq!(p.gsd.other, ["UnitDiagType", "endunitdiagtype"]);
        assert!(p
            .warnings
            .iter()
            .any(|w| w.pos.line == 4 && w.message.contains("`#` starts another section")));
        assert_eq!(lenient(&p.gsd.write()).gsd, p.gsd);
        // The same for a second `#Profibus_DP`, which is ignored, and at
        // the station level.
        let text = "#Profibus_DP\nIdent_Number=1\nUnitDiagType\n \\\n #profibus_dp\nx\n\
                    EndUnitDiagType\n\\\n#Other\nIdent_Number=2\n";
        let p = lenient(text);
        assert_eq!(p.gsd.ident_number, 1);
        assert_eq!(p.gsd.other, ["UnitDiagType", "x", "EndUnitDiagType"]);
        assert_eq!(lenient(&p.gsd.write()).gsd, p.gsd);
    }
}
