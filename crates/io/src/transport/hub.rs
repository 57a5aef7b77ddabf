//! A virtual RS-485 multidrop bus made of ptys (the library behind
//! `dpctl bus`).
//!
//! Each station gets a pty; the links given to [`Hub::open`] become
//! symlinks to the pty ends the station processes open (like any serial
//! port). The hub keeps the other ends and runs them through a
//! [`Medium`] driven by real time (nanoseconds since the hub started):
//! every byte a station writes reaches every other station, in order, and
//! not the writer; with a baud rate the line is paced at wire speed;
//! faults are injected as configured.
//!
//! # Line timing as receivers see it
//!
//! A paced hub delivers each transmission (one station's bytes while it
//! holds the line) in one write when its last character has crossed the
//! wire ([`Medium::with_whole_transmissions`]): the characters of one
//! telegram never arrive with an idle gap inside, even when the hub or a
//! receiver is scheduled late, and the idle time between telegrams is the
//! one on the modelled wire (a transmission starts on the wire when the
//! hub reads it) plus the hub's wake-up latency: never shortened, delayed
//! by at most one telegram's duration. Receivers that frame by idle time,
//! as slave ASICs do, see the telegrams as they would on RS-485. A master
//! sees the first character of a reply only when the whole reply has
//! arrived; on ptys ([`super::Port::whole_telegrams`]) a master's wait for
//! each answer allows for the wire time of the longest answer that
//! request can get.
//! Unpaced, bytes pass as fast as they come, in the chunks they were read
//! in: the gaps are the ones the writers left, plus scheduling jitter.
//!
//! # Stations come and go
//!
//! A pty whose end is not open (or was closed by a restarting process)
//! reads EIO and polls HUP. The hub then stops delivering to it, throws
//! away what it had queued, checks every few milliseconds whether a
//! process opened it again, and carries on.
//!
//! # Readers that fall behind
//!
//! A pty takes only about 12 KiB (Linux 6.x; 11 ms of a 12 Mbit/s line).
//! What a station's pty does not take is kept for it in a backlog, like
//! the receive buffer of a serial adapter's driver, and handed on as the
//! station reads; the hub never waits for a station, so a slow or
//! stopped reader delays neither the line nor the other stations. The
//! backlog holds [`BACKLOG_TIME`] of the line (one second: longer than a
//! busy machine stops a process that keeps up on average), at least
//! [`BACKLOG_MIN`]; [`UNPACED_BACKLOG`] on an unpaced line, which has no
//! rate. Only a station that falls further behind than that loses
//! bytes: the newest ones, as a full receive FIFO does, counted as
//! overruns (a warning names the station once per episode). Long
//! transmissions reach the backlog in pieces
//! ([`profibus_fdl::line::medium::WHOLE_MAX`]), so
//! a station that sends without a pause is handed on at the line's rate,
//! not in one burst at its end. A station cannot write faster than the
//! paced line either: the hub reads no more from one that is
//! [`WRITE_AHEAD`] ahead of the wire, so its pty fills and its writes
//! wait, as with a serial port's full transmit buffer.
//!
//! # Driving it
//!
//! [`Hub::poll`] runs one round of a plain `ppoll` loop over the pty
//! masters (no runtime, no per-byte allocation; writes go straight to the
//! fds, and without pacing nothing sleeps between a read and the writes it
//! causes). A caller passes its own file descriptor to wake on (a signalfd,
//! an eventfd) and calls it in a loop; [`Hub::finish`] flushes the pcap
//! recording and removes the links (dropping the hub removes them too).

use nix::errno::Errno;
use nix::poll::{PollFd, PollFlags};
use nix::sys::termios::{self, SetArg};
use nix::sys::time::TimeSpec;
use profibus_fdl::capture::pcap::PcapWriter;
use profibus_fdl::codec::CodecStats;
use profibus_fdl::line::medium::{Medium, MediumConfig, MediumStats};
use profibus_fdl::line::tap::{Tap, TapEvent};
use profibus_fdl::time::Instant;
use profibus_fdl::timing::Baud;
use profibus_fdl::wire::consts::BITS_PER_CHAR;
use std::collections::VecDeque;
use std::fmt;
use std::io::{self, Write};
use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// How long the line must be quiet before the pcap framer gives up an
/// incomplete telegram.
const IDLE_GAP: Duration = Duration::from_millis(5);
/// How often ptys without a process are checked for a new one.
const RECONNECT_CHECK: Duration = Duration::from_millis(5);
/// How far behind the paced line a station's reading may fall before it
/// loses bytes (see the module docs).
pub const BACKLOG_TIME: Duration = Duration::from_secs(1);
/// The smallest backlog of a station on a paced line (at low rates one
/// second of line is less than a pty holds).
pub const BACKLOG_MIN: usize = 64 << 10;
/// A station's backlog on an unpaced line.
pub const UNPACED_BACKLOG: usize = 1 << 20;
/// How far ahead of the paced line a station may write: the hub reads no
/// more from a station whose bytes already fill the line for this long,
/// so its pty fills and its writes wait, as on a serial port whose
/// transmit buffer is full (a station cannot send faster than the line,
/// and the hub's memory stays bounded). Long enough that a hub woken late
/// still reads the rest before the line runs dry.
pub const WRITE_AHEAD: Duration = Duration::from_millis(100);

