//! Parsing and emitting FDL telegrams.
//!
//! [`Telegram::parse`] validates a telegram at the start of a byte slice
//! once (delimiters, lengths, FCS) and returns a borrowed view whose data
//! unit is a sub-slice of the input. [`Telegram::emit`] writes a telegram
//! into a caller-provided buffer and computes the FCS. A parsed telegram
//! remembers the start delimiter it arrived with, so that it is shown as
//! received and re-emitted byte for byte; a telegram built by a caller is
//! sent as SD1 without a data field and as SD2 otherwise, as slave ASICs
//! and the real devices in the traces do (SD3 only when asked for).

use super::consts::*;
use super::fc::FunctionCode;
#[allow(unused_imports)]
use crate::prelude::*;
use bytes::{BufMut, BytesMut};

/// Frame check sequence: arithmetic sum modulo 256 of the covered bytes
/// (DA, SA, FC, the SAP bytes and the data unit).
#[inline]
pub fn fcs(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |acc, &b| acc.wrapping_add(b))
}

/// Why a byte sequence is not a valid telegram.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ParseError {
    /// More bytes are needed; `needed` is the total length of the telegram
    /// as far as it is known from the bytes seen so far.
    #[error("truncated telegram: {needed} bytes needed, {available} available")]
    Truncated {
        /// Bytes the telegram needs in total (a lower bound while the
        /// length byte is not yet seen).
        needed: usize,
        /// Bytes available.
        available: usize,
    },
    /// The first byte is none of SD1, SD2, SD3, SD4 or SC.
    #[error("invalid start delimiter 0x{0:02X}")]
    BadStartDelimiter(u8),
    /// SD2: LE and its repetition LEr differ.
    #[error("length LE=0x{le:02X} differs from its repetition LEr=0x{ler:02X}")]
    LengthMismatch {
        /// The length byte.
        le: u8,
        /// Its repetition.
        ler: u8,
    },
    /// SD2: LE outside 3..=249.
    #[error("length LE={0} outside the range 3..=249")]
    LengthOutOfRange(u8),
    /// SD2: the fourth byte is not a second 0x68.
    #[error("repeated start delimiter is 0x{0:02X}, expected 0x68")]
    BadRepeatedDelimiter(u8),
    /// The FCS byte does not match the sum of the covered bytes.
    #[error("FCS mismatch: telegram carries 0x{received:02X}, computed 0x{computed:02X}")]
    FcsMismatch {
        /// FCS byte found in the telegram.
        received: u8,
        /// FCS computed over DA … end of data unit.
        computed: u8,
    },
    /// The byte after the FCS is not the end delimiter 0x16.
    #[error("missing end delimiter: found 0x{0:02X} instead of 0x16")]
    MissingEndDelimiter(u8),
    /// DA or SA announce an address extension but the data field is too
    /// short to hold the DSAP/SSAP byte.
    #[error("address extension announced but the data field holds no SAP byte")]
    MissingAddressExtension,
    /// A token telegram with an address above 126.
    #[error("token telegram with invalid address DA={da} SA={sa}")]
    BadTokenAddress {
        /// Destination address byte.
        da: u8,
        /// Source address byte.
        sa: u8,
    },
}

impl ParseError {
    /// Whether the error only means "wait for more bytes".
    pub fn is_truncated(&self) -> bool {
        matches!(self, ParseError::Truncated { .. })
    }
}

/// Why a telegram cannot be emitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EmitError {
    /// The output buffer is too small.
    #[error("output buffer too small: {needed} bytes needed, {available} available")]
    BufferTooSmall {
        /// Bytes the telegram needs.
        needed: usize,
        /// Bytes available in the buffer.
        available: usize,
    },
    /// The data field (SAP bytes plus data unit) exceeds 246 bytes.
    #[error("data field of {0} bytes exceeds the maximum of 246")]
    DataTooLong(usize),
    /// An address above 127 (the extension bit is set from the SAP fields,
    /// not by the caller).
    #[error("address {0} out of range (0..=127)")]
    BadAddress(u8),
    /// The requested start delimiter cannot carry this data field (SD1
    /// carries none, SD3 exactly 8 bytes including the SAP bytes).
    #[error("{} cannot carry a data field of {data_field} bytes", format.name())]
    FormatMismatch {
        /// The format asked for.
        format: Format,
        /// Length of the data field (SAP bytes plus data unit).
        data_field: usize,
    },
}

