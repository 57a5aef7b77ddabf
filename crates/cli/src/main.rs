//! `dpctl`: the command line of the PROFIBUS-DP stack. Thin: it parses
//! arguments, builds library objects, runs them and prints.
//!
//! Exit status: 0 success, 2 usage error, 1 any other failure with a
//! one-line reason on stderr. A standard output whose reader went away
//! (`dpctl … | head -1`) ends the command quietly with status 0
//! ([`out`]).

// The doc comments of clap arguments are `--help` texts, not rustdoc:
// brackets such as `HOST[:PORT]` there are not links.
#![allow(rustdoc::broken_intra_doc_links)]

mod bus;
mod common;
mod completions;
mod control;
mod decode;
mod demo;
mod doctor;
mod dpv1;
mod fms;
mod gateway;
mod gsd;
mod im;
mod logs;
mod master;
mod medium_args;
mod monitor;
mod ops;
mod out;
mod pkw;
mod profile_args;
mod report;
mod rfid;
mod scan;
mod service;
mod slave;
mod sniff;
mod soak;
mod stats_args;
mod via;
mod view;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// PROFIBUS-DP master, slave emulator and bus tools.
#[derive(Parser)]
#[command(
    name = "dpctl",
    version = concat!(env!("CARGO_PKG_VERSION"), " (git ", env!("DPCTL_GIT_REV"), ")"),
    about,
    long_about = None
)]
pub(crate) struct Cli {
    /// Run under SCHED_FIFO at this real-time priority (1-99, below 50
    /// keeps the serial interrupts first): the station keeps its deadlines
    /// and the line's idle times on a busy machine. Needs root,
    /// CAP_SYS_NICE or `ulimit -r`.
    #[arg(long, global = true, value_name = "PRIO")]
    rt_priority: Option<u8>,
    /// Log lines on stderr: `text` (colours only on a terminal, no time
    /// under systemd) or `json` (one object a line: time, level, target,
    /// message, fields). Filter with DPCTL_LOG (e.g. `info`).
    #[arg(long, global = true, value_name = "FORMAT", default_value = "text")]
    log_format: logs::LogFormat,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Decode telegram bytes given in hex.
    Decode(decode::Args),
    /// Live list: join the bus as a master and list the stations.
    Scan(scan::Args),
    /// Run a DP master from a bus file.
    Master(master::Args),
    /// A whole virtual plant in one process: master and emulated slaves
    /// on a simulated bus.
    Demo(demo::Args),
    /// Show or check a GSD file.
    Gsd(gsd::Args),
    /// Emulate a DP slave (a device profile or any GSD-described device).
    Slave(Box<slave::Args>),
    /// Virtual RS-485 bus of N ptys (links PREFIX0 … PREFIX{N-1}).
    Bus(bus::Args),
    /// Listen passively on a line and print every telegram.
    Sniff(sniff::Args),
    /// Turn a capture into an HTML report (or JSON): live list,
    /// per-station statistics, plots, diagnoses in words.
    Report(report::Args),
    /// Read or write a parameter over a slave's PKW channel.
    Pkw(pkw::Args),
    /// Run commands on an RFID reader (AEG ID ARE I2 / K1 PFB) over its
    /// 16-byte handshake.
    ///
    /// Only VER is from the reader's PROFIBUS manual; GT, RD, WD, TOR and
    /// the answers NAK #nn and XXXXXXXX are modelled by the emulator (an
    /// emulated reader takes its own command set with --device-opt
    /// commands=FILE.toml, see docs/devices/rfid.md).
    Rfid(rfid::Args),
    /// Read or write a DP-V1 data record (slot, index) of a slave, as the
    /// bus file's class-1 master or as a class-2 master (--class2).
    Dpv1(dpv1::Args),
    /// Read a slave's I&M0..I&M4 (identification and maintenance) in
    /// words, or write its I&M1 tag.
    Im(im::Args),
    /// One PROFIBUS-FMS service (identify, status, get-od, read, write)
    /// on an FMS server, e.g. a BK3000 in DP/FMS mixed mode, next to the
    /// running masters.
    Fms(fms::Args),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions(completions::Args),
    /// Print the man page dpctl(1), or write all pages with --out-dir.
    Man(completions::ManArgs),
    /// Listen only (never send) and follow another master's slaves: state,
    /// data, diagnosis, cycle times, retries, errors, masters in the ring.
    Monitor(monitor::Args),
    /// Check a serial port for PROFIBUS (8E1, baud rates, latency timer,
    /// RS-485 mode, slot time against the adapter's latency).
    Doctor(doctor::Args),
    /// Publish a DP master's slaves on an MQTT broker (JSON topics) and
    /// take output writes.
    Gateway(gateway::Args),
    /// Fault soak on the simulated bus: a master and one slave of every
    /// device profile with dropped characters, bit errors and noise.
    Soak(soak::Args),
    /// A slave's diagnosis in words, with its GSD's texts (works on a
    /// slave another master owns).
    Diag(service::DiagArgs),
    /// A slave's configuration (Get_Cfg), decoded into its GSD's modules
    /// (works on a slave another master owns).
    GetCfg(service::GetCfgArgs),
    /// Give a slave a new station address (Set_Slave_Add with the ident
    /// number read from the slave; only a slave no master parameterised
    /// takes it).
    SetAddress(service::SetAddressArgs),
    /// A slave's inputs and outputs (Rd_Inp, Rd_Outp; answered in
    /// Data_Exchange, whichever master owns it).
    ReadIo(service::ReadIoArgs),
    /// Send one Global_Control (clear, operate, sync, unsync, freeze,
    /// unfreeze) to every slave or to groups.
    GlobalControl(service::GlobalControlArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    logs::init(cli.log_format);
    // Before any runtime starts a thread: its threads inherit the policy.
    if let Some(p) = cli.rt_priority {
        if let Err(e) = profibus_io::transport::realtime::set_fifo_priority(p) {
            crate::out::errln!("dpctl: --rt-priority: {e}");
            return ExitCode::from(1);
        }
    }
    let result = match cli.command {
        Command::Decode(a) => decode::run(a),
        Command::Scan(a) => scan::run(a),
        Command::Master(a) => master::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Gsd(a) => gsd::run(a),
        Command::Slave(a) => slave::run(*a),
        Command::Bus(a) => bus::run(a),
        Command::Sniff(a) => sniff::run(a),
        Command::Report(a) => report::run(a),
        Command::Pkw(a) => pkw::run(a),
        Command::Rfid(a) => rfid::run(a),
        Command::Dpv1(a) => dpv1::run(a),
        Command::Im(a) => im::run(a),
        Command::Fms(a) => fms::run(a),
        Command::Completions(a) => completions::run(a),
        Command::Man(a) => completions::man(a),
        Command::Gateway(a) => gateway::run(a),
        Command::Soak(a) => soak::run(a),
        Command::Diag(a) => service::diag(a),
        Command::GetCfg(a) => service::get_cfg(a),
        Command::SetAddress(a) => service::set_address(a),
        Command::ReadIo(a) => service::read_io(a),
        Command::GlobalControl(a) => service::global_control(a),
        Command::Monitor(a) => monitor::run(a),
        Command::Doctor(a) => doctor::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // Nobody reads the output any more: not a failure.
        Err(e) if out::is_closed(&e) => ExitCode::SUCCESS,
        Err(e) => {
            crate::out::errln!("dpctl: {e:#}");
            ExitCode::from(1)
        }
    }
}
