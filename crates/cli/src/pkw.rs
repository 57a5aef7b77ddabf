//! `dpctl pkw`: read or write one parameter of a slave through its PKW
//! channel (BM4-O-PRO-01, Omega Drive-Line II).
//!
//! Runs the DP master of the bus file like `dpctl master`; once the slave
//! is in Data_Exchange, the PKW client (`profibus_devices::pkw::client`)
//! runs the handshake over its cyclic data. Exit 0 with the result in
//! words (or one JSON line), 1 with the decoded error on a PKW error, a
//! timeout, or a slave that does not reach Data_Exchange.

use crate::common;
use anyhow::{bail, Context, Result};
use profibus_devices::pkw::client::{PkwAnswer, PkwClient, PkwError};
use profibus_devices::pkw::{Command, Dialect, Reply};
use profibus_dp::busfile::{BusFile, BusSlave};
use std::ops::ControlFlow;
use std::time::Duration;

/// Read or write a parameter over the PKW channel of a slave.
///
/// P is a parameter number (218, P218, 0x7E) or, for a BM4-O-PRO-01, the
/// name of a variable module of its GSD (di_MyReadVar3); `P[i]` is array
/// element i.
#[derive(clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The line, the bus file, the slave.
    #[command(flatten)]
    link: common::SlaveArgs,
    /// Milliseconds to wait for the PKW response.
    #[arg(long, global = true, value_name = "MS", default_value_t = 2000)]
    timeout: u64,
    /// Print one JSON object.
    #[arg(long, global = true)]
    json: bool,
    #[command(subcommand)]
    op: Op,
}

/// What to do.
#[derive(clap::Subcommand)]
enum Op {
    /// Read parameter P (or array element P[i]).
    Read {
        /// Parameter.
        #[arg(value_name = "P")]
        param: String,
    },
    /// Write V to parameter P: `P=V` (V decimal, 0x hex or negative).
    /// Word or double word as the parameter is (read first), unless
    /// --word or --dword says.
    Write {
        /// `P=V`.
        #[arg(value_name = "P=V")]
        assignment: String,
        /// Use the word write command.
        #[arg(long, conflicts_with = "dword")]
        word: bool,
        /// Use the double word write command.
        #[arg(long)]
        dword: bool,
    },
    /// Read an element of the parameter description (Omega: PBE).
    Describe {
        /// Parameter.
        #[arg(value_name = "P")]
        param: String,
        /// attribute, info, min or max.
        #[arg(value_name = "ATTR")]
        attr: String,
    },
}

/// A parameter reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Param {
    pnu: u16,
    index: Option<u16>,
}

fn parse_num(s: &str) -> Option<i64> {
    let s = s.trim();
    let (neg, s) = match s.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, s),
    };
    let v = if let Some(h) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        i64::from_str_radix(h, 16).ok()?
    } else if let Some(h) = s.strip_prefix("16#") {
        i64::from_str_radix(&h.replace('_', ""), 16).ok()?
    } else {
        s.parse().ok()?
    };
    Some(if neg { -v } else { v })
}

fn parse_param(s: &str, slave: &BusSlave) -> Result<Param> {
    let (name, index) = match s.split_once('[') {
        Some((n, i)) => {
            let i = i
                .strip_suffix(']')
                .and_then(parse_num)
                .filter(|i| (0..=0xFFFF).contains(i))
                .with_context(|| format!("bad array index in `{s}`"))?;
            (n, Some(i as u16))
        }
        None => (s, None),
    };
    let num = name.strip_prefix(['P', 'p']).unwrap_or(name);
    let pnu = match parse_num(num) {
        Some(n) if (0..=2047).contains(&n) => n as u16,
        Some(n) => bail!("parameter number {n} is outside 0..=2047"),
        // A name the device gives a parameter (a BM4 variable module).
        None => profibus_devices::pkw_parameter(slave.params.ident_number, &slave.gsd, name)
            .with_context(|| {
                format!(
                    "`{name}` is neither a parameter number nor a variable module of {}",
                    slave.gsd_path.display()
                )
            })?,
    };
    Ok(Param { pnu, index })
}