/// The backlog bound in bytes for a line at `baud` (`None`: unpaced),
/// covering `time` of it.
fn backlog_bound(baud: Option<Baud>, time: Duration) -> usize {
    match baud {
        None => UNPACED_BACKLOG,
        Some(b) => {
            let chars =
                time.as_nanos() * u128::from(b.bps()) / (BITS_PER_CHAR as u128 * 1_000_000_000);
            usize::try_from(chars)
                .unwrap_or(usize::MAX)
                .max(BACKLOG_MIN)
        }
    }
}

/// Why a hub could not be set up or run.
#[derive(Debug, thiserror::Error)]
pub enum HubError {
    /// A link path exists and is not a symlink (the hub never replaces
    /// other files).
    #[error("{} exists and is not a symlink; refusing to replace it", .0.display())]
    NotASymlink(PathBuf),
    /// A link could not be checked, created or replaced.
    #[error("cannot create link {}: {error}", .path.display())]
    Link {
        /// The link.
        path: PathBuf,
        /// The cause (in the message; not also `source()`, so that a
        /// printed error chain names it once).
        error: io::Error,
    },
    /// A pty could not be made or configured.
    #[error("cannot set up a pty: {0}")]
    Pty(io::Error),
    /// Waiting for the ptys failed.
    #[error("ppoll: {0}")]
    Poll(io::Error),
    /// Writing the pcap recording failed.
    #[error("writing the pcap recording: {0}")]
    Pcap(io::Error),
}

/// Counters of the hub itself (the line's are [`MediumStats`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HubStats {
    /// Bytes handed to stations (counted once per receiving station).
    pub delivered_bytes: u64,
    /// Bytes lost because a station fell further behind than its backlog
    /// holds (see the module docs).
    pub overrun_bytes: u64,
    /// Times a process opened a station's pty.
    pub connects: u64,
}

/// A snapshot of a hub's counters; `Display` gives the one-line summary
/// `dpctl bus` prints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HubStatus {
    /// What the line carried and injected.
    pub medium: MediumStats,
    /// The hub's own counters.
    pub hub: HubStats,
    /// Stations whose pty a process has open.
    pub connected: usize,
    /// Stations on the bus.
    pub stations: usize,
    /// With a pcap recording: packets written (telegrams and flagged
    /// corrupt stretches), the corrupt ones among them, and the framer's
    /// counters.
    pub pcap: Option<(u64, u64, CodecStats)>,
}

impl fmt::Display for HubStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}; delivered {} bytes, overruns {} bytes, {}/{} stations connected ({} connects)",
            self.medium,
            self.hub.delivered_bytes,
            self.hub.overrun_bytes,
            self.connected,
            self.stations,
            self.hub.connects
        )?;
        if let Some((packets, corrupt, c)) = self.pcap {
            write!(
                f,
                "; pcap {packets} packets, {corrupt} corrupt (codec: {} garbage bytes, {} bad FCS, {} other errors)",
                c.garbage_bytes,
                c.bad_fcs,
                c.errors() - c.bad_fcs
            )?;
        }
        Ok(())
    }
}

struct Station {
    master: OwnedFd,
    link: PathBuf,
    /// Where the link points (the pty end for the station process).
    tty: PathBuf,
    /// A process has the pty open.
    connected: bool,
    /// Bytes the pty did not take yet.
    backlog: Backlog,
}

type Recorder = PcapWriter<Box<dyn Write + Send>>;

/// The virtual bus; see the module docs.
pub struct Hub {
    stations: Vec<Station>,
    medium: Medium,
    clock: std::time::Instant,
    stats: HubStats,
    tap: Tap,
    pcap: Option<Recorder>,
    /// Corrupt stretches written to the recording.
    corrupt_packets: u64,
    next_reconnect: Instant,
    last_delivery: Instant,
    buf: Box<[u8; 4096]>,
    slack_set: bool,
    check_rates: bool,
}

impl fmt::Debug for Hub {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Hub")
            .field("stations", &self.stations.len())
            .field("medium", self.medium.config())
            .finish_non_exhaustive()
    }
}

