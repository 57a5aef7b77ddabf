//! Recording telegrams in capture files (and reading them back).
//!
//! The files use link type 257, `LINKTYPE_PROFIBUS_DL`: each packet is one
//! FDL telegram from its start delimiter through its end delimiter (a
//! token is 3 bytes, a short acknowledge 1 byte). Time stamps have
//! nanosecond resolution, enough for 12 Mbit/s, where a character lasts
//! 917 ns.
//!
//! Two container formats: pcapng (the default) and classic pcap (the
//! variant with nanosecond stamps, magic `0xA1B23C4D`). Why pcapng by
//! default: Wireshark maps link type 257 to no encapsulation of its own,
//! and its classic-pcap reader then refuses the whole file ("network type
//! 257 unknown or unsupported", tshark 4.0 of Debian 12), while its
//! pcapng reader shows the packets (as raw data). libpcap-based tools read
//! both. Writer and reader work on any [`std::io::Write`] /
//! [`std::io::Read`]; nothing here needs tokio.
//!
//! Why written here rather than taken from a crate (e.g. `pcap-file`):
//! the part needed is small (pcapng section header, interface description
//! with `if_tsresol` = 9 for nanoseconds, enhanced packet blocks; the
//! classic header with the nanosecond magic) and is checked against
//! Wireshark's reader by `crates/cli/tests/wireshark.rs`; `profibus-fdl` keeps its
//! promise of no dependencies beyond `bytes`, `thiserror` and `tracing`
//! without features; and whether a crate writes link type 257 with
//! nanosecond pcapng stamps exactly this way was not verified (the
//! `pcap-file` 3.0 line is still a release candidate). Switch when a
//! well-kept crate is shown to produce the same bytes.

use super::read::{CaptureDecoder, Header, ReadError, Record};
use crate::time::Instant;
use std::io::{self, Read, Write};
use std::time::Duration;

/// `LINKTYPE_PROFIBUS_DL`: PROFIBUS data link layer telegrams.
pub const LINKTYPE_PROFIBUS_DL: u32 = 257;
/// Magic number of a classic pcap file with nanosecond time stamps.
pub const MAGIC_NANOS: u32 = 0xA1B2_3C4D;
/// Magic number of a classic pcap file with microsecond time stamps.
pub const MAGIC_MICROS: u32 = 0xA1B2_C3D4;
/// pcapng block type of the section header (also its magic number).
pub const PCAPNG_SHB: u32 = 0x0A0D_0D0A;
/// pcapng block type of an interface description.
pub(crate) const PCAPNG_IDB: u32 = 1;
/// pcapng block type of an enhanced packet block.
pub(crate) const PCAPNG_EPB: u32 = 6;
/// pcapng byte-order magic.
pub(crate) const PCAPNG_BYTE_ORDER: u32 = 0x1A2B_3C4D;
/// Option code of `opt_comment` (any block).
const OPT_COMMENT: u16 = 1;
/// Option code of `epb_flags` in an enhanced packet block.
pub(crate) const EPB_FLAGS: u16 = 2;
/// `epb_flags` bit 24, a link-layer error: "CRC error" (pcapng
/// specification, enhanced packet block flags word). For PROFIBUS: the
/// bytes are no valid telegram (bad FCS, length or delimiter, garbage).
pub const EPB_FLAG_CRC_ERROR: u32 = 1 << 24;
/// Snapshot length written in the headers (a telegram is at most 255
/// bytes; this leaves room for anything a reader might add).
pub const SNAPLEN: u32 = 65_535;

/// Container format of a capture file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PcapFormat {
    /// pcapng (Wireshark's own format; read by tshark with link type 257).
    #[default]
    Pcapng,
    /// Classic pcap with nanosecond time stamps.
    Pcap,
}

/// Writes a capture file of telegrams to a sink.
#[derive(Debug)]
pub struct PcapWriter<W: Write> {
    sink: W,
    format: PcapFormat,
    epoch: Duration,
    packets: u64,
}

fn pad4(n: usize) -> usize {
    (4 - n % 4) % 4
}

