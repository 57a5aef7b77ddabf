//! Configuration identifiers: the bytes of Chk_Cfg / Get_Cfg and of a GSD
//! `Module` line (EN 50170 part 3).
//!
//! A configuration is a sequence of identifiers, one or more per module:
//!
//! - **General format** (bits 5-4 ≠ 00), one byte: bit 7 consistency over
//!   the whole length, bit 6 unit words (else bytes), bits 5-4 01 input /
//!   10 output / 11 input and output (same length each way), bits 3-0
//!   length − 1 (1..=16 units).
//! - **Special format** (bits 5-4 = 00): bits 7-6 00 free place, 01 an
//!   input length byte follows, 10 an output length byte follows, 11 an
//!   output length byte and then an input length byte follow; bits 3-0 the
//!   number (0..=14) of manufacturer-specific bytes after the length
//!   byte(s). A length byte has bit 7 consistency, bit 6 words, bits 5-0
//!   length − 1 (1..=64 units).
//!
//! [`CfgIter`] walks a configuration without allocating; [`Identifier`]
//! is one decoded identifier with its I/O lengths; its `Display` says it
//! in words.

use std::fmt;

/// Length of the data in one direction of an identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct IoLen {
    /// Number of units (1..=64).
    pub units: u8,
    /// Units are 16-bit words (else bytes).
    pub words: bool,
    /// Consistent over the whole length (else per unit).
    pub consistent: bool,
}

impl IoLen {
    /// Length in bytes.
    pub const fn bytes(&self) -> usize {
        self.units as usize * if self.words { 2 } else { 1 }
    }

    /// The length byte of the special format.
    pub const fn length_byte(&self) -> u8 {
        (self.consistent as u8) << 7 | (self.words as u8) << 6 | (self.units - 1) & 0x3F
    }

    const fn from_length_byte(b: u8) -> IoLen {
        IoLen {
            units: (b & 0x3F) + 1,
            words: b & 0x40 != 0,
            consistent: b & 0x80 != 0,
        }
    }
}

/// One decoded identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Identifier<'a> {
    /// The identifier's bytes as they appear in the configuration.
    pub raw: &'a [u8],
    /// Input data (slave → master), if any.
    pub input: Option<IoLen>,
    /// Output data (master → slave), if any.
    pub output: Option<IoLen>,
    /// Manufacturer-specific bytes of a special-format identifier.
    pub manufacturer: &'a [u8],
}

impl Identifier<'_> {
    /// Input bytes.
    pub fn input_bytes(&self) -> usize {
        self.input.map_or(0, |l| l.bytes())
    }

    /// Output bytes.
    pub fn output_bytes(&self) -> usize {
        self.output.map_or(0, |l| l.bytes())
    }

    /// A free place (empty slot): no data either way.
    pub fn is_empty_slot(&self) -> bool {
        self.input.is_none() && self.output.is_none()
    }

    /// Whether this identifier uses the special format.
    pub fn is_special(&self) -> bool {
        self.raw[0] & 0x30 == 0
    }
}

impl fmt::Display for IoLen {
    /// `4 words`, `1 byte`, with ` (consistent)` when consistent over the
    /// whole length.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let unit = match (self.words, self.units) {
            (true, 1) => "word",
            (true, _) => "words",
            (false, 1) => "byte",
            (false, _) => "bytes",
        };
        write!(f, "{} {unit}", self.units)?;
        if self.consistent {
            f.write_str(" (consistent)")?;
        }
        Ok(())
    }
}

impl fmt::Display for Identifier<'_> {
    /// The identifier in words: `4 words in+out`, `2 words (consistent)
    /// in; manufacturer bytes 02 04`, `18 words out + 4 words in`,
    /// `empty slot`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.input, self.output) {
            (None, None) => f.write_str("empty slot")?,
            (Some(i), None) => write!(f, "{i} in")?,
            (None, Some(o)) => write!(f, "{o} out")?,
            (Some(i), Some(o)) if !self.is_special() => {
                debug_assert_eq!(i, o);
                write!(f, "{i} in+out")?
            }
            (Some(i), Some(o)) => write!(f, "{o} out + {i} in")?,
        }
        if !self.manufacturer.is_empty() {
            let bytes = profibus_fdl::wire::Hex(self.manufacturer);
            write!(f, "; manufacturer bytes {bytes}")?;
        }
        Ok(())
    }
}