impl Hub {
    /// Make one pty per link, raw, and point each link at its pty end.
    /// An existing symlink is replaced; any other file is an error
    /// ([`HubError::NotASymlink`], checked for every link before anything
    /// is created). The line behaves as `medium` says.
    pub fn open(links: &[PathBuf], medium: MediumConfig) -> Result<Hub, HubError> {
        for l in links {
            match std::fs::symlink_metadata(l) {
                Ok(m) if m.file_type().is_symlink() => {}
                Ok(_) => return Err(HubError::NotASymlink(l.clone())),
                Err(e) if e.kind() == io::ErrorKind::NotFound => {}
                Err(error) => {
                    return Err(HubError::Link {
                        path: l.clone(),
                        error,
                    })
                }
            }
        }
        let mut stations: Vec<Station> = Vec::with_capacity(links.len());
        for link in links {
            let pty = nix::pty::openpty(None, None).map_err(pty_err)?;
            // Raw mode on the station's end: no echo, no line editing, no
            // CR/LF translation; it stays while the hub holds the master.
            let mut t = termios::tcgetattr(&pty.slave).map_err(pty_err)?;
            termios::cfmakeraw(&mut t);
            termios::tcsetattr(&pty.slave, SetArg::TCSANOW, &t).map_err(pty_err)?;
            let tty = nix::unistd::ttyname(&pty.slave).map_err(pty_err)?;
            set_nonblocking(&pty.master).map_err(pty_err)?;
            drop(pty.slave);
            let st = Station {
                master: pty.master,
                link: link.clone(),
                tty,
                connected: false,
                backlog: Backlog::new(backlog_bound(medium.baud, BACKLOG_TIME)),
            };
            // Pushed first, so that a failure removes the links made so far.
            stations.push(st);
            let st = stations.last().expect("pushed");
            if let Err(error) = replace_symlink(&st.tty, link) {
                stations.pop();
                remove_links(&stations);
                return Err(HubError::Link {
                    path: link.clone(),
                    error,
                });
            }
        }
        Ok(Hub {
            medium: Medium::new(stations.len(), medium).with_whole_transmissions(),
            stations,
            clock: std::time::Instant::now(),
            stats: HubStats::default(),
            tap: Tap::new(),
            pcap: None,
            corrupt_packets: 0,
            next_reconnect: Instant::ZERO,
            last_delivery: Instant::ZERO,
            buf: Box::new([0; 4096]),
            slack_set: false,
            check_rates: false,
        })
    }

    /// Record every telegram on the line to `sink` (pcapng, link type 257,
    /// time stamps from the hub's start at `epoch` since the Unix epoch).
    /// Bytes that form no valid telegram (corrupted by `--flip`/`--noise`
    /// or by two stations at once) are recorded too, flagged
    /// ([`PcapWriter::write_corrupt`]).
    pub fn record(&mut self, sink: Box<dyn Write + Send>, epoch: Duration) -> Result<(), HubError> {
        self.pcap = Some(PcapWriter::new(sink, epoch).map_err(HubError::Pcap)?);
        Ok(())
    }

    /// Let each station fall `line_time` behind the paced line before it
    /// loses bytes (default [`BACKLOG_TIME`]; at least [`BACKLOG_MIN`]
    /// bytes; no effect unpaced).
    pub fn set_backlog(&mut self, line_time: Duration) {
        let bound = backlog_bound(self.medium.config().baud, line_time);
        for s in &mut self.stations {
            s.backlog.bound = bound;
        }
    }

    /// The bytes each station's backlog holds at most.
    pub fn backlog_bytes(&self) -> usize {
        self.stations.first().map_or(0, |s| s.backlog.bound)
    }

    /// The stations' links and the pty ends they point to, by index.
    pub fn links(&self) -> impl Iterator<Item = (&Path, &Path)> {
        self.stations
            .iter()
            .map(|s| (s.link.as_path(), s.tty.as_path()))
    }

    /// The line's configuration.
    pub fn medium_config(&self) -> &MediumConfig {
        self.medium.config()
    }

    /// The counters now.
    pub fn status(&self) -> HubStatus {
        HubStatus {
            medium: self.medium.stats(),
            hub: self.stats,
            connected: self.stations.iter().filter(|s| s.connected).count(),
            stations: self.stations.len(),
            pcap: self
                .pcap
                .as_ref()
                .map(|p| (p.packets(), self.corrupt_packets, self.tap.stats())),
        }
    }

    /// The hub's time now.
    fn now(&self) -> Instant {
        Instant::from_nanos(self.clock.elapsed().as_nanos() as u64)
    }

