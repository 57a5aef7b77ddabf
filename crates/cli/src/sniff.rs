//! `dpctl sniff`: a passive bus monitor.
//!
//! Reads a serial line or pty (never writes), frames what it sees and
//! prints one line per telegram: the time in µs since the start and the
//! telegram as `dpctl decode` describes it. Bytes the framer had to skip
//! (garbage, a bad FCS, a broken length) are printed on lines starting
//! with `!! `, with their hex and the errors they raised. `--json` prints
//! the same as JSON lines (`"error"` marks the skipped bytes); `--pcap`
//! records the telegrams. On Ctrl-C / SIGTERM it prints a summary line
//! with the codec counters and stops.

use crate::common;
use crate::describe::hex;
use anyhow::{Context, Result};
use profibus_dp::describe::TelegramSummary;
use profibus_fdl::codec::CodecStats;
use profibus_fdl::pcap::PcapWriter;
use profibus_fdl::tap::{Tap, TapEvent};
use profibus_fdl::transport::Port;
use profibus_fdl::wire::{Hex, Telegram};
use profibus_fdl::{Baud, BusParams, Instant};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::time::Duration;
use tokio::io::AsyncReadExt;
use tokio::signal::unix::{signal, SignalKind};

/// Listen passively on a line and print every telegram.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial port or pty to listen on (e.g. /dev/ttyUSB0, a `dpctl bus`
    /// link), or tcp://HOST:PORT (serial device server, raw TCP).
    #[arg(long, value_name = "PATH")]
    pub port: String,
    /// Baud rate of the line (9600 … 12M); irrelevant on a pty.
    #[arg(long, value_name = "B", default_value = "19200")]
    pub baud: Baud,
    /// Print one JSON object per line.
    #[arg(long)]
    pub json: bool,
    /// Record the telegrams to FILE (pcapng, link type 257 PROFIBUS DL).
    #[arg(long, value_name = "FILE")]
    pub pcap: Option<PathBuf>,
    /// Quiet time in ms after which an incomplete telegram is given up
    /// (default: 5 on a pty; on a serial line twice TSYN, at least 2).
    #[arg(long, value_name = "MS")]
    pub idle_ms: Option<f64>,
}

/// The kinds of error in `e`, for humans.
fn error_text(e: &CodecStats, skipped: usize) -> String {
    let mut parts = vec![];
    for (n, what) in [
        (e.bad_fcs, "bad FCS"),
        (e.bad_length, "bad length"),
        (e.bad_end_delimiter, "missing end delimiter"),
        (e.bad_format, "bad format"),
        (e.truncated, "truncated"),
    ] {
        if n > 0 {
            parts.push(if n == 1 {
                what.to_string()
            } else {
                format!("{n}× {what}")
            });
        }
    }
    if e.garbage_bytes > 0 {
        parts.push(format!("{} garbage bytes", e.garbage_bytes));
    }
    if parts.is_empty() {
        parts.push(format!("{skipped} bytes skipped"));
    }
    parts.join(", ")
}

/// A line of `--json`: what was seen, and when (µs since the start).
#[derive(serde::Serialize)]
struct Seen<T: serde::Serialize> {
    t_us: u64,
    #[serde(flatten)]
    what: T,
}

/// Bytes the framer skipped, and why.
#[derive(serde::Serialize)]
struct Skipped<'a> {
    error: String,
    skipped: usize,
    raw: Hex<'a>,
    #[serde(flatten)]
    errors: CodecStats,
}

struct Printer {
    json: bool,
    out: BufWriter<std::io::Stdout>,
    pcap: Option<PcapWriter<BufWriter<File>>>,
}