/// Telegram with a data field (SD1, SD2 or SD3): a request or a response.
///
/// `da`/`sa` are the plain station addresses (0..=127); the address
/// extension bit on the wire is set when `dsap`/`ssap` is `Some`. A DSAP or
/// SSAP byte keeps its raw value: bits 5-0 are the LSAP (0..=63) unless bit 6
/// (segment) is set; bit 7 says another extension byte follows (not used by
/// DP, kept as is).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataTelegram<'a> {
    /// Destination address (0..=127, 127 = broadcast).
    pub da: u8,
    /// Source address (0..=127).
    pub sa: u8,
    /// Frame control.
    pub fc: FunctionCode,
    /// Destination service access point (address extension of DA).
    pub dsap: Option<u8>,
    /// Source service access point (address extension of SA).
    pub ssap: Option<u8>,
    /// The data unit, borrowed from the receive buffer.
    pub data: &'a [u8],
    /// The start delimiter: the one received (set by
    /// [`Telegram::parse`]), or the one a caller asks for. `None` lets the
    /// emitter choose: SD1 for an empty data field, SD2 otherwise (also
    /// for exactly 8 bytes, where SD3 would be allowed: real devices and
    /// slave ASICs send SD2 with LE = 0x0B there). Only `Sd1`, `Sd2` and
    /// `Sd3` are meaningful here.
    pub format: Option<Format>,
}

impl<'a> DataTelegram<'a> {
    /// A telegram from `sa` to `da` with frame control `fc` and data unit
    /// `data`, without SAPs, in the format the emitter chooses.
    pub const fn new(da: u8, sa: u8, fc: FunctionCode, data: &'a [u8]) -> DataTelegram<'a> {
        DataTelegram {
            da,
            sa,
            fc,
            dsap: None,
            ssap: None,
            data,
            format: None,
        }
    }

    /// The same telegram with these address extensions (DSAP, SSAP).
    pub const fn with_saps(self, dsap: Option<u8>, ssap: Option<u8>) -> DataTelegram<'a> {
        DataTelegram { dsap, ssap, ..self }
    }

    /// Length of the data field on the wire: SAP bytes plus data unit.
    #[inline]
    pub fn data_field_len(&self) -> usize {
        self.dsap.is_some() as usize + self.ssap.is_some() as usize + self.data.len()
    }

    /// Whether the DSAP byte addresses a segment (bit 6) instead of an LSAP.
    pub fn dsap_is_segment(&self) -> bool {
        self.dsap.is_some_and(|s| s & 0x40 != 0)
    }

    /// Whether the SSAP byte addresses a segment (bit 6) instead of an LSAP.
    pub fn ssap_is_segment(&self) -> bool {
        self.ssap.is_some_and(|s| s & 0x40 != 0)
    }

    /// Whether this telegram is addressed to every station.
    pub fn is_broadcast(&self) -> bool {
        self.da == BROADCAST
    }

