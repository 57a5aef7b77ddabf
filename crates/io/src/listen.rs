//! The passive driver: reads a line, never writes to it, and hands what a
//! [`Tap`] frames off it to the caller (bus monitors: `dpctl monitor`).
//!
//! [`listen`] takes only an [`AsyncRead`], so nothing it does can send a
//! byte. Time stamps are real time since the call, as [`Instant`]s; a
//! [`Heard::Tick`] comes at least every [`ListenOptions::tick`] even on a
//! silent line, for status output and timeouts; a [`Heard::Drained`]
//! after the events of the bytes read so far, when the line has no more
//! ready (a caller that buffers its output flushes there).

use crate::transport::Port;
use profibus_fdl::codec::CodecStats;
use profibus_fdl::line::tap::{Tap, TapEvent};
use profibus_fdl::time::Instant;
use profibus_fdl::timing::BusParams;
use std::future::Future;
use std::io;
use std::ops::ControlFlow;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt};

/// What [`listen`] passes on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Heard {
    /// A telegram or skipped bytes, in line order.
    Event(TapEvent),
    /// Time passed (at least every [`ListenOptions::tick`]).
    Tick(Instant),
    /// Every event of the bytes read so far was passed on, and the last
    /// read took all the line had ready (it did not fill the buffer): a
    /// good moment to flush buffered output, so a person sees each
    /// telegram at once while a busy line is printed in large writes.
    /// Comes only after events.
    Drained(Instant),
}

/// Options of [`listen`].
#[derive(Debug, Clone, Copy)]
pub struct ListenOptions {
    /// Quiet time after which an incomplete telegram is given up.
    pub idle: Duration,
    /// Longest time between two [`Heard::Tick`]s.
    pub tick: Duration,
}

impl ListenOptions {
    /// Options for `port`: an idle time of 5 ms on a pty or a serial
    /// server connection (their bytes come in bursts), else twice TSYN
    /// (33 bit times) at the port's rate, at least 2 ms; a tick every
    /// 100 ms.
    pub fn for_port(port: &Port) -> ListenOptions {
        let idle = if port.is_pty() || port.is_tcp() {
            Duration::from_millis(5)
        } else {
            (BusParams::defaults(port.baud()).bits(33) * 2).max(Duration::from_millis(2))
        };
        ListenOptions {
            idle,
            tick: Duration::from_millis(100),
        }
    }
}

/// Reading the line failed; the counters up to then come with it.
#[derive(Debug, thiserror::Error)]
#[error("{io}")]
pub struct ListenError {
    /// Why reading failed.
    pub io: io::Error,
    /// The codec counters up to the failure.
    pub stats: CodecStats,
}

/// Read `line` until `stop` completes, the line ends (EOF) or `f` breaks;
/// returns the codec counters. Never writes. An incomplete telegram is
/// given up after [`ListenOptions::idle`] without a byte.
pub async fn listen<R, S, F>(
    line: &mut R,
    options: ListenOptions,
    stop: S,
    mut f: F,
) -> Result<CodecStats, ListenError>
where
    R: AsyncRead + Unpin,
    S: Future<Output = ()>,
    F: FnMut(Heard) -> ControlFlow<()>,
{
    let clock = std::time::Instant::now();
    let now = || Instant::from_nanos(clock.elapsed().as_nanos() as u64);
    let mut tap = Tap::new();
    let mut buf = [0u8; 4096];
    let mut next_tick = clock + options.tick;
    let mut last_byte = clock;
    tokio::pin!(stop);
    let mut result = Ok(());
    // Events passed on since the last `Drained`.
    let mut undrained = false;
    'outer: loop {
        let mut more_ready = false;
        let to_tick = next_tick.saturating_duration_since(std::time::Instant::now());
        let wait = if tap.pending() > 0 {
            (last_byte + options.idle)
                .saturating_duration_since(std::time::Instant::now())
                .min(to_tick)
        } else {
            to_tick
        };
        tokio::select! {
            _ = &mut stop => break,
            r = tokio::time::timeout(wait, line.read(&mut buf)) => match r {
                Err(_elapsed) => {
                    if tap.pending() > 0 && last_byte.elapsed() >= options.idle {
                        tap.line_idle();
                    }
                }
                Ok(Ok(0)) => break,
                Ok(Ok(n)) => {
                    last_byte = std::time::Instant::now();
                    tap.push(now(), &buf[..n]);
                    more_ready = n == buf.len();
                }
                Ok(Err(e)) => {
                    result = Err(e);
                    break;
                }
            },
        }
        while let Some(ev) = tap.poll() {
            undrained = true;
            if f(Heard::Event(ev)).is_break() {
                break 'outer;
            }
        }
        if undrained && !more_ready {
            undrained = false;
            if f(Heard::Drained(now())).is_break() {
                break;
            }
        }
        if std::time::Instant::now() >= next_tick {
            next_tick = std::time::Instant::now() + options.tick;
            if f(Heard::Tick(now())).is_break() {
                break;
            }
        }
    }
    tap.line_idle();
    while let Some(ev) = tap.poll() {
        if f(Heard::Event(ev)).is_break() {
            break;
        }
    }
    let stats = tap.stats();
    result
        .map(|()| stats)
        .map_err(|io| ListenError { io, stats })
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::AsyncWriteExt;

    #[tokio::test]
    async fn frames_telegrams_and_ticks_on_a_silent_line() {
        let (mut a, mut b) = tokio::io::duplex(64);
        a.write_all(&[0xDC, 2, 3, 0x00, 0xE5]).await.unwrap();
        drop(a);
        let mut heard = vec![];
        let stats = listen(
            &mut b,
            ListenOptions {
                idle: Duration::from_millis(5),
                tick: Duration::from_millis(10),
            },
            std::future::pending(),
            |h| {
                heard.push(h);
                ControlFlow::Continue(())
            },
        )
        .await
        .unwrap();
        // The two telegrams came in one read: one `Drained` after both.
        let kinds: Vec<&str> = (heard.iter())
            .map(|h| match h {
                Heard::Event(_) => "event",
                Heard::Tick(_) => "tick",
                Heard::Drained(_) => "drained",
            })
            .filter(|k| *k != "tick")
            .collect();
        assert_eq!(kinds, ["event", "event", "event", "drained"], "{heard:?}");
        let bytes: Vec<Vec<u8>> = heard
            .iter()
            .filter_map(|h| match h {
                Heard::Event(TapEvent::Telegram { bytes, .. }) => Some(bytes.clone()),
                _ => None,
            })
            .collect();
        assert_eq!(bytes, [vec![0xDC, 2, 3], vec![0xE5]]);
        assert_eq!(stats.garbage_bytes, 1);

        // Silence: ticks come anyway, and `f` can stop the listener.
        let (_a, mut b) = tokio::io::duplex(64);
        let mut ticks = 0;
        listen(
            &mut b,
            ListenOptions {
                idle: Duration::from_millis(5),
                tick: Duration::from_millis(5),
            },
            std::future::pending(),
            |h| {
                if matches!(h, Heard::Tick(_)) {
                    ticks += 1;
                }
                if ticks == 3 {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            },
        )
        .await
        .unwrap();
        assert_eq!(ticks, 3);
    }
}
