//! Byte-stream transports for FDL stations (tokio).
//!
//! [`Port`] is the one async byte stream the station drivers use: an
//! RS-485 adapter (via `tokio-serial`) or any tty path, including the pty
//! ends made by `socat` or by `dpctl bus`. It is configured 8E1 (8 data
//! bits, even parity, 1 stop bit) in raw mode (no echo, no line
//! discipline) at a PROFIBUS [`Baud`] rate; a rate the adapter refuses is
//! a [`TransportError::BaudRefused`] naming it. On a pty the rate only
//! matters to the peer: ptys carry bytes, not bits, and no parity.
//!
//! A path `tcp://HOST:PORT` opens a TCP connection to an RS-485 serial
//! device server in raw TCP mode (also called "TCP server" or "raw
//! socket" mode: the server relays the bytes of the connection to its
//! serial line and back, unchanged). The server's own settings give the
//! line its rate and 8E1; [`Port::set_baud`] only records the rate for
//! the bus timing, and RTS control is the server's business (asking for
//! it is a [`TransportError::Rts`]). See [`Port::is_tcp`].
//!
//! A path that does not exist yet but may be a pty link on its way (see
//! [`PATH_WAIT`]) is waited for: a station started right after `dpctl
//! bus` or `socat`, as in a script, finds its link once they have made it.
//!
//! Framing never depends on inter-character timing: wrap the port in
//! `tokio_util::codec::Framed` with [`crate::FdlCodec`].
//!
//! Optional RTS direction control ([`RtsControl`]) drives the transmit
//! enable of adapters without automatic direction switching: RTS is
//! asserted while sending and released once the last bit has left. On
//! Linux the kernel does this when the driver supports RS-485 mode
//! (`TIOCSRS485`); otherwise the port toggles RTS itself around writes and
//! waits with `tcdrain` in [`tokio::io::AsyncWriteExt::flush`], so a
//! driver must flush after each telegram.
//!
//! Facts about the line a port leads to, for the shells that run stations
//! on it: [`Port::is_pty`], [`Port::default_latency`],
//! [`Port::whole_telegrams`] and [`Port::may_gather`].
//!
//! [`doctor`] checks what can be checked about a port (8E1, baud rates,
//! an FTDI latency timer, RS-485 mode, slot time against latency).
//!
//! [`hub`] is the virtual RS-485 bus of ptys behind `dpctl bus`. The
//! in-process simulated bus is not a `Port`: it is the sans-IO
//! [`Medium`](profibus_fdl::line::medium::Medium) driven on virtual time.
//!
//! [`realtime`] puts a station process under `SCHED_FIFO`, so that it
//! runs at its deadlines on a busy machine (`dpctl --rt-priority`).

pub mod doctor;
pub mod hub;
pub mod realtime;
mod rs485;

use mio_serial::SerialStream;
use profibus_fdl::timing::Baud;
use std::future::Future;
use std::io;
use std::os::fd::{AsRawFd, BorrowedFd, OwnedFd};
use std::path::Path;
use std::pin::Pin;
use std::task::{ready, Context, Poll};
use std::time::Duration;
use tokio::io::unix::AsyncFd;
use tokio::io::{AsyncRead, AsyncWrite, Interest, ReadBuf};
use tokio::task::JoinHandle;
use tokio_serial::{DataBits, FlowControl, Parity, SerialPort, StopBits};

/// How the port drives RTS for the transceiver's transmit enable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RtsControl {
    /// RTS is left alone (adapters with automatic direction control,
    /// ptys).
    #[default]
    Off,
    /// RTS asserted while sending: by the kernel's RS-485 mode when the
    /// driver supports it, else toggled by the port around writes.
    OnSend,
}

/// Which mechanism drives RTS on an open [`Port`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RtsMechanism {
    /// RTS is not driven.
    None,
    /// The kernel's RS-485 mode (`TIOCSRS485`).
    Kernel,
    /// The port toggles RTS around writes and `tcdrain`.
    Manual,
}

/// Options for [`Port::open_with`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PortOptions {
    /// Bit rate.
    pub baud: Baud,
    /// RTS direction control.
    pub rts: RtsControl,
}

