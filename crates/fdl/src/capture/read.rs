//! Reading capture files without I/O: [`CaptureDecoder`] is fed the
//! file's bytes in pieces of any size ([`CaptureDecoder::push`]) and
//! hands out its records ([`CaptureDecoder::next_record`]); at the end of
//! the file [`CaptureDecoder::finish`] says whether anything was cut off.
//! [`PcapReader`](super::pcap::PcapReader) drives it from any
//! [`std::io::Read`].
//!
//! Formats: classic pcap (both byte orders, micro- and nanosecond
//! stamps) and pcapng (one section; the first interface's `if_tsresol`;
//! enhanced and simple packet blocks, other blocks passed over; the
//! `epb_flags` option, where our writer marks corrupt telegrams with
//! [`EPB_FLAG_CRC_ERROR`]). Every error
//! is a [`ReadError`]: what is wrong, in words, at which byte of the file;
//! no input panics (fuzzed: `fuzz/fuzz_targets/pcap_read.rs`).

use super::pcap::{
    PcapFormat, EPB_FLAGS, EPB_FLAG_CRC_ERROR, MAGIC_MICROS, MAGIC_NANOS, PCAPNG_BYTE_ORDER,
    PCAPNG_EPB, PCAPNG_IDB, PCAPNG_SHB,
};
use crate::prelude::*;
use core::fmt;
use core::time::Duration;

/// pcapng block type of a simple packet block.
const PCAPNG_SPB: u32 = 3;
/// Option code of `if_tsresol`.
const IF_TSRESOL: u16 = 9;
/// Largest pcapng block taken (a telegram is at most 255 bytes; this
/// leaves room for any other tool's blocks).
pub const MAX_BLOCK: u32 = 1 << 20;
/// Largest classic record taken.
pub const MAX_RECORD: u32 = 262_144;

/// What is wrong with a capture file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReadErrorKind {
    /// The first four bytes are no pcap or pcapng magic number.
    NotACapture(u32),
    /// The pcapng byte-order magic is neither order of 0x1A2B3C4D.
    ByteOrder(u32),
    /// A pcapng block length below 12, not a multiple of 4, or above
    /// [`MAX_BLOCK`].
    BlockLength(u32),
    /// A block's trailing length differs from its leading one.
    LengthMismatch(u32, u32),
    /// An interface description block too short for its fields.
    ShortInterface(usize),
    /// An `if_tsresol` beyond what 64 bits count.
    TimeResolution(u8),
    /// A packet's captured length runs past its block or above
    /// [`MAX_RECORD`].
    PacketLength(u32),
    /// A packet block too short for its fields.
    ShortPacket(usize),
    /// A packet block before any interface description.
    NoInterface,
    /// A second section header (files joined; one section is read).
    SecondSection,
    /// The file ends inside a header or record.
    Truncated {
        /// Bytes the header or record needs.
        needed: u64,
        /// Bytes left in the file.
        left: u64,
    },
}

impl fmt::Display for ReadErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReadErrorKind::NotACapture(m) => {
                write!(f, "not a pcap or pcapng file (magic 0x{m:08X})")
            }
            ReadErrorKind::ByteOrder(b) => write!(f, "bad pcapng byte-order magic 0x{b:08X}"),
            ReadErrorKind::BlockLength(l) => write!(f, "pcapng block of {l} bytes"),
            ReadErrorKind::LengthMismatch(a, b) => {
                write!(f, "pcapng block length {a} at its start but {b} at its end")
            }
            ReadErrorKind::ShortInterface(n) => {
                write!(f, "interface block of {n} bytes (at least 8 needed)")
            }
            ReadErrorKind::TimeResolution(r) => write!(f, "if_tsresol {r} out of range"),
            ReadErrorKind::PacketLength(n) => write!(f, "packet of {n} bytes does not fit"),
            ReadErrorKind::ShortPacket(n) => write!(f, "packet block of {n} bytes"),
            ReadErrorKind::NoInterface => f.write_str("packet before any interface block"),
            ReadErrorKind::SecondSection => f.write_str("second pcapng section"),
            ReadErrorKind::Truncated { needed, left } => {
                write!(f, "file cut off: {needed} bytes needed, {left} left")
            }
        }
    }
}

