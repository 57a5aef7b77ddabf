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
//! Waiting: tokio's timer wheel has 1 ms granularity, and a thread's
//! timers fire up to 50 µs late by default (the timer slack); both are
//! coarse next to PROFIBUS bit times (TID1 is 24.7 µs at 1.5 Mbit/s, min
//! TSDR 0.9 µs at 12 Mbit/s). On a port with a file descriptor
//! ([`Waitable`]: serial lines, ptys, TCP) the driver sets its thread's
//! timer slack to 1 µs and waits for deadlines less than [`SPIN_BELOW`]
//! away in the kernel (`ppoll` on the port with a nanosecond timeout,
//! waking early when bytes arrive) until shortly before the deadline,
//! then spins on the clock for the rest; how late such a sleep wakes is
//! learned as it runs, so a deadline is met to within a microsecond or
//! two without spinning through the whole wait. A deadline less than
//! [`SPIN_INLINE`] away (the idle time before a request, the slave's min
//! TSDR) is handled in the same pass, and what it sends is written at
//! once (no round through the runtime and the port's read); it is spun
//! for, except right after a write on a pty, where the driver sleeps
//! instead so that the kernel's worker can deliver what it wrote (see
//! [`Waitable::writes_need_cpu`]: spinning there merged the token to
//! itself and the next request on the far end in most cycles). Longer
//! deadlines sleep in the runtime. [`Options::anticipate`] (off by
//! default) also wakes up shortly before an expected answer and polls the
//! port for it. Without a descriptor (an in-memory duplex stream) short
//! deadlines are spun or yielded for.
//!
//! Line timing: a station's transmission is never written before its
//! deadline, so the idle time the station keeps before a telegram (TID1 ≥
//! TSYN + TSM before each request, including after a token to itself) is
//! on the line as computed. Each transmission is polled with the time read
//! just before it is written, so a station can account for a late write.
//! Gathering several telegrams into one write ([`Options::gather`]) gives
//! this up for speed on ptys; it is off by default.
//!
//! # A DP master gateway loop
//!
//! A gateway copies the inputs of a slave somewhere else and writes
//! outputs it got from elsewhere, between two events of the driver, with
//! no locks and no allocation:
//!
//! ```no_run
//! use profibus_dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams, SlaveState};
//! use profibus_io::driver::{run, Clock};
//! use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
//! use profibus_io::transport::Port;
//! use profibus_fdl::{Baud, BusParams};
//! use std::ops::ControlFlow;
//!
//! # async fn gateway() -> Result<(), Box<dyn std::error::Error>> {
//! let params = BusParams::defaults(Baud::B1500000);
//! let cfg = MasterConfig {
//!     address: 1,
//!     params,
//!     // Slave 8: 2 bytes in, 2 bytes out (identifiers 0x11, 0x21).
//!     slaves: vec![SlaveParams::new(8, 0x0DCE, vec![0x11, 0x21])],
//!     options: MasterOptions::default(),
//! };
//! let master = DpMaster::new(&cfg)?;
//! let valve = master.handle(8).expect("configured");
//! let mut station = ActiveStation::new(ActiveConfig::new(1, params), master);
//! let mut port = Port::open("/dev/ttyUSB0", Baud::B1500000)?;
//! let mut setpoint: u16 = 0;
//! run(&mut station, &mut port, Clock::start(), std::future::pending(), |st, _now| {
//!     let m = st.app_mut();
//!     let view = m.slave(valve);
//!     if view.state == SlaveState::DataExchange {
//!         let level = u16::from_be_bytes([view.inputs[0], view.inputs[1]]);
//!         setpoint = if level < 500 { 1000 } else { 0 };
//!     }
//!     m.outputs_mut(valve).copy_from_slice(&setpoint.to_be_bytes());
//!     while let Some(event) = m.poll_event() {
//!         eprintln!("{event:?}"); // state changes, diagnosis, faults
//!     }
//!     ControlFlow::Continue(())
//! })
//! .await?;
//! # Ok(())
//! # }
//! ```

