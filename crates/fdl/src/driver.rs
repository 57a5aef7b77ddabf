//! The tokio driver: runs any sans-IO [`Station`] on an async byte stream
//! (a serial port, a pty, one end of an in-memory duplex).
//!
//! The driver owns nothing but a read buffer. It passes the real time as
//! an [`Instant`] counted from the driver's start, feeds received bytes and
//! due timeouts to the station, and writes what the station wants sent.
//! After each event it calls the caller's `tick` closure with the station,
//! so a command line or gateway can look at the state, exchange process
//! data and decide to stop, without locks or channels inside the core.
//!
//! Timers: tokio's timer wheel has 1 ms granularity, which is coarse next
//! to PROFIBUS bit times (min TSDR is 0.9 µs at 12 Mbit/s). A deadline
//! less than [`SPIN_INLINE`] away is awaited on the spot by spinning on
//! the clock, then handled and what it sends is written in the same pass
//! (no round through the runtime and the port's read). Deadlines up to
//! [`SPIN_BELOW`] away are awaited by yielding to the runtime in a loop
//! (still reading the port); longer ones sleep, then spin the rest.
//!
//! Line timing: a station's transmission is never written before its
//! deadline, so the idle time the station keeps before a telegram (TID1 ≥
//! TSYN + TSM before each request, including after a token to itself) is
//! on the line as computed. Each transmission is polled with the time read
//! just before it is written, so a station can account for a late write.
//! Gathering several telegrams into one write ([`Options::gather`]) gives
//! this up for speed on ptys; it is off by default.

use crate::station::Station;
use crate::time::Instant;
use std::future::Future;
use std::io;
use std::ops::ControlFlow;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

/// Deadlines closer than this are awaited by yielding instead of sleeping.
pub const SPIN_BELOW: Duration = Duration::from_micros(1500);

/// Deadlines closer than this are awaited by spinning on the clock in the
/// same pass (no sleep, no trip through the runtime).
pub const SPIN_INLINE: Duration = Duration::from_micros(60);

/// With [`Options::gather`]: telegrams due within this window join the
/// same write (the driver's clock jumps to their deadline).
pub const GATHER_WINDOW: Duration = Duration::from_micros(100);

/// The clock of a driver: real time since its start as an [`Instant`],
/// never running backwards after a jump ([`Clock::jump_to`]).
#[derive(Debug, Clone)]
pub struct Clock {
    epoch: tokio::time::Instant,
    floor: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl Clock {
    /// A clock whose epoch is now.
    pub fn start() -> Clock {
        Clock {
            epoch: tokio::time::Instant::now(),
            floor: Default::default(),
        }
    }

    /// Now.
    pub fn now(&self) -> Instant {
        let real = self.epoch.elapsed().as_nanos() as u64;
        let floor = self.floor.load(std::sync::atomic::Ordering::Relaxed);
        Instant::from_nanos(real.max(floor))
    }

    /// Let the clock read at least `t` from now on.
    pub fn jump_to(&self, t: Instant) {
        self.floor
            .fetch_max(t.as_nanos(), std::sync::atomic::Ordering::Relaxed);
    }

    /// The tokio instant of `t`.
    pub fn to_tokio(&self, t: Instant) -> tokio::time::Instant {
        self.epoch + Duration::from_nanos(t.as_nanos())
    }
}

/// Why the driver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    /// The `tick` closure asked to stop.
    Done,
    /// The shutdown future completed (Ctrl-C, SIGTERM …).
    Shutdown,
}

/// How the driver writes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Options {
    /// Benchmark option, off by default: gather what the station sends
    /// within [`GATHER_WINDOW`] (e.g. a token to itself and the request
    /// that follows it after TID1) into one write, jumping the clock to
    /// the later deadlines. On a pty the peer then gets one wake-up
    /// instead of two, but the idle time between the gathered telegrams
    /// (TSYN) disappears: receivers that frame by idle time (slave ASICs,
    /// and any slave behind `dpctl bus`) see one frame and reject the
    /// request. Only for ptys ([`crate::transport::Port::may_gather`])
    /// whose peer frames by length, never for a real line.
    pub gather: bool,
    /// After each event, keep polling the port for this long instead of
    /// sleeping in the operating system (busy polling): the answer to a
    /// request is seen microseconds earlier, at the price of a busy CPU
    /// while waiting. Zero (the default) sleeps at once.
    pub busy_poll: Duration,
}

/// Run `station` on `port` until `tick` breaks, `shutdown` completes or
/// the port fails. End of file on the port is an error (the other side
/// went away).
pub async fn run<S, P, F>(
    station: &mut S,
    port: &mut P,
    clock: Clock,
    shutdown: F,
    tick: impl FnMut(&mut S, Instant) -> ControlFlow<()>,
) -> io::Result<Stop>
where
    S: Station + ?Sized,
    P: AsyncRead + AsyncWrite + Unpin + ?Sized,
    F: Future<Output = ()>,
{
    run_with(station, port, clock, Options::default(), shutdown, tick).await
}