impl PcapWriter<io::BufWriter<std::fs::File>> {
    /// A new pcapng file at `path` (replacing one that exists), buffered;
    /// see [`PcapWriter::with_format`]. Call [`PcapWriter::flush`] or
    /// [`PcapWriter::into_inner`] at the end.
    pub fn create(path: &std::path::Path, epoch: Duration) -> io::Result<Self> {
        let f = std::fs::File::create(path)?;
        Self::new(io::BufWriter::new(f), epoch)
    }
}

impl<W: Write> PcapWriter<W> {
    /// A pcapng file on `sink`; see [`PcapWriter::with_format`].
    pub fn new(sink: W, epoch: Duration) -> io::Result<Self> {
        Self::with_format(sink, PcapFormat::Pcapng, epoch)
    }

    /// Write the file header to `sink`. `epoch` is the wall-clock time
    /// (since 1970-01-01 UTC) of [`Instant::ZERO`]; the time stamp of a
    /// telegram written with [`PcapWriter::write_telegram`] is
    /// `epoch + at`.
    pub fn with_format(mut sink: W, format: PcapFormat, epoch: Duration) -> io::Result<Self> {
        match format {
            PcapFormat::Pcap => {
                let mut h = [0u8; 24];
                h[0..4].copy_from_slice(&MAGIC_NANOS.to_le_bytes());
                h[4..6].copy_from_slice(&2u16.to_le_bytes());
                h[6..8].copy_from_slice(&4u16.to_le_bytes());
                // thiszone and sigfigs stay 0.
                h[16..20].copy_from_slice(&SNAPLEN.to_le_bytes());
                h[20..24].copy_from_slice(&LINKTYPE_PROFIBUS_DL.to_le_bytes());
                sink.write_all(&h)?;
            }
            PcapFormat::Pcapng => {
                // Section header: byte-order magic, version 1.0, section
                // length unknown (-1), no options.
                let mut shb = [0u8; 28];
                shb[0..4].copy_from_slice(&PCAPNG_SHB.to_le_bytes());
                shb[4..8].copy_from_slice(&28u32.to_le_bytes());
                shb[8..12].copy_from_slice(&PCAPNG_BYTE_ORDER.to_le_bytes());
                shb[12..14].copy_from_slice(&1u16.to_le_bytes());
                shb[16..24].copy_from_slice(&(-1i64).to_le_bytes());
                shb[24..28].copy_from_slice(&28u32.to_le_bytes());
                sink.write_all(&shb)?;
                // Interface description: link type, snaplen, option
                // if_tsresol (9) = 9 (10^-9 s), end of options.
                let mut idb = [0u8; 32];
                idb[0..4].copy_from_slice(&PCAPNG_IDB.to_le_bytes());
                idb[4..8].copy_from_slice(&32u32.to_le_bytes());
                idb[8..10].copy_from_slice(&(LINKTYPE_PROFIBUS_DL as u16).to_le_bytes());
                idb[12..16].copy_from_slice(&SNAPLEN.to_le_bytes());
                idb[16..18].copy_from_slice(&9u16.to_le_bytes());
                idb[18..20].copy_from_slice(&1u16.to_le_bytes());
                idb[20] = 9;
                // idb[24..28]: opt_endofopt (0, 0).
                idb[28..32].copy_from_slice(&32u32.to_le_bytes());
                sink.write_all(&idb)?;
            }
        }
        Ok(PcapWriter {
            sink,
            format,
            epoch,
            packets: 0,
        })
    }

    /// Record one telegram seen at `at` (driver time).
    pub fn write_telegram(&mut self, at: Instant, telegram: &[u8]) -> io::Result<()> {
        let ts = self.epoch + Duration::from_nanos(at.as_nanos());
        self.write_packet(ts, telegram)
    }

    /// Record bytes seen at `at` (driver time) that are no valid
    /// telegram (a bad FCS, a broken length, garbage): kept so that a
    /// capture shows the line as it was. In pcapng the packet is flagged
    /// with the CRC-error bit of `epb_flags` ([`EPB_FLAG_CRC_ERROR`];
    /// Wireshark: `frame.packet_flags_crc_error`); the dissector of
    /// `tools/wireshark` also finds it with `pbdl.fcs.good == 0`.
    pub fn write_corrupt(&mut self, at: Instant, bytes: &[u8]) -> io::Result<()> {
        let ts = self.epoch + Duration::from_nanos(at.as_nanos());
        self.write_packet_flagged(ts, bytes, EPB_FLAG_CRC_ERROR)
    }

