//! Bytes as hex text, the one formatter every crate and `dpctl` use.

#[allow(unused_imports)]
use crate::prelude::*;
use core::fmt;

/// Bytes shown as upper-case hex: `Hex(&[1, 10, 255])` displays as
/// `01 0A FF`; the alternate form `{:#}` leaves out the spaces
/// (`010AFF`). Formatting does not allocate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hex<'a>(pub &'a [u8]);

impl fmt::Display for Hex<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, b) in self.0.iter().enumerate() {
            if i > 0 && !f.alternate() {
                f.write_str(" ")?;
            }
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

/// Why text is not hex bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HexError {
    /// An odd number of hex digits in a group of more than one byte.
    #[error("odd number of hex digits")]
    OddDigits,
    /// Something that is not a hex digit.
    #[error("`{0}` is not a hex byte")]
    NotHex(String),
}

/// Bytes from hex text as people write it: `01 0A FF`, `010aff`,
/// `01:0a:ff`, `0x01,0x0A`; a lone digit between separators is one byte
/// (`1 a` = `01 0A`).
pub fn parse_hex(text: &str) -> Result<Vec<u8>, HexError> {
    let mut out = Vec::with_capacity(text.len() / 2);
    for group in text.split(|c: char| c.is_whitespace() || c == ':' || c == ',') {
        let g = group.trim_start_matches("0x").trim_start_matches("0X");
        if g.is_empty() {
            continue;
        }
        if !g.chars().all(|c| c.is_ascii_hexdigit()) {
            return Err(HexError::NotHex(group.to_string()));
        }
        if g.len() == 1 {
            out.push(u8::from_str_radix(g, 16).unwrap_or(0));
            continue;
        }
        if !g.len().is_multiple_of(2) {
            return Err(HexError::OddDigits);
        }
        for i in (0..g.len()).step_by(2) {
            out.push(u8::from_str_radix(&g[i..i + 2], 16).unwrap_or(0));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::{parse_hex, Hex, HexError};

    #[test]
    fn parse_what_people_write() {
        for text in [
            "01 0A FF",
            "010aff",
            "01:0a:ff",
            "0x01,0x0A, 0xff",
            "1 a ff",
        ] {
            assert_eq!(parse_hex(text), Ok(vec![1, 10, 255]), "{text}");
        }
        assert_eq!(parse_hex(""), Ok(vec![]));
        assert_eq!(parse_hex("123"), Err(HexError::OddDigits));
        assert_eq!(parse_hex("0g"), Err(HexError::NotHex("0g".into())));
    }

    #[test]
    fn spaced_and_compact() {
        assert_eq!(Hex(&[1, 10, 255]).to_string(), "01 0A FF");
        assert_eq!(format!("{:#}", Hex(&[1, 10, 255])), "010AFF");
        assert_eq!(Hex(&[]).to_string(), "");
    }
}
