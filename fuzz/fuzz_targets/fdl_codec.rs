//! Arbitrary bytes, cut into arbitrary fragments, through the telegram
//! parser, the streaming codec (with idle flushes) and the station receive
//! path: nothing panics or loops, and everything framed is a valid
//! telegram that re-emits to the same bytes.
#![no_main]

use bytes::BytesMut;
use libfuzzer_sys::fuzz_target;
use profibus_fdl::codec::Framer;
use profibus_fdl::wire::Telegram;

fuzz_target!(|data: &[u8]| {
    let _ = Telegram::parse(data);
    // First byte: fragment size; the rest: the stream.
    let Some((&cut, stream)) = data.split_first() else {
        return;
    };
    let cut = (cut as usize % 64) + 1;
    let mut codec = Framer::new();
    let mut buf = BytesMut::new();
    let mut framed = 0usize;
    for (i, chunk) in stream.chunks(cut).enumerate() {
        buf.extend_from_slice(chunk);
        while let Some(t) = codec.next_telegram(&mut buf) {
            framed += 1;
            let (tel, n) = Telegram::parse(t.as_bytes()).expect("framed telegram parses");
            assert_eq!(n, t.as_bytes().len());
            // Re-emitting gives a valid telegram of the same meaning (the
            // format may change: SD2 with 8 bytes becomes SD3).
            let mut out = [0u8; 300];
            let m = tel.emit(&mut out).expect("re-emit");
            assert_eq!(Telegram::parse(&out[..m]).unwrap().0, tel);
        }
        if i % 3 == 2 {
            let _ = codec.next_after_idle(&mut buf);
        }
    }
    while codec.next_at_end(&mut buf).is_some() {
        framed += 1;
    }
    assert!(buf.is_empty());
    assert!(framed <= stream.len());
});
