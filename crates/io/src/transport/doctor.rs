//! What can be checked about a port before a bus is run on it (`dpctl
//! doctor`): whether it takes 8E1 and the PROFIBUS baud rates (the
//! non-standard ones, 45.45 k, 93.75 k, 187.5 k, 6 M and 12 M, need a
//! driver that sets arbitrary rates), the latency timer of an FTDI USB
//! adapter (sysfs `/sys/bus/usb-serial/devices/NAME/latency_timer`), and
//! the kernel's RS-485 mode (`TIOCGRS485`); and whether the configured
//! slot time can be met with the adapter's latency.
//!
//! With [`DoctorOptions::rts`] it also checks the RTS direction control
//! a command would ask for (`--rts`): the kernel's RS-485 mode, or RTS
//! toggled around writes, or neither.
//!
//! A pty carries bytes, not bits: rates, parity, latency and RS-485 mode
//! mean nothing there, and the report says so instead of passing them. A
//! `tcp://` port is a serial device server whose own settings decide all
//! of it; only the connection is checked.
//!
//! The [`Report`] is text ([`fmt::Display`]: the lines `dpctl doctor`
//! prints) and, with the `serde` feature, one JSON object (`dpctl doctor
//! --json`): `path`, `device`, `kind` (`{"type": "usb", "driver": …}`),
//! `rts`, `checks` (`what`, `verdict`: `ok` | `warn` | `fail` |
//! `unchecked`, `detail`), `failed` and `unchecked` (the number of
//! checks that could not be made).

use super::{is_pty_fd, RtsControl, TCP_SCHEME};
use profibus_fdl::timing::{Baud, BusParams};
use std::fmt;
use std::io;
use std::os::fd::{AsRawFd, BorrowedFd};
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio_serial::{DataBits, FlowControl, Parity, SerialPort, StopBits};

impl RtsControl {
    /// The name of the value on the command line (`--rts`) and in
    /// reports: `off`, `on-send`.
    pub fn as_str(self) -> &'static str {
        match self {
            RtsControl::Off => "off",
            RtsControl::OnSend => "on-send",
        }
    }
}

/// The outcome of one check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Verdict {
    /// Fine.
    Ok,
    /// Works, with a caveat.
    Warn,
    /// Will not work.
    Fail,
    /// Could not be checked on this port.
    Unchecked,
}

impl Verdict {
    /// Short word for people.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Ok => "ok",
            Verdict::Warn => "warning",
            Verdict::Fail => "FAIL",
            Verdict::Unchecked => "not checked",
        }
    }
}

/// One check and what it found.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Check {
    /// What was checked (`open`, `8E1`, `baud 1.5Mbit/s`, `latency timer` …).
    pub what: String,
    /// The outcome.
    pub verdict: Verdict,
    /// Details in words.
    pub detail: String,
}

impl fmt::Display for Check {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:<11} {}: {}",
            self.verdict.word(),
            self.what,
            self.detail
        )
    }
}

/// The kind of port, as far as it can be told.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(feature = "serde", serde(tag = "type", rename_all = "snake_case"))]
pub enum PortKind {
    /// A pseudo terminal (socat pair, `dpctl bus` link).
    Pty,
    /// A USB serial adapter (`ttyUSB*`, `ttyACM*`), with its driver name
    /// when sysfs gives it.
    Usb {
        /// Kernel driver (`ftdi_sio`, `cp210x`, `ch341-uart` …).
        driver: Option<String>,
    },
    /// Another tty (an on-board UART and the like).
    Tty,
    /// A serial device server (`tcp://HOST:PORT`).
    Tcp,
    /// Could not be opened.
    Unknown,
}

/// What [`diagnose`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Report {
    /// The path as given.
    pub path: String,
    /// The device it leads to (symlinks resolved).
    pub device: Option<PathBuf>,
    /// Its kind.
    pub kind: PortKind,
    /// The RTS direction control checked for.
    pub rts: RtsControl,
    /// The checks in order.
    pub checks: Vec<Check>,
}

