//! A GSD library: the GSD files a program may find a slave's file in, by
//! its ident number (commissioning: `dpctl scan --write-config`,
//! `dpctl get-cfg`, `dpctl diag`).
//!
//! The places, searched in this order (the first file with a fitting
//! configuration wins):
//!
//! 1. the folders given (`--gsd-dir DIR`, in the order given, not
//!    recursive);
//! 2. the files built into the program (the layer above passes them:
//!    `profibus_devices::gsd_files::BUILT_IN`);
//! 3. the user library, `$XDG_DATA_HOME/dpctl/gsd` (default
//!    `~/.local/share/dpctl/gsd`; [`user_dir`]), where `dpctl gsd install`
//!    copies files.
//!
//! A GSD file is `NAME.gsd` or a localised variant `NAME.gs?` (`.gse`
//! English, `.gsg` German, `.gsf` French, `.gsi` Italian, `.gss` Spanish;
//! any letter is taken; case does not matter). Of the variants of one
//! name in one folder only one is read: `.gsd`, else `.gse`, else the
//! first by name. Files that do not parse are left out and listed
//! ([`GsdLibrary::skipped`]).

use crate::config::gsd::{decode_latin1, Gsd, GsdError, ParseOptions};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where a library file comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GsdSource {
    /// A file on disk (a `--gsd-dir` folder or the user library).
    File(PathBuf),
    /// A file built into the program, by its file name.
    BuiltIn(&'static str),
}

impl std::fmt::Display for GsdSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            GsdSource::File(p) => write!(f, "{}", p.display()),
            GsdSource::BuiltIn(name) => write!(f, "{name} (built in)"),
        }
    }
}

/// One GSD file of the library.
#[derive(Debug, Clone)]
pub struct LibraryEntry {
    /// Where it is.
    pub source: GsdSource,
    /// The file as parsed (leniently).
    pub gsd: Gsd,
    /// For a built-in file: its bytes (to write it out next to a bus
    /// file).
    pub bytes: Option<&'static [u8]>,
}

/// A file the library could not read, and why.
#[derive(Debug, Clone)]
pub struct Skipped {
    /// The file.
    pub path: PathBuf,
    /// The parser's first error with its position.
    pub error: String,
}

/// The GSD files of the places in the module docs, indexed by ident
/// number.
#[derive(Debug, Clone, Default)]
pub struct GsdLibrary {
    entries: Vec<LibraryEntry>,
    by_ident: BTreeMap<u16, Vec<usize>>,
    skipped: Vec<Skipped>,
    /// The folders read, in order, for messages.
    places: Vec<String>,
}

/// Why a library folder cannot be read.
#[derive(Debug, thiserror::Error)]
#[error("GSD folder {}: {error}", path.display())]
pub struct LibraryError {
    /// The folder.
    pub path: PathBuf,
    /// The cause.
    pub error: std::io::Error,
}

/// The user library: `$XDG_DATA_HOME/dpctl/gsd`, else
/// `$HOME/.local/share/dpctl/gsd`; `None` without either variable.
pub fn user_dir() -> Option<PathBuf> {
    let data = std::env::var_os("XDG_DATA_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|v| !v.is_empty())
                .map(|h| PathBuf::from(h).join(".local/share"))
        })?;
    Some(data.join("dpctl/gsd"))
}

/// Whether `path` names a GSD file: extension `gsd` or a localised
/// `gs?` (any case).
pub fn is_gsd_name(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.len() == 3 && e[..2].eq_ignore_ascii_case("gs"))
}

/// Preference among the variants of one name: `.gsd`, `.gse`, the rest.
fn variant_rank(path: &Path) -> u8 {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .as_deref()
    {
        Some("gsd") => 0,
        Some("gse") => 1,
        _ => 2,
    }
}

impl GsdLibrary {
    /// An empty library.
    pub fn new() -> GsdLibrary {
        GsdLibrary::default()
    }

    /// Add the GSD files of folder `dir` (not recursive). A folder that
    /// cannot be listed is an error; a file that does not parse is
    /// skipped and listed.
    pub fn add_dir(&mut self, dir: &Path) -> Result<(), LibraryError> {
        let err = |error| LibraryError {
            path: dir.to_path_buf(),
            error,
        };
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(err)?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && is_gsd_name(p))
            .collect();
        files.sort();
        // One variant per name: the preferred one.
        let mut chosen: BTreeMap<String, PathBuf> = BTreeMap::new();
        for p in files {
            let stem = p
                .file_stem()
                .map(|s| s.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default();
            match chosen.get(&stem) {
                Some(q) if variant_rank(q) <= variant_rank(&p) => {}
                _ => {
                    chosen.insert(stem, p);
                }
            }
        }
        let mut files: Vec<PathBuf> = chosen.into_values().collect();
        files.sort();
        for p in files {
            match Gsd::from_file(&p, ParseOptions::LENIENT) {
                Ok(parsed) => self.push(LibraryEntry {
                    source: GsdSource::File(p),
                    gsd: parsed.gsd,
                    bytes: None,
                }),
                Err(e) => self.skipped.push(Skipped {
                    error: first_error(&p, &e),
                    path: p,
                }),
            }
        }
        self.places.push(dir.display().to_string());
        Ok(())
    }

