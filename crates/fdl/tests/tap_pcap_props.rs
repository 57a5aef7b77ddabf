//! Property tests of the tap (passive framing with time stamps) and the
//! pcap reader/writer: arbitrary input never panics, nothing is lost.

use profibus_fdl::capture::pcap::{PcapFormat, PcapReader, PcapWriter};
use profibus_fdl::line::tap::{Tap, TapEvent};
use profibus_fdl::Instant;
use proptest::prelude::*;
use std::time::Duration;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Every byte pushed comes out exactly once, in order, either in a
    /// telegram or as skipped; time stamps never go backwards.
    #[test]
    fn tap_accounts_for_every_byte(
        chunks in proptest::collection::vec(
            proptest::collection::vec(
                prop_oneof![
                    Just(0x10u8), Just(0x68), Just(0xA2), Just(0xDC), Just(0xE5), Just(0x16),
                    any::<u8>()
                ],
                0..40,
            ),
            0..30,
        ),
        idle_every in 1usize..10,
    ) {
        let mut tap = Tap::new();
        let mut out = vec![];
        let mut last = Instant::ZERO;
        let mut pushed = vec![];
        let check = |ev: TapEvent, out: &mut Vec<u8>, last: &mut Instant| {
            let (at, bytes) = match ev {
                TapEvent::Telegram { at, bytes } => {
                    prop_assert!(profibus_fdl::Telegram::parse_exact(&bytes).is_ok());
                    (at, bytes)
                }
                TapEvent::Skipped { at, bytes, .. } => {
                    prop_assert!(!bytes.is_empty());
                    (at, bytes)
                }
            };
            prop_assert!(at >= *last);
            *last = at;
            out.extend_from_slice(&bytes);
            Ok(())
        };
        for (i, c) in chunks.iter().enumerate() {
            tap.push(Instant::from_nanos(i as u64 * 1000), c);
            pushed.extend_from_slice(c);
            if i % idle_every == 0 {
                tap.line_idle();
            }
            while let Some(ev) = tap.poll() {
                check(ev, &mut out, &mut last)?;
            }
        }
        tap.line_idle();
        while let Some(ev) = tap.poll() {
            check(ev, &mut out, &mut last)?;
        }
        prop_assert_eq!(tap.pending(), 0);
        prop_assert_eq!(out, pushed);
    }

    /// The reader never panics on arbitrary bytes and ends.
    #[test]
    fn pcap_reader_survives_garbage(data in proptest::collection::vec(any::<u8>(), 0..400),
                                    header in prop_oneof![
                                        Just(vec![0x0A, 0x0D, 0x0D, 0x0A]),
                                        Just(vec![0x4D, 0x3C, 0xB2, 0xA1]),
                                        Just(vec![0xA1, 0xB2, 0xC3, 0xD4]),
                                        Just(vec![]),
                                    ]) {
        let mut bytes = header;
        bytes.extend_from_slice(&data);
        if let Ok(r) = PcapReader::new(&bytes[..]) {
            // Each packet consumes at least 12 bytes, so this ends.
            for p in r.take(1000) {
                if p.is_err() {
                    break;
                }
            }
        }
    }

    /// What the writer writes, the reader reads back (both formats).
    #[test]
    fn pcap_round_trip(
        packets in proptest::collection::vec(
            (0u64..10_000_000_000, proptest::collection::vec(any::<u8>(), 1..256)),
            0..20,
        ),
        classic in any::<bool>(),
    ) {
        let format = if classic { PcapFormat::Pcap } else { PcapFormat::Pcapng };
        let epoch = Duration::new(1_700_000_000, 0);
        let mut w = PcapWriter::with_format(Vec::new(), format, epoch).unwrap();
        for (at, data) in &packets {
            w.write_telegram(Instant::from_nanos(*at), data).unwrap();
        }
        let file = w.into_inner().unwrap();
        let r = PcapReader::new(&file[..]).unwrap();
        prop_assert_eq!(r.format(), format);
        let back: Vec<_> = r.map(|p| p.unwrap()).collect();
        prop_assert_eq!(back.len(), packets.len());
        for (p, (at, data)) in back.iter().zip(&packets) {
            prop_assert_eq!(&p.data, data);
            prop_assert_eq!(p.ts, epoch + Duration::from_nanos(*at));
        }
    }
}
