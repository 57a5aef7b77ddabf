//! Linux RS-485 mode (`TIOCSRS485`): the UART driver asserts RTS while
//! sending and releases it after the last bit.

use std::io;
use std::os::fd::{AsRawFd, BorrowedFd};

/// `struct serial_rs485` of `<linux/serial.h>` (32 bytes), written by
/// TIOCSRS485 and read by TIOCGRS485.
#[repr(C)]
#[derive(Debug, Default, Clone, Copy)]
struct SerialRs485 {
    flags: u32,
    delay_rts_before_send: u32,
    delay_rts_after_send: u32,
    padding: [u32; 5],
}

/// RS-485 mode on.
const SER_RS485_ENABLED: u32 = 1 << 0;
/// RTS asserted (logical 1) while sending.
const SER_RS485_RTS_ON_SEND: u32 = 1 << 1;

#[cfg(target_os = "linux")]
nix::ioctl_write_ptr_bad!(tiocsrs485, nix::libc::TIOCSRS485, SerialRs485);
#[cfg(target_os = "linux")]
nix::ioctl_read_bad!(tiocgrs485, nix::libc::TIOCGRS485, SerialRs485);

/// Switch the UART behind `fd` to RS-485 mode with RTS on send. Fails
/// (ENOTTY, EINVAL, …) when the driver has no RS-485 support, as for ptys
/// and most USB adapters.
#[cfg(target_os = "linux")]
pub(super) fn enable(fd: BorrowedFd<'_>) -> io::Result<()> {
    let conf = SerialRs485 {
        flags: SER_RS485_ENABLED | SER_RS485_RTS_ON_SEND,
        ..Default::default()
    };
    // SAFETY: `fd` is an open descriptor for the duration of the call and
    // `conf` is a valid `struct serial_rs485` the kernel only reads.
    unsafe { tiocsrs485(fd.as_raw_fd(), &conf) }
        .map(|_| ())
        .map_err(io::Error::from)
}

/// No kernel RS-485 mode outside Linux.
#[cfg(not(target_os = "linux"))]
pub(super) fn enable(_fd: BorrowedFd<'_>) -> io::Result<()> {
    Err(io::Error::new(
        io::ErrorKind::Unsupported,
        "kernel RS-485 mode is Linux only",
    ))
}

/// The RS-485 flags of the UART behind `fd` (`Err`: no RS-485 support;
/// `dpctl doctor`).
#[cfg(target_os = "linux")]
pub(super) fn flags(fd: BorrowedFd<'_>) -> io::Result<u32> {
    let mut conf = SerialRs485::default();
    // SAFETY: `fd` is open for the call; `conf` is a valid, writable
    // `struct serial_rs485` the kernel fills in.
    unsafe { tiocgrs485(fd.as_raw_fd(), &mut conf) }.map_err(io::Error::from)?;
    Ok(conf.flags)
}

/// No kernel RS-485 mode outside Linux.
#[cfg(not(target_os = "linux"))]
pub(super) fn flags(_fd: BorrowedFd<'_>) -> io::Result<u32> {
    Err(io::Error::new(io::ErrorKind::Unsupported, "Linux only"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn struct_matches_the_kernel_layout() {
        assert_eq!(std::mem::size_of::<SerialRs485>(), 32);
    }

    #[test]
    fn a_pty_has_no_rs485_mode() {
        let pty = nix::pty::openpty(None, None).unwrap();
        use std::os::fd::AsFd;
        assert!(enable(pty.slave.as_fd()).is_err());
    }
}
