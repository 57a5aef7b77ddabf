//! Terminals the catalogue lacks, described by the user in a small TOML
//! table (bus file `terminal_types`, or a file named by
//! `--device-opt terminal-types-file=FILE`), one table per terminal
//! name:
//!
//! ```toml
//! [KL3404]                      # the name used in `terminals`
//! type = "complex"              # "digital", "complex" or "passive"
//! summary = "4 analog inputs -10..+10 V"
//! channels = 4
//! bytes_in = 12                 # the whole terminal, complete mapping
//! bytes_out = 12
//! status = true                 # each channel starts with status/control
//! cfg = "B2 B2 B2 B2"           # identifier bytes of that mapping
//! compact_cfg = "50 50 50 50"   # optional data-only mapping …
//! compact_bytes_in = 8          # … with its sizes
//! compact_bytes_out = 0
//! range = [-10.0, 10.0]         # optional: engineering range of 0x8000..0x7FFF
//! unit = "V"
//! sim = "sine"                  # sine, temperature, counter, echo, walk, none
//! registers = { R8 = 3404, R32 = 0x0006 }  # register defaults, every channel
//!
//! [KL1889]
//! type = "digital"
//! bits_in = 16
//! bits_out = 0
//! ```
//!
//! A complex terminal's bytes are split evenly over its channels; with
//! `status = true` the first byte of a channel is its status byte (in)
//! and control byte (out), the next 1, 2 or 4 bytes its value (a longer
//! rest: a 16-bit value and unused bytes). Descriptions live for the
//! whole program (the catalogue is static).

use super::catalogue::{
    self, Class, Field, Mapping, Role, Scale, Sim, Source, TerminalType, Variant,
};
use serde::Deserialize;
use std::collections::BTreeMap;

/// Why a user terminal description is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("terminal type `{name}`: {message}")]
pub struct UserTerminalError {
    /// The terminal's name.
    pub name: String,
    /// What is wrong.
    pub message: String,
}

/// One terminal as the user describes it; see the module docs.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UserTerminal {
    /// `digital`, `complex` or `passive`.
    #[serde(rename = "type")]
    pub kind: String,
    /// One line for people.
    pub summary: Option<String>,
    /// Digital input bits.
    pub bits_in: u8,
    /// Digital output bits.
    pub bits_out: u8,
    /// Channels of a complex terminal (default 1).
    pub channels: Option<u8>,
    /// Input bytes of a complex terminal (complete mapping).
    pub bytes_in: u8,
    /// Output bytes of a complex terminal.
    pub bytes_out: u8,
    /// Each channel starts with a status (in) and control (out) byte.
    pub status: bool,
    /// The identifier bytes (hex) of the complete mapping.
    pub cfg: Option<String>,
    /// The identifier bytes of a data-only mapping.
    pub compact_cfg: Option<String>,
    /// Input bytes of the data-only mapping.
    pub compact_bytes_in: u8,
    /// Output bytes of the data-only mapping.
    pub compact_bytes_out: u8,
    /// Engineering values of raw -0x8000 (or 0) and 0x7FFF.
    pub range: Option<[f64; 2]>,
    /// Unit of `range`.
    pub unit: Option<String>,
    /// What the emulation simulates.
    pub sim: Option<String>,
    /// Register defaults (`R8 = 3404` or `8 = 3404`), every channel.
    pub registers: BTreeMap<String, u16>,
}

fn leak<T>(v: Vec<T>) -> &'static [T] {
    Vec::leak(v)
}

fn leak_str(s: String) -> &'static str {
    String::leak(s)
}

/// Hex bytes: `"B2 B2"`, `"0xB2,0xB2"`.
fn hex_bytes(s: &str) -> Option<Vec<u8>> {
    let v: Option<Vec<u8>> = s
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty())
        .map(|t| {
            let t = t.trim_start_matches("0x").trim_start_matches("0X");
            u8::from_str_radix(t, 16).ok()
        })
        .collect();
    v.filter(|v| !v.is_empty())
}

/// The fields of `bytes` bytes split over `channels` channels.
fn fields(channels: u8, bytes: u8, status: bool, dir_in: bool) -> Result<Vec<Field>, String> {
    if bytes == 0 {
        return Ok(vec![]);
    }
    if channels == 0 || !bytes.is_multiple_of(channels) {
        return Err(format!(
            "{bytes} bytes do not split evenly over {channels} channels"
        ));
    }
    let per = bytes / channels;
    let mut out = vec![];
    for c in 0..channels {
        let base = c * per;
        let ch = c + 1;
        let mut at = 0;
        if status {
            let role = if dir_in { Role::Status } else { Role::Control };
            out.push(Field {
                channel: ch,
                role,
                offset: base,
                bytes: 1,
            });
            at = 1;
        }
        let rest = per - at;
        match rest {
            0 => {}
            1 | 2 | 4 => out.push(Field {
                channel: ch,
                role: Role::Value,
                offset: base + at,
                bytes: rest,
            }),
            _ => {
                out.push(Field {
                    channel: ch,
                    role: Role::Value,
                    offset: base + at,
                    bytes: 2,
                });
                for k in at + 2..per {
                    out.push(Field {
                        channel: ch,
                        role: Role::Reserved,
                        offset: base + k,
                        bytes: 1,
                    });
                }
            }
        }
    }
    Ok(out)
}