use profibus_fdl::station::Station;
use profibus_fdl::time::Instant;
use std::future::Future;
use std::io;
use std::ops::ControlFlow;
use std::os::fd::BorrowedFd;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

/// Deadlines closer than this are waited for precisely (in the kernel
/// with a nanosecond timeout on a [`Waitable`] port, else by yielding to
/// the runtime) instead of with the runtime's 1 ms timers.
pub const SPIN_BELOW: Duration = Duration::from_micros(1500);

/// Deadlines closer than this are handled in the same pass, waited for
/// precisely without a trip through the runtime and the port's read.
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

/// How the driver writes and waits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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
    /// Anticipate answers (see the module docs, "Waiting"): after a
    /// telegram that awaits an answer ([`Station::awaits_answer`]), sleep
    /// in the kernel until shortly before the answer is expected (learned
    /// from the last answers), then poll the port until it comes, for at
    /// most this long past the expected time, before sleeping in the
    /// runtime. Zero (the default) sleeps in the runtime at once. About
    /// one round trip (100 µs on a pty) is a good value on a machine with
    /// a CPU to spare; on a busy machine the polling takes the CPU the far
    /// end needs to answer and makes things slower. Only on ports with a
    /// file descriptor ([`Waitable`]); ignored with `busy_poll`.
    pub anticipate: Duration,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            gather: false,
            busy_poll: Duration::ZERO,
            anticipate: Duration::ZERO,
        }
    }
}

/// A port the driver can wait on in the kernel with a precise timeout
/// (`ppoll` on its file descriptor with the thread's timer slack at
/// 1 µs), instead of the runtime's 1 ms timers or spinning. Without a
/// descriptor (`None`, e.g. an in-memory duplex stream) the driver spins
/// and yields as before.
pub trait Waitable {
    /// The descriptor that becomes readable when bytes arrive.
    fn wait_fd(&self) -> Option<BorrowedFd<'_>> {
        None
    }

    /// Whether the kernel hands written bytes on in a worker thread that
    /// needs a CPU after `write` returns (a pty: its flip buffer is
    /// pushed by a workqueue thread, usually on the writer's CPU). The
    /// driver then gives the CPU up while it waits right after a write,
    /// instead of spinning: a spinning writer (above all one under
    /// `SCHED_FIFO`) holds the telegram it just wrote back until its next
    /// write, and the far end reads both as one, without the idle time
    /// between them.
    fn writes_need_cpu(&self) -> bool {
        false
    }
}

impl Waitable for crate::transport::Port {
    fn wait_fd(&self) -> Option<BorrowedFd<'_>> {
        Some(self.fd())
    }

    fn writes_need_cpu(&self) -> bool {
        self.is_pty()
    }
}

impl Waitable for tokio::io::DuplexStream {}

