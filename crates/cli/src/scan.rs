//! `dpctl scan`: live list of the stations on a bus.

use crate::common::{self, LineArgs};
use anyhow::{bail, Result};
use profibus_dp::scan::{LiveListScan, LiveRow};
use profibus_fdl::station::active::{ActiveConfig, ActiveStation, RingState};
use profibus_fdl::BusParams;
use profibus_io::driver::{self, Clock, Stop};
use std::ops::ControlFlow;
use std::time::Duration;

/// Join the bus as a master and list every station that answers FDL
/// Status, with the ident number of DP slaves.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    line: LineArgs,
    /// This station's address while scanning.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(0..=125))]
    addr: u8,
    /// Give up after this many seconds.
    #[arg(long, default_value_t = 30.0, value_name = "SECS")]
    timeout: f64,
    /// Print one JSON object per station.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> Result<()> {
    common::runtime()?.block_on(scan(args))
}

async fn scan(args: Args) -> Result<()> {
    let mut cfg = ActiveConfig::new(args.addr, BusParams::defaults(args.line.baud));
    let mut port = args.line.open()?;
    common::allow_for_port(&mut cfg, args.line.latency, &port)?;
    let mut station = ActiveStation::new(cfg, LiveListScan::new(args.addr));
    let limit = Duration::from_secs_f64(args.timeout.max(0.0));
    let deadline = tokio::time::sleep(limit);
    let stop = driver::run_with(
        &mut station,
        &mut port,
        Clock::start(),
        driver::Options::default(),
        async {
            tokio::select! {
                _ = common::shutdown() => {}
                _ = deadline => {}
            }
        },
        |st, _| {
            if st.app().is_done() {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
    )
    .await?;
    if stop == Stop::Shutdown && !station.app().is_done() {
        if station.ring_state() == RingState::ListenToken {
            bail!(
                "no token within {:.0} s: not invited into the ring",
                limit.as_secs_f64()
            );
        }
        bail!("scan did not finish within {:.0} s", limit.as_secs_f64());
    }
    let mut rows: Vec<LiveRow> = vec![LiveRow::scanner(args.addr)];
    rows.extend(station.app().stations().iter().map(|&s| LiveRow::from(s)));
    rows[1..].sort_by_key(|r| r.station.address);
    for row in rows {
        if args.json {
            crate::out::outln!("{}", common::json_line(&row))?;
        } else {
            crate::out::outln!("{row}")?;
        }
    }
    Ok(())
}