impl PortOptions {
    /// `baud`, no RTS control.
    pub fn new(baud: Baud) -> Self {
        PortOptions {
            baud,
            rts: RtsControl::Off,
        }
    }
}

/// Why a port could not be opened or configured.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The path could not be opened as a tty.
    #[error("cannot open {path}: {error}")]
    Open {
        /// The path.
        path: String,
        /// The cause (in the message; not also `source()`, so that a
        /// printed error chain names it once).
        error: io::Error,
    },
    /// The adapter does not accept the baud rate (or runs at another).
    #[error("{path} does not support {baud} ({detail})")]
    BaudRefused {
        /// The path.
        path: String,
        /// The requested rate.
        baud: Baud,
        /// What the adapter said.
        detail: String,
    },
    /// RTS control could not be set up.
    #[error("{path}: RTS direction control failed: {error}")]
    Rts {
        /// The path.
        path: String,
        /// The cause (in the message; not also `source()`, so that a
        /// printed error chain names it once).
        error: io::Error,
    },
}

fn serial_err(e: tokio_serial::Error) -> io::Error {
    io::Error::from(e)
}

/// What a [`Port`] reads and writes: a tty, or a TCP connection to a
/// serial device server; non-blocking, registered with the runtime for
/// readability only (see [`Port`]'s I/O notes).
#[derive(Debug)]
enum Link {
    Serial(AsyncFd<SerialStream>),
    Tcp(AsyncFd<std::net::TcpStream>),
}

impl AsRawFd for Link {
    fn as_raw_fd(&self) -> std::os::fd::RawFd {
        match self {
            Link::Serial(s) => s.as_raw_fd(),
            Link::Tcp(t) => t.as_raw_fd(),
        }
    }
}

/// Register `io` (already non-blocking) with the runtime for readability
/// only.
fn readable<T: AsRawFd>(io: T) -> io::Result<AsyncFd<T>> {
    // SAFETY: `T` is a serial stream or a TCP stream, which own their fd
    // and keep it open, the same one, until they are dropped.
    Ok(unsafe { AsyncFd::register_with_interest(io, Interest::READABLE) }?)
}

/// The scheme of a serial device server's address: `tcp://HOST:PORT`.
pub const TCP_SCHEME: &str = "tcp://";

/// How long [`Port::open`] waits for a serial device server to accept the
/// connection.
pub const TCP_CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// How long [`Port::open`] waits for a path that does not exist yet when
/// it may be a pty link still being made (`dpctl bus --link`, `socat
/// pty,link=…`, started a moment before): the path is not under `/dev`
/// (device nodes there come from the kernel, and a missing adapter does
/// not appear by waiting) and its directory exists. The wait is logged as
/// one warning line; a path that does not appear in time fails with
/// [`TransportError::Open`] saying so. The wait blocks the calling
/// thread: on a current-thread runtime, a signal the runtime handles
/// (Ctrl-C in `dpctl`) takes effect once the wait has ended.
pub const PATH_WAIT: Duration = Duration::from_secs(10);

/// How often a path waited for is looked for.
const PATH_POLL: Duration = Duration::from_millis(10);

/// Wait up to `limit` for `path` when it does not exist yet and may be a
/// link on its way (see [`PATH_WAIT`]); blocks the calling thread.
/// Returns at once when the path exists or cannot appear this way (the
/// open that follows then says why it fails).
fn wait_for_path(path: &Path, limit: Duration) -> io::Result<()> {
    // `metadata` follows links: a link made before its pty is not there yet.
    let missing = |p: &Path| matches!(p.metadata(), Err(e) if e.kind() == io::ErrorKind::NotFound);
    let may_appear = !path.starts_with("/dev")
        && path
            .parent()
            .is_some_and(|d| d.as_os_str().is_empty() || d.is_dir());
    if !missing(path) || !may_appear {
        return Ok(());
    }
    tracing::warn!(
        "{} does not exist yet: waiting up to {} s for it",
        path.display(),
        limit.as_secs()
    );
    let end = std::time::Instant::now() + limit;
    while missing(path) {
        if std::time::Instant::now() >= end {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                format!("no such file, also after waiting {} s", limit.as_secs()),
            ));
        }
        std::thread::sleep(PATH_POLL);
    }
    Ok(())
}