    /// Add the user library ([`user_dir`]) when it exists.
    pub fn add_user_dir(&mut self) -> Result<(), LibraryError> {
        match user_dir() {
            Some(d) if d.is_dir() => self.add_dir(&d),
            _ => Ok(()),
        }
    }

    /// Add built-in files: (file name, Latin-1 bytes). A file that does
    /// not parse is skipped and listed.
    pub fn add_built_in(&mut self, files: &[(&'static str, &'static [u8])]) {
        for (name, bytes) in files {
            match Gsd::parse(&decode_latin1(bytes), ParseOptions::LENIENT) {
                Ok(parsed) => self.push(LibraryEntry {
                    source: GsdSource::BuiltIn(name),
                    gsd: parsed.gsd,
                    bytes: Some(bytes),
                }),
                Err(e) => self.skipped.push(Skipped {
                    path: PathBuf::from(name),
                    error: first_error(Path::new(name), &e),
                }),
            }
        }
        self.places.push("the built-in files".into());
    }

    fn push(&mut self, entry: LibraryEntry) {
        self.by_ident
            .entry(entry.gsd.ident_number)
            .or_default()
            .push(self.entries.len());
        self.entries.push(entry);
    }

    /// The files with ident number `ident`, in library order.
    pub fn find(&self, ident: u16) -> Vec<&LibraryEntry> {
        self.by_ident
            .get(&ident)
            .map(|v| v.iter().map(|i| &self.entries[*i]).collect())
            .unwrap_or_default()
    }

    /// Every file, in library order.
    pub fn entries(&self) -> &[LibraryEntry] {
        &self.entries
    }

    /// Files left out because they do not parse.
    pub fn skipped(&self) -> &[Skipped] {
        &self.skipped
    }

    /// The places read, in words (`DIR, the built-in files, DIR`).
    pub fn places(&self) -> String {
        if self.places.is_empty() {
            "no place".into()
        } else {
            self.places.join(", ")
        }
    }
}

/// `FILE:LINE:COL: message` of the parser's first error.
pub fn first_error(path: &Path, e: &GsdError) -> String {
    let d = e.first();
    if d.pos.line == 0 {
        format!("{}: {}", path.display(), d.message)
    } else {
        format!("{}:{}: {}", path.display(), d.pos, d.message)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "#Profibus_DP\nGSD_Revision=1\nIdent_Number=0x4711\nProtocol_Ident=0\n\
        Station_Type=0\n9.6_supp=1\nModule=\"m\" 0x10\nEndModule\n";

    #[test]
    fn folders_variants_and_broken_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = |n: &str| dir.path().join(n);
        std::fs::write(p("A.GSG"), FILE.replace("\"m\"", "\"deutsch\"")).unwrap();
        std::fs::write(p("A.gse"), FILE.replace("\"m\"", "\"english\"")).unwrap();
        std::fs::write(p("B.gsd"), FILE.replace("4711", "4712")).unwrap();
        std::fs::write(p("broken.gsd"), "#Profibus_DP\nIdent_Number=zz\n").unwrap();
        std::fs::write(p("notes.txt"), "x").unwrap();
        let mut lib = GsdLibrary::new();
        lib.add_dir(dir.path()).unwrap();
        let a = lib.find(0x4711);
        assert_eq!(a.len(), 1, "one variant of A");
        assert_eq!(a[0].gsd.modules[0].name, "english");
        assert_eq!(lib.find(0x4712).len(), 1);
        assert!(lib.find(0x1).is_empty());
        assert_eq!(lib.skipped().len(), 1);
        assert!(
            lib.skipped()[0].error.contains("broken.gsd:"),
            "{:?}",
            lib.skipped()
        );
        let e = GsdLibrary::new()
            .add_dir(&p("missing"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("GSD folder ") && e.contains("missing"), "{e}");
    }

    #[test]
    fn built_in_files_come_after_folders() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("x.gsd"), FILE).unwrap();
        let mut lib = GsdLibrary::new();
        lib.add_dir(dir.path()).unwrap();
        lib.add_built_in(&[("BUILTIN.GSD", FILE.as_bytes())]);
        let found = lib.find(0x4711);
        assert_eq!(found.len(), 2);
        assert!(matches!(found[0].source, GsdSource::File(_)));
        assert_eq!(found[1].source, GsdSource::BuiltIn("BUILTIN.GSD"));
        assert_eq!(found[1].source.to_string(), "BUILTIN.GSD (built in)");
    }
}
