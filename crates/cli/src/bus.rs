//! `dpctl bus`: a virtual RS-485 multidrop bus made of ptys.
//!
//! Each station gets a pty; `PREFIX0 … PREFIX{N-1}` are symlinks to the
//! pty ends the station processes open (like any serial port). The hub
//! keeps the other ends and runs them through a
//! [`profibus_fdl::medium::Medium`] driven by real time (nanoseconds
//! since the hub started): every byte a station writes reaches every other
//! station, in order, and not the writer; with `--baud` the line is paced
//! at wire speed; faults are injected as configured.
//!
//! Stations come and go: a pty whose end is not open (or was closed by a
//! restarting process) reads EIO and polls HUP. The hub then stops
//! delivering to it, throws away what it had queued, checks every few
//! milliseconds whether a process opened it again, and carries on. A
//! station that does not read for so long that its pty fills up loses
//! bytes (counted as overruns) instead of stalling the bus.
//!
//! The loop is a plain `ppoll` over the pty masters and a signalfd: no
//! runtime, no per-byte allocation, writes go straight to the fds, and
//! without pacing nothing sleeps between a read and the writes it causes.

use anyhow::{bail, Context, Result};
use nix::errno::Errno;
use nix::poll::{PollFd, PollFlags};
use nix::sys::signal::{SigSet, Signal};
use nix::sys::signalfd::{SfdFlags, SignalFd};
use nix::sys::termios::{self, SetArg};
use nix::sys::time::TimeSpec;
use profibus_fdl::medium::{Collisions, Medium, MediumConfig, MediumStats};
use profibus_fdl::pcap::PcapWriter;
use profibus_fdl::tap::{Tap, TapEvent};
use profibus_fdl::{Baud, Instant};
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Create a virtual RS-485 bus of N ptys linked as PREFIX0 … PREFIX{N-1}.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Number of stations (ptys) on the bus, 2 to 1024.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(2..=1024))]
    pub stations: u16,
    /// Link prefix: PREFIX0 … PREFIX{N-1} become symlinks to the pty ends
    /// the stations open (an existing symlink is replaced; any other file
    /// is an error).
    #[arg(long, value_name = "PREFIX")]
    pub link: String,
    /// Pace the line at this rate (9600 … 12M; 11 bit per character, one
    /// transmitter at a time). Without it bytes pass as fast as they come.
    #[arg(long, value_name = "B")]
    pub baud: Option<Baud>,
    /// Probability of losing each character (0 … 1).
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = probability)]
    pub drop: f64,
    /// Bit error rate: probability of flipping each data bit (0 … 1).
    #[arg(long, value_name = "BER", default_value_t = 0.0, value_parser = probability)]
    pub flip: f64,
    /// Bursts of random characters per second of idle line.
    #[arg(long, value_name = "RATE", default_value_t = 0.0, value_parser = rate)]
    pub noise: f64,
    /// Seed of the fault injection, for reproducible runs (default: from
    /// the clock; printed at start).
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// What two stations sending at once do on a paced line: garble each
    /// other (as on a real line) or serialize (the later one waits).
    #[arg(long, value_enum, default_value_t = CollisionMode::Garble)]
    pub collisions: CollisionMode,
    /// Also print the counters every SECS seconds (they are printed on
    /// SIGUSR1 and at exit anyway).
    #[arg(long, value_name = "SECS", value_parser = rate)]
    pub stats: Option<f64>,
    /// Record every telegram on the line to FILE (pcapng, link type 257
    /// PROFIBUS DL; tshark and Wireshark read it).
    #[arg(long, value_name = "FILE")]
    pub pcap: Option<PathBuf>,
}

/// `--collisions`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CollisionMode {
    /// Overlapping characters of both transmissions are corrupted.
    Garble,
    /// A station that starts while the line is busy waits its turn.
    Serialize,
}

fn probability(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(p) if (0.0..=1.0).contains(&p) => Ok(p),
        _ => Err(format!("`{s}` is not a probability between 0 and 1")),
    }
}

fn rate(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(r) if r >= 0.0 && r.is_finite() => Ok(r),
        _ => Err(format!("`{s}` is not a number ≥ 0")),
    }
}

/// A usage error found after parsing: one line, exit status 2.
fn usage(msg: impl std::fmt::Display) -> ! {
    eprintln!("dpctl bus: {msg}");
    std::process::exit(2)
}

/// How long the line must be quiet before the pcap framer gives up an
/// incomplete telegram.
const IDLE_GAP: Duration = Duration::from_millis(5);
/// How often ptys without a process are checked for a new one.
const RECONNECT_CHECK: Duration = Duration::from_millis(5);
/// Bytes queued for a station that does not read before it loses bytes.
const MAX_QUEUED: usize = 1 << 20;