/// An async byte stream to an FDL medium; see the module docs.
///
/// I/O: the descriptor is registered with the runtime for readability
/// only. Writes go straight to the kernel (a telegram always fits its
/// buffer unless the far end stops reading); only a write that would
/// block registers a duplicate descriptor for writability until it has
/// gone through. A port registered for both (as `tokio-serial` and
/// `tokio::net` register theirs) wakes its task's thread each time the far
/// end has read what was written: two needless wake-ups per exchange on a
/// pty, in the middle of the round trip.
#[derive(Debug)]
pub struct Port {
    stream: Link,
    name: String,
    baud: Baud,
    rts: RtsMechanism,
    /// The port is a pseudo terminal.
    pty: bool,
    /// Manual RTS: asserted since the last completed flush.
    rts_raised: bool,
    /// Manual RTS: `tcdrain` running on a duplicate of the fd.
    drain: Option<JoinHandle<io::Result<()>>>,
    /// A write would block: a duplicate of the fd registered for
    /// writability, dropped after the next write that goes through.
    write_wait: Option<AsyncFd<OwnedFd>>,
}

impl Port {
    /// Open `path` at `baud`, 8E1, raw, without RTS control (a path that
    /// is not there yet is waited for: [`PATH_WAIT`]).
    pub fn open(path: &str, baud: Baud) -> Result<Port, TransportError> {
        Self::open_with(path, PortOptions::new(baud))
    }

    /// A port on `stream` named `name`, at `baud`: no pty, no RTS control.
    fn new(stream: Link, name: &str, baud: Baud) -> Port {
        Port {
            stream,
            name: name.to_string(),
            baud,
            rts: RtsMechanism::None,
            pty: false,
            rts_raised: false,
            drain: None,
            write_wait: None,
        }
    }

    /// Open `path` with `opts` (a tty path, or `tcp://HOST:PORT`). A tty
    /// path that does not exist yet is waited for up to [`PATH_WAIT`]
    /// when it may be a pty link being made (blocking the thread).
    pub fn open_with(path: &str, opts: PortOptions) -> Result<Port, TransportError> {
        let open_err = |error| TransportError::Open {
            path: path.to_string(),
            error,
        };
        if let Some(addr) = path.strip_prefix(TCP_SCHEME) {
            return Self::open_tcp(path, addr, opts);
        }
        wait_for_path(Path::new(path), PATH_WAIT).map_err(open_err)?;
        // Open at a standard rate first so that a refused PROFIBUS rate is
        // reported as such, not as a failure to open.
        let builder = tokio_serial::new(path, 9600)
            .data_bits(DataBits::Eight)
            .parity(Parity::Even)
            .stop_bits(StopBits::One)
            .flow_control(FlowControl::None);
        let stream = SerialStream::open(&builder).map_err(|e| open_err(serial_err(e)))?;
        let link = Link::Serial(readable(stream).map_err(open_err)?);
        let mut port = Port::new(link, path, opts.baud);
        port.pty = is_pty_fd(port.fd());
        port.check_parity_on_input().map_err(open_err)?;
        port.set_baud(opts.baud)?;
        if opts.rts == RtsControl::OnSend {
            port.rts = match rs485::enable(port.fd()) {
                Ok(()) => RtsMechanism::Kernel,
                Err(e) => {
                    tracing::debug!(path, error = %e, "no kernel RS-485 mode; toggling RTS around writes");
                    port.write_rts(false).map_err(|error| TransportError::Rts {
                        path: path.to_string(),
                        error,
                    })?;
                    RtsMechanism::Manual
                }
            };
        }
        Ok(port)
    }