impl Report {
    /// Whether any check failed.
    pub fn failed(&self) -> bool {
        self.checks.iter().any(|c| c.verdict == Verdict::Fail)
    }

    /// How many checks could not be made on this port.
    pub fn unchecked(&self) -> usize {
        self.checks
            .iter()
            .filter(|c| c.verdict == Verdict::Unchecked)
            .count()
    }

    fn add(&mut self, what: impl Into<String>, verdict: Verdict, detail: impl Into<String>) {
        self.checks.push(Check {
            what: what.into(),
            verdict,
            detail: detail.into(),
        });
    }
}

/// The path, the device it leads to, the checks one per line, and how
/// many could not be made.
impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.device {
            Some(d) if d.as_os_str() != self.path.as_str() => {
                write!(f, "{} → {}", self.path, d.display())?
            }
            _ => f.write_str(&self.path)?,
        }
        for c in &self.checks {
            write!(f, "\n  {c}")?;
        }
        match self.unchecked() {
            0 => Ok(()),
            n => write!(
                f,
                "\n{n} check(s) could not be made on this port (see above)"
            ),
        }
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for Report {
    fn serialize<S: serde::Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        #[derive(serde::Serialize)]
        struct Shape<'a> {
            path: &'a str,
            device: Option<&'a Path>,
            kind: &'a PortKind,
            rts: &'static str,
            checks: &'a [Check],
            failed: bool,
            unchecked: usize,
        }
        Shape {
            path: &self.path,
            device: self.device.as_deref(),
            kind: &self.kind,
            rts: self.rts.as_str(),
            checks: &self.checks,
            failed: self.failed(),
            unchecked: self.unchecked(),
        }
        .serialize(ser)
    }
}

/// What to check the port for.
#[derive(Debug, Clone)]
pub struct DoctorOptions {
    /// The bus parameters to be used (rate and slot time), e.g. from a
    /// bus file; `None`: check every PROFIBUS rate, no timing check.
    pub params: Option<BusParams>,
    /// The RTS direction control the port is to be opened with.
    pub rts: RtsControl,
    /// Where sysfs is mounted (`/sys`; tests give a fake tree).
    pub sysfs: PathBuf,
}

impl Default for DoctorOptions {
    fn default() -> Self {
        DoctorOptions {
            params: None,
            rts: RtsControl::Off,
            sysfs: PathBuf::from("/sys"),
        }
    }
}

/// Rates that have a `B…` constant of their own in Linux termios; the
/// others need arbitrary-rate support (`BOTHER`) in the driver.
fn is_standard_rate(b: Baud) -> bool {
    matches!(
        b,
        Baud::B9600 | Baud::B19200 | Baud::B500000 | Baud::B1500000 | Baud::B3000000
    )
}

/// The latency timer of the usb-serial device `tty` (e.g. `ttyUSB0`) in
/// ms, from `sysfs/bus/usb-serial/devices/TTY/latency_timer`; `None` when
/// the file does not exist (not an FTDI adapter).
pub fn latency_timer(sysfs: &Path, tty: &str) -> Option<io::Result<u32>> {
    let f = sysfs
        .join("bus/usb-serial/devices")
        .join(tty)
        .join("latency_timer");
    if !f.exists() {
        return None;
    }
    Some(std::fs::read_to_string(&f).and_then(|s| {
        s.trim().parse().map_err(|e| {
            io::Error::new(io::ErrorKind::InvalidData, format!("{}: {e}", f.display()))
        })
    }))
}

/// The kernel driver of the tty `tty` from sysfs.
fn tty_driver(sysfs: &Path, tty: &str) -> Option<String> {
    let link = std::fs::read_link(sysfs.join("class/tty").join(tty).join("device/driver")).ok()?;
    Some(link.file_name()?.to_string_lossy().into_owned())
}