struct Station {
    master: OwnedFd,
    link: PathBuf,
    /// Where the link points (the pty end for the station process).
    tty: PathBuf,
    /// A process has the pty open.
    connected: bool,
    /// Bytes the pty did not take yet.
    queued: Vec<u8>,
}

/// Removes the links it made when dropped (only those still pointing to
/// our ptys).
struct Links(Vec<(PathBuf, PathBuf)>);

impl Drop for Links {
    fn drop(&mut self) {
        for (link, target) in &self.0 {
            if std::fs::read_link(link).is_ok_and(|t| &t == target) {
                let _ = std::fs::remove_file(link);
            }
        }
    }
}

#[derive(Default)]
struct HubStats {
    delivered_bytes: u64,
    overrun_bytes: u64,
    reconnects: u64,
}

/// Run the bus until SIGINT or SIGTERM.
pub fn run(args: Args) -> Result<()> {
    let n = args.stations as usize;
    let links: Vec<PathBuf> = (0..n)
        .map(|i| PathBuf::from(format!("{}{i}", args.link)))
        .collect();
    for l in &links {
        match std::fs::symlink_metadata(l) {
            Ok(m) if m.file_type().is_symlink() => {}
            Ok(_) => usage(format_args!(
                "{} exists and is not a symlink; refusing to replace it",
                l.display()
            )),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => bail!("cannot check {}: {e}", l.display()),
        }
    }
    let seed = args.seed.unwrap_or_else(|| {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or(0)
    });
    let cfg = MediumConfig {
        baud: args.baud,
        drop: args.drop,
        flip_ber: args.flip,
        noise_rate: args.noise,
        seed,
        collisions: match args.collisions {
            CollisionMode::Garble => Collisions::Garble,
            CollisionMode::Serialize => Collisions::Serialize,
        },
    };
    if let Err(e) = cfg.validate() {
        usage(e);
    }

    // Signals arrive through a signalfd in the poll set.
    let mut mask = SigSet::empty();
    for s in [Signal::SIGINT, Signal::SIGTERM, Signal::SIGUSR1] {
        mask.add(s);
    }
    mask.thread_block().context("blocking signals")?;
    let signals = SignalFd::with_flags(&mask, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC)
        .context("signalfd")?;

    let mut made = Links(Vec::new());
    let mut stations = Vec::with_capacity(n);
    for link in links {
        let pty = nix::pty::openpty(None, None).context("openpty")?;
        // Raw mode on the station's end: no echo, no line editing, no CR/LF
        // translation; it stays while the hub holds the master.
        let mut t = termios::tcgetattr(&pty.slave).context("tcgetattr")?;
        termios::cfmakeraw(&mut t);
        termios::tcsetattr(&pty.slave, SetArg::TCSANOW, &t).context("tcsetattr")?;
        let tty = nix::unistd::ttyname(&pty.slave).context("ttyname")?;
        set_nonblocking(&pty.master)?;
        drop(pty.slave);
        replace_symlink(&tty, &link)?;
        made.0.push((link.clone(), tty.clone()));
        stations.push(Station {
            master: pty.master,
            link,
            tty,
            connected: false,
            queued: Vec::new(),
        });
    }

    if args.baud.is_some() {
        // Wake-ups on time matter when pacing; the default slack is 50 µs.
        if let Err(e) = nix::sys::prctl::set_timerslack(1) {
            tracing::debug!(error = %e, "cannot reduce the timer slack");
        }
    }

    let clock = std::time::Instant::now();
    let epoch = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    let mut pcap = match &args.pcap {
        Some(path) => {
            let f =
                File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
            Some(PcapWriter::new(BufWriter::new(f), epoch)?)
        }
        None => None,
    };
    let mut tap = Tap::new();

    {
        let mut out = std::io::stdout().lock();
        for s in &stations {
            writeln!(out, "{} -> {}", s.link.display(), s.tty.display())?;
        }
        let pace = args
            .baud
            .map_or("unpaced".to_string(), |b| format!("paced at {b}"));
        writeln!(out, "bus of {n} stations, {pace}, seed {seed}")?;
        out.flush()?;
    }

    let mut medium = Medium::new(n, cfg);
    let mut hub = HubStats::default();
    let stats_every = args.stats.map(Duration::from_secs_f64);
    let mut next_stats = stats_every.map(|d| Instant::ZERO + d);
    let mut next_reconnect = Instant::ZERO;
    let mut last_delivery = Instant::ZERO;
    let mut buf = [0u8; 4096];
    let mut poll_index: Vec<usize> = Vec::with_capacity(n);
    let now_fn = || Instant::from_nanos(clock.elapsed().as_nanos() as u64);

    loop {
        let now = now_fn();

        // Ptys without a process: has one opened them (HUP gone)?
        if now >= next_reconnect {
            for s in stations.iter_mut().filter(|s| !s.connected) {
                if !hung_up(&s.master) {
                    // Drop anything written to the pty while nobody had it
                    // open, so the new process starts on a clean line.
                    let _ = termios::tcflush(&s.master, termios::FlushArg::TCOFLUSH);
                    s.connected = true;
                    hub.reconnects += 1;
                    tracing::debug!(link = %s.link.display(), "station connected");
                }
            }
            next_reconnect = now + RECONNECT_CHECK;
        }

        // Deliveries that are due.
        while let Some(d) = medium.poll_delivery(now) {
            last_delivery = d.at;
            for (j, s) in stations.iter_mut().enumerate() {
                if d.reaches(j) && s.connected {
                    deliver(s, &d.bytes, &mut hub);
                }
            }
            if pcap.is_some() {
                tap.push(d.at, &d.bytes);
                drain_tap(&mut tap, &mut pcap)?;
            }
        }
        if pcap.is_some()
            && tap.pending() > 0
            && now >= last_delivery.max(medium.busy_until()) + IDLE_GAP
        {
            tap.line_idle();
            drain_tap(&mut tap, &mut pcap)?;
            if let Some(p) = pcap.as_mut() {
                p.flush()?;
            }
        }
        if let Some(t) = next_stats.filter(|&t| now >= t) {
            eprintln!("{}", summary(&medium.stats(), &hub, &stations, &tap, &pcap));
            next_stats = stats_every.map(|d| t.max(now) + d);
        }

        // Sleep until something happens or is due.
        let mut deadline = medium.poll_timeout();
        let mut consider = |t: Instant| deadline = Some(deadline.map_or(t, |d| d.min(t)));
        if stations.iter().any(|s| !s.connected) {
            consider(next_reconnect);
        }
        if let Some(t) = next_stats {
            consider(t);
        }
        if pcap.is_some() && tap.pending() > 0 {
            consider(last_delivery.max(medium.busy_until()) + IDLE_GAP);
        }
        let timeout = deadline.map(|d| {
            let wait = d.saturating_duration_since(now_fn());
            TimeSpec::from_duration(wait)
        });

        let mut fds = Vec::with_capacity(n + 1);
        fds.push(PollFd::new(signals.as_fd(), PollFlags::POLLIN));
        poll_index.clear();
        for (i, s) in stations.iter().enumerate().filter(|(_, s)| s.connected) {
            let mut ev = PollFlags::POLLIN;
            if !s.queued.is_empty() {
                ev |= PollFlags::POLLOUT;
            }
            fds.push(PollFd::new(s.master.as_fd(), ev));
            poll_index.push(i);
        }
        match nix::poll::ppoll(&mut fds, timeout, None) {
            Ok(_) | Err(Errno::EINTR) => {}
            Err(e) => return Err(e).context("ppoll"),
        }
        let revents: Vec<PollFlags> = fds
            .iter()
            .map(|f| f.revents().unwrap_or(PollFlags::empty()))
            .collect();
        drop(fds);

        if revents[0].contains(PollFlags::POLLIN) {
            let mut stop = false;
            while let Ok(Some(info)) = signals.read_signal() {
                match Signal::try_from(info.ssi_signo as i32) {
                    Ok(Signal::SIGUSR1) => {
                        eprintln!("{}", summary(&medium.stats(), &hub, &stations, &tap, &pcap))
                    }
                    _ => stop = true,
                }
            }
            if stop {
                break;
            }
        }

        for (k, &i) in poll_index.iter().enumerate() {
            let ev = revents[k + 1];
            if ev.contains(PollFlags::POLLOUT) {
                flush_queue(&mut stations[i]);
            }
            if ev.intersects(PollFlags::POLLIN | PollFlags::POLLHUP | PollFlags::POLLERR) {
                // Read all there is; the medium gets each chunk as it came.
                loop {
                    match nix::unistd::read(&stations[i].master, &mut buf) {
                        Ok(0) => break,
                        Ok(len) => {
                            let now = now_fn();
                            medium.transmit(now, i, &buf[..len]);
                            // Unpaced: hand it on at once.
                            while let Some(d) = medium.poll_delivery(now) {
                                last_delivery = d.at;
                                for (j, s) in stations.iter_mut().enumerate() {
                                    if d.reaches(j) && s.connected {
                                        deliver(s, &d.bytes, &mut hub);
                                    }
                                }
                                if pcap.is_some() {
                                    tap.push(d.at, &d.bytes);
                                    drain_tap(&mut tap, &mut pcap)?;
                                }
                            }
                            // A pty read returns all there is (up to the
                            // buffer size): skip the read that would say
                            // EAGAIN.
                            if len < buf.len() {
                                break;
                            }
                        }
                        Err(Errno::EAGAIN) | Err(Errno::EINTR) => break,
                        Err(Errno::EIO) => {
                            disconnect(&mut stations[i]);
                            break;
                        }
                        Err(e) => {
                            tracing::warn!(link = %stations[i].link.display(), error = %e, "read failed");
                            disconnect(&mut stations[i]);
                            break;
                        }
                    }
                }
            }
        }
    }

    if pcap.is_some() {
        tap.line_idle();
        drain_tap(&mut tap, &mut pcap)?;
    }
    eprintln!("{}", summary(&medium.stats(), &hub, &stations, &tap, &pcap));
    if let Some(p) = pcap {
        p.into_inner().context("writing the pcap file")?;
    }
    drop(made);
    Ok(())
}