    /// Write the telegram in one pass (see [`Telegram::emit`]): header,
    /// SAPs and data unit, then the FCS over what was written.
    #[inline]
    fn emit(&self, buf: &mut [u8]) -> Result<usize, EmitError> {
        for a in [self.da, self.sa] {
            if a > BROADCAST {
                return Err(EmitError::BadAddress(a));
            }
        }
        let n = self.data_field_len();
        if n > MAX_DATA_FIELD {
            return Err(EmitError::DataTooLong(n));
        }
        let (sd, head, len) = match (self.format, n) {
            (None | Some(Format::Sd1), 0) => (SD1, 1, 6),
            (None | Some(Format::Sd2), _) => (SD2, 4, n + 9),
            (Some(Format::Sd3), SD3_DATA_FIELD) => (SD3, 1, 6 + SD3_DATA_FIELD),
            (Some(format), _) => {
                return Err(EmitError::FormatMismatch {
                    format,
                    data_field: n,
                })
            }
        };
        let available = buf.len();
        let buf = buf.get_mut(..len).ok_or(EmitError::BufferTooSmall {
            needed: len,
            available,
        })?;
        // Header, SAPs and the sum of what the FCS covers in one pass; the
        // data unit is copied and summed on its own (no second read of the
        // written bytes, no index checks per byte).
        let (da, sa, fc) = (self.da_byte(), self.sa_byte(), self.fc.to_byte());
        let mut sum = da.wrapping_add(sa).wrapping_add(fc);
        let rest = if head == 4 {
            let le = (n + 3) as u8;
            let (h, rest) = buf.split_at_mut(7);
            h.copy_from_slice(&[sd, le, le, SD2, da, sa, fc]);
            rest
        } else {
            let (h, rest) = buf.split_at_mut(4);
            h.copy_from_slice(&[sd, da, sa, fc]);
            rest
        };
        let mut rest = rest;
        for sap in [self.dsap, self.ssap].into_iter().flatten() {
            let (b, r) = rest.split_at_mut(1);
            b[0] = sap;
            sum = sum.wrapping_add(sap);
            rest = r;
        }
        let (unit, tail) = rest.split_at_mut(self.data.len());
        unit.copy_from_slice(self.data);
        sum = sum.wrapping_add(fcs(self.data));
        tail.copy_from_slice(&[sum, ED]);
        Ok(len)
    }

    fn da_byte(&self) -> u8 {
        self.da
            | if self.dsap.is_some() {
                ADDRESS_EXTENSION
            } else {
                0
            }
    }

    fn sa_byte(&self) -> u8 {
        self.sa
            | if self.ssap.is_some() {
                ADDRESS_EXTENSION
            } else {
                0
            }
    }
}

/// A validated FDL telegram borrowed from a byte buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Telegram<'a> {
    /// SD1, SD2 or SD3: a request or response, with or without data.
    Data(DataTelegram<'a>),
    /// SD4: the token passed from `sa` to `da`.
    Token {
        /// Station receiving the token.
        da: u8,
        /// Station passing the token.
        sa: u8,
    },
    /// SC (0xE5): short acknowledge.
    ShortAck,
}

/// The wire format a telegram was or will be sent in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// SD1: no data field.
    Sd1,
    /// SD2: variable data field.
    Sd2,
    /// SD3: fixed data field of 8 bytes.
    Sd3,
    /// SD4: token.
    Sd4,
    /// SC: short acknowledge.
    Sc,
}

impl Format {
    /// Name as written in the standard.
    pub fn name(self) -> &'static str {
        match self {
            Format::Sd1 => "SD1",
            Format::Sd2 => "SD2",
            Format::Sd3 => "SD3",
            Format::Sd4 => "SD4",
            Format::Sc => "SC",
        }
    }

    /// The format announced by a start delimiter byte.
    pub fn from_start_delimiter(sd: u8) -> Option<Format> {
        Some(match sd {
            SD1 => Format::Sd1,
            SD2 => Format::Sd2,
            SD3 => Format::Sd3,
            SD4 => Format::Sd4,
            SC => Format::Sc,
            _ => return None,
        })
    }
}

/// Total telegram length announced by the bytes at the start of `buf`, as
/// far as it can be known: `Ok(n)` when the length is known (the telegram
/// may still be incomplete or invalid), `Err` for a bad start delimiter or a
/// broken SD2 header, `Ok(4)` as a lower bound while LE is not yet seen.
#[inline]
pub fn frame_len(buf: &[u8]) -> Result<usize, ParseError> {
    let Some(&sd) = buf.first() else {
        return Err(ParseError::Truncated {
            needed: 1,
            available: 0,
        });
    };
    match sd {
        SC => Ok(1),
        SD4 => Ok(3),
        SD1 => Ok(6),
        SD3 => Ok(6 + SD3_DATA_FIELD),
        SD2 => {
            if buf.len() < 3 {
                return Ok(4);
            }
            let (le, ler) = (buf[1], buf[2]);
            if le != ler {
                return Err(ParseError::LengthMismatch { le, ler });
            }
            if !(MIN_LE..=MAX_LE).contains(&le) {
                return Err(ParseError::LengthOutOfRange(le));
            }
            Ok(le as usize + 6)
        }
        other => Err(ParseError::BadStartDelimiter(other)),
    }
}

