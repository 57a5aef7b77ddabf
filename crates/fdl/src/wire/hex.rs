//! Bytes as hex text, the one formatter every crate and `dpctl` use.

use std::fmt;

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

#[cfg(test)]
mod tests {
    use super::Hex;

    #[test]
    fn spaced_and_compact() {
        assert_eq!(Hex(&[1, 10, 255]).to_string(), "01 0A FF");
        assert_eq!(format!("{:#}", Hex(&[1, 10, 255])), "010AFF");
        assert_eq!(Hex(&[]).to_string(), "");
    }
}