impl UserTerminal {
    /// The catalogue entry of this description named `name`.
    pub fn build(&self, name: &str) -> Result<&'static TerminalType, UserTerminalError> {
        let err = |m: String| UserTerminalError {
            name: name.to_string(),
            message: m,
        };
        if name.is_empty() || name.contains([',', ':', '#', ' ']) {
            return Err(err("a terminal name has no blanks, `,`, `:` or `#`".into()));
        }
        if catalogue::lookup(name).is_some() {
            return Err(err("the catalogue has it already; pick another name".into()));
        }
        let mut registers = vec![];
        for (k, v) in &self.registers {
            let r: u8 = k
                .trim_start_matches(['R', 'r'])
                .parse()
                .ok()
                .filter(|r| *r < 64)
                .ok_or_else(|| err(format!("register `{k}`: registers are R0..R63")))?;
            registers.push((r, *v));
        }
        let sim = match self.sim.as_deref() {
            None => None,
            Some("sine") => Some(Sim::Sine),
            Some("temperature") => Some(Sim::Temperature),
            Some("counter") => Some(Sim::Counter),
            Some("echo") => Some(Sim::Echo),
            Some("walk") => Some(Sim::Walk),
            Some("none") => Some(Sim::None),
            Some(o) => {
                return Err(err(format!(
                    "sim `{o}`: one of sine, temperature, counter, echo, walk, none"
                )))
            }
        };
        let scale = match (self.range, &self.unit) {
            (Some([lo, hi]), unit) if hi > lo => {
                let unit = leak_str(unit.clone().unwrap_or_default());
                if lo == 0.0 {
                    Scale::Positive { full: hi, unit }
                } else if lo == -hi {
                    Scale::Signed { full: hi, unit }
                } else {
                    Scale::Span { lo, hi, unit }
                }
            }
            (Some(_), _) => return Err(err("range = [low, high] with low < high".into())),
            (None, _) => Scale::Count,
        };
        let summary = leak_str(
            self.summary
                .clone()
                .unwrap_or_else(|| format!("{name} (described by the user)")),
        );
        let name = leak_str(name.to_string());
        let base = TerminalType {
            name,
            summary,
            class: Class::Passive,
            channels: 0,
            scale,
            variants: &[],
            sim: sim.unwrap_or(Sim::None),
            registers: leak(registers),
            source: Source::User,
        };
        let ty = match self.kind.as_str() {
            "passive" => base,
            "digital" => {
                let (i, o) = (self.bits_in, self.bits_out);
                let (class, channels) = match (i, o) {
                    (0, 0) => return Err(err("a digital terminal needs bits_in or bits_out".into())),
                    (i, 0) => (Class::DigitalIn, i),
                    (0, o) => (Class::DigitalOut, o),
                    (i, o) if i == o => (Class::DigitalInOut, i),
                    _ => {
                        return Err(err(
                            "bits_in and bits_out differ; the emulation takes equal counts or one direction".into(),
                        ))
                    }
                };
                TerminalType {
                    class,
                    channels,
                    scale: Scale::Bit,
                    sim: sim.unwrap_or(if i > 0 { Sim::Walk } else { Sim::None }),
                    ..base
                }
            }
            "complex" => {
                let channels = self.channels.unwrap_or(1);
                let cfg = self.cfg.as_deref().ok_or_else(|| {
                    err("a complex terminal needs cfg (its identifier bytes)".into())
                })?;
                let cfg =
                    hex_bytes(cfg).ok_or_else(|| err(format!("cfg `{cfg}` is not hex bytes")))?;
                if self.bytes_in == 0 && self.bytes_out == 0 {
                    return Err(err("a complex terminal needs bytes_in or bytes_out".into()));
                }
                let src = "described by the user";
                let mut variants = vec![Variant {
                    mapping: Mapping::Complete,
                    cfg: leak(cfg),
                    in_len: self.bytes_in,
                    out_len: self.bytes_out,
                    inputs: leak(fields(channels, self.bytes_in, self.status, true).map_err(err)?),
                    outputs: leak(
                        fields(channels, self.bytes_out, self.status, false).map_err(err)?,
                    ),
                    source: src,
                }];
                if let Some(c) = self.compact_cfg.as_deref() {
                    let bytes = hex_bytes(c)
                        .ok_or_else(|| err(format!("compact_cfg `{c}` is not hex bytes")))?;
                    variants.push(Variant {
                        mapping: Mapping::Compact,
                        cfg: leak(bytes),
                        in_len: self.compact_bytes_in,
                        out_len: self.compact_bytes_out,
                        inputs: leak(
                            fields(channels, self.compact_bytes_in, false, true).map_err(err)?,
                        ),
                        outputs: leak(
                            fields(channels, self.compact_bytes_out, false, false).map_err(err)?,
                        ),
                        source: src,
                    });
                }
                TerminalType {
                    class: Class::Complex,
                    channels,
                    variants: leak(variants),
                    sim: sim.unwrap_or(if self.bytes_in > 0 {
                        Sim::Sine
                    } else {
                        Sim::None
                    }),
                    ..base
                }
            }
            other => {
                return Err(err(format!(
                    "type `{other}`: one of digital, complex, passive"
                )))
            }
        };
        Ok(Box::leak(Box::new(ty)))
    }
}

/// The terminal types of a table `{ NAME = { … }, … }`.
pub fn parse_table(table: &toml::Table) -> Result<Vec<&'static TerminalType>, UserTerminalError> {
    let mut out = vec![];
    for (name, v) in table {
        let t: UserTerminal =
            v.clone()
                .try_into()
                .map_err(|e: toml::de::Error| UserTerminalError {
                    name: name.clone(),
                    message: e.message().to_string(),
                })?;
        out.push(t.build(name)?);
    }
    Ok(out)
}

/// The terminal types of a TOML text (a terminal-types file).
pub fn parse_text(text: &str) -> Result<Vec<&'static TerminalType>, String> {
    let table: toml::Table = text.parse().map_err(|e: toml::de::Error| e.to_string())?;
    parse_table(&table).map_err(|e| e.to_string())
}
