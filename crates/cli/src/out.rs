//! Standard output of every command, and what happens when its reader
//! goes away (`dpctl gsd show F | head -1`, a consumer that quit).
//!
//! Rust ignores SIGPIPE, so a write to a pipe nobody reads fails with
//! EPIPE, and `println!` panics on it. Commands therefore print through
//! [`outln!`] and [`out!`] (or a writer from [`stdout`]), which turn
//! EPIPE into [`Closed`]. A closed output is not a failure: a one-shot
//! command returns it as its error, a long-running one stops as on
//! SIGTERM ([`crate::common::request_stop`]: links, sockets and files
//! are cleaned up), and `dpctl` exits with status 0 without a message
//! (see [`is_closed`] and `main`). Messages on stderr go through
//! [`errln!`], which never panics either.

use std::fmt;
use std::io::{self, Write};

/// Standard output's reader has gone: nothing more can be shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Closed;

impl fmt::Display for Closed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("standard output closed by its reader")
    }
}

impl std::error::Error for Closed {}

/// Standard output where a closed pipe is an `io::Error` of kind
/// `BrokenPipe` that carries [`Closed`].
pub struct Stdout(io::Stdout);

/// Standard output (line-buffered, as `println!` writes it).
pub fn stdout() -> Stdout {
    Stdout(io::stdout())
}

/// `e`, with EPIPE marked as [`Closed`].
fn mark(e: io::Error) -> io::Error {
    if e.kind() == io::ErrorKind::BrokenPipe {
        io::Error::new(io::ErrorKind::BrokenPipe, Closed)
    } else {
        e
    }
}

impl Write for Stdout {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0.write(buf).map_err(mark)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.0.flush().map_err(mark)
    }
}

/// Whether `e` is [`Closed`] (itself, or inside an `io::Error`).
pub fn closed(e: &(dyn std::error::Error + 'static)) -> bool {
    e.is::<Closed>()
        || e.downcast_ref::<io::Error>()
            .and_then(|e| e.get_ref())
            .is_some_and(|inner| inner.is::<Closed>())
}

/// Whether `e`, or an error in its chain, is [`Closed`]: the command
/// stopped because nobody reads its output, which is no failure.
pub fn is_closed(e: &anyhow::Error) -> bool {
    e.chain().any(closed)
}

/// `println!` that returns `io::Result<()>` instead of panicking; a
/// closed standard output is [`Closed`].
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!($crate::out::stdout(), $($arg)*)
    }};
}

/// `print!` as [`outln!`].
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        write!($crate::out::stdout(), $($arg)*)
    }};
}

/// `eprintln!` for messages and warnings on stderr, which never panics:
/// a closed stderr (`dpctl … 2>&1 | head -1`) only loses the line.
macro_rules! errln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

pub(crate) use {errln, out, outln};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broken_pipe_is_closed_and_other_errors_are_not() {
        let e = mark(io::Error::from(io::ErrorKind::BrokenPipe));
        assert!(closed(&e));
        assert_eq!(e.kind(), io::ErrorKind::BrokenPipe);
        let chained = anyhow::Error::new(e).context("printing");
        assert!(is_closed(&chained));
        let other = mark(io::Error::from(io::ErrorKind::StorageFull));
        assert!(!closed(&other));
        // A broken pipe elsewhere (a tcp:// line, a socket) is a failure.
        let line = anyhow::Error::new(io::Error::from(io::ErrorKind::BrokenPipe));
        assert!(!is_closed(&line));
    }
}
