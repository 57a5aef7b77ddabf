//! `profibus-io`: PROFIBUS over the operating system.
//!
//! The protocol crates (`profibus-fdl`, `profibus-dp`, `profibus-devices`)
//! are sans-IO: a core takes received bytes or telegrams and the current
//! time and returns bytes to send, the next deadline and events. This
//! crate is everything between such a core and the OS, in the way `quinn`
//! is the I/O half of `quinn-proto`: tokio, serial ports, ptys, sockets,
//! clocks and every `unsafe` block of the project (each wrapped and
//! commented where a syscall needs it).
//!
//! - [`transport`]: serial ports (RS-485 adapters), ptys and TCP links as
//!   one async byte stream, [`transport::Port`]; the virtual bus
//!   [`transport::hub`] behind `dpctl bus`; the line [`transport::doctor`];
//!   real-time scheduling ([`transport::realtime`]) and the kernel's RS-485
//!   mode (`transport::rs485`).
//! - [`driver`]: the thin tokio shell that runs any `profibus_fdl`
//!   station (an active master or a passive slave) on a byte stream,
//!   with its [`driver::Clock`].
//! - [`class2`]: a class-2 master (MSAC_C2) on a port, next to the
//!   running masters, for one connection's requests.
//! - [`fms`]: an FMS client (`FmsMaster`) on a port, next to the running
//!   masters, for one connection's requests (`dpctl fms`).
//! - [`runner`]: a slave's station on a port with the baud-rate search,
//!   searching again after silence or a lost master.
//! - [`listen`]: the passive driver of bus monitors: reads a line (never
//!   writes) and hands the tap's events on (`dpctl sniff`, `monitor`).
//! - [`emulation`]: a device profile of `profibus-devices` as a DP slave on
//!   a port (`dpctl slave`), keeping Set_Slave_Add addresses and device
//!   state in files.
//! - [`control_io`]: control lines for a device's `ControlInbox` from a
//!   file, stdin or a Unix socket.
//! - [`jx2`]: the JX2-PROFI1's register clients (console, control socket,
//!   script) while the slave runs.
//! - [`pace`]: a simulated line in step with the wall clock
//!   (`dpctl gateway --sim`).
//! - [`FdlCodec`]: the FDL framer as a `tokio_util` codec.
//! - [`alloc_count`]: a counting global allocator for the tests and
//!   benchmarks that prove allocation-free steady states.

pub mod alloc_count;
pub mod baud;
pub mod class2;
pub mod codec;
pub mod control_io;
pub mod driver;
pub mod emulation;
pub mod fms;
pub mod jx2;
pub mod listen;
pub mod pace;
pub mod port_lock;
pub mod runner;
#[cfg(test)]
mod testing;
pub mod transport;

pub use codec::FdlCodec;
