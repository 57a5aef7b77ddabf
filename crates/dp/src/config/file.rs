//! Reading the files the stack takes as input (bus files, a device
//! profile's table and script files) with a size limit: the length in the
//! metadata is checked first, and the read itself stops one byte after
//! the limit, so a pipe, `/dev/zero` or a file that grows while it is
//! read cannot make the reader allocate without bound. (GSD files have
//! their own reader with the same rule, `Gsd::from_file`.)

use std::io::Read;
use std::path::Path;

/// Why a file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadFileError {
    /// The operating system refused (missing file, no permission, a
    /// directory). The message includes the cause, which is therefore not
    /// also returned as `source()`: a printed error chain names it once.
    #[error("cannot read: {0}")]
    Io(std::io::Error),
    /// The file is larger than what this kind of file may have.
    #[error("the file is {} the {limit} bytes {what} may have", match size {
        Some(n) => format!("{n} bytes long, more than"),
        None => "longer than".to_string(),
    })]
    TooLarge {
        /// Its length from the metadata, if that already told.
        size: Option<u64>,
        /// The limit in bytes.
        limit: u64,
        /// The kind of file ("a bus file").
        what: &'static str,
    },
    /// Text that is not UTF-8.
    #[error("not UTF-8 text: byte 0x{byte:02X} at line {line}, column {column} (save the file as UTF-8)")]
    NotUtf8 {
        /// Line of the first invalid byte (from 1).
        line: usize,
        /// Its column in bytes (from 1).
        column: usize,
        /// The byte.
        byte: u8,
    },
}

impl From<std::io::Error> for ReadFileError {
    fn from(e: std::io::Error) -> Self {
        ReadFileError::Io(e)
    }
}

/// The bytes of `path`, at most `limit` of them; `what` names the kind
/// of file in the error ("a bus file").
pub fn read_limited(path: &Path, limit: u64, what: &'static str) -> Result<Vec<u8>, ReadFileError> {
    let file = std::fs::File::open(path)?;
    let too_large = |size| ReadFileError::TooLarge { size, limit, what };
    if let Ok(meta) = file.metadata() {
        if meta.len() > limit {
            return Err(too_large(Some(meta.len())));
        }
    }
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(None));
    }
    Ok(bytes)
}

/// The UTF-8 text of `path`, at most `limit` bytes (see
/// [`read_limited`]).
pub fn read_text(path: &Path, limit: u64, what: &'static str) -> Result<String, ReadFileError> {
    utf8(read_limited(path, limit, what)?)
}

/// `bytes` as UTF-8 text, or where the first invalid byte is.
pub fn utf8(bytes: Vec<u8>) -> Result<String, ReadFileError> {
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let b = e.as_bytes();
        let before = &b[..at];
        let line = before.iter().filter(|&&c| c == b'\n').count() + 1;
        let column = at
            - before
                .iter()
                .rposition(|&c| c == b'\n')
                .map_or(0, |p| p + 1)
            + 1;
        ReadFileError::NotUtf8 {
            line,
            column,
            byte: b[at],
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invalid_utf8_names_line_and_column() {
        let e = utf8(b"a = 1\nb = \"x\xFFy\"\n".to_vec()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "not UTF-8 text: byte 0xFF at line 2, column 7 (save the file as UTF-8)"
        );
        assert_eq!(utf8(b"ok".to_vec()).unwrap(), "ok");
    }

    #[test]
    fn an_endless_stream_is_cut_at_the_limit() {
        // /dev/zero has length 0 in its metadata and never ends.
        let e = read_limited(Path::new("/dev/zero"), 1000, "a test file").unwrap_err();
        assert_eq!(
            e.to_string(),
            "the file is longer than the 1000 bytes a test file may have"
        );
        assert_eq!(read_limited(Path::new("/dev/null"), 10, "x").unwrap(), b"");
    }

    #[test]
    fn a_failed_read_names_its_cause_once() {
        let e = read_limited(Path::new("/nonexistent/bus.toml"), 10, "x").unwrap_err();
        assert!(e.to_string().starts_with("cannot read: "), "{e}");
        // In the message, so not also the source: `{:#}` prints it once.
        assert!(std::error::Error::source(&e).is_none());
    }
}