/// Check the port at `path`; see the module docs. Never sends a byte.
pub fn diagnose(path: &str, opts: &DoctorOptions) -> Report {
    let mut r = Report {
        path: path.to_string(),
        device: None,
        kind: PortKind::Unknown,
        rts: opts.rts,
        checks: vec![],
    };
    if let Some(addr) = path.strip_prefix(TCP_SCHEME) {
        diagnose_tcp(&mut r, addr);
        return r;
    }
    let device = std::fs::canonicalize(path).ok();
    r.device.clone_from(&device);
    let tty = device
        .as_ref()
        .and_then(|d| d.file_name())
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut port = match tokio_serial::new(path, 9600)
        .data_bits(DataBits::Eight)
        .parity(Parity::Even)
        .stop_bits(StopBits::One)
        .flow_control(FlowControl::None)
        .timeout(Duration::from_millis(10))
        .open_native()
    {
        Ok(p) => p,
        Err(e) => {
            r.add("open", Verdict::Fail, e.to_string());
            return r;
        }
    };
    // SAFETY: the fd belongs to `port`, alive until the end of this function.
    let fd = unsafe { BorrowedFd::borrow_raw(port.as_raw_fd()) };
    r.kind = if is_pty_fd(fd) {
        PortKind::Pty
    } else if tty.starts_with("ttyUSB") || tty.starts_with("ttyACM") {
        PortKind::Usb {
            driver: tty_driver(&opts.sysfs, &tty),
        }
    } else {
        PortKind::Tty
    };
    let what = match &r.kind {
        PortKind::Pty => "a pseudo terminal".to_string(),
        PortKind::Usb { driver: Some(d) } => format!("a USB serial adapter (driver {d})"),
        PortKind::Usb { driver: None } => "a USB serial adapter".to_string(),
        _ => "a tty".to_string(),
    };
    r.add("open", Verdict::Ok, format!("{path} is {what}"));
    let pty = r.kind == PortKind::Pty;
    let pty_note = "a pty carries bytes, not bits: it has no line to check";

    // 8E1.
    if pty {
        r.add("8E1", Verdict::Unchecked, pty_note);
    } else {
        let got = (port.data_bits(), port.parity(), port.stop_bits());
        match got {
            (Ok(DataBits::Eight), Ok(Parity::Even), Ok(StopBits::One)) => {
                r.add("8E1", Verdict::Ok, "8 data bits, even parity, 1 stop bit")
            }
            (d, p, s) => r.add(
                "8E1",
                Verdict::Fail,
                format!(
                    "the port reports {} after asking for 8E1",
                    line_words(d.ok(), p.ok(), s.ok())
                ),
            ),
        }
    }

    // Baud rates.
    let rates: Vec<Baud> = match &opts.params {
        Some(p) => vec![p.baud],
        None => Baud::ALL.to_vec(),
    };
    if pty {
        r.add(
            "baud rates",
            Verdict::Unchecked,
            format!("{pty_note}; any rate is accepted and none is real"),
        );
    } else {
        // A rate the port cannot do fails only when it is the bus file's.
        let refused = if opts.params.is_some() {
            Verdict::Fail
        } else {
            Verdict::Warn
        };
        for b in rates {
            let kind = if is_standard_rate(b) {
                "standard rate"
            } else {
                "custom rate"
            };
            match port.set_baud_rate(b.bps()) {
                Err(e) => r.add(
                    format!("baud {b}"),
                    Verdict::Fail,
                    format!("{kind} refused: {e}"),
                ),
                Ok(()) => match port.baud_rate() {
                    Ok(actual)
                        if (actual as u64).abs_diff(b.bps() as u64) * 50 <= b.bps() as u64 =>
                    {
                        r.add(format!("baud {b}"), Verdict::Ok, format!("{kind} accepted"))
                    }
                    Ok(actual) => r.add(
                        format!("baud {b}"),
                        refused,
                        format!("{kind} not taken: the port runs at {actual} bit/s"),
                    ),
                    Err(e) => r.add(
                        format!("baud {b}"),
                        Verdict::Warn,
                        format!("{kind} set, but it cannot be read back: {e}"),
                    ),
                },
            }
        }
    }

    // RS-485 mode.
    if pty {
        r.add("RS-485 mode", Verdict::Unchecked, pty_note);
    } else {
        match super::rs485::flags(fd) {
            Ok(f) if f & 1 != 0 => r.add(
                "RS-485 mode",
                Verdict::Ok,
                "the driver's RS-485 mode is on (it drives the transmit enable)",
            ),
            Ok(_) => r.add(
                "RS-485 mode",
                Verdict::Ok,
                "the driver has an RS-485 mode, now off (--rts on-send switches it on)",
            ),
            Err(e) => r.add(
                "RS-485 mode",
                Verdict::Ok,
                format!("no kernel RS-485 mode ({e}): fine for adapters that switch direction themselves (most USB RS-485 adapters)"),
            ),
        }
    }

    rts_check(&mut r, opts.rts, &mut port, fd);

    // Latency.
    let latency: Option<Duration> = if pty {
        r.add(
            "latency",
            Verdict::Unchecked,
            format!("{pty_note}; its latency is the peer's"),
        );
        None
    } else {
        match latency_timer(&opts.sysfs, &tty) {
            Some(Ok(ms)) => {
                let v = if ms > 1 { Verdict::Warn } else { Verdict::Ok };
                r.add(
                    "latency timer",
                    v,
                    format!(
                        "{ms} ms{}",
                        if ms > 1 {
                            format!(" (replies wait up to {ms} ms in the adapter; `echo 1 > {}/bus/usb-serial/devices/{tty}/latency_timer` as root)", opts.sysfs.display())
                        } else {
                            String::new()
                        }
                    ),
                );
                Some(Duration::from_millis(ms as u64))
            }
            Some(Err(e)) => {
                r.add(
                    "latency timer",
                    Verdict::Unchecked,
                    format!("cannot read it: {e}"),
                );
                None
            }
            None if matches!(r.kind, PortKind::Usb { .. }) => {
                r.add(
                    "latency timer",
                    Verdict::Unchecked,
                    "no latency_timer in sysfs (not an FTDI adapter); a USB adapter adds at least 1 ms (one USB frame)",
                );
                Some(Duration::from_millis(1))
            }
            None => {
                r.add("latency timer", Verdict::Ok, "not a USB adapter");
                Some(Duration::ZERO)
            }
        }
    };

    // Slot time against the latency.
    if let Some(p) = &opts.params {
        r.checks.push(slot_time_check(p, latency));
    }
    r
}

