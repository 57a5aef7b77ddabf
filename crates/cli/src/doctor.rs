//! `dpctl doctor`: what can be checked about a port, by
//! `profibus_fdl::transport::doctor`; this prints the report.

use anyhow::{bail, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_fdl::transport::doctor::{diagnose, DoctorOptions, Verdict};
use std::path::PathBuf;

/// Check a serial port for PROFIBUS: 8E1, the baud rates (custom ones
/// too), an FTDI adapter's latency timer, the kernel's RS-485 mode, and
/// whether the bus file's slot time can be met with the adapter's
/// latency. Sends nothing. Exit status 1 when a check fails.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial device or pty path, or tcp://HOST:PORT (serial device server).
    #[arg(long, value_name = "PATH")]
    port: String,
    /// Bus file: check its baud rate and slot time (default: every
    /// PROFIBUS rate, no timing check).
    #[arg(long, value_name = "BUS.toml")]
    config: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    let params = match &args.config {
        Some(path) => Some(ProfiledBus::load(path)?.file.master.params),
        None => None,
    };
    let report = diagnose(
        &args.port,
        &DoctorOptions {
            params,
            ..DoctorOptions::default()
        },
    );
    match &report.device {
        Some(d) if d.as_os_str() != args.port.as_str() => {
            println!("{} → {}", args.port, d.display())
        }
        _ => println!("{}", args.port),
    }
    for c in &report.checks {
        println!("  {c}");
    }
    let unchecked = report
        .checks
        .iter()
        .filter(|c| c.verdict == Verdict::Unchecked)
        .count();
    if unchecked > 0 {
        println!("{unchecked} check(s) could not be made on this port (see above)");
    }
    if report.failed() {
        bail!("{} is not fit for PROFIBUS (see above)", args.port);
    }
    Ok(())
}