/// A capture file's error and where it is.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("at byte {offset}: {kind}")]
pub struct ReadError {
    /// Offset in the file of the header, block or record at fault.
    pub offset: u64,
    /// What is wrong.
    pub kind: ReadErrorKind,
}

/// One record of a capture file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Record {
    /// Time stamp since the Unix epoch (zero for pcapng simple packets,
    /// which have none).
    pub ts: Duration,
    /// Length of the packet on the wire.
    pub orig_len: u32,
    /// The captured bytes.
    pub data: Vec<u8>,
    /// pcapng `epb_flags` (0 when absent, and in classic files).
    pub flags: u32,
    /// Offset of the record in the file.
    pub offset: u64,
}

impl Record {
    /// Flagged as corrupt (the CRC-error bit of `epb_flags`).
    pub fn is_corrupt(&self) -> bool {
        self.flags & EPB_FLAG_CRC_ERROR != 0
    }
}

/// The file's header, once read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// Container format.
    pub format: PcapFormat,
    /// Link type (of the first interface, for pcapng).
    pub linktype: u32,
}

/// Where the decoder is in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// Before the magic number.
    Start,
    /// pcapng: blocks up to the first interface description.
    Interfaces,
    /// Records.
    Records,
    /// After an error: nothing more.
    Failed,
}

/// The sans-IO capture decoder; see the module docs.
#[derive(Debug)]
pub struct CaptureDecoder {
    buf: Vec<u8>,
    /// Bytes of `buf` already consumed.
    pos: usize,
    /// File offset of `buf[0]`.
    base: u64,
    stage: Stage,
    format: PcapFormat,
    swapped: bool,
    units_per_s: u64,
    linktype: u32,
}

impl Default for CaptureDecoder {
    fn default() -> Self {
        CaptureDecoder::new()
    }
}

fn pad4(n: usize) -> usize {
    (4 - n % 4) % 4
}

impl CaptureDecoder {
    /// A decoder at the start of a file.
    pub fn new() -> CaptureDecoder {
        CaptureDecoder {
            buf: Vec::new(),
            pos: 0,
            base: 0,
            stage: Stage::Start,
            format: PcapFormat::Pcap,
            swapped: false,
            units_per_s: 1_000_000,
            linktype: 0,
        }
    }

    /// The next bytes of the file.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.pos > 0 && self.pos >= self.buf.len() / 2 {
            self.buf.drain(..self.pos);
            self.base += self.pos as u64;
            self.pos = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// The header, once [`CaptureDecoder::next_record`] has read it
    /// (`None` before, or when it is bad).
    pub fn header(&self) -> Option<Header> {
        matches!(self.stage, Stage::Records).then_some(Header {
            format: self.format,
            linktype: self.linktype,
        })
    }

    /// Offset in the file of the next byte to decode.
    pub fn offset(&self) -> u64 {
        self.base + self.pos as u64
    }

    fn left(&self) -> &[u8] {
        &self.buf[self.pos..]
    }

    fn fail(&mut self, kind: ReadErrorKind) -> ReadError {
        self.stage = Stage::Failed;
        ReadError {
            offset: self.offset(),
            kind,
        }
    }

    fn u32_at(&self, b: &[u8], at: usize) -> u32 {
        let v = u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
        if self.swapped {
            v.swap_bytes()
        } else {
            v
        }
    }

    fn u16_at(&self, b: &[u8], at: usize) -> u16 {
        let v = u16::from_le_bytes([b[at], b[at + 1]]);
        if self.swapped {
            v.swap_bytes()
        } else {
            v
        }
    }