/// Whether the slot time of `p` covers an adapter latency of `latency`
/// (`None`: unknown).
pub fn slot_time_check(p: &BusParams, latency: Option<Duration>) -> Check {
    let tsl = p.bits(p.slot_time as u64);
    let what = format!(
        "TSL {} bit = {} µs at {}",
        p.slot_time,
        tsl.as_micros(),
        p.baud
    );
    let (verdict, detail) = match latency {
        None => (
            Verdict::Unchecked,
            format!("{what}; the port's latency is unknown"),
        ),
        Some(l) if l > tsl => (
            Verdict::Warn,
            format!(
                "{what} is shorter than the adapter's latency ({} µs): replies arrive after the slot time. \
                 dpctl adds its --latency allowance to its own timeouts, but other masters on the bus will count our replies as lost; \
                 lower the latency timer or raise slot_time",
                l.as_micros()
            ),
        ),
        Some(l) => (
            Verdict::Ok,
            format!("{what} covers the adapter's latency ({} µs)", l.as_micros()),
        ),
    };
    Check {
        what: "slot time".into(),
        verdict,
        detail,
    }
}

/// Whether the RTS direction control `rts` can work on the port.
fn rts_check(r: &mut Report, rts: RtsControl, port: &mut dyn SerialPort, fd: BorrowedFd<'_>) {
    let pty = r.kind == PortKind::Pty;
    match rts {
        RtsControl::Off if pty => r.add("RTS control", Verdict::Ok, "off (a pty has no RTS line)"),
        RtsControl::Off => r.add(
            "RTS control",
            Verdict::Ok,
            "off: RTS is left alone; the adapter must switch direction itself (--rts on-send if it needs RTS)",
        ),
        RtsControl::OnSend if pty => r.add(
            "RTS control",
            Verdict::Fail,
            "on-send cannot work: a pty has no RTS line (leave --rts off)",
        ),
        RtsControl::OnSend => match super::rs485::flags(fd) {
            Ok(_) => r.add(
                "RTS control",
                Verdict::Ok,
                "on-send: the kernel's RS-485 mode will assert RTS while sending",
            ),
            Err(_) => match port.write_request_to_send(false) {
                Ok(()) => r.add(
                    "RTS control",
                    Verdict::Warn,
                    "on-send: no kernel RS-485 mode, RTS is toggled around each write and released after tcdrain; \
                     the release can come late (the next reply may be lost): prefer an adapter with automatic direction control",
                ),
                Err(e) => r.add(
                    "RTS control",
                    Verdict::Fail,
                    format!("on-send cannot work: RTS cannot be set ({e})"),
                ),
            },
        },
    }
}