    /// One round: check for reconnected stations, deliver what is due,
    /// then wait (at most `max_wait`, or until the next delivery) for
    /// station writes or for `wake` to become readable, and carry the
    /// bytes read. Returns whether `wake` is readable (the caller reads
    /// it). Call it in a loop.
    pub fn poll(
        &mut self,
        wake: Option<BorrowedFd<'_>>,
        max_wait: Option<Duration>,
    ) -> Result<bool, HubError> {
        if !self.slack_set && self.medium.config().baud.is_some() {
            // Wake-ups on time matter when pacing; the default slack of
            // this thread is 50 µs.
            self.slack_set = true;
            crate::driver::set_timer_slack();
        }
        let now = self.now();
        // Ptys without a process: has one opened them (HUP gone)?
        if now >= self.next_reconnect {
            for s in self.stations.iter_mut().filter(|s| !s.connected) {
                if !hung_up(&s.master) {
                    // Drop anything written to the pty while nobody had
                    // it open, so the new process starts on a clean line.
                    let _ = termios::tcflush(&s.master, termios::FlushArg::TCOFLUSH);
                    s.connected = true;
                    self.stats.connects += 1;
                    tracing::debug!(link = %s.link.display(), "station connected");
                }
            }
            self.next_reconnect = now + RECONNECT_CHECK;
        }
        self.deliver_due(now)?;
        if self.tap.pending() > 0 && now >= self.idle_at() {
            self.tap.line_idle();
            self.drain_tap()?;
            if let Some(p) = self.pcap.as_mut() {
                p.flush().map_err(HubError::Pcap)?;
            }
        }

        // Sleep until something happens or is due.
        let mut deadline = self.medium.poll_timeout();
        let mut consider = |t: Instant| deadline = Some(deadline.map_or(t, |d| d.min(t)));
        if self.stations.iter().any(|s| !s.connected) {
            consider(self.next_reconnect);
        }
        if let Some(w) = max_wait {
            consider(now + w);
        }
        if self.tap.pending() > 0 {
            consider(self.idle_at());
        }
        // Stations far ahead of the line: read them again when it has
        // carried enough.
        let ahead: Vec<bool> = (0..self.stations.len())
            .map(|i| match self.medium.sending_until(i) {
                Some(end) if end > now + WRITE_AHEAD => {
                    consider(Instant::from_nanos(
                        end.as_nanos() - WRITE_AHEAD.as_nanos() as u64,
                    ));
                    true
                }
                _ => false,
            })
            .collect();
        let timeout =
            deadline.map(|d| TimeSpec::from_duration(d.saturating_duration_since(self.now())));

        let mut fds = Vec::with_capacity(self.stations.len() + 1);
        let mut index = Vec::with_capacity(self.stations.len());
        if let Some(w) = wake {
            fds.push(PollFd::new(w, PollFlags::POLLIN));
        }
        let first = fds.len();
        for (i, s) in self
            .stations
            .iter()
            .enumerate()
            .filter(|(_, s)| s.connected)
        {
            let mut ev = if ahead[i] {
                PollFlags::empty()
            } else {
                PollFlags::POLLIN
            };
            if !s.backlog.is_empty() {
                ev |= PollFlags::POLLOUT;
            }
            fds.push(PollFd::new(s.master.as_fd(), ev));
            index.push(i);
        }
        match nix::poll::ppoll(&mut fds, timeout, None) {
            Ok(_) | Err(Errno::EINTR) => {}
            Err(e) => return Err(HubError::Poll(e.into())),
        }
        let revents: Vec<PollFlags> = fds
            .iter()
            .map(|f| f.revents().unwrap_or(PollFlags::empty()))
            .collect();
        drop(fds);
        let woken = wake.is_some() && revents[0].contains(PollFlags::POLLIN);

        for (k, &i) in index.iter().enumerate() {
            let ev = revents[first + k];
            if ev.contains(PollFlags::POLLOUT) {
                flush_backlog(&mut self.stations[i]);
            }
            if ev.intersects(PollFlags::POLLIN | PollFlags::POLLHUP | PollFlags::POLLERR) {
                self.read_station(i)?;
            }
        }
        Ok(woken)
    }

    /// Read everything station `i` wrote; the medium gets each chunk as it
    /// came.
    /// Check each station's rate on a paced line, as a UART does: a
    /// station whose port is set to another rate than the line's
    /// ([`MediumConfig::baud`]) receives every character as garbage
    /// (0xFF, never a start delimiter), and what it sends reaches the
    /// others as garbage. Off by default (on a pty the rate otherwise
    /// only sets the bus timing); `dpctl bus --check-rates`.
    pub fn check_rates(&mut self, on: bool) {
        self.check_rates = on;
    }

    /// Whether station `i` runs at another rate than the paced line.
    fn off_rate(&self, i: usize) -> bool {
        match (self.check_rates, self.medium.config().baud) {
            (true, Some(line)) => pty_rate(&self.stations[i].master)
                .is_some_and(|bps| bps.abs_diff(line.bps()) * 50 > line.bps()),
            _ => false,
        }
    }

    fn read_station(&mut self, i: usize) -> Result<(), HubError> {
        loop {
            match nix::unistd::read(&self.stations[i].master, &mut self.buf[..]) {
                Ok(0) => return Ok(()),
                Ok(len) => {
                    let now = self.now();
                    if self.off_rate(i) {
                        self.buf[..len].fill(0xFF);
                    }
                    self.medium.transmit(now, i, &self.buf[..len]);
                    // Unpaced: hand it on at once.
                    self.deliver_due(now)?;
                    // A pty read returns all there is (up to the buffer
                    // size): skip the read that would say EAGAIN.
                    if len < self.buf.len() {
                        return Ok(());
                    }
                }
                Err(Errno::EAGAIN) | Err(Errno::EINTR) => return Ok(()),
                Err(Errno::EIO) => {
                    disconnect(&mut self.stations[i]);
                    return Ok(());
                }
                Err(e) => {
                    tracing::warn!(link = %self.stations[i].link.display(), error = %e, "read failed");
                    disconnect(&mut self.stations[i]);
                    return Ok(());
                }
            }
        }
    }