impl Printer {
    fn event(&mut self, ev: TapEvent) -> Result<()> {
        match ev {
            TapEvent::Telegram { at, bytes } => {
                let us = at.as_nanos() / 1000;
                // The tap only yields telegrams that parse.
                let Ok((t, _)) = Telegram::parse(&bytes) else {
                    return Ok(());
                };
                let summary = TelegramSummary::new(t, &bytes);
                if self.json {
                    let line = Seen {
                        t_us: us,
                        what: &summary,
                    };
                    writeln!(self.out, "{}", common::json_line(&line))?;
                } else {
                    writeln!(self.out, "{us:>12} {summary}")?;
                }
                if let Some(p) = self.pcap.as_mut() {
                    p.write_telegram(at, &bytes)
                        .context("writing the pcap file")?;
                }
            }
            TapEvent::Skipped { at, bytes, errors } => {
                let us = at.as_nanos() / 1000;
                let what = error_text(&errors, bytes.len());
                if self.json {
                    let line = Seen {
                        t_us: us,
                        what: Skipped {
                            error: what,
                            skipped: bytes.len(),
                            raw: Hex(&bytes),
                            errors,
                        },
                    };
                    writeln!(self.out, "{}", common::json_line(&line))?;
                } else {
                    writeln!(
                        self.out,
                        "!! {us:>9} {what}: {} bytes skipped: {}",
                        bytes.len(),
                        hex(&bytes)
                    )?;
                }
            }
        }
        Ok(())
    }

    fn summary(&mut self, s: &CodecStats) -> Result<()> {
        if self.json {
            #[derive(serde::Serialize)]
            struct Summary<'a> {
                summary: &'a CodecStats,
            }
            writeln!(self.out, "{}", common::json_line(&Summary { summary: s }))?;
        } else {
            writeln!(
                self.out,
                "summary: {} telegrams, {} garbage bytes, {} bad FCS, {} bad length, {} missing end delimiter, {} bad format, {} truncated",
                s.telegrams,
                s.garbage_bytes,
                s.bad_fcs,
                s.bad_length,
                s.bad_end_delimiter,
                s.bad_format,
                s.truncated
            )?;
        }
        self.out.flush()?;
        Ok(())
    }
}

/// Listen until Ctrl-C / SIGTERM (or until the line goes away).
pub fn run(args: Args) -> Result<()> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the runtime")?;
    rt.block_on(sniff(args))
}

async fn sniff(args: Args) -> Result<()> {
    let mut port = Port::open(&args.port, args.baud)?;
    let idle = match args.idle_ms {
        Some(ms) if ms > 0.0 && ms.is_finite() => Duration::from_secs_f64(ms / 1000.0),
        Some(ms) => {
            eprintln!("dpctl sniff: --idle-ms {ms} must be a positive number");
            std::process::exit(2)
        }
        None if port.is_pty() || port.is_tcp() => Duration::from_millis(5),
        None => (BusParams::defaults(args.baud).bits(33) * 2).max(Duration::from_millis(2)),
    };
    let clock = std::time::Instant::now();
    let epoch = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    let pcap = match &args.pcap {
        Some(path) => {
            let f =
                File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
            Some(PcapWriter::new(BufWriter::new(f), epoch)?)
        }
        None => None,
    };
    let mut printer = Printer {
        json: args.json,
        out: BufWriter::new(std::io::stdout()),
        pcap,
    };
    let mut int = signal(SignalKind::interrupt())?;
    let mut term = signal(SignalKind::terminate())?;
    let mut tap = Tap::new();
    let mut buf = [0u8; 4096];
    let mut failure = None;
    loop {
        let wait = async {
            if tap.pending() > 0 {
                tokio::time::timeout(idle, port.read(&mut buf)).await
            } else {
                Ok(port.read(&mut buf).await)
            }
        };
        tokio::select! {
            _ = int.recv() => break,
            _ = term.recv() => break,
            r = wait => match r {
                Err(_elapsed) => tap.line_idle(),
                Ok(Ok(0)) => break,
                Ok(Ok(n)) => {
                    let at = Instant::from_nanos(clock.elapsed().as_nanos() as u64);
                    tap.push(at, &buf[..n]);
                }
                Ok(Err(e)) => {
                    failure = Some(anyhow::Error::new(e).context(format!("reading {}", args.port)));
                    break;
                }
            },
        }
        while let Some(ev) = tap.poll() {
            printer.event(ev)?;
        }
        printer.out.flush()?;
    }
    tap.line_idle();
    while let Some(ev) = tap.poll() {
        printer.event(ev)?;
    }
    printer.summary(&tap.stats())?;
    if let Some(p) = printer.pcap.take() {
        p.into_inner().context("writing the pcap file")?;
    }
    match failure {
        Some(e) => Err(e),
        None => Ok(()),
    }
}
