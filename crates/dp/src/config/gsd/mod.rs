//! GSD files (Gerätestammdatei, EN 50170 / IEC 61784): the description of
//! a DP slave that a master is configured from.
//!
//! - Parsing ([`Gsd::parse`], [`Gsd::from_file`]): GSD revisions 1–5 as
//!   found in the field. Keywords are case-insensitive, `;` starts a
//!   comment, `\` continues a line (a string continued so keeps its
//!   quotes: a `;` after its closing quote on a later line starts a
//!   comment), numbers are decimal or `0x` hex, strings are quoted, files
//!   are Latin-1, with the extension `.gsd` or a localised one
//!   ([`FILE_EXTENSIONS`], all read alike). Errors carry line and column
//!   and say what was expected. In lenient mode
//!   ([`ParseOptions::lenient`]) known vendor quirks (a commented-out
//!   `#Profibus_DP`, `MaxTsd_` for `MaxTsdr_`, `Modules=` and single
//!   quotes, stray text, missing `End…` lines, dangling references) are
//!   accepted with a warning; in strict mode they are errors. Inputs over
//!   [`MAX_FILE_LEN`] bytes or with a line over [`MAX_LINE_LEN`] bytes are
//!   rejected before anything else is done with them.
//! - The typed model ([`Gsd`], [`Module`], [`ExtUserPrmData`], …) in
//!   [`model`], with every keyword the DP master and slave need. The
//!   other keywords of the standard (DP-V1 and DP-V2 details, isochronous
//!   mode, I&M, PROFIsafe `F_…`, extended parameterisation `X_…`,
//!   diagnosis help texts, a master's keywords) are known to the parser
//!   and kept as raw text ([`Gsd::other_value`]); only keywords outside
//!   the standard are reported as unknown.
//! - The semantic API in [`semantic`]: identifier decoding per module
//!   (through [`crate::pdu::cfg`]), module lookup by exact name (an error
//!   names the closest, [`crate::config::names`]), Chk_Cfg and User_Prm_Data for a module selection plus named
//!   parameter values, checks of a selection against the `Max_*` limits,
//!   MaxTsdr per baud rate.
//! - The writer ([`Gsd::write`]): a valid GSD file from the model, such
//!   that parse → write → parse gives the same model.

mod keywords;
mod lexer;
pub mod model;
mod parser;
pub mod semantic;
mod summary;
mod writer;

pub use model::*;
pub use semantic::{
    LookupError, ModuleIo, ParamInstance, PrmInput, PrmValue, PrmValueParseError, Problem,
    SelectionError,
};
pub use summary::{GsdCheck, GsdSummary};

use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Largest GSD file accepted, in bytes (4 MiB). Real files are a few
/// kilobytes up to a few hundred (large modular I/O systems with many
/// texts); anything bigger is not a GSD file, and refusing it early keeps
/// memory bounded.
pub const MAX_FILE_LEN: usize = 4 << 20;

/// Longest line accepted, in bytes (64 KiB), for a physical line and for
/// a logical line joined from continuations.
pub const MAX_LINE_LEN: usize = 64 << 10;

/// File name extensions of GSD files, lower case: `gsd`, and the
/// localised variants a vendor ships beside it or instead of it, which
/// differ only in the language of their texts: `gse` (English), `gsf`
/// (French), `gsg` (German), `gsi` (Italian), `gsp` (Portuguese), `gss`
/// (Spanish) and `gst`. Every reader of GSD files accepts any path; this
/// list is for finding GSD files in a directory.
pub const FILE_EXTENSIONS: [&str; 8] = ["gsd", "gse", "gsf", "gsg", "gsi", "gsp", "gss", "gst"];

/// Whether `path` has one of the [`FILE_EXTENSIONS`] (in any case:
/// `SIEM8042.GSE` and `si0180fd.gsg` both count).
pub fn is_gsd_file_name(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| FILE_EXTENSIONS.iter().any(|x| e.eq_ignore_ascii_case(x)))
}

/// Options for [`Gsd::parse`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ParseOptions {
    /// Accept known vendor quirks ([`Quirk`]) with a warning instead of
    /// failing.
    pub lenient: bool,
}

impl ParseOptions {
    /// Lenient parsing: quirks are warnings.
    pub const LENIENT: ParseOptions = ParseOptions { lenient: true };
    /// Strict parsing: quirks are errors.
    pub const STRICT: ParseOptions = ParseOptions { lenient: false };
}

/// A position in a GSD file: 1-based line and column (in characters).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Pos {
    /// Line, from 1.
    pub line: u32,
    /// Column, from 1.
    pub col: u32,
}

impl fmt::Display for Pos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.col)
    }
}