    /// Connect to the serial device server at `addr` (`HOST:PORT`, from
    /// the path `tcp://HOST:PORT`): TCP_NODELAY, so that every telegram
    /// leaves at once.
    fn open_tcp(path: &str, addr: &str, opts: PortOptions) -> Result<Port, TransportError> {
        use std::net::ToSocketAddrs;
        let open_err = |error| TransportError::Open {
            path: path.to_string(),
            error,
        };
        if opts.rts == RtsControl::OnSend {
            return Err(TransportError::Rts {
                path: path.to_string(),
                error: io::Error::new(
                    io::ErrorKind::Unsupported,
                    "a serial device server drives its transceiver itself",
                ),
            });
        }
        let mut last = io::Error::new(
            io::ErrorKind::InvalidInput,
            "give the address as tcp://HOST:PORT",
        );
        for sa in addr.to_socket_addrs().map_err(open_err)? {
            match std::net::TcpStream::connect_timeout(&sa, TCP_CONNECT_TIMEOUT) {
                Ok(s) => {
                    s.set_nodelay(true).map_err(open_err)?;
                    s.set_nonblocking(true).map_err(open_err)?;
                    let link = Link::Tcp(readable(s).map_err(open_err)?);
                    return Ok(Port::new(link, path, opts.baud));
                }
                Err(e) => last = e,
            }
        }
        Err(open_err(last))
    }

    /// Both ends of a new pty pair, raw, as ports (for tests: bytes
    /// written to one end are read from the other).
    pub fn pty_pair(baud: Baud) -> io::Result<(Port, Port)> {
        let (a, b) = SerialStream::pair().map_err(serial_err)?;
        let wrap = |stream, name: &str| -> io::Result<Port> {
            let link = Link::Serial(readable(stream)?);
            Ok(Port {
                pty: true,
                ..Port::new(link, name, baud)
            })
        };
        Ok((wrap(a, "pty master")?, wrap(b, "pty slave")?))
    }

    /// The path the port was opened from.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The configured rate.
    pub fn baud(&self) -> Baud {
        self.baud
    }

    /// How RTS is driven.
    pub fn rts_mechanism(&self) -> RtsMechanism {
        self.rts
    }

    /// Whether the port is a TCP connection to a serial device server
    /// (`tcp://HOST:PORT`): the server sets the line's rate, so a rate
    /// search (autobaud) cannot work through it.
    pub fn is_tcp(&self) -> bool {
        matches!(self.stream, Link::Tcp(_))
    }

    /// Whether the port is a pseudo terminal (a `socat` pair, a `dpctl
    /// bus` link) rather than a serial adapter.
    pub fn is_pty(&self) -> bool {
        self.pty
    }

    /// The transport's latency, the allowance to add to slot times and
    /// token timeouts when the user gives none
    /// ([`profibus_fdl::station::active::ActiveConfig::latency_allowance`]). USB
    /// serial adapters buffer for up to 16 ms (the FTDI latency timer):
    /// 20 ms. A pty answers within a millisecond even on a loaded machine:
    /// 5 ms. A serial device server collects the characters of its line
    /// into packets and adds the network's delay both ways: 20 ms, as for
    /// a USB adapter.
    ///
    /// The wire time of a reply that a paced `dpctl bus` (or a device
    /// server) hands over only once complete is not part of it: see
    /// [`Port::whole_telegrams`]; each request allows for its own longest
    /// answer. So `dpctl scan` of all 126 addresses of a `dpctl bus` at
    /// 19.2 kbit/s takes 5.2 s (2026-11-28; 41 s when this allowance held
    /// the wire time of the longest telegram, 146 ms at that rate).
    pub fn default_latency(&self) -> Duration {
        if self.pty {
            Duration::from_millis(5)
        } else {
            Duration::from_millis(20)
        }
    }

    /// Whether the port may hand over each telegram only once its last
    /// character has crossed the wire, so that an answer's first character
    /// comes its whole wire time late
    /// ([`profibus_fdl::station::active::ActiveConfig::whole_telegrams`]): true on
    /// a pty (a paced `dpctl bus` does so) and on a TCP serial device
    /// server (which packs a telegram into one packet); false on a serial
    /// port, whose characters come as they arrive.
    pub fn whole_telegrams(&self) -> bool {
        self.pty || self.is_tcp()
    }