impl<T: Waitable + ?Sized> Waitable for &mut T {
    fn wait_fd(&self) -> Option<BorrowedFd<'_>> {
        (**self).wait_fd()
    }

    fn writes_need_cpu(&self) -> bool {
        (**self).writes_need_cpu()
    }
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
    P: AsyncRead + AsyncWrite + Waitable + Unpin + ?Sized,
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
    P: AsyncRead + AsyncWrite + Waitable + Unpin + ?Sized,
    F: Future<Output = ()>,
{
    let mut buf = vec![0u8; 4096];
    let mut out: Vec<u8> = Vec::with_capacity(1024);
    let mut pacer = Pacer::new();
    let anticipate = if options.busy_poll.is_zero() {
        options.anticipate
    } else {
        Duration::ZERO
    };
    // Near deadlines handled without a pass through the runtime in a row
    // (bounded, so that the runtime's other tasks and the shutdown signal
    // get their turn).
    let mut precise_in_row = 0u32;
    let release = port.writes_need_cpu();
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
                let mut wrote = false;
                while let Some(bytes) = station.poll_transmit(clock.now()) {
                    stage::mark(b'w', bytes.len());
                    port.write_all(bytes).await?;
                    pacer.sent(clock.now(), station.awaits_answer());
                    wrote = true;
                }
                let Some(d) = station.poll_timeout() else {
                    break;
                };
                let now = clock.now();
                if d > now {
                    if d.saturating_duration_since(now) >= SPIN_INLINE {
                        break;
                    }
                    if wrote && release {
                        // Right after a write on a pty: give the CPU to
                        // the kernel's worker that delivers it (see
                        // `Waitable::writes_need_cpu`), then wait; bytes
                        // that arrive meanwhile are read first.
                        if sleep_after_write(&clock, port.wait_fd(), d) {
                            break;
                        }
                    } else {
                        // Spun: a kernel sleep this short wakes too late
                        // too often (the request would leave late).
                        spin_until(&clock, d);
                    }
                }
                station.handle_timeout(clock.now());
            }
            while let Some(bytes) = station.poll_transmit(clock.now()) {
                stage::mark(b'w', bytes.len());
                port.write_all(bytes).await?;
                pacer.sent(clock.now(), station.awaits_answer());
            }
        }
        port.flush().await?;
        if tick(station, clock.now()).is_break() {
            stage::dump();
            return Ok(Stop::Done);
        }
        let mut deadline = station.poll_timeout();
        if options.busy_poll.is_zero() {
            if let Some(fd) = port.wait_fd() {
                let now = clock.now();
                let near = deadline.filter(|d| {
                    d.saturating_duration_since(now) < SPIN_BELOW && precise_in_row < 32
                });
                if let Some(d) = near {
                    // A near deadline: sleep for it precisely, waking
                    // early when bytes arrive (then the read below takes
                    // them; the deadline is not due yet).
                    if !pacer.pause(&clock, Some(fd), d) {
                        precise_in_row += 1;
                        station.handle_timeout(clock.now());
                        continue;
                    }
                } else if !anticipate.is_zero() {
                    pacer.anticipate(&clock, fd, anticipate, deadline);
                }
                deadline = station.poll_timeout();
            }
        }
        precise_in_row = 0;
        let wait = deadline.map(|d| d.saturating_duration_since(clock.now()));
        let busy_until = clock.now() + options.busy_poll;
        stage::mark(b's', 0);
        tokio::select! {
            biased;
            _ = &mut shutdown => {
                stage::dump();
                return Ok(Stop::Shutdown);
            }
            r = port.read(&mut buf) => {
                let n = r?;
                stage::mark(b'r', n);
                if n == 0 {
                    return Err(io::Error::new(io::ErrorKind::UnexpectedEof, "port closed"));
                }
                let now = clock.now();
                pacer.received(now);
                station.handle_rx(now, &buf[..n]);
            }
            _ = wait_for(&clock, deadline, wait, busy_until) => {
                station.handle_timeout(clock.now());
            }
        }
    }
}

/// Sleeps shorter than this are not worth a trip through the kernel:
/// the driver spins instead.
const MIN_SLEEP: Duration = Duration::from_micros(8);

/// The shortest kernel sleep right after a write on a pty (see
/// [`Waitable::writes_need_cpu`]): long enough for the kernel's worker to
/// push the written bytes to the reader (a few µs).
const RELEASE: Duration = Duration::from_micros(10);

/// Bounds of the learned wake-up latency (see [`Pacer`]).
const WAKE_MIN: Duration = Duration::from_micros(2);
const WAKE_MAX: Duration = Duration::from_micros(300);

/// Telegrams further apart than this are not learned as "the next one
/// comes after" (the line was idle).
const GAP_MAX: Duration = Duration::from_millis(2);

/// The driver's precise waits (see the module docs, "Waiting"): how late
/// the thread wakes from a kernel sleep, and how long after a telegram
/// that awaits an answer ([`Station::awaits_answer`]) the answer arrives,
/// both learned as the driver runs.
#[derive(Debug)]
struct Pacer {
    /// How late a precise sleep wakes up (moving average, ns).
    wake_ns: u64,
    /// How long after a telegram that awaits an answer the answer's
    /// first bytes arrive: follows shorter times quickly and longer ones
    /// slowly, so it stays near the earliest usual arrival (ns; 0 until
    /// learned).
    answer_ns: u64,
    /// When the telegram that awaits an answer went out.
    sent: Option<Instant>,
}