/// A known deviation of real GSD files from the standard, accepted in
/// lenient mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Quirk {
    /// `;#Profibus_DP`: the section header is commented out (BM4-O-PRO-01
    /// default file).
    CommentedSectionHeader,
    /// No `#Profibus_DP` line at all; the whole file is read.
    MissingSectionHeader,
    /// `MaxTsd_<rate>` instead of `MaxTsdr_<rate>` (Omega Drive-Line II).
    MaxTsdSpelling,
    /// `Modules=` instead of `Module=` (Omega Drive-Line II).
    ModulesKeyword,
    /// A string in single quotes (Omega Drive-Line II).
    SingleQuotes,
    /// A string value without quotes.
    UnquotedString,
    /// A line that is no GSD statement (e.g. `=====` banners).
    StrayText,
    /// A block (`Module`, `ExtUserPrmData`, …) not closed by its `End…`
    /// line.
    MissingEnd,
    /// An `End…` line with no open block.
    UnmatchedEnd,
    /// A boolean keyword with a value other than 0 or 1 (read as true).
    BadBoolean,
    /// A reference (`Ext_User_Prm_Data_Ref`, `Prm_Text_Ref`) to a block
    /// the file does not define.
    DanglingReference,
    /// A module whose identifier bytes do not decode.
    BadIdentifier,
    /// A parameter definition the parser cannot read (unknown data type,
    /// default outside the type).
    BadParameter,
}

/// What a [`Diagnostic`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DiagKind {
    /// The input could not be read (I/O error).
    Io,
    /// The input is over [`MAX_FILE_LEN`] or has a line over
    /// [`MAX_LINE_LEN`].
    TooLarge,
    /// Not valid GSD syntax, or a value outside its range.
    Syntax,
    /// A known quirk (warning in lenient mode, error in strict mode).
    Quirk(Quirk),
    /// A keyword the parser does not know (kept in `other`).
    UnknownKeyword,
    /// Valid syntax with a questionable meaning (duplicate keyword,
    /// limits beyond the protocol's, missing recommended keywords, …).
    Semantic,
}

/// An error or warning with its position.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Diagnostic {
    /// Where (line 0 for the file as a whole).
    pub pos: Pos,
    /// What kind.
    pub kind: DiagKind,
    /// What is wrong, in words, including what was expected.
    pub message: String,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.pos.line > 0 {
            write!(f, "{}: ", self.pos)?;
        }
        f.write_str(&self.message)
    }
}

impl DiagKind {
    /// A short name for scripts: `io`, `too-large`, `syntax`,
    /// `quirk:NAME`, `unknown-keyword`, `semantic`.
    pub fn name(self) -> String {
        match self {
            DiagKind::Io => "io".into(),
            DiagKind::TooLarge => "too-large".into(),
            DiagKind::Syntax => "syntax".into(),
            DiagKind::Quirk(q) => format!("quirk:{q:?}"),
            DiagKind::UnknownKeyword => "unknown-keyword".into(),
            DiagKind::Semantic => "semantic".into(),
        }
    }
}

/// A [`Diagnostic`] of a named file with its severity, as `dpctl gsd
/// check` prints it: `Display` is `FILE:LINE:COL: severity: message`
/// (`FILE: …` for the whole file); with the feature `serde` it
/// serialises as `{file, line, col, severity, kind, message}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileDiagnostic<'a> {
    /// The file.
    pub file: &'a std::path::Path,
    /// `error` or `warning`.
    pub severity: &'static str,
    /// The diagnostic.
    pub diagnostic: &'a Diagnostic,
}

impl<'a> FileDiagnostic<'a> {
    /// `diagnostic` of `file` as an `error` or `warning` (`severity`).
    pub fn new(
        file: &'a std::path::Path,
        severity: &'static str,
        diagnostic: &'a Diagnostic,
    ) -> Self {
        FileDiagnostic {
            file,
            severity,
            diagnostic,
        }
    }
}

impl fmt::Display for FileDiagnostic<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (file, d) = (self.file.display(), self.diagnostic);
        if d.pos.line == 0 {
            write!(f, "{file}: {}: {}", self.severity, d.message)
        } else {
            write!(f, "{file}:{}: {}: {}", d.pos, self.severity, d.message)
        }
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for FileDiagnostic<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let d = self.diagnostic;
        let mut st = s.serialize_struct("FileDiagnostic", 6)?;
        st.serialize_field("file", &self.file.display().to_string())?;
        st.serialize_field("line", &d.pos.line)?;
        st.serialize_field("col", &d.pos.col)?;
        st.serialize_field("severity", self.severity)?;
        st.serialize_field("kind", &d.kind.name())?;
        st.serialize_field("message", &d.message)?;
        st.end()
    }
}

impl Gsd {
    /// Problems of the file's modules beyond syntax: each module that
    /// alone breaks the limits (a modular station takes it with others,
    /// a compact station as its one configuration), as semantic warnings
    /// of the whole file.
    pub fn module_problems(&self) -> Vec<Diagnostic> {
        let mut out = Vec::new();
        for (i, m) in self.modules.iter().enumerate() {
            for p in self.check_selection(&[i]) {
                out.push(Diagnostic {
                    pos: Pos::default(),
                    kind: DiagKind::Semantic,
                    message: format!("module {i} `{}` alone: {p}", m.name),
                });
            }
        }
        out
    }
}