fn diagnose_tcp(r: &mut Report, addr: &str) {
    use std::net::ToSocketAddrs;
    r.kind = PortKind::Tcp;
    let connected = addr
        .to_socket_addrs()
        .ok()
        .into_iter()
        .flatten()
        .find_map(|a| std::net::TcpStream::connect_timeout(&a, Duration::from_secs(3)).ok());
    match connected {
        Some(_) => r.add(
            "open",
            Verdict::Ok,
            format!("connected to the serial device server at {addr}"),
        ),
        None => r.add("open", Verdict::Fail, format!("cannot connect to {addr}")),
    }
    r.add(
        "line",
        Verdict::Unchecked,
        "the server's own settings give its line the rate, 8E1, latency and direction control: check them in its configuration",
    );
    if r.rts == RtsControl::OnSend {
        r.add(
            "RTS control",
            Verdict::Fail,
            "on-send cannot work: a serial device server drives its transceiver itself (leave --rts off)",
        );
    }
}

/// Line settings in words, as the 8E1 check reports them: `7 data
/// bits, no parity, 2 stop bits` (`unknown …` for what the port cannot
/// tell).
fn line_words(d: Option<DataBits>, p: Option<Parity>, s: Option<StopBits>) -> String {
    let d = match d {
        Some(DataBits::Five) => "5 data bits",
        Some(DataBits::Six) => "6 data bits",
        Some(DataBits::Seven) => "7 data bits",
        Some(DataBits::Eight) => "8 data bits",
        None => "unknown data bits",
    };
    let p = match p {
        Some(Parity::None) => "no parity",
        Some(Parity::Odd) => "odd parity",
        Some(Parity::Even) => "even parity",
        None => "unknown parity",
    };
    let s = match s {
        Some(StopBits::One) => "1 stop bit",
        Some(StopBits::Two) => "2 stop bits",
        None => "unknown stop bits",
    };
    format!("{d}, {p}, {s}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_settings_in_words() {
        assert_eq!(
            line_words(
                Some(DataBits::Seven),
                Some(Parity::None),
                Some(StopBits::Two)
            ),
            "7 data bits, no parity, 2 stop bits"
        );
        assert_eq!(
            line_words(None, Some(Parity::Even), None),
            "unknown data bits, even parity, unknown stop bits"
        );
    }

    #[test]
    fn latency_timer_from_a_sysfs_tree() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let d = dir.join("bus/usb-serial/devices/ttyUSB7");
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join("latency_timer"), "16\n").unwrap();
        assert_eq!(latency_timer(dir, "ttyUSB7").unwrap().unwrap(), 16);
        assert!(latency_timer(dir, "ttyUSB8").is_none());
        std::fs::write(d.join("latency_timer"), "x\n").unwrap();
        assert!(latency_timer(dir, "ttyUSB7").unwrap().is_err());
    }

    #[test]
    fn a_pty_says_what_it_could_not_check() {
        let pty = nix::pty::openpty(None, None).unwrap();
        let name = nix::unistd::ttyname(&pty.slave).unwrap();
        let r = diagnose(
            name.to_str().unwrap(),
            &DoctorOptions {
                params: Some(BusParams::defaults(Baud::B1500000)),
                ..DoctorOptions::default()
            },
        );
        assert_eq!(r.kind, PortKind::Pty);
        assert!(!r.failed(), "{r:?}");
        for what in ["8E1", "baud rates", "RS-485 mode", "latency", "slot time"] {
            let c = r.checks.iter().find(|c| c.what == what).unwrap();
            assert_eq!(c.verdict, Verdict::Unchecked, "{c}");
        }
    }

    #[test]
    fn rts_on_send_fails_on_a_pty_and_the_text_says_why() {
        let pty = nix::pty::openpty(None, None).unwrap();
        let name = nix::unistd::ttyname(&pty.slave).unwrap();
        let path = name.to_str().unwrap();
        let off = diagnose(path, &DoctorOptions::default());
        let c = off.checks.iter().find(|c| c.what == "RTS control").unwrap();
        assert_eq!(c.verdict, Verdict::Ok, "{c}");
        let r = diagnose(
            path,
            &DoctorOptions {
                rts: RtsControl::OnSend,
                ..DoctorOptions::default()
            },
        );
        assert!(r.failed());
        let text = r.to_string();
        assert!(text.starts_with(path), "{text}");
        assert!(
            text.contains("FAIL        RTS control: on-send cannot work: a pty has no RTS line"),
            "{text}"
        );
        assert!(
            text.ends_with("4 check(s) could not be made on this port (see above)"),
            "{text}"
        );
        assert_eq!(r.unchecked(), 4);
    }

    #[test]
    fn a_missing_port_fails_to_open() {
        let r = diagnose("/nonexistent/ttyUSB9", &DoctorOptions::default());
        assert!(r.failed());
        assert_eq!(r.checks[0].what, "open");
    }

    #[test]
    fn slot_time_against_latency() {
        // 1.5 Mbit/s, TSL 300 bit = 200 µs: an FTDI adapter at its default
        // latency timer (16 ms) cannot answer in time, an on-board UART can.
        let p = BusParams::defaults(Baud::B1500000);
        let c = slot_time_check(&p, Some(Duration::from_millis(16)));
        assert_eq!(c.verdict, Verdict::Warn, "{c}");
        assert!(c.detail.contains("16000 µs"), "{c}");
        assert_eq!(
            slot_time_check(&p, Some(Duration::ZERO)).verdict,
            Verdict::Ok
        );
        assert_eq!(slot_time_check(&p, None).verdict, Verdict::Unchecked);
        // 9.6 kbit/s with a slot time of 100 bit (10.4 ms) covers 1 ms.
        let mut slow = BusParams::defaults(Baud::B9600);
        slow.slot_time = 100;
        assert_eq!(
            slot_time_check(&slow, Some(Duration::from_millis(1))).verdict,
            Verdict::Ok
        );
    }

    #[test]
    fn custom_rates_are_named() {
        assert!(is_standard_rate(Baud::B1500000));
        assert!(!is_standard_rate(Baud::B93750));
        assert!(!is_standard_rate(Baud::B12000000));
    }
}