/// A configuration byte sequence that cannot be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum CfgError {
    /// A special-format identifier announces more bytes than remain.
    #[error("identifier at byte {offset} announces {needed} bytes, only {available} remain")]
    Truncated {
        /// Offset of the identifier's first byte.
        offset: usize,
        /// Bytes the identifier needs.
        needed: usize,
        /// Bytes left in the configuration.
        available: usize,
    },
    /// Bits 3-0 = 15 in a special-format header (reserved).
    #[error("identifier 0x{byte:02X} at byte {offset} has the reserved manufacturer length 15")]
    ReservedLength {
        /// Offset of the identifier.
        offset: usize,
        /// The header byte.
        byte: u8,
    },
}

/// Iterator over the identifiers of a configuration.
#[derive(Debug, Clone)]
pub struct CfgIter<'a> {
    bytes: &'a [u8],
    pos: usize,
}

/// Walk the identifiers of `bytes`.
pub fn identifiers(bytes: &[u8]) -> CfgIter<'_> {
    CfgIter { bytes, pos: 0 }
}

impl<'a> Iterator for CfgIter<'a> {
    type Item = Result<Identifier<'a>, CfgError>;

    fn next(&mut self) -> Option<Self::Item> {
        let rest = &self.bytes[self.pos..];
        let &head = rest.first()?;
        let offset = self.pos;
        if head & 0x30 != 0 {
            self.pos += 1;
            let len = IoLen {
                units: (head & 0x0F) + 1,
                words: head & 0x40 != 0,
                consistent: head & 0x80 != 0,
            };
            let (input, output) = match head & 0x30 {
                0x10 => (Some(len), None),
                0x20 => (None, Some(len)),
                _ => (Some(len), Some(len)),
            };
            return Some(Ok(Identifier {
                raw: &rest[..1],
                input,
                output,
                manufacturer: &[],
            }));
        }
        let mfr = (head & 0x0F) as usize;
        if mfr == 15 {
            self.pos = self.bytes.len();
            return Some(Err(CfgError::ReservedLength { offset, byte: head }));
        }
        let len_bytes = match head >> 6 {
            0 => 0,
            1 | 2 => 1,
            _ => 2,
        };
        let needed = 1 + len_bytes + mfr;
        if rest.len() < needed {
            self.pos = self.bytes.len();
            return Some(Err(CfgError::Truncated {
                offset,
                needed,
                available: rest.len(),
            }));
        }
        let (input, output) = match head >> 6 {
            0 => (None, None),
            1 => (Some(IoLen::from_length_byte(rest[1])), None),
            2 => (None, Some(IoLen::from_length_byte(rest[1]))),
            _ => (
                Some(IoLen::from_length_byte(rest[2])),
                Some(IoLen::from_length_byte(rest[1])),
            ),
        };
        self.pos += needed;
        Some(Ok(Identifier {
            raw: &rest[..needed],
            input,
            output,
            manufacturer: &rest[1 + len_bytes..needed],
        }))
    }
}

/// Total input and output bytes of a configuration.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CfgTotals {
    /// Number of identifiers.
    pub identifiers: usize,
    /// Input bytes (slave → master).
    pub input_bytes: usize,
    /// Output bytes (master → slave).
    pub output_bytes: usize,
}

/// Sum the I/O lengths of a configuration.
pub fn totals(bytes: &[u8]) -> Result<CfgTotals, CfgError> {
    let mut t = CfgTotals::default();
    for id in identifiers(bytes) {
        let id = id?;
        t.identifiers += 1;
        t.input_bytes += id.input_bytes();
        t.output_bytes += id.output_bytes();
    }
    Ok(t)
}

/// Direction of a general-format identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Input (slave → master).
    Input,
    /// Output (master → slave).
    Output,
    /// Input and output of the same length.
    InOut,
}

