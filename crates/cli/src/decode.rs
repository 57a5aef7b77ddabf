//! `dpctl decode HEX...`: decode telegram bytes.

use crate::common;
use crate::out::outln;
use profibus_dp::fms::decode::FmsTelegram;
use profibus_dp::pdu::decode::{Exchanges, Layer};
use profibus_dp::pdu::describe::{summaries, TelegramSummary};

/// Decode one or more telegrams given as hex bytes. A telegram of an FMS
/// connection (both SAPs, the server's 0…48, an LLI or FMS PDU in its
/// data unit) also gets its LLI and FMS PDUs in words, as `dpctl sniff`
/// prints them (docs/fms.md).
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

/// One line of `--json`: the telegram, and its FMS PDUs like `dpctl
/// sniff --json`'s `"fms"` object.
#[derive(serde::Serialize)]
struct Decoded<'a> {
    #[serde(flatten)]
    what: TelegramSummary<'a>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fms: Option<FmsTelegram>,
}

pub fn parse_hex(parts: &[String]) -> anyhow::Result<Vec<u8>> {
    Ok(profibus_fdl::wire::parse_hex(&parts.join(" "))?)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let bytes = parse_hex(&args.hex)?;
    // Telegrams in a row are a stream: a poll or an empty answer on an
    // FMS connection seen before is FMS too (the sniffer's rule).
    let mut exchanges = Exchanges::default();
    for summary in summaries(&bytes) {
        let mut what = summary?;
        let fms = match exchanges.decode_layer(&what.telegram) {
            Some(Layer::Fms(f)) => {
                what.service_sap = Some("FMS");
                Some(*f)
            }
            _ => None,
        };
        if args.json {
            outln!("{}", common::json_line(&Decoded { what, fms }))?;
        } else if let Some(fms) = fms {
            outln!("{what} | {fms}")?;
        } else {
            outln!("{what}")?;
        }
    }
    Ok(())
}