impl Pacer {
    fn new() -> Pacer {
        set_timer_slack();
        Pacer {
            wake_ns: 30_000,
            answer_ns: 0,
            sent: None,
        }
    }

    fn wake(&self) -> Duration {
        // A margin over the average: waking late costs more than early.
        Duration::from_nanos(self.wake_ns + self.wake_ns / 2)
    }

    /// A telegram went out at `now`; `awaits`: the station awaits an
    /// answer to it.
    fn sent(&mut self, now: Instant, awaits: bool) {
        self.sent = awaits.then_some(now);
    }

    /// Bytes came in at `now`.
    fn received(&mut self, now: Instant) {
        let Some(sent) = self.sent.take() else {
            return;
        };
        let gap = now.saturating_duration_since(sent);
        if gap < GAP_MAX {
            let g = gap.as_nanos() as u64;
            self.answer_ns = if self.answer_ns == 0 {
                g
            } else if g < self.answer_ns {
                self.answer_ns - (self.answer_ns - g) / 4
            } else {
                self.answer_ns + (g - self.answer_ns) / 16
            };
        }
    }

    /// Wait until `t`: sleep in the kernel until shortly before (waking
    /// early when `fd` becomes readable), then spin. Returns whether `fd`
    /// became readable before `t`.
    fn pause(&mut self, clock: &Clock, fd: Option<BorrowedFd<'_>>, t: Instant) -> bool {
        let now = clock.now();
        let left = t.saturating_duration_since(now);
        let wake = self.wake();
        if left > wake + MIN_SLEEP {
            let want = now + (left - wake);
            if ppoll(fd, left - wake) {
                return true;
            }
            self.learn_wake(clock.now().saturating_duration_since(want));
        }
        match fd {
            None => {
                spin_until(clock, t);
                false
            }
            Some(fd) => loop {
                if clock.now() >= t {
                    return false;
                }
                if ppoll(Some(fd), Duration::ZERO) {
                    return true;
                }
                std::hint::spin_loop();
            },
        }
    }

    /// Before sleeping in the runtime: when the next telegram is expected
    /// soon, sleep in the kernel until shortly before it, then poll `fd`
    /// until it is readable, at most `window` past the expected time (and
    /// not past `deadline`). Returns whether `fd` is readable.
    fn anticipate(
        &mut self,
        clock: &Clock,
        fd: BorrowedFd<'_>,
        window: Duration,
        deadline: Option<Instant>,
    ) -> bool {
        let Some(sent) = self.sent else {
            return false;
        };
        if self.answer_ns == 0 {
            return false;
        }
        let expected = sent + Duration::from_nanos(self.answer_ns);
        let mut end = expected + window;
        if let Some(d) = deadline {
            end = end.min(d);
        }
        let now = clock.now();
        if now >= end {
            return false;
        }
        let wake = self.wake();
        let start = Instant::from_nanos(expected.as_nanos().saturating_sub(wake.as_nanos() as u64));
        if start > now + MIN_SLEEP {
            let nap = start.saturating_duration_since(now);
            if ppoll(Some(fd), nap) {
                return true;
            }
            self.learn_wake(clock.now().saturating_duration_since(start));
        }
        loop {
            if ppoll(Some(fd), Duration::ZERO) {
                return true;
            }
            if clock.now() >= end {
                return false;
            }
            std::hint::spin_loop();
        }
    }

    fn learn_wake(&mut self, late: Duration) {
        let late = late.clamp(WAKE_MIN, WAKE_MAX).as_nanos() as u64;
        self.wake_ns = self.wake_ns - self.wake_ns / 8 + late / 8;
    }
}