    /// Whether telegrams may be gathered into one write
    /// ([`crate::driver::Options::gather`]) without changing what the
    /// peer can observe beyond the idle gaps: true on a pty, which carries
    /// bytes without their timing. Gathering removes the idle time (TSYN)
    /// between the gathered telegrams, so receivers that frame by idle
    /// time (slave ASICs, and `dpctl bus` relaying to them) see one frame;
    /// it is a benchmark option, never the default. Never on a serial line.
    pub fn may_gather(&self) -> bool {
        self.pty
    }

    /// Change the rate; fails with [`TransportError::BaudRefused`] when the
    /// adapter refuses it or reports another rate afterwards (more than 2 %
    /// off).
    pub fn set_baud(&mut self, baud: Baud) -> Result<(), TransportError> {
        let Link::Serial(stream) = &mut self.stream else {
            // The serial device server's settings give its line the rate.
            self.baud = baud;
            return Ok(());
        };
        let refused = |detail: String| TransportError::BaudRefused {
            path: self.name.clone(),
            baud,
            detail,
        };
        let stream = stream.get_mut();
        stream
            .set_baud_rate(baud.bps())
            .map_err(|e| refused(e.to_string()))?;
        match stream.baud_rate() {
            Ok(actual) => {
                let want = baud.bps() as u64;
                let diff = (actual as u64).abs_diff(want);
                if diff * 50 > want {
                    return Err(refused(format!("the port runs at {actual} bit/s")));
                }
            }
            Err(e) => {
                tracing::debug!(path = %self.name, error = %e, "cannot read back the baud rate")
            }
        }
        self.baud = baud;
        Ok(())
    }

    /// Set RTS (serial lines only; a no-op over TCP, where RTS control is
    /// refused at open).
    fn write_rts(&mut self, level: bool) -> io::Result<()> {
        match &mut self.stream {
            Link::Serial(s) => s.get_mut().write_request_to_send(level).map_err(serial_err),
            Link::Tcp(_) => Ok(()),
        }
    }

    pub(crate) fn fd(&self) -> BorrowedFd<'_> {
        // SAFETY: the fd belongs to `self.stream`, which outlives the
        // returned borrow (tied to `&self`).
        unsafe { BorrowedFd::borrow_raw(self.stream.as_raw_fd()) }
    }

    /// Let the UART check parity (INPCK): a character with a parity error
    /// reads as 0x00, which the FCS and framing checks then reject. Ptys
    /// carry no parity; there this changes nothing.
    fn check_parity_on_input(&mut self) -> io::Result<()> {
        use nix::sys::termios::{tcgetattr, tcsetattr, InputFlags, SetArg};
        let mut t = tcgetattr(self.fd()).map_err(io::Error::from)?;
        t.input_flags |= InputFlags::INPCK;
        t.input_flags &= !(InputFlags::IGNPAR | InputFlags::PARMRK);
        tcsetattr(self.fd(), SetArg::TCSANOW, &t).map_err(io::Error::from)
    }
}

/// Whether `fd` is a pseudo terminal (either end): Unix 98 pty masters
/// and slaves, the multiplexer `/dev/ptmx`, and BSD-style ptys, by device
/// number.
fn is_pty_fd(fd: BorrowedFd<'_>) -> bool {
    #[cfg(target_os = "linux")]
    {
        use nix::sys::stat::{fstat, major, minor};
        let Ok(st) = fstat(fd) else {
            return false;
        };
        let (maj, min) = (major(st.st_rdev), minor(st.st_rdev));
        // 128..=135 Unix 98 masters, 136..=143 Unix 98 slaves, 5:2 ptmx,
        // 2 and 3 BSD masters and slaves (Documentation/admin-guide/devices.txt).
        (128..=143).contains(&maj) || (maj, min) == (5, 2) || maj == 2 || maj == 3
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = fd;
        false
    }
}

