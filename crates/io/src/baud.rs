//! Finding a line's baud rate from a port: listening ([`listen_for_baud`],
//! the [`AutoBaud`] search of a slave with `Auto_Baud_supp`) and, on a
//! silent line, asking ([`probe_baud`]: FDL Status requests at each rate
//! until a station answers). Used by the passive runner
//! ([`crate::runner`]) and by `dpctl scan|sniff|monitor --baud auto`.
//!
//! On a pty the bytes pass whatever rate the port is set to, so a search
//! locks at the first rate tried, unless the `dpctl bus` hub checks the
//! rates ([`crate::transport::hub::Hub::check_rates`]).

use crate::driver::Clock;
use crate::runner::RunnerError;
use crate::transport::Port;
use profibus_fdl::codec::{Framed, Framer};
use profibus_fdl::station::autobaud::{AutoBaud, BaudSet};
use profibus_fdl::timing::{Baud, BusParams};
use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, Telegram};
use std::future::Future;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// Listen at each rate of `rates` (fastest first, wrapping around) until
/// a valid telegram with a frame check sequence decodes; the rate, or
/// `None` when `shutdown` completed first.
pub async fn listen_for_baud<F: Future<Output = ()>>(
    port: &mut Port,
    clock: &Clock,
    rates: BaudSet,
    shutdown: F,
) -> Result<Option<Baud>, RunnerError> {
    tokio::pin!(shutdown);
    let mut ab = AutoBaud::new(clock.now()).with_rates(rates);
    port.set_baud(ab.baud())?;
    let mut buf = [0u8; 512];
    loop {
        let Some(due) = ab.poll_timeout() else {
            return Ok(ab.locked());
        };
        let wait = due.saturating_duration_since(clock.now());
        tokio::select! {
            _ = shutdown.as_mut() => return Ok(None),
            r = port.read(&mut buf) => {
                let n = r?;
                if n == 0 {
                    return Err(std::io::Error::new(
                        std::io::ErrorKind::UnexpectedEof,
                        format!("{}: port closed", port.name()),
                    )
                    .into());
                }
                if let Some(b) = ab.handle_rx(clock.now(), &buf[..n]) {
                    return Ok(Some(b));
                }
            }
            _ = tokio::time::sleep(wait) => {
                if let Some(b) = ab.handle_timeout(clock.now()) {
                    port.set_baud(b)?;
                }
            }
        }
    }
}

/// How long [`listen_for_baud`] takes to listen once at every rate of
/// `rates` (use it as the time limit of one round).
pub fn listen_round(rates: BaudSet) -> Duration {
    let ab = AutoBaud::new(profibus_fdl::Instant::ZERO).with_rates(rates);
    ab.rates().iter().map(|b| ab.dwell(b)).sum()
}

/// A rate found by [`probe_baud`] and the station that answered there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Probed {
    /// The rate.
    pub baud: Baud,
    /// The first station that answered.
    pub station: u8,
}

/// Ask at each rate of `rates` (fastest first): send an FDL Status
/// request from `own` to each address 0 … 125 and keep the first rate
/// where a station answers with a valid telegram. Only for a silent line
/// (a master that sends there would collide). `latency` is the
/// transport's allowance added to each wait (see
/// [`Port::default_latency`]). `None` when no station answered at any
/// rate.
pub async fn probe_baud(
    port: &mut Port,
    own: u8,
    latency: Duration,
    rates: BaudSet,
) -> Result<Option<Probed>, RunnerError> {
    let mut buf = [0u8; 512];
    for baud in rates.iter() {
        port.set_baud(baud)?;
        let slot = baud.bits_to_duration(u64::from(BusParams::defaults(baud).slot_time));
        // The request and the reply cross the wire (a pty hub paced at
        // the rate hands each over whole), the slot time, the transport.
        let wait = slot + baud.chars_to_duration(16) + latency;
        for da in (0..=125u8).filter(|&a| a != own) {
            let fc = FunctionCode::request(RequestKind::FdlStatus);
            let req = Telegram::Data(DataTelegram::new(da, own, fc, &[]))
                .to_vec()
                .expect("a telegram without data always encodes");
            port.write_all(&req).await?;
            let mut got = Vec::new();
            let deadline = tokio::time::Instant::now() + wait;
            loop {
                tokio::select! {
                    r = port.read(&mut buf) => {
                        let n = r?;
                        if n == 0 {
                            return Err(std::io::Error::new(
                                std::io::ErrorKind::UnexpectedEof,
                                format!("{}: port closed", port.name()),
                            )
                            .into());
                        }
                        got.extend_from_slice(&buf[..n]);
                        if answered(&got, da, own) {
                            return Ok(Some(Probed { baud, station: da }));
                        }
                    }
                    _ = tokio::time::sleep_until(deadline) => break,
                }
            }
        }
    }
    Ok(None)
}

/// Whether `bytes` hold a valid answer from `da` to `own`.
fn answered(bytes: &[u8], da: u8, own: u8) -> bool {
    let mut framer = Framer::new();
    let mut start = 0;
    while start < bytes.len() {
        match framer.frame(&bytes[start..]) {
            Framed::Telegram { skip, len } => {
                let at = start + skip;
                if let Ok((Telegram::Data(t), _)) = Telegram::parse(&bytes[at..at + len]) {
                    if t.sa & 0x7F == da && t.da & 0x7F == own {
                        return true;
                    }
                }
                start = at + len;
            }
            Framed::NeedMore { .. } => return false,
        }
    }
    false
}