/// Sleep in the kernel for `d` or until `fd` is readable; whether it is.
/// Zero `d`: only look.
fn ppoll(fd: Option<BorrowedFd<'_>>, d: Duration) -> bool {
    use nix::poll::{PollFd, PollFlags};
    use nix::sys::time::TimeSpec;
    let timeout = TimeSpec::from_duration(d);
    match fd {
        Some(fd) => {
            let mut fds = [PollFd::new(fd, PollFlags::POLLIN)];
            let n = nix::poll::ppoll(&mut fds, Some(timeout), None).unwrap_or(0);
            n > 0
        }
        None => {
            let _ = nix::poll::ppoll(&mut [], Some(timeout), None);
            false
        }
    }
}

/// Wait until `t` right after a write whose bytes a kernel worker hands
/// on ([`Waitable::writes_need_cpu`]): sleep in the kernel for the whole
/// wait (at least [`RELEASE`]), so that this CPU stays free for that
/// worker and for the other stations' workers (a thread spinning at
/// real-time priority keeps every ordinary thread off its CPU). The wait
/// may end a wake-up latency after `t`: the idle time on the line only
/// grows. Returns at once, `true`, when `fd` becomes readable first.
fn sleep_after_write(clock: &Clock, fd: Option<BorrowedFd<'_>>, t: Instant) -> bool {
    let nap = t.saturating_duration_since(clock.now()).max(RELEASE);
    if ppoll(fd, nap) {
        return true;
    }
    spin_until(clock, t);
    false
}

/// Let this thread's timers (the precise waits) fire within 1 µs of
/// their time instead of the default 50 µs.
pub(crate) fn set_timer_slack() {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: PR_SET_TIMERSLACK takes an unsigned long by value and
        // touches no memory.
        let r = unsafe { nix::libc::prctl(nix::libc::PR_SET_TIMERSLACK, 1 as nix::libc::c_ulong) };
        if r != 0 {
            tracing::debug!("cannot reduce the timer slack");
        }
    }
}

/// Stage times for profiling (feature `stage-times`, off by default): the
/// monotonic time of each read, write and wait of the driver, kept in
/// memory and written to `$FDL_STAGE_TIMES.<pid>` when the driver stops.
#[cfg(feature = "stage-times")]
mod stage {
    use std::sync::Mutex;

    static TIMES: Mutex<Vec<(u64, u8, u16)>> = Mutex::new(Vec::new());

    fn now_ns() -> u64 {
        let mut t = nix::libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: clock_gettime writes into the struct it is given.
        unsafe { nix::libc::clock_gettime(nix::libc::CLOCK_MONOTONIC, &mut t) };
        t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64
    }

    /// Note a stage: `kind` (b'r' read, b'w' write, b's' about to wait)
    /// and its byte count.
    pub fn mark(kind: u8, n: usize) {
        let t = now_ns();
        let mut v = TIMES.lock().expect("stage times");
        if v.capacity() == 0 {
            v.reserve(1 << 22);
        }
        if v.len() < v.capacity() {
            v.push((t, kind, n as u16));
        }
    }

    /// Write the times kept so far (and forget them).
    pub fn dump() {
        use std::io::Write;
        let Ok(base) = std::env::var("FDL_STAGE_TIMES") else {
            return;
        };
        let v = std::mem::take(&mut *TIMES.lock().expect("stage times"));
        let path = format!("{base}.{}", std::process::id());
        if let Ok(f) = std::fs::File::create(path) {
            let mut f = std::io::BufWriter::new(f);
            for (t, k, n) in v {
                let _ = writeln!(f, "{t} {} {n}", k as char);
            }
        }
    }
}

#[cfg(not(feature = "stage-times"))]
mod stage {
    #[inline(always)]
    pub fn mark(_: u8, _: usize) {}
    #[inline(always)]
    pub fn dump() {}
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
    use profibus_fdl::station::echo::Echo;
    use profibus_fdl::station::passive::PassiveStation;
    use profibus_fdl::timing::{Baud, BusParams};

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
