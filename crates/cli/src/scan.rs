//! `dpctl scan`: live list of the stations on a bus.

use crate::common::{self, LineArgs};
use anyhow::{bail, Result};
use profibus_dp::scan::LiveListScan;
use profibus_fdl::driver::{self, Clock, Stop};
use profibus_fdl::station::active::{ActiveConfig, ActiveStation, RingState};
use profibus_fdl::wire::StationType;
use profibus_fdl::BusParams;
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
    cfg.latency_allowance = common::latency(args.line.latency, &port)?;
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
    let own = args.addr;
    let mut rows: Vec<_> = station.app().stations().to_vec();
    rows.sort_by_key(|s| s.address);
    if args.json {
        let row = Row {
            address: own,
            kind: "active, in ring",
            this: true,
            ident: None,
            master: None,
        };
        println!("{}", common::json_line(&row));
    } else {
        println!("{own:3}  active, in ring (this scanner)");
    }
    for s in rows {
        let kind = s.station.describe();
        if args.json {
            let row = Row {
                address: s.address,
                kind,
                this: false,
                ident: s.ident_number.map(|id| format!("0x{id:04X}")),
                // 255: no master (not parameterised).
                master: s.master_address.map(|m| (m != 255).then_some(m)),
            };
            println!("{}", common::json_line(&row));
        } else {
            let mut line = format!("{:3}  {kind}", s.address);
            if s.station == StationType::Passive {
                match (s.ident_number, s.master_address) {
                    (Some(id), Some(255)) => {
                        line.push_str(&format!(", DP slave ident 0x{id:04X}, not parameterised"))
                    }
                    (Some(id), Some(m)) => line.push_str(&format!(
                        ", DP slave ident 0x{id:04X}, parameterised by master {m}"
                    )),
                    _ => line.push_str(", no DP diagnosis"),
                }
            }
            println!("{line}");
        }
    }
    Ok(())
}

/// A station of the live list, `--json`.
#[derive(serde::Serialize)]
struct Row {
    address: u8,
    #[serde(rename = "type")]
    kind: &'static str,
    #[serde(rename = "self", skip_serializing_if = "std::ops::Not::not")]
    this: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    ident: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    master: Option<Option<u8>>,
}