impl<'a> Telegram<'a> {
    /// Parse and validate the telegram at the start of `buf`. On success
    /// returns the telegram and the number of bytes it occupies; bytes after
    /// it are ignored.
    #[inline]
    pub fn parse(buf: &'a [u8]) -> Result<(Telegram<'a>, usize), ParseError> {
        let truncated = |needed: usize| ParseError::Truncated {
            needed,
            available: buf.len(),
        };
        let Some(&sd) = buf.first() else {
            return Err(truncated(1));
        };
        // `body` start (DA) and total length.
        let (start, len) = match sd {
            SC => return Ok((Telegram::ShortAck, 1)),
            SD4 => {
                let [_, da, sa, ..] = *buf else {
                    return Err(truncated(3));
                };
                if da > MAX_STATION_ADDRESS || sa > MAX_STATION_ADDRESS {
                    return Err(ParseError::BadTokenAddress { da, sa });
                }
                return Ok((Telegram::Token { da, sa }, 3));
            }
            SD1 => (1, 6),
            SD3 => (1, 6 + SD3_DATA_FIELD),
            SD2 => {
                let len = frame_len(buf)?;
                if buf.len() < 4 {
                    return Err(truncated(len));
                }
                if buf[3] != SD2 {
                    return Err(ParseError::BadRepeatedDelimiter(buf[3]));
                }
                (4, len)
            }
            other => return Err(ParseError::BadStartDelimiter(other)),
        };
        if buf.len() < len {
            return Err(truncated(len));
        }
        let body = &buf[start..len - 2];
        let (received, ed) = (buf[len - 2], buf[len - 1]);
        let computed = fcs(body);
        if received != computed {
            return Err(ParseError::FcsMismatch { received, computed });
        }
        if ed != ED {
            return Err(ParseError::MissingEndDelimiter(ed));
        }
        let (da, sa, fc) = (body[0], body[1], body[2]);
        let mut i = 3;
        let mut sap = |present: bool| -> Result<Option<u8>, ParseError> {
            if !present {
                return Ok(None);
            }
            let b = *body.get(i).ok_or(ParseError::MissingAddressExtension)?;
            i += 1;
            Ok(Some(b))
        };
        let dsap = sap(da & ADDRESS_EXTENSION != 0)?;
        let ssap = sap(sa & ADDRESS_EXTENSION != 0)?;
        Ok((
            Telegram::Data(DataTelegram {
                da: da & !ADDRESS_EXTENSION,
                sa: sa & !ADDRESS_EXTENSION,
                fc: FunctionCode::from_byte(fc),
                dsap,
                ssap,
                data: &body[i..],
                format: Format::from_start_delimiter(sd),
            }),
            len,
        ))
    }