/// A parsed GSD file with the warnings the parser gave.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Parsed {
    /// The model.
    pub gsd: Gsd,
    /// Warnings, in file order.
    pub warnings: Vec<Diagnostic>,
}

/// A GSD file that could not be parsed: every error found (at least
/// one), plus the warnings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GsdError {
    /// The file, when parsing came from one.
    pub file: Option<PathBuf>,
    /// The errors, in file order (never empty).
    pub errors: Vec<Diagnostic>,
    /// The warnings, in file order.
    pub warnings: Vec<Diagnostic>,
}

impl GsdError {
    fn single(file: Option<&Path>, kind: DiagKind, message: String) -> GsdError {
        GsdError {
            file: file.map(Path::to_path_buf),
            errors: vec![Diagnostic {
                pos: Pos::default(),
                kind,
                message,
            }],
            warnings: Vec::new(),
        }
    }

    /// The first error.
    pub fn first(&self) -> &Diagnostic {
        &self.errors[0]
    }
}

impl fmt::Display for GsdError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(file) = &self.file {
            write!(f, "{}:", file.display())?;
            if self.first().pos.line == 0 {
                f.write_str(" ")?;
            }
        }
        write!(f, "{}", self.first())?;
        match self.errors.len() {
            1 => Ok(()),
            2 => f.write_str(" (and 1 more error)"),
            n => write!(f, " (and {} more errors)", n - 1),
        }
    }
}

impl std::error::Error for GsdError {}

/// Decode Latin-1 bytes (the encoding of GSD files) into a string: every
/// byte is the character of the same number.
pub fn decode_latin1(bytes: &[u8]) -> String {
    // Most GSD files are plain ASCII, which is the same text in UTF-8:
    // copy it in one go instead of character by character.
    if bytes.is_ascii() {
        if let Ok(s) = std::str::from_utf8(bytes) {
            return s.to_owned();
        }
    }
    // U+0080..=U+00FF take two bytes in UTF-8: 110000xx 10xxxxxx.
    let mut utf8 = Vec::with_capacity(bytes.len() * 2);
    for &b in bytes {
        if b < 0x80 {
            utf8.push(b);
        } else {
            utf8.extend_from_slice(&[0xC0 | (b >> 6), 0x80 | (b & 0x3F)]);
        }
    }
    String::from_utf8(utf8).expect("Latin-1 encoded as UTF-8 is valid UTF-8")
}

/// Encode a string as Latin-1; characters beyond U+00FF become `?`.
pub fn encode_latin1(text: &str) -> Vec<u8> {
    text.chars()
        .map(|c| u8::try_from(u32::from(c)).unwrap_or(b'?'))
        .collect()
}

impl Gsd {
    /// Parse the text of a GSD file.
    ///
    /// Returns the model with the warnings, or every error found. Text
    /// longer than [`MAX_FILE_LEN`] is rejected at once.
    pub fn parse(text: &str, opts: ParseOptions) -> Result<Parsed, GsdError> {
        if text.len() > MAX_FILE_LEN {
            return Err(GsdError::single(
                None,
                DiagKind::TooLarge,
                format!(
                    "the text is {} bytes long, more than the {} bytes a GSD file may have",
                    text.len(),
                    MAX_FILE_LEN
                ),
            ));
        }
        parser::parse(text, opts).map_err(|(errors, warnings)| GsdError {
            file: None,
            errors,
            warnings,
        })
    }

    /// Read and parse a GSD file (Latin-1). A file longer than
    /// [`MAX_FILE_LEN`] is rejected without reading it.
    pub fn from_file(path: impl AsRef<Path>, opts: ParseOptions) -> Result<Parsed, GsdError> {
        let path = path.as_ref();
        let io = |e: std::io::Error| {
            GsdError::single(
                Some(path),
                DiagKind::Io,
                format!("cannot read the file: {e}"),
            )
        };
        let file = std::fs::File::open(path).map_err(io)?;
        let too_large = |len: Option<u64>| {
            let size = match len {
                Some(n) => format!("{n} bytes long, more than"),
                None => "longer than".to_string(),
            };
            GsdError::single(
                Some(path),
                DiagKind::TooLarge,
                format!("the file is {size} the {MAX_FILE_LEN} bytes a GSD file may have"),
            )
        };
        if let Ok(meta) = file.metadata() {
            if meta.len() > MAX_FILE_LEN as u64 {
                return Err(too_large(Some(meta.len())));
            }
        }
        // The size may change or be unknown (pipes): never read more than
        // the limit plus one byte.
        let mut bytes = Vec::new();
        file.take(MAX_FILE_LEN as u64 + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        if bytes.len() > MAX_FILE_LEN {
            return Err(too_large(None));
        }
        let text = decode_latin1(&bytes);
        Gsd::parse(&text, opts).map_err(|mut e| {
            e.file = Some(path.to_path_buf());
            e
        })
    }
}