    fn deliver_due(&mut self, now: Instant) -> Result<(), HubError> {
        while let Some(d) = self.medium.poll_delivery(now) {
            self.last_delivery = d.at;
            let off: Vec<bool> = (0..self.stations.len()).map(|j| self.off_rate(j)).collect();
            let garbage = vec![0xFF; d.bytes.len()];
            for (j, s) in self.stations.iter_mut().enumerate() {
                if d.reaches(j) && s.connected {
                    let bytes: &[u8] = if off[j] { &garbage } else { &d.bytes };
                    deliver(s, bytes, &mut self.stats);
                }
            }
            if self.pcap.is_some() {
                self.tap.push(d.at, &d.bytes);
                self.drain_tap()?;
            }
        }
        Ok(())
    }

    /// When the pcap framer may take the line as idle.
    fn idle_at(&self) -> Instant {
        self.last_delivery.max(self.medium.busy_until()) + IDLE_GAP
    }

    fn drain_tap(&mut self) -> Result<(), HubError> {
        while let Some(ev) = self.tap.poll() {
            let Some(p) = self.pcap.as_mut() else {
                continue;
            };
            match ev {
                TapEvent::Telegram { at, bytes } => p.write_telegram(at, &bytes),
                // Corrupted telegrams (a flipped bit, noise, two stations
                // at once) stay in the recording, flagged.
                TapEvent::Skipped { at, bytes, .. } => {
                    self.corrupt_packets += 1;
                    p.write_corrupt(at, &bytes)
                }
            }
            .map_err(HubError::Pcap)?;
        }
        Ok(())
    }

    /// Stop: frame what is left for the recording, flush it, remove the
    /// links; the final counters.
    pub fn finish(mut self) -> Result<HubStatus, HubError> {
        if self.pcap.is_some() {
            self.tap.line_idle();
            self.drain_tap()?;
        }
        let status = self.status();
        if let Some(p) = self.pcap.take() {
            p.into_inner()
                .and_then(|mut w| w.flush())
                .map_err(HubError::Pcap)?;
        }
        Ok(status)
    }
}

impl Drop for Hub {
    /// Removes the links (only those still pointing to our ptys).
    fn drop(&mut self) {
        remove_links(&self.stations);
    }
}

fn remove_links(stations: &[Station]) {
    for s in stations {
        if std::fs::read_link(&s.link).is_ok_and(|t| t == s.tty) {
            let _ = std::fs::remove_file(&s.link);
        }
    }
}

/// The rate a pty's station set on its end (the master end shares the
/// termios; `termios2` carries any rate), if it can be read.
#[cfg(target_os = "linux")]
fn pty_rate(master: &OwnedFd) -> Option<u32> {
    use std::os::fd::AsRawFd;
    // SAFETY: TCGETS2 fills a `termios2` the pointer points to and reads
    // nothing else; the fd is open for the call.
    let mut t: nix::libc::termios2 = unsafe { std::mem::zeroed() };
    let r = unsafe { nix::libc::ioctl(master.as_raw_fd(), nix::libc::TCGETS2, &mut t) };
    (r == 0).then_some(t.c_ospeed)
}

#[cfg(not(target_os = "linux"))]
fn pty_rate(_master: &OwnedFd) -> Option<u32> {
    None
}

fn pty_err(e: Errno) -> HubError {
    HubError::Pty(e.into())
}

fn set_nonblocking(fd: &OwnedFd) -> Result<(), Errno> {
    use nix::fcntl::{fcntl, FcntlArg, OFlag};
    let flags = OFlag::from_bits_truncate(fcntl(fd, FcntlArg::F_GETFL)?);
    fcntl(fd, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK))?;
    Ok(())
}

