//! `dpctl decode HEX...`: decode telegram bytes.

use crate::describe;
use anyhow::{bail, Context};
use profibus_fdl::wire::Telegram;

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
    let digits: String = parts
        .iter()
        .flat_map(|p| p.split(|c: char| c.is_whitespace() || c == ':' || c == ','))
        .map(|p| p.trim_start_matches("0x").trim_start_matches("0X"))
        .map(|p| {
            if p.len() == 1 {
                format!("0{p}")
            } else {
                p.to_string()
            }
        })
        .collect();
    if !digits.len().is_multiple_of(2) {
        bail!("odd number of hex digits");
    }
    (0..digits.len())
        .step_by(2)
        .map(|i| {
            u8::from_str_radix(&digits[i..i + 2], 16)
                .with_context(|| format!("`{}` is not a hex byte", &digits[i..i + 2]))
        })
        .collect()
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let bytes = parse_hex(&args.hex)?;
    let mut rest = &bytes[..];
    let mut offset = 0;
    while !rest.is_empty() {
        let (t, n) = Telegram::parse(rest)
            .with_context(|| format!("malformed telegram at byte {offset}"))?;
        if args.json {
            println!("{}", describe::json(&t, &rest[..n]));
        } else {
            println!("{}", describe::line(&t));
        }
        rest = &rest[n..];
        offset += n;
    }
    Ok(())
}