impl Port {
    /// Write what fits now; when nothing does, wait for room on a
    /// duplicate descriptor registered for writability (see the I/O notes
    /// on [`Port`]).
    fn poll_write_fd(&mut self, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        loop {
            match nix::unistd::write(self.fd(), buf) {
                Ok(n) => {
                    self.write_wait = None;
                    return Poll::Ready(Ok(n));
                }
                Err(nix::errno::Errno::EINTR) => continue,
                Err(nix::errno::Errno::EAGAIN) => {}
                Err(e) => return Poll::Ready(Err(e.into())),
            }
            if self.write_wait.is_none() {
                let dup = self.fd().try_clone_to_owned()?;
                // SAFETY: an `OwnedFd` keeps its fd open until dropped.
                let reg = unsafe { AsyncFd::register_with_interest(dup, Interest::WRITABLE) }?;
                self.write_wait = Some(reg);
            }
            let wait = self.write_wait.as_ref().expect("set above");
            ready!(wait.poll_write_ready(cx))?.clear_ready();
        }
    }
}

/// Read from `io` when the runtime has seen it readable, until a read
/// would block. (A short read does not prove the queue empty on a tty:
/// a pty hands over at most its line discipline's buffer per read, and
/// with edge-triggered readiness a reader that stopped early would wait
/// for an edge that never comes once the writer is blocked.)
fn poll_read_fd<T: AsRawFd>(
    io: &AsyncFd<T>,
    cx: &mut Context<'_>,
    buf: &mut ReadBuf<'_>,
) -> Poll<io::Result<()>> {
    loop {
        let mut guard = ready!(io.poll_read_ready(cx))?;
        let unfilled = buf.initialize_unfilled();
        let fd = io.as_raw_fd();
        let res = guard.try_io(|_| loop {
            // SAFETY: `fd` is open for the lifetime of `io`, borrowed here.
            let fd = unsafe { BorrowedFd::borrow_raw(fd) };
            match nix::unistd::read(fd, unfilled) {
                Err(nix::errno::Errno::EINTR) => continue,
                r => return r.map_err(io::Error::from),
            }
        });
        match res {
            Ok(Ok(n)) => {
                buf.advance(n);
                return Poll::Ready(Ok(()));
            }
            Ok(Err(e)) => return Poll::Ready(Err(e)),
            Err(_would_block) => continue,
        }
    }
}

impl AsyncRead for Port {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        match &self.stream {
            Link::Serial(s) => poll_read_fd(s, cx, buf),
            Link::Tcp(t) => poll_read_fd(t, cx, buf),
        }
    }
}