/// The jobs to run, in order.
fn plan(op: &Op, slave: &BusSlave, dialect: &Dialect) -> Result<(Param, Vec<Step>)> {
    Ok(match op {
        Op::Read { param } => {
            let p = parse_param(param, slave)?;
            let cmd = match p.index {
                Some(i) => Command::ReadElement(i),
                None => Command::Read,
            };
            (p, vec![Step::Run(cmd)])
        }
        Op::Describe { param, attr } => {
            let p = parse_param(param, slave)?;
            let ind = match attr.as_str() {
                "attribute" => 1,
                "info" => 2,
                "min" => 5,
                "max" => 6,
                other => bail!("unknown description element `{other}` (attribute, info, min, max)"),
            };
            if dialect.describe.is_none() {
                bail!(
                    "the {} has no parameter description (PBE) command",
                    dialect.name
                );
            }
            (p, vec![Step::Run(Command::Describe(ind))])
        }
        Op::Write {
            assignment,
            word,
            dword,
        } => {
            let (ps, vs) = assignment.split_once('=').context("write takes P=V")?;
            let p = parse_param(ps.trim(), slave)?;
            let v = parse_num(vs).with_context(|| format!("`{vs}` is not a number"))?;
            if !(-(1i64 << 31)..=0xFFFF_FFFF).contains(&v) {
                bail!("{v} does not fit 32 bits");
            }
            let v = v as u32;
            let dword = if *word {
                Some(false)
            } else if *dword || p.pnu >= 1000 && dialect.describe.is_some() {
                Some(true)
            } else {
                None
            };
            let mut steps = vec![];
            if dword.is_none() {
                steps.push(Step::Probe(match p.index {
                    Some(i) => Command::ReadElement(i),
                    None => Command::Read,
                }));
            }
            steps.push(Step::Write {
                value: v,
                dword,
                index: p.index,
            });
            (p, steps)
        }
    })
}

#[derive(Debug, Clone, Copy)]
enum Step {
    /// Read to learn the format (word or double word).
    Probe(Command),
    Run(Command),
    Write {
        value: u32,
        dword: Option<bool>,
        index: Option<u16>,
    },
}

fn write_command(value: u32, dword: bool, index: Option<u16>) -> Command {
    match (index, dword) {
        (None, false) => Command::WriteWord(value as u16),
        (None, true) => Command::WriteDword(value),
        (Some(index), false) => Command::WriteElementWord {
            index,
            value: value as u16,
        },
        (Some(index), true) => Command::WriteElementDword { index, value },
    }
}

fn describe_attr(ind: u16, v: u16) -> String {
    match ind {
        1 => {
            let len = [1, 2, 4, 8][(v & 3) as usize];
            let ty = ["SIGNED", "UNSIGNED", "FLOAT", "reserved type"][(v >> 2 & 3) as usize];
            let num = if v >> 4 & 3 == 0 { "FIXED" } else { "VARIABLE" };
            let el = if v >> 6 & 3 == 0 { "DATA" } else { "COMMAND" };
            let disp = match v >> 8 & 0xF {
                0 => "BIN",
                1 => "DEC",
                2 => "HEX",
                4 => "NORM",
                5 => "FIX",
                6 => "SCI",
                7 => "ENG",
                8 => "ASCII",
                _ => "reserved display",
            };
            format!(
                "{len} bytes, {ty}, {num}, {el}, display {disp}, {} decimals",
                v >> 12
            )
        }
        2 => format!(
            "{}, {}",
            if v & 7 == 1 {
                "write-protected"
            } else {
                "not protected"
            },
            if v & 8 != 0 { "STORE" } else { "NONSTORE" }
        ),
        _ => String::new(),
    }
}

pub fn run(args: Args) -> Result<()> {
    let bus = profibus_devices::bus::ProfiledBus::load(&args.link.config)?.file;
    common::runtime()?.block_on(pkw(args, bus))
}