    /// Read the header when its bytes are there: `Ok(false)` when more
    /// are needed.
    fn start(&mut self) -> Result<bool, ReadError> {
        let b = self.left();
        if b.len() < 4 {
            return Ok(false);
        }
        let magic = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        if magic == PCAPNG_SHB {
            // Section header: type, length, byte-order magic, version,
            // section length, options, length.
            if b.len() < 12 {
                return Ok(false);
            }
            let bom = u32::from_le_bytes([b[8], b[9], b[10], b[11]]);
            self.swapped = match bom {
                PCAPNG_BYTE_ORDER => false,
                o if o.swap_bytes() == PCAPNG_BYTE_ORDER => true,
                o => return Err(self.fail(ReadErrorKind::ByteOrder(o))),
            };
            self.format = PcapFormat::Pcapng;
            self.stage = Stage::Interfaces;
            // The section header is a block like the others.
            return Ok(true);
        }
        let (swapped, units) = match magic {
            MAGIC_MICROS => (false, 1_000_000),
            MAGIC_NANOS => (false, 1_000_000_000),
            m if m.swap_bytes() == MAGIC_MICROS => (true, 1_000_000),
            m if m.swap_bytes() == MAGIC_NANOS => (true, 1_000_000_000),
            m => return Err(self.fail(ReadErrorKind::NotACapture(m))),
        };
        if b.len() < 24 {
            return Ok(false);
        }
        let lt = [b[20], b[21], b[22], b[23]];
        self.swapped = swapped;
        self.units_per_s = units;
        self.linktype = self.u32_at(&lt, 0);
        self.format = PcapFormat::Pcap;
        self.pos += 24;
        self.stage = Stage::Records;
        Ok(true)
    }

    /// The next pcapng block (type, body without the trailing length,
    /// offset), consumed; `None` when its bytes are not all there yet.
    fn block(&mut self) -> Result<Option<(u32, Vec<u8>, u64)>, ReadError> {
        let b = self.left();
        if b.len() < 8 {
            return Ok(None);
        }
        let kind = self.u32_at(b, 0);
        let len = self.u32_at(b, 4);
        if !(12..=MAX_BLOCK).contains(&len) || len & 3 != 0 {
            return Err(self.fail(ReadErrorKind::BlockLength(len)));
        }
        let n = len as usize;
        if b.len() < n {
            return Ok(None);
        }
        let trail = self.u32_at(b, n - 4);
        if trail != len {
            return Err(self.fail(ReadErrorKind::LengthMismatch(len, trail)));
        }
        let body = b[8..n - 4].to_vec();
        let at = self.offset();
        self.pos += n;
        Ok(Some((kind, body, at)))
    }

    /// Time units per second from the options of an interface block.
    fn tsresol(&self, mut opts: &[u8]) -> Result<u64, ReadErrorKind> {
        while opts.len() >= 4 {
            let code = self.u16_at(opts, 0);
            let len = self.u16_at(opts, 2) as usize;
            if code == 0 {
                break;
            }
            let Some(val) = opts.get(4..4 + len) else {
                break;
            };
            if code == IF_TSRESOL && len == 1 {
                let r = val[0];
                let units = if r & 0x80 == 0 {
                    10u64.checked_pow(r as u32)
                } else {
                    1u64.checked_shl((r & 0x7F) as u32)
                };
                return units.ok_or(ReadErrorKind::TimeResolution(r));
            }
            opts = opts.get(4 + len + pad4(len)..).unwrap_or(&[]);
        }
        Ok(1_000_000)
    }

    /// The `epb_flags` option among `opts` (0 when absent).
    fn epb_flags(&self, mut opts: &[u8]) -> u32 {
        while opts.len() >= 4 {
            let code = self.u16_at(opts, 0);
            let len = self.u16_at(opts, 2) as usize;
            if code == 0 {
                break;
            }
            if code == EPB_FLAGS && len == 4 && opts.len() >= 8 {
                return self.u32_at(opts, 4);
            }
            opts = opts.get(4 + len + pad4(len)..).unwrap_or(&[]);
        }
        0
    }