    /// Record one packet with an absolute time stamp (since the Unix
    /// epoch).
    pub fn write_packet(&mut self, ts: Duration, data: &[u8]) -> io::Result<()> {
        self.write_packet_flagged(ts, data, 0)
    }

    /// Record one packet with `epb_flags` (pcapng; 0: none written; the
    /// classic format has no place for flags).
    pub fn write_packet_flagged(
        &mut self,
        ts: Duration,
        data: &[u8],
        flags: u32,
    ) -> io::Result<()> {
        self.write_packet_with(ts, data, flags, None)
    }

    /// Record bytes seen at `at` (driver time), a telegram or, when
    /// `corrupt`, bytes that are none ([`PcapWriter::write_corrupt`]),
    /// with a comment (pcapng `opt_comment`; Wireshark shows it as
    /// `frame.comment` and in the packet list's expert info). The
    /// triggered recorder names the segment and its trigger this way.
    pub fn write_record(
        &mut self,
        at: Instant,
        bytes: &[u8],
        corrupt: bool,
        comment: Option<&str>,
    ) -> io::Result<()> {
        let ts = self.epoch + Duration::from_nanos(at.as_nanos());
        let flags = if corrupt { EPB_FLAG_CRC_ERROR } else { 0 };
        self.write_packet_with(ts, bytes, flags, comment)
    }

    /// Record one packet with `epb_flags` (0: none) and a comment
    /// (pcapng only; the classic format has no place for either).
    pub fn write_packet_with(
        &mut self,
        ts: Duration,
        data: &[u8],
        flags: u32,
        comment: Option<&str>,
    ) -> io::Result<()> {
        let len = u32::try_from(data.len())
            .ok()
            .filter(|&l| l <= SNAPLEN)
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "packet too long"))?;
        match self.format {
            PcapFormat::Pcap => {
                let secs = u32::try_from(ts.as_secs()).map_err(|_| {
                    io::Error::new(io::ErrorKind::InvalidInput, "time stamp beyond 2106")
                })?;
                let mut h = [0u8; 16];
                h[0..4].copy_from_slice(&secs.to_le_bytes());
                h[4..8].copy_from_slice(&ts.subsec_nanos().to_le_bytes());
                h[8..12].copy_from_slice(&len.to_le_bytes());
                h[12..16].copy_from_slice(&len.to_le_bytes());
                self.sink.write_all(&h)?;
                self.sink.write_all(data)?;
            }
            PcapFormat::Pcapng => {
                let nanos = u64::try_from(ts.as_nanos()).map_err(|_| {
                    io::Error::new(io::ErrorKind::InvalidInput, "time stamp beyond 2554")
                })?;
                let pad = pad4(data.len());
                // Options: opt_comment (code 1, UTF-8), epb_flags (code
                // 2, 4 bytes), then opt_endofopt.
                let comment = comment.map(str::as_bytes).filter(|c| !c.is_empty());
                let comment = comment.map(|c| &c[..c.len().min(u16::MAX as usize - 3)]);
                let comment_len = comment.map_or(0, |c| 4 + c.len() + pad4(c.len()));
                let flags_len = if flags != 0 { 8 } else { 0 };
                let opts = if comment_len + flags_len > 0 {
                    comment_len + flags_len + 4
                } else {
                    0
                };
                let total = (32 + data.len() + pad + opts) as u32;
                let mut h = [0u8; 28];
                h[0..4].copy_from_slice(&PCAPNG_EPB.to_le_bytes());
                h[4..8].copy_from_slice(&total.to_le_bytes());
                // h[8..12]: interface 0.
                h[12..16].copy_from_slice(&((nanos >> 32) as u32).to_le_bytes());
                h[16..20].copy_from_slice(&(nanos as u32).to_le_bytes());
                h[20..24].copy_from_slice(&len.to_le_bytes());
                h[24..28].copy_from_slice(&len.to_le_bytes());
                self.sink.write_all(&h)?;
                self.sink.write_all(data)?;
                self.sink.write_all(&[0u8; 3][..pad])?;
                if let Some(c) = comment {
                    self.sink.write_all(&OPT_COMMENT.to_le_bytes())?;
                    self.sink.write_all(&(c.len() as u16).to_le_bytes())?;
                    self.sink.write_all(c)?;
                    self.sink.write_all(&[0u8; 3][..pad4(c.len())])?;
                }
                if flags != 0 {
                    let mut o = [0u8; 8];
                    o[0..2].copy_from_slice(&EPB_FLAGS.to_le_bytes());
                    o[2..4].copy_from_slice(&4u16.to_le_bytes());
                    o[4..8].copy_from_slice(&flags.to_le_bytes());
                    self.sink.write_all(&o)?;
                }
                if opts > 0 {
                    // opt_endofopt.
                    self.sink.write_all(&[0u8; 4])?;
                }
                self.sink.write_all(&total.to_le_bytes())?;
            }
        }
        self.packets += 1;
        Ok(())
    }

    /// Packets written so far.
    pub fn packets(&self) -> u64 {
        self.packets
    }

    /// Flush the sink.
    pub fn flush(&mut self) -> io::Result<()> {
        self.sink.flush()
    }

    /// The sink, after flushing.
    pub fn into_inner(mut self) -> io::Result<W> {
        self.sink.flush()?;
        Ok(self.sink)
    }
}

