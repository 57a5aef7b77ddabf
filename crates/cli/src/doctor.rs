//! `dpctl doctor`: what can be checked about a port, by
//! `profibus_io::transport::doctor`; this prints the report (its
//! `Display` text, or its JSON with `--json`).

use crate::common::RtsArg;
use anyhow::{bail, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_io::transport::doctor::{diagnose, DoctorOptions};
use std::path::PathBuf;

/// Check a serial port for PROFIBUS: 8E1, the baud rates (custom ones
/// too), an FTDI adapter's latency timer, the kernel's RS-485 mode, the
/// RTS direction control of `--rts`, and whether the bus file's slot
/// time can be met with the adapter's latency. Sends nothing. Exit
/// status 1 when a check fails.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial device or pty path, or tcp://HOST:PORT (serial device server).
    #[arg(long, value_name = "PATH")]
    port: String,
    /// Bus file: check its baud rate and slot time (default: every
    /// PROFIBUS rate, no timing check).
    #[arg(long, value_name = "BUS.toml")]
    config: Option<PathBuf>,
    #[command(flatten)]
    rts: RtsArg,
    /// Print the report as one JSON object: path, device, kind, rts,
    /// checks (what, verdict, detail), failed, unchecked.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> Result<()> {
    let params = match &args.config {
        Some(path) => Some(ProfiledBus::load(path)?.file.master.params),
        None => None,
    };
    let options = DoctorOptions {
        params,
        rts: args.rts.control(),
        ..DoctorOptions::default()
    };
    let report = diagnose(&args.port, &options);
    if args.json {
        crate::out::outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        crate::out::outln!("{report}")?;
    }
    if report.failed() {
        bail!("{} is not fit for PROFIBUS (see above)", args.port);
    }
    Ok(())
}