    fn stamp(&self, units: u64) -> Duration {
        let per = self.units_per_s;
        let secs = units / per;
        let nanos = ((units % per) as u128 * 1_000_000_000 / per as u128) as u64;
        Duration::from_secs(secs) + Duration::from_nanos(nanos)
    }

    /// The next record: `Ok(None)` when the bytes pushed so far hold no
    /// further complete one (push more, or [`CaptureDecoder::finish`] at
    /// the end of the file). After an error it returns `Ok(None)`.
    pub fn next_record(&mut self) -> Result<Option<Record>, ReadError> {
        loop {
            match self.stage {
                Stage::Failed => return Ok(None),
                Stage::Start => {
                    if !self.start()? {
                        return Ok(None);
                    }
                }
                Stage::Interfaces | Stage::Records if self.format == PcapFormat::Pcapng => {
                    let Some((kind, body, at)) = self.block()? else {
                        return Ok(None);
                    };
                    let fail = |s: &mut Self, kind| {
                        s.stage = Stage::Failed;
                        ReadError { offset: at, kind }
                    };
                    match kind {
                        PCAPNG_SHB if at == 0 => {}
                        PCAPNG_SHB => return Err(fail(self, ReadErrorKind::SecondSection)),
                        PCAPNG_IDB if self.stage == Stage::Interfaces => {
                            if body.len() < 8 {
                                return Err(fail(self, ReadErrorKind::ShortInterface(body.len())));
                            }
                            self.linktype = self.u16_at(&body, 0) as u32;
                            self.units_per_s = match self.tsresol(&body[8..]) {
                                Ok(u) => u,
                                Err(k) => return Err(fail(self, k)),
                            };
                            self.stage = Stage::Records;
                        }
                        PCAPNG_EPB | PCAPNG_SPB if self.stage == Stage::Interfaces => {
                            return Err(fail(self, ReadErrorKind::NoInterface))
                        }
                        PCAPNG_EPB => {
                            if body.len() < 20 {
                                return Err(fail(self, ReadErrorKind::ShortPacket(body.len())));
                            }
                            let units =
                                (self.u32_at(&body, 4) as u64) << 32 | self.u32_at(&body, 8) as u64;
                            let incl = self.u32_at(&body, 12);
                            let orig_len = self.u32_at(&body, 16);
                            let Some(data) = body.get(20..20 + incl as usize) else {
                                return Err(fail(self, ReadErrorKind::PacketLength(incl)));
                            };
                            let opts = body.get(20 + incl as usize + pad4(incl as usize)..);
                            return Ok(Some(Record {
                                ts: self.stamp(units),
                                orig_len,
                                data: data.to_vec(),
                                flags: self.epb_flags(opts.unwrap_or(&[])),
                                offset: at,
                            }));
                        }
                        PCAPNG_SPB => {
                            if body.len() < 4 {
                                return Err(fail(self, ReadErrorKind::ShortPacket(body.len())));
                            }
                            let orig_len = self.u32_at(&body, 0);
                            let n = (orig_len as usize).min(body.len() - 4);
                            return Ok(Some(Record {
                                ts: Duration::ZERO,
                                orig_len,
                                data: body[4..4 + n].to_vec(),
                                flags: 0,
                                offset: at,
                            }));
                        }
                        _ => {}
                    }
                }
                Stage::Interfaces => return Ok(None),
                Stage::Records => {
                    let b = self.left();
                    if b.len() < 16 {
                        return Ok(None);
                    }
                    let secs = self.u32_at(b, 0) as u64;
                    let frac = self.u32_at(b, 4) as u64;
                    let incl = self.u32_at(b, 8);
                    let orig_len = self.u32_at(b, 12);
                    if incl > MAX_RECORD {
                        return Err(self.fail(ReadErrorKind::PacketLength(incl)));
                    }
                    let n = 16 + incl as usize;
                    if b.len() < n {
                        return Ok(None);
                    }
                    let data = b[16..n].to_vec();
                    let at = self.offset();
                    self.pos += n;
                    return Ok(Some(Record {
                        ts: Duration::from_secs(secs) + self.stamp(frac),
                        orig_len,
                        data,
                        flags: 0,
                        offset: at,
                    }));
                }
            }
        }
    }

