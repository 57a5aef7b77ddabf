//! `dpctl decode HEX...`: decode telegram bytes.

use crate::common;
use crate::out::outln;
use profibus_dp::pdu::describe::summaries;

/// Decode one or more telegrams given as hex bytes.
#[derive(clap::Args)]
pub struct Args {
    /// Telegram bytes in hex: separate arguments (`10 02 08 00 0A 16`) or
    /// joined (`1002080000A16`, `10:02:08`); several telegrams in a row
    /// are decoded one after another.
    #[arg(required = true, value_name = "HEX")]
    hex: Vec<String>,
    /// Print one JSON object per telegram.
    #[arg(long)]
    json: bool,
}

pub fn parse_hex(parts: &[String]) -> anyhow::Result<Vec<u8>> {
    Ok(profibus_fdl::wire::parse_hex(&parts.join(" "))?)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let bytes = parse_hex(&args.hex)?;
    for summary in summaries(&bytes) {
        let summary = summary?;
        if args.json {
            outln!("{}", common::json_line(&summary))?;
        } else {
            outln!("{summary}")?;
        }
    }
    Ok(())
}