fn set_nonblocking(fd: &OwnedFd) -> Result<()> {
    use nix::fcntl::{fcntl, FcntlArg, OFlag};
    let flags = OFlag::from_bits_truncate(fcntl(fd, FcntlArg::F_GETFL)?);
    fcntl(fd, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK))?;
    Ok(())
}

/// Point `link` at `target`, replacing a stale symlink atomically.
fn replace_symlink(target: &Path, link: &Path) -> Result<()> {
    let tmp = PathBuf::from(format!("{}.dpctl-{}", link.display(), std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(target, &tmp)
        .with_context(|| format!("cannot create link {}", link.display()))?;
    std::fs::rename(&tmp, link).with_context(|| {
        let _ = std::fs::remove_file(&tmp);
        format!("cannot create link {}", link.display())
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
    s.queued.clear();
    let _ = termios::tcflush(&s.master, termios::FlushArg::TCOFLUSH);
}

/// Write `bytes` to a station's pty, queueing what it does not take.
fn deliver(s: &mut Station, bytes: &[u8], hub: &mut HubStats) {
    hub.delivered_bytes += bytes.len() as u64;
    if !s.queued.is_empty() {
        flush_queue(s);
    }
    let mut rest = bytes;
    if s.queued.is_empty() {
        match nix::unistd::write(&s.master, bytes) {
            Ok(k) => rest = &bytes[k..],
            Err(Errno::EAGAIN) | Err(Errno::EINTR) => {}
            Err(_) => {
                disconnect(s);
                return;
            }
        }
    }
    if !rest.is_empty() {
        let room = MAX_QUEUED.saturating_sub(s.queued.len());
        let take = rest.len().min(room);
        s.queued.extend_from_slice(&rest[..take]);
        hub.overrun_bytes += (rest.len() - take) as u64;
    }
}

fn flush_queue(s: &mut Station) {
    while !s.queued.is_empty() {
        match nix::unistd::write(&s.master, &s.queued) {
            Ok(k) => {
                s.queued.drain(..k);
            }
            Err(Errno::EINTR) => {}
            Err(Errno::EAGAIN) => return,
            Err(_) => {
                disconnect(s);
                return;
            }
        }
    }
}

fn drain_tap(tap: &mut Tap, pcap: &mut Option<PcapWriter<BufWriter<File>>>) -> Result<()> {
    while let Some(ev) = tap.poll() {
        if let (TapEvent::Telegram { at, bytes }, Some(p)) = (ev, pcap.as_mut()) {
            p.write_telegram(at, &bytes)
                .context("writing the pcap file")?;
        }
    }
    Ok(())
}

fn summary(
    m: &MediumStats,
    hub: &HubStats,
    stations: &[Station],
    tap: &Tap,
    pcap: &Option<PcapWriter<BufWriter<File>>>,
) -> String {
    let connected = stations.iter().filter(|s| s.connected).count();
    let mut s = format!(
        "dpctl bus: {m}; delivered {} bytes, overruns {} bytes, {connected}/{} stations connected ({} connects)",
        hub.delivered_bytes,
        hub.overrun_bytes,
        stations.len(),
        hub.reconnects
    );
    if let Some(p) = pcap {
        let c = tap.stats();
        let _ = write!(
            s,
            "; pcap {} telegrams (codec: {} garbage bytes, {} bad FCS, {} other errors)",
            p.packets(),
            c.garbage_bytes,
            c.bad_fcs,
            c.errors() - c.bad_fcs
        );
    }
    s
}