/// One packet read from a capture file (with its offset in the file).
pub type PcapPacket = Record;

/// Reads classic pcap (both byte orders, micro- and nanosecond stamps)
/// and pcapng files (one section; enhanced and simple packet blocks)
/// from any [`Read`]: the sans-IO [`CaptureDecoder`] fed in pieces.
/// Errors in the file are [`io::ErrorKind::InvalidData`] carrying the
/// decoder's [`ReadError`] (what, at which byte); a file that ends
/// inside a record is one too.
#[derive(Debug)]
pub struct PcapReader<R: Read> {
    source: R,
    decoder: CaptureDecoder,
    header: Header,
    /// A record decoded with the header.
    first: Option<Record>,
    eof: bool,
}

/// Bytes read from the source at a time.
const CHUNK: usize = 64 * 1024;

fn invalid(e: ReadError) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, e)
}

impl<R: Read> PcapReader<R> {
    /// Read and check the file header (for pcapng, up to the first
    /// interface description).
    pub fn new(source: R) -> io::Result<Self> {
        let mut decoder = CaptureDecoder::new();
        let mut first = None;
        let mut source = source;
        let header = loop {
            if let Some(r) = decoder.next_record().map_err(invalid)? {
                first = Some(r);
            }
            if let Some(h) = decoder.header() {
                break h;
            }
            if !fill(&mut source, &mut decoder)? {
                decoder.finish().map_err(invalid)?;
                // Whole blocks, but no interface description.
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    "at the end of the file: no interface block",
                ));
            }
        };
        Ok(PcapReader {
            source,
            decoder,
            header,
            first,
            eof: false,
        })
    }

    /// The container format of the file.
    pub fn format(&self) -> PcapFormat {
        self.header.format
    }

    /// The link type of the file (of its first interface for pcapng).
    pub fn linktype(&self) -> u32 {
        self.header.linktype
    }

    /// The next packet, or `None` at the end of the file.
    pub fn next_packet(&mut self) -> io::Result<Option<PcapPacket>> {
        if let Some(r) = self.first.take() {
            return Ok(Some(r));
        }
        loop {
            if let Some(r) = self.decoder.next_record().map_err(invalid)? {
                return Ok(Some(r));
            }
            if self.eof {
                return Ok(None);
            }
            if !fill(&mut self.source, &mut self.decoder)? {
                self.eof = true;
                self.decoder.finish().map_err(invalid)?;
            }
        }
    }
}