/// A general-format identifier byte; `units` is 1..=16.
pub const fn general(dir: Direction, units: u8, words: bool, consistent: bool) -> u8 {
    let d = match dir {
        Direction::Input => 0x10,
        Direction::Output => 0x20,
        Direction::InOut => 0x30,
    };
    (consistent as u8) << 7 | (words as u8) << 6 | d | (units.saturating_sub(1) & 0x0F)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn omega_example_a() {
        // 73 71 5F 6F → 44 in / 44 out (Omega manual 5.01013.03 §5.4).
        let t = totals(&[0x73, 0x71, 0x5F, 0x6F]).unwrap();
        assert_eq!((t.identifiers, t.input_bytes, t.output_bytes), (4, 44, 44));
        // F9: consistent words in+out 10 → 20/20.
        let id = identifiers(&[0xF9]).next().unwrap().unwrap();
        assert_eq!((id.input_bytes(), id.output_bytes()), (20, 20));
        assert!(id.input.unwrap().consistent);
        // C0,81,81 (81 decimal = 0x51): 18 words out + 18 words in.
        let id = identifiers(&[0xC0, 0x51, 0x51]).next().unwrap().unwrap();
        assert_eq!((id.input_bytes(), id.output_bytes()), (36, 36));
    }

    #[test]
    fn bm4_special_identifier() {
        // 42 C1 02 04: 2 words in, consistent, manufacturer bytes 02 04.
        let v: Vec<_> = identifiers(&[0x42, 0xC1, 0x02, 0x04, 0x82, 0xC0, 0x01, 0x03])
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!(
            v[0].input,
            Some(IoLen {
                units: 2,
                words: true,
                consistent: true
            })
        );
        assert_eq!(v[0].manufacturer, &[0x02, 0x04]);
        assert_eq!(v[0].output, None);
        assert_eq!(v[1].output_bytes(), 2);
        assert_eq!(v[1].manufacturer, &[0x01, 0x03]);
        let t = totals(&[0x2F, 0x6F, 0x6F, 0x6F, 0x1F, 0x5F, 0x5F, 0x5F]).unwrap();
        assert_eq!((t.input_bytes, t.output_bytes), (112, 112));
    }

    #[test]
    fn beckhoff_and_trace_examples() {
        // C0,00,82: 1 B out, 3 B in, consistent.
        let id = identifiers(&[0xC0, 0x00, 0x82]).next().unwrap().unwrap();
        assert_eq!((id.output_bytes(), id.input_bytes()), (1, 3));
        // 00 10 20: a free place, 1 B in, 1 B out.
        let v: Vec<_> = identifiers(&[0x00, 0x10, 0x20])
            .collect::<Result<_, _>>()
            .unwrap();
        assert!(v[0].is_empty_slot());
        assert_eq!((v[1].input_bytes(), v[2].output_bytes()), (1, 1));
    }

    #[test]
    fn described_in_words() {
        let d = |b: &[u8]| identifiers(b).next().unwrap().unwrap().to_string();
        assert_eq!(d(&[0x73]), "4 words in+out");
        assert_eq!(d(&[0x10]), "1 byte in");
        assert_eq!(d(&[0x2F]), "16 bytes out");
        assert_eq!(
            d(&[0x42, 0xC1, 0x02, 0x04]),
            "2 words (consistent) in; manufacturer bytes 02 04"
        );
        assert_eq!(d(&[0xC0, 0x51, 0x43]), "18 words out + 4 words in");
        assert_eq!(d(&[0x00]), "empty slot");
    }

    #[test]
    fn errors() {
        assert_eq!(
            totals(&[0x10, 0x42, 0xC1, 0x02]),
            Err(CfgError::Truncated {
                offset: 1,
                needed: 4,
                available: 3
            })
        );
        assert!(matches!(
            totals(&[0x0F]),
            Err(CfgError::ReservedLength { .. })
        ));
    }

    #[test]
    fn general_encoding() {
        assert_eq!(general(Direction::InOut, 4, true, false), 0x73);
        assert_eq!(general(Direction::Input, 16, true, false), 0x5F);
        assert_eq!(general(Direction::InOut, 10, true, true), 0xF9);
        for b in 0x10..=0xFFu8 {
            if b & 0x30 == 0 {
                continue;
            }
            let one = [b];
            let id = identifiers(&one).next().unwrap().unwrap();
            let l = id.input.or(id.output).unwrap();
            let dir = match (id.input.is_some(), id.output.is_some()) {
                (true, false) => Direction::Input,
                (false, true) => Direction::Output,
                _ => Direction::InOut,
            };
            assert_eq!(general(dir, l.units, l.words, l.consistent), b);
        }
    }
}