    /// At the end of the file: an error when a header or record was cut
    /// off (call after [`CaptureDecoder::next_record`] gave `Ok(None)`).
    pub fn finish(&self) -> Result<(), ReadError> {
        if self.stage == Stage::Failed {
            return Ok(());
        }
        let left = self.left();
        let needed = match self.stage {
            Stage::Start => match left.len() {
                0 => 4,
                _ if left.starts_with(&PCAPNG_SHB.to_le_bytes()) => 28,
                _ => 24,
            },
            Stage::Interfaces if left.is_empty() => 8,
            _ if left.is_empty() => return Ok(()),
            _ if self.format == PcapFormat::Pcap && left.len() >= 16 => {
                16 + self.u32_at(left, 8) as usize
            }
            _ if self.format == PcapFormat::Pcap => 16,
            _ if left.len() >= 8 => self.u32_at(left, 4) as usize,
            _ => 8,
        };
        Err(ReadError {
            offset: self.offset(),
            kind: ReadErrorKind::Truncated {
                needed: needed as u64,
                left: left.len() as u64,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::pcap::PcapWriter;
    use crate::time::Instant;

    fn file(format: PcapFormat) -> Vec<u8> {
        let mut w = PcapWriter::with_format(Vec::new(), format, Duration::new(100, 0)).unwrap();
        w.write_telegram(Instant::from_nanos(1_500), &[0xDC, 0x02, 0x02])
            .unwrap();
        w.write_corrupt(Instant::from_nanos(2_000), &[0x68, 5, 5, 0x68, 0x00])
            .unwrap();
        w.write_telegram(Instant::from_nanos(3_000), &[0xE5])
            .unwrap();
        w.into_inner().unwrap()
    }

    /// Every record of `bytes` fed in pieces of `chunk` bytes.
    fn decode(bytes: &[u8], chunk: usize) -> Result<(Header, Vec<Record>), ReadError> {
        let mut d = CaptureDecoder::new();
        let mut out = vec![];
        for piece in bytes.chunks(chunk.max(1)) {
            d.push(piece);
            while let Some(r) = d.next_record()? {
                out.push(r);
            }
        }
        d.finish()?;
        Ok((d.header().expect("a header"), out))
    }

    #[test]
    fn reads_our_files_in_any_pieces() {
        for format in [PcapFormat::Pcapng, PcapFormat::Pcap] {
            let f = file(format);
            for chunk in [1, 3, 7, 64, f.len()] {
                let (h, r) = decode(&f, chunk).unwrap();
                assert_eq!(
                    h,
                    Header {
                        format,
                        linktype: 257
                    }
                );
                assert_eq!(r.len(), 3);
                assert_eq!(r[0].data, [0xDC, 0x02, 0x02]);
                assert_eq!(r[0].ts, Duration::new(100, 1_500));
                assert_eq!(r[1].data, [0x68, 5, 5, 0x68, 0x00]);
                assert_eq!(r[1].is_corrupt(), format == PcapFormat::Pcapng);
                assert!(!r[2].is_corrupt());
                assert_eq!((r[2].orig_len, r[2].ts), (1, Duration::new(100, 3_000)));
            }
        }
    }

    #[test]
    fn records_know_their_offsets() {
        let (_, r) = decode(&file(PcapFormat::Pcapng), 5).unwrap();
        // SHB 28 + IDB 32, then EPB 36 (3 bytes + pad).
        assert_eq!(r[0].offset, 60);
        assert_eq!(r[1].offset, 96);
        let (_, r) = decode(&file(PcapFormat::Pcap), 5).unwrap();
        assert_eq!((r[0].offset, r[1].offset), (24, 24 + 16 + 3));
    }

    #[test]
    fn a_cut_off_file_names_the_record_and_what_is_missing() {
        let f = file(PcapFormat::Pcapng);
        let e = decode(&f[..f.len() - 3], 16).unwrap_err();
        // SHB 28, IDB 32, EPB 36, EPB 52 with the flags option: the
        // third EPB starts at 148.
        assert_eq!(e.offset, 148);
        assert_eq!(
            e.to_string(),
            "at byte 148: file cut off: 36 bytes needed, 33 left"
        );
        let f = file(PcapFormat::Pcap);
        let e = decode(&f[..30], 64).unwrap_err();
        assert_eq!(e.offset, 24);
        assert!(matches!(
            e.kind,
            ReadErrorKind::Truncated {
                needed: 16,
                left: 6
            }
        ));
        let e = decode(&[], 1).unwrap_err();
        assert_eq!(
            e.to_string(),
            "at byte 0: file cut off: 4 bytes needed, 0 left"
        );
    }

    #[test]
    fn a_wrong_magic_is_named() {
        let e = decode(b"hello, this is no capture file", 4).unwrap_err();
        assert_eq!(
            e.to_string(),
            "at byte 0: not a pcap or pcapng file (magic 0x6C6C6568)"
        );
        let mut f = file(PcapFormat::Pcapng);
        f[8..12].copy_from_slice(&[1, 2, 3, 4]);
        let e = decode(&f, 64).unwrap_err();
        assert_eq!(e.kind, ReadErrorKind::ByteOrder(0x0403_0201));
    }

    #[test]
    fn broken_blocks_are_errors_at_their_offset() {
        let mut f = file(PcapFormat::Pcapng);
        // The second EPB's length: not a multiple of 4.
        f[100..104].copy_from_slice(&13u32.to_le_bytes());
        let e = decode(&f, 64).unwrap_err();
        assert_eq!((e.offset, e.kind), (96, ReadErrorKind::BlockLength(13)));
        let mut f = file(PcapFormat::Pcapng);
        // The first EPB's captured length beyond its block.
        f[60 + 20..60 + 24].copy_from_slice(&200u32.to_le_bytes());
        let e = decode(&f, 64).unwrap_err();
        assert_eq!((e.offset, e.kind), (60, ReadErrorKind::PacketLength(200)));
        // A packet before the interface block.
        let g = file(PcapFormat::Pcapng);
        let mut f = g[..28].to_vec();
        f.extend_from_slice(&g[60..96]);
        let e = decode(&f, 64).unwrap_err();
        assert_eq!((e.offset, e.kind), (28, ReadErrorKind::NoInterface));
        // After an error the decoder stays quiet.
        let mut d = CaptureDecoder::new();
        d.push(b"garbage!garbage!garbage!garbage!");
        assert!(d.next_record().is_err());
        assert_eq!(d.next_record(), Ok(None));
    }

    #[test]
    fn big_endian_microsecond_files() {
        let mut f = vec![];
        f.extend_from_slice(&MAGIC_MICROS.to_be_bytes());
        f.extend_from_slice(&[
            0, 2, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xFF, 0xFF, 0, 0, 1, 1,
        ]);
        f.extend_from_slice(&[0, 0, 0, 5, 0, 0, 0, 7, 0, 0, 0, 1, 0, 0, 0, 1, 0xE5]);
        let (h, r) = decode(&f, 2).unwrap();
        assert_eq!(h.linktype, 257);
        assert_eq!(r[0].ts, Duration::new(5, 7_000));
    }
}