/// Feed the decoder the next piece of `source`; `false` at its end.
fn fill(source: &mut impl Read, decoder: &mut CaptureDecoder) -> io::Result<bool> {
    let mut buf = [0u8; CHUNK];
    loop {
        match source.read(&mut buf) {
            Ok(0) => return Ok(false),
            Ok(n) => {
                decoder.push(&buf[..n]);
                return Ok(true);
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
}

impl<R: Read> Iterator for PcapReader<R> {
    type Item = io::Result<PcapPacket>;
    fn next(&mut self) -> Option<Self::Item> {
        match self.next_packet() {
            Ok(p) => p.map(Ok),
            Err(e) => {
                // Nothing follows an error in the file.
                self.eof = true;
                Some(Err(e))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(format: PcapFormat) -> Vec<u8> {
        let epoch = Duration::new(1_700_000_000, 999_999_000);
        let mut w = PcapWriter::with_format(Vec::new(), format, epoch).unwrap();
        w.write_telegram(Instant::from_nanos(1_500), &[0xDC, 0x02, 0x01])
            .unwrap();
        w.write_telegram(Instant::from_nanos(2_000), &[0xE5])
            .unwrap();
        assert_eq!(w.packets(), 2);
        w.into_inner().unwrap()
    }

    #[test]
    fn create_writes_a_pcapng_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("create.pcapng");
        let mut w = PcapWriter::create(&path, Duration::ZERO).unwrap();
        w.write_telegram(Instant::from_nanos(1_000), &[0xE5])
            .unwrap();
        w.into_inner().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let packets: Vec<_> = PcapReader::new(&bytes[..]).unwrap().collect();
        assert_eq!(packets.len(), 1);
        assert_eq!(packets[0].as_ref().unwrap().data, [0xE5]);
    }

    fn check_packets(file: &[u8]) {
        let mut r = PcapReader::new(file).unwrap();
        assert_eq!(r.linktype(), LINKTYPE_PROFIBUS_DL);
        let a = r.next_packet().unwrap().unwrap();
        assert_eq!(a.ts, Duration::new(1_700_000_001, 500));
        assert_eq!(a.data, [0xDC, 0x02, 0x01]);
        let b = r.next_packet().unwrap().unwrap();
        assert_eq!((b.orig_len, b.data), (1, vec![0xE5]));
        assert!(r.next_packet().unwrap().is_none());
    }

    #[test]
    fn classic_write_then_read_back() {
        let file = sample(PcapFormat::Pcap);
        assert_eq!(file.len(), 24 + 16 + 3 + 16 + 1);
        assert_eq!(&file[0..4], &[0x4D, 0x3C, 0xB2, 0xA1]);
        assert_eq!(&file[20..24], &[0x01, 0x01, 0, 0]);
        check_packets(&file);
    }

    #[test]
    fn pcapng_write_then_read_back() {
        let file = sample(PcapFormat::Pcapng);
        // SHB 28 + IDB 32 + EPB (32 + 4) + EPB (32 + 4).
        assert_eq!(file.len(), 28 + 32 + 36 + 36);
        assert_eq!(&file[0..4], &[0x0A, 0x0D, 0x0D, 0x0A]);
        assert_eq!(&file[36..38], &[0x01, 0x01]);
        assert_eq!(
            PcapReader::new(&file[..]).unwrap().format(),
            PcapFormat::Pcapng
        );
        check_packets(&file);
        let mut cut = PcapReader::new(&file[..100]).unwrap();
        assert!(cut.next_packet().is_ok());
        assert!(cut.next_packet().is_err());
    }

    #[test]
    fn corrupt_telegrams_are_kept_and_flagged() {
        // A Slave_Diag request with a wrong FCS (0x00 instead of 0xF1),
        // then a token.
        let bad = [0x68, 5, 5, 0x68, 0x88, 0x82, 0x6D, 0x3C, 0x3E, 0x00, 0x16];
        let mut w = PcapWriter::new(Vec::new(), Duration::from_secs(5)).unwrap();
        w.write_corrupt(Instant::from_nanos(1_000), &bad).unwrap();
        w.write_telegram(Instant::from_nanos(2_000), &[0xDC, 2, 2])
            .unwrap();
        assert_eq!(w.packets(), 2);
        let file = w.into_inner().unwrap();
        // EPB 32 + 11 bytes + 1 pad + epb_flags option 8 + end of options 4.
        assert_eq!(file.len(), 28 + 32 + 56 + 36);
        let packets: Vec<PcapPacket> = PcapReader::new(&file[..])
            .unwrap()
            .map(Result::unwrap)
            .collect();
        assert_eq!(packets[0].data, bad);
        assert_eq!(packets[0].flags, 0x0100_0000);
        assert!(packets[0].is_corrupt());
        assert_eq!(packets[1].data, [0xDC, 2, 2]);
        assert!(!packets[1].is_corrupt());
        // The classic format keeps the bytes, without a flag.
        let mut w = PcapWriter::with_format(Vec::new(), PcapFormat::Pcap, Duration::ZERO).unwrap();
        w.write_corrupt(Instant::ZERO, &bad).unwrap();
        let file = w.into_inner().unwrap();
        let p = PcapReader::new(&file[..])
            .unwrap()
            .next_packet()
            .unwrap()
            .unwrap();
        assert_eq!((p.data.as_slice(), p.flags), (&bad[..], 0));
    }

    #[test]
    fn records_carry_comments_before_their_flags() {
        let bad = [0x68, 5, 5, 0x68, 0x88, 0x82, 0x6D, 0x3C, 0x3E, 0x00, 0x16];
        let mut w = PcapWriter::new(Vec::new(), Duration::ZERO).unwrap();
        w.write_record(Instant::from_nanos(1), &bad, true, Some("trigger: fcs"))
            .unwrap();
        w.write_record(Instant::from_nanos(2), &[0xE5], false, Some("x"))
            .unwrap();
        let file = w.into_inner().unwrap();
        // EPB 32 + 11 + 1 pad + comment (4 + 12) + flags 8 + end 4; then
        // EPB 32 + 1 + 3 pad + comment (4 + 1 + 3 pad) + end 4.
        assert_eq!(file.len(), 60 + 72 + 48);
        let at = 60 + 28 + 12;
        assert_eq!(&file[at..at + 4], &[1, 0, 12, 0]);
        assert_eq!(&file[at + 4..at + 16], b"trigger: fcs");
        let packets: Vec<PcapPacket> = PcapReader::new(&file[..])
            .unwrap()
            .map(Result::unwrap)
            .collect();
        assert!(packets[0].is_corrupt());
        assert_eq!(packets[1].data, [0xE5]);
        assert!(!packets[1].is_corrupt());
    }

    #[test]
    fn short_interface_block_is_an_error() {
        // Found by fuzzing (pcap_read): an IDB with a 4-byte body.
        let mut f = sample(PcapFormat::Pcapng)[..28].to_vec();
        f.extend_from_slice(&1u32.to_le_bytes());
        f.extend_from_slice(&16u32.to_le_bytes());
        f.extend_from_slice(&[0x01, 0x01, 0, 0]);
        f.extend_from_slice(&16u32.to_le_bytes());
        let e = PcapReader::new(&f[..]).unwrap_err();
        assert!(e.to_string().contains("interface block"), "{e}");
    }

    #[test]
    fn reads_big_endian_microsecond_files() {
        let mut f = vec![];
        f.extend_from_slice(&MAGIC_MICROS.to_be_bytes());
        f.extend_from_slice(&[
            0, 2, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xFF, 0xFF, 0, 0, 1, 1,
        ]);
        f.extend_from_slice(&[0, 0, 0, 5, 0, 0, 0, 7, 0, 0, 0, 1, 0, 0, 0, 1, 0xE5]);
        let mut r = PcapReader::new(&f[..]).unwrap();
        assert_eq!(r.linktype(), 257);
        let p = r.next().unwrap().unwrap();
        assert_eq!(p.ts, Duration::new(5, 7_000));
        assert!(r.next().is_none());
        assert!(PcapReader::new(&[0u8; 24][..]).is_err());
        let mut cut = PcapReader::new(&f[..30]).unwrap();
        assert!(cut.next_packet().is_err());
    }
}