/// [`run`] with [`Options`].
pub async fn run_with<S, P, F>(
    station: &mut S,
    port: &mut P,
    clock: Clock,
    options: Options,
    shutdown: F,
    mut tick: impl FnMut(&mut S, Instant) -> ControlFlow<()>,
) -> io::Result<Stop>
where
    S: Station + ?Sized,
    P: AsyncRead + AsyncWrite + Unpin + ?Sized,
    F: Future<Output = ()>,
{
    let mut buf = vec![0u8; 4096];
    let mut out: Vec<u8> = Vec::with_capacity(1024);
    tokio::pin!(shutdown);
    loop {
        if options.gather {
            gather_due(station, &clock, &mut out);
            if !out.is_empty() {
                port.write_all(&out).await?;
            }
        } else {
            // Deadlines due or about to come are handled in this pass (a
            // response due after min TSDR, the request TID1 after a token
            // to itself), each transmission written at its deadline. The
            // bound keeps a station that never stops asking from starving
            // the runtime.
            for _ in 0..16 {
                while let Some(bytes) = station.poll_transmit(clock.now()) {
                    port.write_all(bytes).await?;
                }
                let Some(d) = station.poll_timeout() else {
                    break;
                };
                let now = clock.now();
                if d > now {
                    if d.saturating_duration_since(now) >= SPIN_INLINE {
                        break;
                    }
                    spin_until(&clock, d);
                }
                station.handle_timeout(clock.now());
            }
            while let Some(bytes) = station.poll_transmit(clock.now()) {
                port.write_all(bytes).await?;
            }
        }
        port.flush().await?;
        if tick(station, clock.now()).is_break() {
            return Ok(Stop::Done);
        }
        let deadline = station.poll_timeout();
        let wait = deadline.map(|d| d.saturating_duration_since(clock.now()));
        let busy_until = clock.now() + options.busy_poll;
        tokio::select! {
            biased;
            _ = &mut shutdown => return Ok(Stop::Shutdown),
            r = port.read(&mut buf) => {
                let n = r?;
                if n == 0 {
                    return Err(io::Error::new(io::ErrorKind::UnexpectedEof, "port closed"));
                }
                station.handle_rx(clock.now(), &buf[..n]);
            }
            _ = wait_for(&clock, deadline, wait, busy_until) => {
                station.handle_timeout(clock.now());
            }
        }
    }
}

/// [`Options::gather`]: what the station sends now and within
/// [`GATHER_WINDOW`], into `out` (cleared first).
fn gather_due<S: Station + ?Sized>(station: &mut S, clock: &Clock, out: &mut Vec<u8>) {
    out.clear();
    warp(station, clock);
    let now = clock.now();
    gather(station, now, out);
    for _ in 0..8 {
        if out.is_empty() || !warp(station, clock) {
            break;
        }
        let t = clock.now();
        station.handle_timeout(t);
        if !gather(station, t, out) {
            break;
        }
    }
}

/// Busy-wait until the clock reads `t`.
fn spin_until(clock: &Clock, t: Instant) {
    while clock.now() < t {
        std::hint::spin_loop();
    }
}

/// Append what the station sends now to `out`; whether there was any.
fn gather<S: Station + ?Sized>(station: &mut S, now: Instant, out: &mut Vec<u8>) -> bool {
    let before = out.len();
    while let Some(bytes) = station.poll_transmit(now) {
        out.extend_from_slice(bytes);
    }
    out.len() > before
}

/// Jump the clock to the station's deadline when it is due or less than
/// [`GATHER_WINDOW`] away; whether the deadline is reached now.
fn warp<S: Station + ?Sized>(station: &S, clock: &Clock) -> bool {
    match station.poll_timeout() {
        Some(d) => {
            let now = clock.now();
            if d > now && d.saturating_duration_since(now) < GATHER_WINDOW {
                clock.jump_to(d);
            }
            d <= clock.now()
        }
        None => false,
    }
}

async fn wait_for(
    clock: &Clock,
    deadline: Option<Instant>,
    wait: Option<Duration>,
    spin_until: Instant,
) {
    // Busy polling: yield to the runtime (which then polls the port
    // without blocking) until the spin window or the deadline ends.
    while clock.now() < spin_until {
        if deadline.is_some_and(|d| clock.now() >= d) {
            return;
        }
        tokio::task::yield_now().await;
    }
    let wait = match (deadline, wait) {
        (Some(d), Some(_)) => Some(d.saturating_duration_since(clock.now())),
        _ => wait,
    };
    match (deadline, wait) {
        (None, _) | (_, None) => std::future::pending().await,
        (Some(_), Some(w)) if w.is_zero() => {}
        (Some(d), Some(w)) if w < SPIN_BELOW => {
            while clock.now() < d {
                tokio::task::yield_now().await;
            }
        }
        (Some(d), Some(_)) => {
            // Sleep to just before the deadline, then spin the rest.
            tokio::time::sleep_until(clock.to_tokio(d) - SPIN_BELOW / 2).await;
            while clock.now() < d {
                tokio::task::yield_now().await;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::station::echo::Echo;
    use crate::station::passive::PassiveStation;
    use crate::timing::{Baud, BusParams};

    #[tokio::test]
    async fn passive_station_answers_over_a_duplex_stream() {
        let (mut a, mut b) = tokio::io::duplex(1024);
        let mut st = PassiveStation::new(Echo::new(4), BusParams::defaults(Baud::B12000000));
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let server = tokio::spawn(async move {
            run(
                &mut st,
                &mut b,
                Clock::start(),
                async {
                    let _ = stop_rx.await;
                },
                |_, _| ControlFlow::Continue(()),
            )
            .await
        });
        // SRD high first frame 2 → 4 with data 0xAB.
        let req = [0x68, 4, 4, 0x68, 4, 2, 0x6D, 0xAB, 0x1E, 0x16];
        a.write_all(&req).await.unwrap();
        let mut resp = [0u8; 10];
        a.read_exact(&mut resp).await.unwrap();
        assert_eq!(resp, [0x68, 4, 4, 0x68, 2, 4, 0x08, 0xAB, 0xB9, 0x16]);
        stop_tx.send(()).unwrap();
        assert_eq!(server.await.unwrap().unwrap(), Stop::Shutdown);
    }
}
