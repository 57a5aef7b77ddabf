//! Property tests of the telegram wire format and the streaming codec.

use bytes::BytesMut;
use profibus_fdl::codec::Framer;
use profibus_fdl::wire::{DataTelegram, Format, FunctionCode, Telegram};
use proptest::prelude::*;

#[derive(Debug, Clone)]
enum Owned {
    /// A data telegram: its header fields (`head.data` empty) and its data.
    Data {
        head: DataTelegram<'static>,
        data: Vec<u8>,
    },
    Token(u8, u8),
    Ack,
}

impl Owned {
    fn view(&self) -> Telegram<'_> {
        match self {
            Owned::Data { head, data } => Telegram::Data(DataTelegram { data, ..*head }),
            Owned::Token(da, sa) => Telegram::Token { da: *da, sa: *sa },
            Owned::Ack => Telegram::ShortAck,
        }
    }

    fn bytes(&self) -> Vec<u8> {
        let mut b = vec![0u8; 255];
        let n = self.view().emit(&mut b).unwrap();
        b.truncate(n);
        b
    }
}

fn sent_format(bytes: &[u8]) -> Format {
    Format::from_start_delimiter(bytes[0]).unwrap()
}

fn telegram() -> impl Strategy<Value = Owned> {
    let data = (
        0u8..=127,
        0u8..=127,
        any::<u8>(),
        proptest::option::of(any::<u8>()),
        proptest::option::of(any::<u8>()),
        // Bias towards the format boundaries: empty, SD3 (8 bytes with the
        // SAPs) and the 246-byte maximum.
        prop_oneof![0usize..=10, 0usize..=244],
        // The start delimiter: the emitter's choice, SD2 (fits any length)
        // or the fixed-length format of the data field when there is one.
        0u8..3,
    )
        .prop_flat_map(|(da, sa, fc, dsap, ssap, n, pick)| {
            let room = 246 - dsap.is_some() as usize - ssap.is_some() as usize;
            proptest::collection::vec(any::<u8>(), n.min(room)).prop_map(move |data| {
                let field = dsap.is_some() as usize + ssap.is_some() as usize + data.len();
                let format = match (pick, field) {
                    (0, _) => None,
                    (1, _) => Some(Format::Sd2),
                    (_, 0) => Some(Format::Sd1),
                    (_, 8) => Some(Format::Sd3),
                    _ => Some(Format::Sd2),
                };
                let fc = FunctionCode::from_byte(fc);
                let head = DataTelegram {
                    da,
                    sa,
                    fc,
                    dsap,
                    ssap,
                    data: &[],
                    format,
                };
                Owned::Data { head, data }
            })
        });
    prop_oneof![
        8 => data,
        1 => (0u8..=126, 0u8..=126).prop_map(|(a, b)| Owned::Token(a, b)),
        1 => Just(Owned::Ack),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn emit_then_parse_is_identity(t in telegram()) {
        let bytes = t.bytes();
        prop_assert_eq!(bytes.len(), t.view().emitted_len());
        let (parsed, n) = Telegram::parse(&bytes).unwrap();
        prop_assert_eq!(n, bytes.len());
        // The parsed telegram is the emitted one, with the start delimiter
        // it was sent in; emitting it again gives the same bytes.
        let mut sent = t.view();
        if let Telegram::Data(d) = &mut sent {
            d.format = Some(sent_format(&bytes));
        }
        prop_assert_eq!(parsed, sent);
        let mut again = vec![0u8; 255];
        let m = parsed.emit(&mut again).unwrap();
        prop_assert_eq!(&again[..m], &bytes[..]);
        // Parsing a prefix reports truncation, never a wrong telegram.
        for cut in 0..bytes.len() {
            prop_assert!(Telegram::parse(&bytes[..cut]).is_err());
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let _ = Telegram::parse(&bytes);
        let mut codec = Framer::new();
        let mut buf = BytesMut::from(&bytes[..]);
        let mut framed = 0usize;
        while let Some(t) = codec.next_at_end(&mut buf) {
            // Everything the codec returns is a valid telegram.
            prop_assert!(Telegram::parse(t.as_bytes()).is_ok());
            framed += 1;
            prop_assert!(framed <= bytes.len());
        }
        prop_assert!(buf.is_empty());
    }

    /// Garbage, then the idle line a sender keeps before every request
    /// (TSYN), then a valid telegram: the codec frames exactly that
    /// telegram after the garbage.
    #[test]
    fn valid_telegram_after_garbage_is_recovered(
        garbage in proptest::collection::vec(any::<u8>(), 0..300),
        t in telegram(),
    ) {
        let want = t.bytes();
        let mut codec = Framer::new();
        let mut buf = BytesMut::from(&garbage[..]);
        // Whatever the garbage holds is framed or dropped by the time the
        // line has been idle.
        loop {
            if codec.next_telegram(&mut buf).is_some() {
                continue;
            }
            if buf.is_empty() {
                break;
            }
            codec.next_after_idle(&mut buf);
        }
        buf.extend_from_slice(&want);
        let got = codec.next_telegram(&mut buf).expect("telegram after garbage");
        prop_assert_eq!(got.as_bytes(), &want[..]);
        prop_assert!(buf.is_empty());
    }

    /// Garbage that cannot start a telegram (no start delimiter byte)
    /// directly followed by a telegram, with no idle gap.
    #[test]
    fn telegram_glued_to_garbage_is_recovered(
        garbage in proptest::collection::vec(any::<u8>().prop_filter("no SD", |b| ![0x10, 0x68, 0xA2, 0xDC, 0xE5].contains(b)), 0..300),
        t in telegram(),
    ) {
        let want = t.bytes();
        let mut codec = Framer::new();
        let mut buf = BytesMut::from(&garbage[..]);
        buf.extend_from_slice(&want);
        let got = codec.next_telegram(&mut buf).expect("telegram after garbage");
        prop_assert_eq!(got.as_bytes(), &want[..]);
        prop_assert_eq!(codec.stats().garbage_bytes, garbage.len() as u64);
    }

    #[test]
    fn fragmented_stream_yields_every_telegram(
        ts in proptest::collection::vec(telegram(), 1..20),
        cuts in proptest::collection::vec(1usize..40, 1..50),
    ) {
        let stream: Vec<u8> = ts.iter().flat_map(|t| t.bytes()).collect();
        let mut codec = Framer::new();
        let mut buf = BytesMut::new();
        let mut got = vec![];
        let mut pos = 0;
        let mut i = 0;
        while pos < stream.len() {
            let n = cuts[i % cuts.len()].min(stream.len() - pos);
            buf.extend_from_slice(&stream[pos..pos + n]);
            pos += n;
            i += 1;
            while let Some(t) = codec.next_telegram(&mut buf) {
                got.push(t.as_bytes().to_vec());
            }
        }
        let want: Vec<Vec<u8>> = ts.iter().map(|t| t.bytes()).collect();
        prop_assert_eq!(got, want);
        prop_assert_eq!(codec.stats().errors(), 0);
    }
}