/// Point `link` at `target`, replacing a stale symlink atomically.
fn replace_symlink(target: &Path, link: &Path) -> io::Result<()> {
    let tmp = PathBuf::from(format!("{}.dpctl-{}", link.display(), std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(target, &tmp)?;
    std::fs::rename(&tmp, link).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}

/// Whether nobody has the pty's other end open.
fn hung_up(master: &OwnedFd) -> bool {
    let mut fds = [PollFd::new(master.as_fd(), PollFlags::empty())];
    match nix::poll::poll(&mut fds, nix::poll::PollTimeout::ZERO) {
        Ok(_) => fds[0]
            .revents()
            .is_some_and(|r| r.contains(PollFlags::POLLHUP)),
        Err(_) => true,
    }
}

fn disconnect(s: &mut Station) {
    if s.connected {
        tracing::debug!(link = %s.link.display(), "station disconnected");
    }
    s.connected = false;
    s.backlog.clear();
    let _ = termios::tcflush(&s.master, termios::FlushArg::TCOFLUSH);
}

/// Write `bytes` to a station's pty, keeping what it does not take.
fn deliver(s: &mut Station, bytes: &[u8], stats: &mut HubStats) {
    stats.delivered_bytes += bytes.len() as u64;
    let master = &s.master;
    match s.backlog.put(&mut |b| nix::unistd::write(master, b), bytes) {
        Ok(0) => {}
        Ok(lost) => {
            // Warned once until the backlog is empty again.
            if !std::mem::replace(&mut s.backlog.warned, true) {
                tracing::warn!(
                    link = %s.link.display(),
                    backlog = s.backlog.bound,
                    "station fell behind the line by more than its backlog: losing bytes"
                );
            }
            stats.overrun_bytes += lost;
        }
        Err(_) => disconnect(s),
    }
}

fn flush_backlog(s: &mut Station) {
    let master = &s.master;
    if s.backlog
        .flush(&mut |b| nix::unistd::write(master, b))
        .is_err()
    {
        disconnect(s);
    }
}

/// A station's receive backlog: the bytes its pty has not taken yet, in
/// order, at most `bound` of them. Sans-IO: the pty is a write function
/// that takes a prefix of what it is given (a short write), or fails with
/// `EAGAIN` when full.
#[derive(Debug)]
struct Backlog {
    queued: VecDeque<u8>,
    bound: usize,
    /// A loss was warned about since the backlog was last empty.
    warned: bool,
}

impl Backlog {
    fn new(bound: usize) -> Backlog {
        Backlog {
            queued: VecDeque::new(),
            bound,
            warned: false,
        }
    }

    fn is_empty(&self) -> bool {
        self.queued.is_empty()
    }

    fn clear(&mut self) {
        self.queued.clear();
        self.warned = false;
    }

    /// Hand `bytes` on after what is queued: write what the pty takes,
    /// keep the rest up to the bound; the bytes that did not fit (the
    /// newest). An error other than `EAGAIN`/`EINTR` is the writer's (the
    /// station is gone).
    fn put(
        &mut self,
        write: &mut dyn FnMut(&[u8]) -> Result<usize, Errno>,
        bytes: &[u8],
    ) -> Result<u64, Errno> {
        self.flush(write)?;
        let mut rest = bytes;
        if self.queued.is_empty() {
            while !rest.is_empty() {
                match write(rest) {
                    Ok(0) | Err(Errno::EAGAIN) => break,
                    Ok(k) => rest = &rest[k..],
                    Err(Errno::EINTR) => {}
                    Err(e) => return Err(e),
                }
            }
        }
        let room = self.bound.saturating_sub(self.queued.len());
        let take = rest.len().min(room);
        self.queued.extend(&rest[..take]);
        if self.queued.is_empty() {
            self.warned = false;
        }
        Ok((rest.len() - take) as u64)
    }

    /// Write as much of the queue as the pty takes.
    fn flush(&mut self, write: &mut dyn FnMut(&[u8]) -> Result<usize, Errno>) -> Result<(), Errno> {
        while !self.queued.is_empty() {
            let (front, _) = self.queued.as_slices();
            match write(front) {
                Ok(0) | Err(Errno::EAGAIN) => return Ok(()),
                Ok(k) => {
                    self.queued.drain(..k);
                }
                Err(Errno::EINTR) => {}
                Err(e) => return Err(e),
            }
        }
        self.warned = false;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_fdl::timing::Baud;
    use std::io::Read;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;

    /// A hub in a thread of this process, polled until dropped.
    struct Running {
        stop: Arc<AtomicBool>,
        /// The counters after the latest round.
        status: Arc<std::sync::Mutex<Option<HubStatus>>>,
        thread: Option<std::thread::JoinHandle<HubStatus>>,
        links: Vec<PathBuf>,
    }

    impl Running {
        /// A hub of two stations with their links in `dir`.
        fn start(dir: &Path, medium: MediumConfig) -> Running {
            Running::with(dir, medium, 2, |_| {})
        }

        /// A hub of `n` stations, set up by `setup`.
        fn with(
            dir: &Path,
            medium: MediumConfig,
            n: usize,
            setup: impl FnOnce(&mut Hub),
        ) -> Running {
            let links: Vec<PathBuf> = (0..n).map(|i| dir.join(format!("hub-{i}"))).collect();
            let mut hub = Hub::open(&links, medium).unwrap();
            setup(&mut hub);
            let stop = Arc::new(AtomicBool::new(false));
            let status = Arc::new(std::sync::Mutex::new(None));
            let (s, st) = (stop.clone(), status.clone());
            let thread = std::thread::spawn(move || {
                while !s.load(Ordering::Relaxed) {
                    hub.poll(None, Some(Duration::from_millis(2))).unwrap();
                    *st.lock().unwrap() = Some(hub.status());
                }
                hub.finish().unwrap()
            });
            Running {
                stop,
                status,
                thread: Some(thread),
                links,
            }
        }

        fn open(&self, i: usize) -> std::fs::File {
            std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(&self.links[i])
                .unwrap()
        }

        /// Wait until the counters satisfy `f`.
        fn wait_status(&self, what: &str, f: impl Fn(&HubStatus) -> bool) -> HubStatus {
            let t0 = std::time::Instant::now();
            loop {
                if let Some(s) = *self.status.lock().unwrap() {
                    if f(&s) {
                        return s;
                    }
                    assert!(t0.elapsed() < Duration::from_secs(30), "{what}: {s}");
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        }

        fn stop(mut self) -> HubStatus {
            self.stop.store(true, Ordering::Relaxed);
            self.thread.take().unwrap().join().unwrap()
        }
    }

    impl Drop for Running {
        fn drop(&mut self) {
            self.stop.store(true, Ordering::Relaxed);
            if let Some(t) = self.thread.take() {
                let _ = t.join();
            }
        }
    }

    /// Write `data` on `a` until `b` reads something (the hub notices new
    /// openers every few milliseconds); what `b` read first.
    fn first_read(a: &mut std::fs::File, b: &mut std::fs::File, data: &[u8]) -> Vec<u8> {
        use nix::poll::{PollFd, PollFlags, PollTimeout};
        let mut buf = [0u8; 64];
        for _ in 0..500 {
            a.write_all(data).unwrap();
            let mut fds = [PollFd::new(b.as_fd(), PollFlags::POLLIN)];
            if nix::poll::poll(&mut fds, PollTimeout::from(200u16)).unwrap() > 0 {
                let n = b.read(&mut buf).unwrap();
                return buf[..n].to_vec();
            }
        }
        panic!("nothing arrived");
    }

    #[test]
    fn paced_hub_delivers_a_telegram_in_one_piece_in_process() {
        let dir = tempfile::tempdir().unwrap();
        let hub = Running::start(dir.path(), MediumConfig::paced(Baud::B19200));
        let (mut a, mut b) = (hub.open(0), hub.open(1));
        // An 11-byte telegram at 19.2 kbit/s: 6.3 ms on the wire. However
        // late this thread reads, it gets all 11 bytes in one read.
        let t = [
            0x68, 0x05, 0x05, 0x68, 0x88, 0x82, 0x6D, 0x3C, 0x3E, 0x87, 0x16,
        ];
        for _ in 0..5 {
            let got = first_read(&mut a, &mut b, &t);
            assert_eq!(got, t);
        }
        drop((a, b));
        let status = hub.stop();
        assert!(status.medium.transmissions >= 5, "{status}");
        assert_eq!(status.medium.collisions, 0, "{status}");
    }

    #[test]
    fn links_are_refused_over_other_files_and_removed_at_the_end() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("hub-file");
        std::fs::write(&file, b"precious").unwrap();
        let e = Hub::open(std::slice::from_ref(&file), MediumConfig::default()).unwrap_err();
        assert!(matches!(e, HubError::NotASymlink(_)), "{e}");
        assert_eq!(std::fs::read(&file).unwrap(), b"precious");

        let hub = Running::start(dir.path(), MediumConfig::default());
        let links = hub.links.clone();
        assert!(links.iter().all(|l| std::fs::read_link(l).is_ok()));
        hub.stop();
        assert!(links.iter().all(|l| std::fs::symlink_metadata(l).is_err()));
    }

    /// A fake pty: takes at most `room` bytes (what its reader has not
    /// read yet counts against it), at most `per_write` at a time, and
    /// fails every `eintr_every`th call with EINTR.
    struct FakePty {
        read: Vec<u8>,
        held: Vec<u8>,
        room: usize,
        per_write: usize,
        calls: usize,
        eintr_every: usize,
    }

    impl FakePty {
        fn new(room: usize, per_write: usize) -> FakePty {
            FakePty {
                read: vec![],
                held: vec![],
                room,
                per_write,
                calls: 0,
                eintr_every: 0,
            }
        }
        fn write(&mut self, b: &[u8]) -> Result<usize, Errno> {
            self.calls += 1;
            if self.eintr_every > 0 && self.calls.is_multiple_of(self.eintr_every) {
                return Err(Errno::EINTR);
            }
            let k = b.len().min(self.per_write).min(self.room - self.held.len());
            if k == 0 {
                return Err(Errno::EAGAIN);
            }
            self.held.extend_from_slice(&b[..k]);
            Ok(k)
        }
        /// The reader takes everything the pty holds.
        fn drain(&mut self) {
            self.read.append(&mut self.held);
        }
    }

    fn stream(n: usize) -> Vec<u8> {
        (0..n).map(|i| (i * 31 + i / 251) as u8).collect()
    }

    #[test]
    fn a_reader_that_falls_behind_within_the_backlog_and_catches_up_loses_nothing() {
        let data = stream(50_000);
        let mut pty = FakePty::new(1200, 700);
        pty.eintr_every = 5;
        let mut b = Backlog::new(20_000);
        let mut lost = 0;
        for (k, chunk) in data.chunks(333).enumerate() {
            lost += b.put(&mut |x| pty.write(x), chunk).unwrap();
            // The reader stops for the first 18 000 bytes (1 200 in its
            // pty, the rest in the backlog), then reads now and then.
            if k * 333 > 18_000 && k.is_multiple_of(2) {
                pty.drain();
                b.flush(&mut |x| pty.write(x)).unwrap();
            }
        }
        while !b.is_empty() {
            pty.drain();
            b.flush(&mut |x| pty.write(x)).unwrap();
        }
        pty.drain();
        assert_eq!(lost, 0);
        assert!(pty.read == data, "bytes changed or reordered");
    }

    #[test]
    fn a_reader_that_never_reads_loses_only_what_exceeds_its_backlog() {
        let data = stream(100_000);
        let mut stalled = FakePty::new(4096, usize::MAX);
        let mut fine = FakePty::new(4096, 1000);
        let (mut bs, mut bf) = (Backlog::new(10_000), Backlog::new(10_000));
        let (mut lost_s, mut lost_f) = (0, 0);
        for chunk in data.chunks(512) {
            // Every put returns at once, however full the stalled pty is.
            lost_s += bs.put(&mut |x| stalled.write(x), chunk).unwrap();
            lost_f += bf.put(&mut |x| fine.write(x), chunk).unwrap();
            fine.drain();
        }
        while !bf.is_empty() {
            fine.drain();
            bf.flush(&mut |x| fine.write(x)).unwrap();
        }
        fine.drain();
        assert_eq!((lost_f, &fine.read[..]), (0, &data[..]));
        // The stalled one kept the oldest bytes (its pty's 4 096 and the
        // backlog's 10 000) and lost the newest, counted.
        assert_eq!(lost_s, 100_000 - 4096 - 10_000);
        while !bs.is_empty() {
            stalled.drain();
            bs.flush(&mut |x| stalled.write(x)).unwrap();
        }
        stalled.drain();
        assert_eq!(stalled.read, &data[..14_096]);
        // A gone station's error ends the put.
        let e = bs.put(&mut |_| Err(Errno::EIO), &[1, 2, 3]).unwrap_err();
        assert_eq!(e, Errno::EIO);
    }

    #[test]
    fn the_backlog_covers_a_second_of_the_line_and_at_least_64_kib() {
        let second = Duration::from_secs(1);
        // 12 Mbit/s: 1 090 909 characters a second.
        assert_eq!(backlog_bound(Some(Baud::B12000000), second), 1_090_909);
        assert_eq!(backlog_bound(Some(Baud::B1500000), second), 136_363);
        assert_eq!(backlog_bound(Some(Baud::B19200), second), BACKLOG_MIN);
        assert_eq!(backlog_bound(None, second), UNPACED_BACKLOG);
    }

    /// A station cannot write faster than the paced line: the hub stops
    /// reading it once it is [`WRITE_AHEAD`] ahead, so its writes wait.
    /// Only a lower bound on the time is asserted (a loaded machine only
    /// makes it longer).
    #[test]
    fn a_station_writing_faster_than_the_line_waits_for_it() {
        let dir = tempfile::tempdir().unwrap();
        let b12 = Baud::B12000000;
        let hub = Running::start(dir.path(), MediumConfig::paced(b12));
        let mut a = hub.open(0);
        hub.wait_status("connected", |s| s.connected == 1);
        let data = stream(1_500_000);
        let t0 = std::time::Instant::now();
        a.write_all(&data).unwrap();
        let took = t0.elapsed();
        // All but what may be ahead (WRITE_AHEAD of line, the pty's
        // buffer, one read of the hub) crossed the wire first.
        let ahead = backlog_bound(Some(b12), WRITE_AHEAD) + (64 << 10);
        let least = b12.chars_to_duration((data.len() - ahead) as u64);
        assert!(
            took >= least,
            "wrote 1.5 MB in {took:?}, the line needs {least:?}"
        );
        hub.wait_status("carried", |s| s.medium.chars == data.len() as u64);
    }

    /// Real ptys at 12 Mbit/s: a station that never reads loses bytes
    /// once it is a backlog behind, and neither delays nor starves a
    /// station that reads. The writer waits for the reading station to
    /// have each chunk before it writes the next, so that station is never
    /// more than a chunk (16 KiB, far less than its backlog) behind,
    /// however loaded the machine.
    #[test]
    fn a_stalled_station_loses_its_overrun_and_the_others_get_everything() {
        let dir = tempfile::tempdir().unwrap();
        let hub = Running::with(dir.path(), MediumConfig::paced(Baud::B12000000), 3, |h| {
            h.set_backlog(Duration::ZERO);
            assert_eq!(h.backlog_bytes(), BACKLOG_MIN);
        });
        let (mut a, mut b, mut stalled) = (hub.open(0), hub.open(1), hub.open(2));
        hub.wait_status("connected", |s| s.connected == 3);
        let data = stream(512 << 10);
        let mut got = Vec::with_capacity(data.len());
        let mut buf = vec![0u8; 1 << 16];
        for chunk in data.chunks(16 << 10) {
            a.write_all(chunk).unwrap();
            let want = got.len() + chunk.len();
            while got.len() < want {
                let n = b.read(&mut buf).unwrap();
                got.extend_from_slice(&buf[..n]);
            }
        }
        assert!(got == data, "the reading station lost or reordered bytes");
        // Both stations had every delivery handed to them.
        let total = data.len() as u64;
        let s = hub.wait_status("delivered", |s| s.hub.delivered_bytes == 2 * total);
        let overrun = s.hub.overrun_bytes;
        assert!(overrun > 0 && overrun <= total - BACKLOG_MIN as u64, "{s}");
        // The stalled station still gets what it kept: the oldest bytes.
        let keep = (total - overrun) as usize;
        let mut kept = Vec::with_capacity(keep);
        while kept.len() < keep {
            let n = stalled.read(&mut buf).unwrap();
            kept.extend_from_slice(&buf[..n]);
        }
        assert!(kept == data[..keep], "the stalled station's bytes changed");
        drop((a, b, stalled));
        let end = hub.stop();
        assert_eq!(end.hub.overrun_bytes, overrun, "{end}");
    }
}