    /// Parse a buffer that must hold exactly one telegram; trailing bytes
    /// are reported as a truncation of the next telegram would be: not at
    /// all. Use [`Telegram::parse`] to learn the consumed length.
    pub fn parse_exact(buf: &'a [u8]) -> Result<Telegram<'a>, ParseError> {
        Self::parse(buf).map(|(t, _)| t)
    }

    /// The wire format: the one received for a parsed telegram, otherwise
    /// the one [`Telegram::emit`] will use (see [`DataTelegram::format`]).
    pub fn format(&self) -> Format {
        match self {
            Telegram::ShortAck => Format::Sc,
            Telegram::Token { .. } => Format::Sd4,
            Telegram::Data(d) => match (d.format, d.data_field_len()) {
                (Some(f), _) => f,
                (None, 0) => Format::Sd1,
                (None, _) => Format::Sd2,
            },
        }
    }

    /// Number of bytes [`Telegram::emit`] writes.
    pub fn emitted_len(&self) -> usize {
        match self {
            Telegram::ShortAck => 1,
            Telegram::Token { .. } => 3,
            Telegram::Data(d) => match self.format() {
                Format::Sd1 => 6,
                Format::Sd3 => 6 + SD3_DATA_FIELD,
                _ => d.data_field_len() + 9,
            },
        }
    }

    /// Write the telegram into `buf`; returns the number of bytes written.
    /// The start delimiter is [`Telegram::format`]'s; a requested format
    /// that does not fit the data field (SD1 with data, SD3 without exactly
    /// 8 bytes) is an error.
    #[inline]
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize, EmitError> {
        match *self {
            Telegram::ShortAck => {
                let b = buf.first_mut().ok_or(EmitError::BufferTooSmall {
                    needed: 1,
                    available: 0,
                })?;
                *b = SC;
                Ok(1)
            }
            Telegram::Token { da, sa } => {
                for a in [da, sa] {
                    if a > MAX_STATION_ADDRESS {
                        return Err(EmitError::BadAddress(a));
                    }
                }
                let available = buf.len();
                let out = buf.get_mut(..3).ok_or(EmitError::BufferTooSmall {
                    needed: 3,
                    available,
                })?;
                out.copy_from_slice(&[SD4, da, sa]);
                Ok(3)
            }
            Telegram::Data(ref d) => d.emit(buf),
        }
    }

    /// Append the telegram to a `BytesMut` (reserving space once; no other
    /// allocation).
    pub fn emit_to(&self, out: &mut BytesMut) -> Result<usize, EmitError> {
        let len = self.check()?;
        out.reserve(len);
        let start = out.len();
        out.put_bytes(0, len);
        self.emit(&mut out[start..])
    }

    /// The telegram's bytes in a new `Vec` (for tools and tests; the
    /// steady-state paths emit into their own buffers).
    pub fn to_vec(&self) -> Result<Vec<u8>, EmitError> {
        let mut out = vec![0; self.check()?];
        self.emit(&mut out)?;
        Ok(out)
    }

    fn check(&self) -> Result<usize, EmitError> {
        match *self {
            Telegram::ShortAck => {}
            Telegram::Token { da, sa } => {
                for a in [da, sa] {
                    if a > MAX_STATION_ADDRESS {
                        return Err(EmitError::BadAddress(a));
                    }
                }
            }
            Telegram::Data(d) => {
                for a in [d.da, d.sa] {
                    if a > BROADCAST {
                        return Err(EmitError::BadAddress(a));
                    }
                }
                let n = d.data_field_len();
                if n > MAX_DATA_FIELD {
                    return Err(EmitError::DataTooLong(n));
                }
                let fits = match self.format() {
                    Format::Sd1 => n == 0,
                    Format::Sd2 => true,
                    Format::Sd3 => n == SD3_DATA_FIELD,
                    Format::Sd4 | Format::Sc => false,
                };
                if !fits {
                    return Err(EmitError::FormatMismatch {
                        format: self.format(),
                        data_field: n,
                    });
                }
            }
        }
        Ok(self.emitted_len())
    }

    /// The data telegram, if this is one.
    pub fn as_data(&self) -> Option<&DataTelegram<'a>> {
        match self {
            Telegram::Data(d) => Some(d),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{RequestKind, ResponseStatus, StationType};

    fn hex(s: &str) -> Vec<u8> {
        s.split_whitespace()
            .map(|b| u8::from_str_radix(b, 16).unwrap())
            .collect()
    }

    #[test]
    fn slave_fdl_status_reply_from_trace() {
        // `10 02 08 00 0A 16` (trace of pyprofibus issue #19): slave 8 answers master 2, FC 00.
        let b = hex("10 02 08 00 0A 16");
        let (t, n) = Telegram::parse(&b).unwrap();
        assert_eq!(n, 6);
        let d = t.as_data().unwrap();
        assert_eq!((d.da, d.sa), (2, 8));
        assert_eq!(d.fc, FunctionCode::slave_response(ResponseStatus::Ok));
        assert_eq!(d.data, &[] as &[u8]);
    }

    #[test]
    fn token_telegram() {
        let b = hex("DC 05 02");
        assert_eq!(
            Telegram::parse(&b).unwrap(),
            (Telegram::Token { da: 5, sa: 2 }, 3)
        );
        let mut out = [0u8; 3];
        assert_eq!(Telegram::Token { da: 5, sa: 2 }.emit(&mut out), Ok(3));
        assert_eq!(out.to_vec(), b);
    }

    #[test]
    fn data_exchange_with_bm4_pkw_request() {
        // Master 2 → slave 6, SRD high FCB=1 FCV=1, no SAPs, data unit = the
        // BM4-O-PRO-01 PKW read request PKE=0x1004 IND=0 PWE1=0 PWE2=0 as
        // 8 bytes: SD3 frame. FCS = 06+02+7D+10+04 = 0x99.
        let fc = FunctionCode::Request {
            kind: RequestKind::SrdHigh,
            fcb: true,
            fcv: true,
        };
        let t = Telegram::Data(DataTelegram {
            format: Some(Format::Sd3),
            ..DataTelegram::new(6, 2, fc, &[0x10, 0x04, 0, 0, 0, 0, 0, 0])
        });
        let mut out = [0u8; 32];
        let n = t.emit(&mut out).unwrap();
        assert_eq!(
            out[..n].to_vec(),
            hex("A2 06 02 7D 10 04 00 00 00 00 00 00 99 16")
        );
        assert_eq!(Telegram::parse(&out[..n]).unwrap(), (t, 14));
    }

    #[test]
    fn eight_byte_data_field_is_sd2_unless_sd3_is_asked_for() {
        // A 6-byte Slave_Diag answer with SAPs: real devices and slave ASICs
        // send SD2 with LE = 0x0B, not SD3.
        let diag = [0x00, 0x0C, 0x00, 0x02, 0x80, 0x6A];
        let mut d = DataTelegram {
            da: 2,
            sa: 8,
            fc: FunctionCode::Response {
                status: ResponseStatus::Dl,
                station: StationType::Passive,
            },
            dsap: Some(62),
            ssap: Some(60),
            data: &diag,
            format: None,
        };
        let mut out = [0u8; 32];
        let n = Telegram::Data(d).emit(&mut out).unwrap();
        assert_eq!(
            out[..n].to_vec(),
            hex("68 0B 0B 68 82 88 08 3E 3C 00 0C 00 02 80 6A 84 16")
        );
        assert_eq!(Telegram::Data(d).format(), Format::Sd2);
        d.format = Some(Format::Sd3);
        let n = Telegram::Data(d).emit(&mut out).unwrap();
        assert_eq!(out[0], 0xA2);
        assert_eq!(n, 14);
        // Asking for a format that cannot carry the data field is an error.
        d.format = Some(Format::Sd1);
        assert!(matches!(
            Telegram::Data(d).emit(&mut out),
            Err(EmitError::FormatMismatch { .. })
        ));
    }

    #[test]
    fn parse_keeps_the_received_start_delimiter() {
        // The same 6-byte Slave_Diag answer (the example) once as
        // SD2 and once as SD3: each is shown as received and re-emitted
        // byte for byte.
        for frame in [
            "A2 82 8B 08 3E 3C 02 09 00 FF 00 2B C4 16",
            "68 0B 0B 68 82 8B 08 3E 3C 02 09 00 FF 00 2B C4 16",
        ] {
            let bytes = hex(frame);
            let (t, n) = Telegram::parse(&bytes).unwrap();
            assert_eq!(n, bytes.len());
            let want = if bytes[0] == 0xA2 {
                Format::Sd3
            } else {
                Format::Sd2
            };
            assert_eq!(t.format(), want, "{frame}");
            let mut out = [0u8; 64];
            let m = t.emit(&mut out).unwrap();
            assert_eq!(out[..m], bytes[..], "{frame}");
        }
    }

    #[test]
    fn set_prm_sd2_with_saps() {
        // Set_Prm 2 → 8 from the trace of pyprofibus issue #19: DA 88, SA 82, FC 6D, DSAP 3D, SSAP 3E,
        // B8 1E 01 00 0A 35 01 00 00 00 82 00 00 00.
        let du = hex("B8 1E 01 00 0A 35 01 00 00 00 82 00 00 00");
        let t = Telegram::Data(DataTelegram {
            da: 8,
            sa: 2,
            fc: FunctionCode::Request {
                kind: RequestKind::SrdHigh,
                fcb: true,
                fcv: false,
            },
            dsap: Some(61),
            ssap: Some(62),
            data: &du,
            format: Some(Format::Sd2),
        });
        let mut out = [0u8; 64];
        let n = t.emit(&mut out).unwrap();
        let le = 3 + 2 + du.len();
        assert_eq!(out[..4], [0x68, le as u8, le as u8, 0x68]);
        assert_eq!(out[4..9], [0x88, 0x82, 0x6D, 0x3D, 0x3E]);
        let sum = out[4..n - 2].iter().fold(0u8, |a, &b| a.wrapping_add(b));
        assert_eq!(out[n - 2], sum);
        assert_eq!(out[n - 1], 0x16);
        assert_eq!(Telegram::parse(&out[..n]).unwrap(), (t, n));
    }

    #[test]
    fn malformed_inputs_are_typed_errors() {
        assert_eq!(
            Telegram::parse(&hex("11")),
            Err(ParseError::BadStartDelimiter(0x11))
        );
        assert_eq!(
            Telegram::parse(&hex("68 05 06 68")),
            Err(ParseError::LengthMismatch { le: 5, ler: 6 })
        );
        assert_eq!(
            Telegram::parse(&hex("68 FA FA 68")),
            Err(ParseError::LengthOutOfRange(0xFA))
        );
        assert_eq!(
            Telegram::parse(&hex("68 02 02 68")),
            Err(ParseError::LengthOutOfRange(2))
        );
        assert_eq!(
            Telegram::parse(&hex("10 02 08 00 0B 16")),
            Err(ParseError::FcsMismatch {
                received: 0x0B,
                computed: 0x0A
            })
        );
        assert_eq!(
            Telegram::parse(&hex("10 02 08 00 0A 17")),
            Err(ParseError::MissingEndDelimiter(0x17))
        );
        assert_eq!(
            Telegram::parse(&hex("10 02 08")),
            Err(ParseError::Truncated {
                needed: 6,
                available: 3
            })
        );
        assert_eq!(
            Telegram::parse(&hex("68 04 04 67 02 08 00 00 0A 16")),
            Err(ParseError::BadRepeatedDelimiter(0x67))
        );
        // DA announces a DSAP but the data field is empty: SD1 with DA|0x80.
        assert_eq!(
            Telegram::parse(&hex("10 82 08 49 D3 16")),
            Err(ParseError::MissingAddressExtension)
        );
        assert_eq!(
            Telegram::parse(&hex("DC 7F 02")),
            Err(ParseError::BadTokenAddress { da: 127, sa: 2 })
        );
    }

    #[test]
    fn emit_errors() {
        let big = [0u8; 245];
        let t = Telegram::Data(DataTelegram {
            da: 1,
            sa: 2,
            fc: FunctionCode::request(RequestKind::SdnLow),
            dsap: Some(1),
            ssap: Some(2),
            data: &big,
            format: None,
        });
        assert_eq!(t.emit(&mut [0u8; 300]), Err(EmitError::DataTooLong(247)));
        assert_eq!(
            Telegram::ShortAck.emit(&mut []),
            Err(EmitError::BufferTooSmall {
                needed: 1,
                available: 0
            })
        );
        assert_eq!(
            Telegram::Token { da: 127, sa: 1 }.emit(&mut [0; 3]),
            Err(EmitError::BadAddress(127))
        );
    }

    #[test]
    fn emit_to_bytesmut_appends() {
        let mut out = BytesMut::new();
        Telegram::ShortAck.emit_to(&mut out).unwrap();
        Telegram::Token { da: 3, sa: 4 }.emit_to(&mut out).unwrap();
        assert_eq!(&out[..], &[0xE5, 0xDC, 3, 4]);
    }
}
