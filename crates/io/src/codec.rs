//! [`FdlCodec`]: the FDL framer of `profibus_fdl::codec` as a `tokio_util`
//! `Decoder`/`Encoder`, for telegram streams over any `AsyncRead` /
//! `AsyncWrite` (`tokio_util::codec::Framed`).

use bytes::BytesMut;
use profibus_fdl::codec::{CodecStats, Framer, RawTelegram};
use profibus_fdl::wire::{EmitError, Telegram};
use tokio_util::codec::{Decoder, Encoder};

/// `tokio_util` codec framing FDL telegrams: items are [`RawTelegram`]s
/// (validated, a slice of the receive buffer), garbage and corrupted
/// telegrams are skipped and counted (see `profibus_fdl::codec`).
#[derive(Debug, Default)]
pub struct FdlCodec {
    framer: Framer,
}

impl FdlCodec {
    /// A codec with zeroed statistics.
    pub fn new() -> Self {
        Self::default()
    }

    /// Error counters so far.
    pub fn stats(&self) -> CodecStats {
        self.framer.stats()
    }

    /// The line went idle: abandon an incomplete candidate at the front of
    /// `src` and return the first telegram after it, if any. A driver calls
    /// this when no byte arrived for longer than a telegram may pause.
    pub fn line_idle(&mut self, src: &mut BytesMut) -> Option<RawTelegram> {
        self.framer.next_after_idle(src)
    }
}

impl Decoder for FdlCodec {
    type Item = RawTelegram;
    type Error = std::io::Error;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<RawTelegram>, std::io::Error> {
        Ok(self.framer.next_telegram(src))
    }

    fn decode_eof(&mut self, src: &mut BytesMut) -> Result<Option<RawTelegram>, std::io::Error> {
        Ok(self.framer.next_at_end(src))
    }
}

impl Encoder<Telegram<'_>> for FdlCodec {
    type Error = std::io::Error;

    /// Emit errors (an address or data field out of range) become
    /// `InvalidInput` I/O errors.
    fn encode(&mut self, item: Telegram<'_>, dst: &mut BytesMut) -> Result<(), std::io::Error> {
        item.emit_to(dst)
            .map(|_| ())
            .map_err(|e: EmitError| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind};

    fn fdl_status(da: u8, sa: u8) -> Vec<u8> {
        let fc = FunctionCode::request(RequestKind::FdlStatus);
        Telegram::Data(DataTelegram::new(da, sa, fc, &[]))
            .to_vec()
            .unwrap()
    }

    #[test]
    fn decodes_fragments_and_abandons_a_false_start_at_eof() {
        let mut codec = FdlCodec::new();
        let mut buf = BytesMut::new();
        let mut out = vec![];
        for b in [fdl_status(3, 1), vec![0xE5], fdl_status(4, 1)].concat() {
            buf.extend_from_slice(&[b]);
            while let Some(t) = codec.decode(&mut buf).unwrap() {
                out.push(t);
            }
        }
        assert_eq!(out.len(), 3);
        assert_eq!(out[1].telegram(), Telegram::ShortAck);
        let mut buf =
            BytesMut::from(&[vec![0x68, 0xF0, 0xF0, 0x68], fdl_status(9, 1)].concat()[..]);
        assert!(codec.decode(&mut buf).unwrap().is_none());
        let t = codec.decode_eof(&mut buf).unwrap().unwrap();
        assert_eq!(t.as_bytes(), &fdl_status(9, 1)[..]);
        assert_eq!(codec.stats().truncated, 1);
    }

    #[test]
    fn encodes_a_telegram() {
        let mut codec = FdlCodec::new();
        let mut dst = BytesMut::new();
        codec.encode(Telegram::ShortAck, &mut dst).unwrap();
        assert_eq!(&dst[..], &[0xE5]);
    }
}