impl AsyncWrite for Port {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        if self.rts == RtsMechanism::Manual && !self.rts_raised {
            self.write_rts(true)?;
            self.rts_raised = true;
        }
        self.poll_write_fd(cx, buf)
    }

    /// Without manual RTS control a flush does nothing: writes go straight
    /// to the kernel. With it, `tcdrain` (which blocks until the last bit
    /// has left; on a pty until the peer has read it) runs on a blocking
    /// thread, then RTS is released.
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        if self.rts != RtsMechanism::Manual || !self.rts_raised {
            return Poll::Ready(Ok(()));
        }
        if self.drain.is_none() {
            // tcdrain blocks until the last bit has left the UART; run it
            // on a duplicate fd so that dropping the port cannot close the
            // fd under it.
            let fd: OwnedFd = self.fd().try_clone_to_owned()?;
            self.drain = Some(tokio::task::spawn_blocking(move || {
                nix::sys::termios::tcdrain(&fd).map_err(io::Error::from)
            }));
        }
        let drain = self.drain.as_mut().expect("set above");
        let res = ready!(Pin::new(drain).poll(cx));
        self.drain = None;
        res.map_err(io::Error::other)??;
        self.write_rts(false)?;
        self.rts_raised = false;
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        ready!(self.as_mut().poll_flush(cx))?;
        if let Link::Tcp(t) = &self.stream {
            t.get_ref().shutdown(std::net::Shutdown::Write)?;
        }
        Poll::Ready(Ok(()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[tokio::test]
    async fn pty_pair_carries_bytes_raw() {
        let (mut a, mut b) = Port::pty_pair(Baud::B12000000).unwrap();
        // Bytes a line discipline would alter: CR, LF, ^C, ^D, DEL, 0xFF.
        let data = [0x0D, 0x0A, 0x03, 0x04, 0x7F, 0xFF, 0x68, 0x11];
        a.write_all(&data).await.unwrap();
        a.flush().await.unwrap();
        let mut got = [0u8; 8];
        b.read_exact(&mut got).await.unwrap();
        assert_eq!(got, data);
        b.write_all(&data).await.unwrap();
        a.read_exact(&mut got).await.unwrap();
        assert_eq!(got, data);
    }

    /// The far end reads only once the writer has filled the pty's buffer:
    /// the write that would block waits for room (on the duplicate
    /// registered for writability) and everything arrives in order.
    #[tokio::test]
    async fn a_write_that_would_block_waits_for_room() {
        let (mut a, mut b) = Port::pty_pair(Baud::B12000000).unwrap();
        let data: Vec<u8> = (0..300_000u32).map(|i| (i % 251) as u8).collect();
        let want = data.clone();
        let writer = tokio::spawn(async move {
            a.write_all(&data).await.unwrap();
            assert!(a.write_wait.is_none(), "dropped after the last write");
            a
        });
        let mut got = vec![0u8; want.len()];
        b.read_exact(&mut got).await.unwrap();
        assert!(got == want, "bytes lost or reordered");
        let mut a = writer.await.unwrap();
        // Bytes written afterwards still wake the reader.
        for i in 0..50u8 {
            a.write_all(&[i, i]).await.unwrap();
            let mut two = [0u8; 2];
            b.read_exact(&mut two).await.unwrap();
            assert_eq!(two, [i, i]);
        }
    }

    #[tokio::test]
    async fn opens_a_pty_path_at_every_profibus_rate() {
        let pty = nix::pty::openpty(None, None).unwrap();
        let path = nix::unistd::ttyname(&pty.slave).unwrap();
        drop(pty.slave);
        let path = path.to_str().unwrap();
        let mut port = Port::open(path, Baud::B9600).unwrap();
        assert!(port.is_pty() && port.may_gather() && port.whole_telegrams());
        assert_eq!(port.default_latency(), Duration::from_millis(5));
        for b in Baud::ALL {
            port.set_baud(b).unwrap();
            assert_eq!(port.baud(), b);
        }
        assert_eq!(port.rts_mechanism(), RtsMechanism::None);
    }

    #[tokio::test]
    async fn rts_control_on_a_pty_is_a_clear_error() {
        let pty = nix::pty::openpty(None, None).unwrap();
        let path = nix::unistd::ttyname(&pty.slave).unwrap();
        let opts = PortOptions {
            baud: Baud::B1500000,
            rts: RtsControl::OnSend,
        };
        let e = Port::open_with(path.to_str().unwrap(), opts).unwrap_err();
        assert!(matches!(e, TransportError::Rts { .. }), "{e}");
        assert!(e.to_string().contains("RTS"), "{e}");
    }

    #[tokio::test]
    async fn tcp_port_carries_bytes_to_a_server() {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let path = format!("tcp://{}", listener.local_addr().unwrap());
        let mut port = Port::open(&path, Baud::B1500000).unwrap();
        let (mut server, _) = listener.accept().await.unwrap();
        assert!(port.is_tcp() && !port.is_pty() && !port.may_gather());
        assert!(port.whole_telegrams());
        assert_eq!(port.name(), path);
        assert_eq!(port.default_latency(), Duration::from_millis(20));
        port.set_baud(Baud::B19200).unwrap();
        assert_eq!(port.baud(), Baud::B19200);
        let data = [0x10, 0x8A, 0x82, 0x6D, 0x00, 0x16];
        port.write_all(&data).await.unwrap();
        port.flush().await.unwrap();
        let mut got = [0u8; 6];
        server.read_exact(&mut got).await.unwrap();
        assert_eq!(got, data);
        server.write_all(&[0xE5]).await.unwrap();
        let mut sc = [0u8; 1];
        port.read_exact(&mut sc).await.unwrap();
        assert_eq!(sc, [0xE5]);
    }

    #[tokio::test]
    async fn tcp_port_errors_name_the_address() {
        // A port nobody listens on: bind, note it, close.
        let free = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let path = format!("tcp://{}", free.local_addr().unwrap());
        drop(free);
        let e = Port::open(&path, Baud::B19200).unwrap_err();
        assert!(matches!(e, TransportError::Open { .. }), "{e}");
        assert!(e.to_string().contains(&path), "{e}");
        let e = Port::open("tcp://no-port-given", Baud::B19200).unwrap_err();
        assert!(e.to_string().contains("tcp://no-port-given"), "{e}");
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let opts = PortOptions {
            baud: Baud::B19200,
            rts: RtsControl::OnSend,
        };
        let path = format!("tcp://{}", listener.local_addr().unwrap());
        let e = Port::open_with(&path, opts).unwrap_err();
        assert!(matches!(e, TransportError::Rts { .. }), "{e}");
    }

    #[tokio::test]
    async fn open_errors_name_the_path() {
        let e = Port::open("/nonexistent/tty", Baud::B19200).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/tty"), "{e}");
    }

    /// The lines a `tracing` subscriber writes, one message per write.
    struct LogLines(std::sync::mpsc::Sender<String>);

    impl io::Write for LogLines {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            let _ = self.0.send(String::from_utf8_lossy(buf).into_owned());
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    /// `Port::open(path)` on a thread of its own (with a runtime), its
    /// log lines sent to the returned receiver as they are written.
    fn open_on_a_thread(
        path: &Path,
    ) -> (
        std::sync::mpsc::Receiver<String>,
        std::thread::JoinHandle<Result<String, TransportError>>,
    ) {
        let (tx, rx) = std::sync::mpsc::channel();
        let path = path.to_str().unwrap().to_string();
        let opener = std::thread::spawn(move || {
            let logs = tracing_subscriber::fmt()
                .with_writer(move || LogLines(tx.clone()))
                .with_ansi(false)
                .finish();
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_io()
                .build()
                .unwrap();
            let _rt = rt.enter();
            tracing::subscriber::with_default(logs, || {
                Port::open(&path, Baud::B19200).map(|p| p.name().to_string())
            })
        });
        (rx, opener)
    }

    /// A station started before `dpctl bus` or socat has made its link
    /// (a script, the tour in docs/tour.md) waits for the link, says so in one
    /// line, and opens it once it is there.
    #[test]
    fn a_link_that_does_not_exist_yet_is_waited_for() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("pb1");
        let (log, opener) = open_on_a_thread(&link);
        // The event: the opener says that it waits (or it has failed).
        let said = log.recv_timeout(Duration::from_secs(60));
        let Ok(said) = said else {
            panic!("open did not wait: {:?}", opener.join().unwrap().err());
        };
        assert!(
            said.contains(&format!("{} does not exist yet", link.display()))
                && said.contains("waiting up to 10 s"),
            "{said}"
        );
        let pty = nix::pty::openpty(None, None).unwrap();
        let tty = nix::unistd::ttyname(&pty.slave).unwrap();
        std::os::unix::fs::symlink(&tty, &link).unwrap();
        let opened = opener.join().unwrap().unwrap();
        assert_eq!(opened, link.to_str().unwrap());
        let more: Vec<String> = log.try_iter().collect();
        assert!(more.is_empty(), "one line only: {more:?}");
    }

    /// Nothing is waited for where no link can be on its way: a device
    /// node under /dev, a path in a directory that does not exist. A path
    /// that stays missing fails naming the wait.
    #[test]
    fn only_a_path_that_may_appear_is_waited_for() {
        for path in ["/dev/ttyNOPE9", "/nonexistent/dir/tty"] {
            let (log, opener) = open_on_a_thread(Path::new(path));
            let e = opener.join().unwrap().unwrap_err();
            assert!(e.to_string().starts_with(&format!("cannot open {path}: ")));
            let lines: Vec<String> = log.try_iter().collect();
            assert!(lines.is_empty(), "{path}: {lines:?}");
        }
        let dir = tempfile::tempdir().unwrap();
        let e = wait_for_path(&dir.path().join("never"), Duration::ZERO).unwrap_err();
        assert_eq!(e.to_string(), "no such file, also after waiting 0 s");
        wait_for_path(dir.path(), Duration::ZERO).unwrap();
    }
}