async fn pkw(args: Args, bus: BusFile) -> Result<()> {
    let slave = args.link.slave_of(&bus)?.clone();
    let dialect = profibus_devices::pkw_dialect(slave.params.ident_number, &slave.params.cfg)
        .map_err(|e| anyhow::anyhow!("slave {}: {e}", args.link.slave))?;
    let (param, mut steps) = plan(&args.op, &slave, dialect)?;
    steps.reverse();
    let addr = args.link.slave;
    let mut client = PkwClient::new(dialect, Duration::from_millis(args.timeout.max(1)));
    let mut wait = args.link.wait();
    let mut outcome: Option<Result<PkwAnswer, PkwError>> = None;
    let mut failure: Option<anyhow::Error> = None;
    let mut probe: Option<Reply> = None;
    let mut inflight: Option<Step> = None;
    args.link
        .run_master(&bus, |m, now| {
            match wait.check(m, now, !client.is_idle()) {
                Ok(false) if client.is_idle() => return ControlFlow::Continue(()),
                Ok(_) => {}
                Err(e) => {
                    failure = Some(e.into());
                    return ControlFlow::Break(());
                }
            }
            let Some(h) = m.handle(addr) else {
                return ControlFlow::Continue(());
            };
            if let Some(r) = client.drive(now, m, h) {
                match (r, inflight.take()) {
                    (Ok(a), Some(Step::Probe(_))) => probe = Some(a.reply),
                    (r, _) => {
                        outcome = Some(r);
                        steps.clear();
                    }
                }
            }
            if client.is_idle() {
                let Some(step) = steps.pop() else {
                    return ControlFlow::Break(());
                };
                let cmd = match step {
                    Step::Probe(c) | Step::Run(c) => c,
                    Step::Write {
                        value,
                        dword,
                        index,
                    } => write_command(
                        value,
                        dword.unwrap_or_else(|| probe.is_some_and(|p| p.is_dword())),
                        index,
                    ),
                };
                if let Err(e) = client.start(now, param.pnu, cmd) {
                    failure = Some(e.into());
                    return ControlFlow::Break(());
                }
                inflight = Some(step);
            }
            ControlFlow::Continue(())
        })
        .await?;
    if let Some(f) = failure {
        return Err(f);
    }
    let answer = match outcome {
        Some(Ok(a)) => a,
        Some(Err(e)) => {
            if args.json {
                let line = Refused {
                    slave: addr,
                    pnu: param.pnu,
                    index: param.index,
                    ok: false,
                    error: e.to_string(),
                    code: match &e {
                        PkwError::Refused { code, .. } => Some(*code),
                        _ => None,
                    },
                };
                println!("{}", common::json_line(&line));
            }
            bail!("slave {addr} P{}: {e}", param.pnu);
        }
        None => bail!("no result"),
    };
    print_answer(&args, dialect, param, &answer);
    Ok(())
}

/// `--json`: the slave refused or did not answer.
#[derive(serde::Serialize)]
struct Refused {
    slave: u8,
    pnu: u16,
    index: Option<u16>,
    ok: bool,
    error: String,
    code: Option<u16>,
}

/// `--json`: the answer.
#[derive(serde::Serialize)]
struct Answered {
    slave: u8,
    device: &'static str,
    op: &'static str,
    pnu: u16,
    index: Option<u16>,
    ok: bool,
    format: &'static str,
    value: u32,
    signed: i64,
    hex: String,
    request: String,
    response: String,
    pke: String,
    ind: u16,
    pwe1: String,
    pwe2: String,
    words: Option<String>,
}

fn print_answer(args: &Args, dialect: &Dialect, param: Param, a: &PkwAnswer) {
    let value = a.reply.value();
    let (format, signed) = if a.reply.is_dword() {
        ("double word", value as i32 as i64)
    } else {
        ("word", value as u16 as i16 as i64)
    };
    let op = match args.op {
        Op::Read { .. } => "read",
        Op::Write { .. } => "write",
        Op::Describe { .. } => "describe",
    };
    let element = match a.reply {
        Reply::Element(v) => Some(describe_attr(a.request.ind, v)).filter(|s| !s.is_empty()),
        _ => None,
    };
    let name = match param.index {
        Some(i) => format!("P{}[{i}]", param.pnu),
        None => format!("P{}", param.pnu),
    };
    if args.json {
        let dword = a.reply.is_dword();
        let line = Answered {
            slave: args.link.slave,
            device: dialect.name,
            op,
            pnu: param.pnu,
            index: param.index,
            ok: true,
            format: if dword { "dword" } else { "word" },
            value,
            signed,
            hex: format!("0x{value:0width$X}", width = if dword { 8 } else { 4 }),
            request: a.request.to_string(),
            response: a.response.to_string(),
            pke: format!("0x{:04X}", a.response.pke),
            ind: a.response.ind,
            pwe1: format!("0x{:04X}", a.response.pwe1),
            pwe2: format!("0x{:04X}", a.response.pwe2),
            words: element,
        };
        println!("{}", common::json_line(&line));
    } else {
        let what = match &args.op {
            Op::Describe { attr, .. } => format!("{name} {attr}"),
            _ => name,
        };
        let verb = if op == "write" { ":=" } else { "=" };
        print!("{what} {verb} {value} (0x{value:X}, {format}");
        if signed != value as i64 {
            print!(", signed {signed}");
        }
        print!(")");
        if let Some(e) = element {
            print!(": {e}");
        }
        println!("  [request {}, response {}]", a.request, a.response);
    }
}
