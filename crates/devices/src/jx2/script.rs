//! The register line protocol: a person, a test or a script plays the
//! PLC program of a [`Plc`] with a JX2-PROFI1, one command per line, one
//! JSON reply per command.
//!
//! ```text
//! read REG [COUNT]              value(s) of REG, REG+1, …
//! write REG VALUE [VALUE…]      REGISTER_LOAD (to REG, REG+1, …)
//! copy N FROM TO                COPY (N, FROM, TO): N registers
//! calc DEST A [OP B]            DEST = A op B (+ - * / % & |), e.g. calc 100 r12118 + 1
//! wait-bit REG BIT[,BIT…] set|clear [TIMEOUT]
//!                               WHEN BIT_SET / BIT_CLEAR (default 10s; with
//!                               several bits: until any of them is so)
//! wait A CMP B [TIMEOUT]        until A CMP B (== != < <= > >=)
//! if A CMP B COMMAND…           run COMMAND when A CMP B holds
//! if-bit REG BIT set|clear COMMAND…       IF BIT_SET / BIT_CLEAR
//! label NAME / goto NAME        jumps (in scripts)
//! delay DURATION                wait, e.g. 100ms, 2s
//! status                        the module's status, error, state and LEDs decoded
//! fail-memory-test              the next reset (command 5) reports error 11
//! ```
//! A value is a number (decimal, `0x` hex, negative) or `rREG`, the
//! content of a register (`r12118`; also for COPY's count: the manual's
//! `COPY (100, 600, 12600)` after `REG 100 = …` is `copy r100 600 12600`).
//! `#` and `;` start comments. Register numbers `1xzzz` (x = the module
//! number) are the module's, all others plain PLC registers.
//!
//! Replies are JSON objects with `"cmd"` and `"ok"`; a write the module
//! ignored has `"ok": false` and `"ignored"` (why), a write that raised an
//! error has `"error"` (the number of 1x134) and `"error_text"`; a wait
//! that timed out has `"ok": false, "timeout": true`. The interpreter is
//! sans-IO: [`Interpreter::run`] executes as far as it can at `now` and
//! says when to call again.

use super::{status, ErrorNumber, Plc, WriteEffect};
use profibus_fdl::Instant;
use serde::Serialize;
use std::collections::{HashMap, VecDeque};
use std::fmt;
use std::time::Duration;

/// Default timeout of `wait-bit` and `wait`.
pub const DEFAULT_WAIT: Duration = Duration::from_secs(10);

/// A line that is not a command.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: {message}")]
pub struct ParseError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong.
    pub message: CommandError,
}

/// What is wrong with a command line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    /// Not a register number (0..=99999999).
    #[error("`{0}` is not a register number")]
    Register(String),
    /// Not a number nor `rREG`.
    #[error("`{0}` is neither a number nor rREG")]
    Operand(String),
    /// Not a comparison operator.
    #[error("`{0}` is not a comparison (== != < <= > >=)")]
    Comparison(String),
    /// Not an arithmetic operator.
    #[error("`{0}` is not an operator (+ - * / % & |)")]
    Operator(String),
    /// Not a duration.
    #[error("`{0}` is not a duration (e.g. 500ms, 5s)")]
    Duration(String),
    /// Not a bit number 0..=23.
    #[error("bit `{0}` is not 0..=23")]
    Bit(String),
    /// Neither `set` nor `clear`.
    #[error("`{0}` is neither `set` nor `clear`")]
    State(String),
    /// A `read` count out of range.
    #[error("COUNT must be 1..=1000")]
    Count,
    /// `if … label`.
    #[error("a label cannot be conditional")]
    ConditionalLabel,
    /// Wrong arguments: the command's usage.
    #[error("usage: {0}")]
    Usage(&'static str),
    /// No such command.
    #[error("unknown command `{0}`")]
    Unknown(String),
    /// A `goto` to a label the script does not have.
    #[error("no label `{0}`")]
    NoLabel(String),
}

/// A value: a number or a register's content.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Operand {
    /// A number.
    Lit(i64),
    /// The content of a register.
    Reg(u32),
}

/// A comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cmp {
    /// `==`
    Eq,
    /// `!=`
    Ne,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
}

/// An arithmetic operator of `calc`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/` (integer, toward zero; by zero gives 0)
    Div,
    /// `%`
    Rem,
    /// `&`
    And,
    /// `|`
    Or,
}

/// One command of the protocol.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `read REG [COUNT]`
    Read {
        /// First register.
        reg: u32,
        /// Registers to read.
        count: u32,
    },
    /// `write REG VALUE…`
    Write {
        /// First register.
        reg: u32,
        /// Values for REG, REG+1, ….
        values: Vec<Operand>,
    },
    /// `copy N FROM TO`
    Copy {
        /// Number of registers.
        count: Operand,
        /// First source register.
        from: u32,
        /// First destination register.
        to: u32,
    },
    /// `calc DEST A [OP B]`
    Calc {
        /// Destination register.
        dest: u32,
        /// First operand.
        a: Operand,
        /// Operator and second operand.
        rest: Option<(Op, Operand)>,
    },
    /// `wait-bit REG BIT[,BIT…] set|clear [TIMEOUT]`
    WaitBit {
        /// Register.
        reg: u32,
        /// Bits 0..=23 (a mask): any of them reaching the state ends the
        /// wait.
        bits: u32,
        /// Wait for set (true) or clear.
        set: bool,
        /// Give up after this long.
        timeout: Duration,
    },
    /// `wait A CMP B [TIMEOUT]`
    Wait {
        /// Left side.
        a: Operand,
        /// Comparison.
        cmp: Cmp,
        /// Right side.
        b: Operand,
        /// Give up after this long.
        timeout: Duration,
    },
    /// `if A CMP B COMMAND`
    If {
        /// Left side.
        a: Operand,
        /// Comparison.
        cmp: Cmp,
        /// Right side.
        b: Operand,
        /// What to do when it holds.
        then: Box<Command>,
    },
    /// `if-bit REG BIT set|clear COMMAND`
    IfBit {
        /// Register.
        reg: u32,
        /// Bit 0..=23.
        bit: u8,
        /// Test for set (true) or clear.
        set: bool,
        /// What to do when it holds.
        then: Box<Command>,
    },
    /// `label NAME`
    Label(String),
    /// `goto NAME`
    Goto(String),
    /// `delay DURATION`
    Delay(Duration),
    /// `status`
    Status,
    /// `fail-memory-test`
    FailMemoryTest,
}

fn parse_int(s: &str) -> Option<i64> {
    let (neg, t) = match s.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, s),
    };
    let v = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => i64::from_str_radix(h, 16).ok()?,
        None => t.parse::<i64>().ok()?,
    };
    Some(if neg { -v } else { v })
}

fn parse_reg(s: &str) -> Result<u32, CommandError> {
    parse_int(s)
        .filter(|v| (0..=99_999_999).contains(v))
        .map(|v| v as u32)
        .ok_or_else(|| CommandError::Register(s.to_string()))
}

fn parse_operand(s: &str) -> Result<Operand, CommandError> {
    if let Some(r) = s.strip_prefix(['r', 'R']) {
        return parse_reg(r).map(Operand::Reg);
    }
    parse_int(s)
        .map(Operand::Lit)
        .ok_or_else(|| CommandError::Operand(s.to_string()))
}

fn parse_cmp(s: &str) -> Result<Cmp, CommandError> {
    Ok(match s {
        "==" | "=" => Cmp::Eq,
        "!=" | "<>" => Cmp::Ne,
        "<" => Cmp::Lt,
        "<=" => Cmp::Le,
        ">" => Cmp::Gt,
        ">=" => Cmp::Ge,
        _ => return Err(CommandError::Comparison(s.to_string())),
    })
}

/// Parse a duration: `5s`, `500ms`, `2m`, or a number of seconds.
pub fn parse_duration(s: &str) -> Result<Duration, CommandError> {
    let bad = || CommandError::Duration(s.to_string());
    let (num, scale) = if let Some(n) = s.strip_suffix("ms") {
        (n, 0.001)
    } else if let Some(n) = s.strip_suffix('s') {
        (n, 1.0)
    } else if let Some(n) = s.strip_suffix('m') {
        (n, 60.0)
    } else {
        (s, 1.0)
    };
    let v: f64 = num.parse().map_err(|_| bad())?;
    if !(v.is_finite() && v >= 0.0 && v * scale < 1e7) {
        return Err(bad());
    }
    Ok(Duration::from_secs_f64(v * scale))
}

impl Command {
    /// Parse one line; `Ok(None)` for a blank or comment line.
    pub fn parse(line: &str) -> Result<Option<Command>, CommandError> {
        let text = line.split(['#', ';']).next().unwrap_or("").trim();
        if text.is_empty() {
            return Ok(None);
        }
        let words: Vec<&str> = text.split_whitespace().collect();
        Command::parse_words(&words).map(Some)
    }

    fn parse_words(w: &[&str]) -> Result<Command, CommandError> {
        let usage = |u: &'static str| Err(CommandError::Usage(u));
        let timeout = |s: Option<&&str>| s.map_or(Ok(DEFAULT_WAIT), |s| parse_duration(s));
        Ok(match w[0].to_ascii_lowercase().as_str() {
            "read" => match w {
                [_, r] => Command::Read {
                    reg: parse_reg(r)?,
                    count: 1,
                },
                [_, r, n] => Command::Read {
                    reg: parse_reg(r)?,
                    count: parse_int(n)
                        .filter(|n| (1..=1000).contains(n))
                        .ok_or(CommandError::Count)? as u32,
                },
                _ => return usage("read REG [COUNT]"),
            },
            "write" => match w {
                [_, r, vals @ ..] if !vals.is_empty() => Command::Write {
                    reg: parse_reg(r)?,
                    values: vals
                        .iter()
                        .map(|v| parse_operand(v))
                        .collect::<Result<_, _>>()?,
                },
                _ => return usage("write REG VALUE [VALUE...]"),
            },
            "copy" => match w {
                [_, n, from, to] => Command::Copy {
                    count: parse_operand(n)?,
                    from: parse_reg(from)?,
                    to: parse_reg(to)?,
                },
                _ => return usage("copy N FROM TO"),
            },
            "calc" => match w {
                [_, d, a] => Command::Calc {
                    dest: parse_reg(d)?,
                    a: parse_operand(a)?,
                    rest: None,
                },
                [_, d, a, op, b] => Command::Calc {
                    dest: parse_reg(d)?,
                    a: parse_operand(a)?,
                    rest: Some((
                        match *op {
                            "+" => Op::Add,
                            "-" => Op::Sub,
                            "*" => Op::Mul,
                            "/" => Op::Div,
                            "%" => Op::Rem,
                            "&" => Op::And,
                            "|" => Op::Or,
                            _ => return Err(CommandError::Operator(op.to_string())),
                        },
                        parse_operand(b)?,
                    )),
                },
                _ => return usage("calc DEST A [OP B]"),
            },
            "wait-bit" => match w {
                [_, r, b, s, rest @ ..] if rest.len() <= 1 => Command::WaitBit {
                    reg: parse_reg(r)?,
                    bits: b
                        .split(',')
                        .map(parse_bit)
                        .try_fold(0u32, |m, b| b.map(|b| m | 1 << b))?,
                    set: parse_state(s)?,
                    timeout: timeout(rest.first())?,
                },
                _ => return usage("wait-bit REG BIT[,BIT...] set|clear [TIMEOUT]"),
            },
            "if-bit" => match w {
                [_, r, b, s, then @ ..] if !then.is_empty() => Command::IfBit {
                    reg: parse_reg(r)?,
                    bit: parse_bit(b)?,
                    set: parse_state(s)?,
                    then: Box::new(conditional(then)?),
                },
                _ => return usage("if-bit REG BIT set|clear COMMAND"),
            },
            "wait" => match w {
                [_, a, c, b, rest @ ..] if rest.len() <= 1 => Command::Wait {
                    a: parse_operand(a)?,
                    cmp: parse_cmp(c)?,
                    b: parse_operand(b)?,
                    timeout: timeout(rest.first())?,
                },
                _ => return usage("wait A CMP B [TIMEOUT]"),
            },
            "if" => match w {
                [_, a, c, b, then @ ..] if !then.is_empty() => Command::If {
                    a: parse_operand(a)?,
                    cmp: parse_cmp(c)?,
                    b: parse_operand(b)?,
                    then: Box::new(conditional(then)?),
                },
                _ => return usage("if A CMP B COMMAND"),
            },
            "label" => match w {
                [_, n] => Command::Label(n.to_string()),
                _ => return usage("label NAME"),
            },
            "goto" => match w {
                [_, n] => Command::Goto(n.to_string()),
                _ => return usage("goto NAME"),
            },
            "delay" => match w {
                [_, d] => Command::Delay(parse_duration(d)?),
                _ => return usage("delay DURATION"),
            },
            "status" if w.len() == 1 => Command::Status,
            "fail-memory-test" if w.len() == 1 => Command::FailMemoryTest,
            other => return Err(CommandError::Unknown(other.to_string())),
        })
    }
}

fn parse_bit(s: &str) -> Result<u8, CommandError> {
    parse_int(s)
        .filter(|b| (0..=23).contains(b))
        .map(|b| b as u8)
        .ok_or_else(|| CommandError::Bit(s.to_string()))
}

fn parse_state(s: &str) -> Result<bool, CommandError> {
    match s.to_ascii_lowercase().as_str() {
        "set" | "1" => Ok(true),
        "clear" | "0" => Ok(false),
        _ => Err(CommandError::State(s.to_string())),
    }
}

fn conditional(words: &[&str]) -> Result<Command, CommandError> {
    let then = Command::parse_words(words)?;
    if matches!(then, Command::Label(_)) {
        return Err(CommandError::ConditionalLabel);
    }
    Ok(then)
}

fn value(plc: &mut Plc, now: Instant, o: Operand) -> i64 {
    match o {
        Operand::Lit(v) => v,
        Operand::Reg(r) => plc.read(now, r) as i64,
    }
}

fn holds(a: i64, cmp: Cmp, b: i64) -> bool {
    match cmp {
        Cmp::Eq => a == b,
        Cmp::Ne => a != b,
        Cmp::Lt => a < b,
        Cmp::Le => a <= b,
        Cmp::Gt => a > b,
        Cmp::Ge => a >= b,
    }
}

/// Names of the set status bits, for people.
pub fn status_bits(s: i32) -> Vec<&'static str> {
    [
        (status::BUFFER_OK, "buffer_ok"),
        (status::ADDRESS_OK, "address_ok"),
        (status::INITIALISED, "initialised"),
        (status::DATA_EXCHANGE, "data_exchange"),
        (status::DS_READ, "ds_read_pending"),
        (status::DS_WRITE, "ds_write_pending"),
        (status::ACYCLIC_BUSY, "acyclic_busy"),
        (status::ACYCLIC_ERROR, "acyclic_access_error"),
        (status::CIN_SENT, "consistent_inputs_sent"),
        (status::COUT_RECEIVED, "consistent_outputs_received"),
        (status::BUSY, "busy"),
        (status::ERROR, "error"),
    ]
    .iter()
    .filter(|(b, _)| s & b != 0)
    .map(|&(_, n)| n)
    .collect()
}

/// The reply to one command: `cmd` and `ok`, and the fields the command
/// has (see the module docs). `Serialize` gives the JSON object (fields
/// that a command does not have are left out); `Display` the same as one
/// line, keys sorted.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct Reply {
    /// The client it answers (`stdin`, `script`), set by the program that
    /// serves several.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub src: Option<&'static str>,
    /// The command (`read`, `write`, …); none for a line that does not
    /// parse.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cmd: Option<&'static str>,
    /// The line that does not parse.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<String>,
    /// It did what it says.
    pub ok: bool,
    /// Register (`read`, `write`, `calc`, `wait-bit`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reg: Option<u32>,
    /// The one value read, written or waited on.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub value: Option<i64>,
    /// The values read or written.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub values: Option<Vec<i64>>,
    /// Status bits by name, or the bits a `wait-bit` waits on.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bits: Option<Bits>,
    /// What the module ignored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ignored: Option<Ignored>,
    /// Registers copied.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub count: Option<i64>,
    /// First register copied from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from: Option<u32>,
    /// First register copied to.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub to: Option<u32>,
    /// The module's error number (1x134), or why the command failed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<ErrorField>,
    /// The module's error in words (`null` in a `status` without error).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_text: Option<Option<&'static str>>,
    /// `set` or `clear` (`wait-bit`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub state: Option<&'static str>,
    /// A wait ended by its timeout.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub timeout: Option<bool>,
    /// Milliseconds waited.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub waited_ms: Option<u64>,
    /// The one bit a `wait-bit` waits on.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bit: Option<u32>,
    /// The bits of several that are so.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hit: Option<Vec<u32>>,
    /// The values compared by `wait`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub a: Option<i64>,
    /// See `a`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub b: Option<i64>,
    /// Whether an `if`'s command ran (only `false` is reported: a taken
    /// `if` replies as its command).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub taken: Option<bool>,
    /// The label jumped to.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
    /// `status`: the LEDs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub leds: Option<Leds>,
    /// `status`: the status register.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub status: Option<i32>,
    /// `status`: the initialisation error register.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub init_error: Option<i32>,
    /// `status`: the DP state register.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dp_state: Option<i32>,
    /// `status`: the station address (`null` while unset).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub address: Option<Option<u8>>,
    /// `status`: diagnosis pending register.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub diag_pending: Option<i32>,
}

impl Reply {
    /// `cmd` answered `ok`.
    pub fn new(cmd: &'static str, ok: bool) -> Reply {
        Reply {
            cmd: Some(cmd),
            ok,
            ..Reply::default()
        }
    }

    /// `cmd` failed for `why`.
    fn failed(cmd: &'static str, why: String) -> Reply {
        Reply {
            error: Some(ErrorField::Text(why)),
            ..Reply::new(cmd, false)
        }
    }
}

impl fmt::Display for Reply {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match serde_json::to_value(self) {
            Ok(v) => v.fmt(f),
            Err(_) => Err(fmt::Error),
        }
    }
}

/// `bits` of a [`Reply`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(untagged)]
pub enum Bits {
    /// Status bits that are set, by name.
    Names(Vec<&'static str>),
    /// Bit numbers.
    Numbers(Vec<u32>),
}

/// `ignored` of a [`Reply`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(untagged)]
pub enum Ignored {
    /// Why the one write was ignored.
    Why(&'static str),
    /// The registers of a multi-register write that were ignored.
    Registers(Vec<IgnoredWrite>),
    /// How many registers of a copy were ignored.
    Count(u32),
}

/// One ignored write of several.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct IgnoredWrite {
    /// The register.
    pub reg: u32,
    /// Why.
    pub why: &'static str,
}

/// `error` of a [`Reply`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(untagged)]
pub enum ErrorField {
    /// The module's error number.
    Number(u8),
    /// Why the command failed.
    Text(String),
}

/// `leds` of a `status` [`Reply`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Leds {
    /// The DX LED is on.
    pub dx: bool,
    /// The ERR LED's state.
    pub err: &'static str,
}

/// What [`Interpreter::run`] needs next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Progress {
    /// Everything queued ran.
    Idle,
    /// Waiting: call again at this time, or earlier when a register may
    /// have changed.
    Waiting(Instant),
    /// More to run right away (a long loop yielded).
    Busy,
}

#[derive(Debug, Clone)]
struct Line {
    no: usize,
    cmd: Command,
}

/// Runs commands against a [`Plc`]: a whole script ([`Interpreter::script`])
/// or lines as they come ([`Interpreter::push`]).
#[derive(Debug, Clone, Default)]
pub struct Interpreter {
    program: Vec<Line>,
    labels: HashMap<String, usize>,
    pc: usize,
    /// The running wait: (start, deadline).
    wait: Option<(Instant, Instant)>,
    replies: VecDeque<Reply>,
    lines: usize,
}

/// Steps [`Interpreter::run`] takes before yielding (a loop without waits
/// must not starve the bus).
const MAX_STEPS: usize = 10_000;

impl Interpreter {
    /// An empty interpreter for lines pushed one by one.
    pub fn new() -> Interpreter {
        Interpreter::default()
    }

    /// A whole script; labels may be used before they are defined.
    pub fn script(text: &str) -> Result<Interpreter, ParseError> {
        let mut it = Interpreter::new();
        for (i, l) in text.lines().enumerate() {
            let no = i + 1;
            match Command::parse(l) {
                Ok(Some(cmd)) => it.add(no, cmd),
                Ok(None) => {}
                Err(message) => return Err(ParseError { line: no, message }),
            }
        }
        it.lines = text.lines().count();
        for l in &it.program {
            let target = match &l.cmd {
                Command::Goto(n) => Some(n),
                Command::If { then, .. } | Command::IfBit { then, .. } => match &**then {
                    Command::Goto(n) => Some(n),
                    _ => None,
                },
                _ => None,
            };
            if let Some(n) = target {
                if !it.labels.contains_key(n) {
                    return Err(ParseError {
                        line: l.no,
                        message: CommandError::NoLabel(n.clone()),
                    });
                }
            }
        }
        Ok(it)
    }

    fn add(&mut self, no: usize, cmd: Command) {
        if let Command::Label(n) = &cmd {
            self.labels.insert(n.clone(), self.program.len());
        }
        self.program.push(Line { no, cmd });
    }

    /// Queue one line; a line that does not parse gets an error reply.
    pub fn push(&mut self, line: &str) {
        self.lines += 1;
        match Command::parse(line) {
            Ok(Some(cmd)) => self.add(self.lines, cmd),
            Ok(None) => {}
            Err(e) => self.replies.push_back(Reply {
                line: Some(line.trim().to_string()),
                error: Some(ErrorField::Text(e.to_string())),
                ..Reply::default()
            }),
        }
    }

    /// The next reply.
    pub fn take_reply(&mut self) -> Option<Reply> {
        self.replies.pop_front()
    }

    /// Whether all queued commands ran.
    pub fn finished(&self) -> bool {
        self.pc >= self.program.len()
    }

    /// Run at `now` until everything queued ran, a wait blocks, or a loop
    /// yields.
    pub fn run(&mut self, plc: &mut Plc, now: Instant) -> Progress {
        for _ in 0..MAX_STEPS {
            let Some(line) = self.program.get(self.pc) else {
                return Progress::Idle;
            };
            let cmd = line.cmd.clone();
            match self.exec(plc, now, &cmd) {
                Step::Next(reply) => {
                    if let Some(r) = reply {
                        self.replies.push_back(r);
                    }
                    self.pc += 1;
                }
                Step::Jump(to, reply) => {
                    self.replies.push_back(reply);
                    self.pc = to;
                }
                Step::Blocked(until) => return Progress::Waiting(until),
            }
        }
        Progress::Busy
    }

    fn exec(&mut self, plc: &mut Plc, now: Instant, cmd: &Command) -> Step {
        match cmd {
            Command::Read { reg, count } => {
                let values: Vec<i64> = (0..*count).map(|i| plc.read(now, reg + i) as i64).collect();
                let mut r = Reply {
                    reg: Some(*reg),
                    ..Reply::new("read", true)
                };
                if *count == 1 {
                    r.value = Some(values[0]);
                    if plc.local(*reg) == Some(super::reg::STATUS) {
                        r.bits = Some(Bits::Names(status_bits(values[0] as i32)));
                    }
                } else {
                    r.values = Some(values);
                }
                Step::Next(Some(r))
            }
            Command::Write { reg, values } => {
                let vals: Vec<i64> = values.iter().map(|&o| value(plc, now, o)).collect();
                let before = plc.module.error_count();
                let mut ignored = Vec::new();
                for (i, v) in vals.iter().enumerate() {
                    if let WriteEffect::Ignored(why) = plc.write(now, reg + i as u32, *v) {
                        let reg = reg + i as u32;
                        ignored.push(IgnoredWrite { reg, why });
                    }
                }
                let mut r = Reply {
                    reg: Some(*reg),
                    ..Reply::new("write", ignored.is_empty())
                };
                if vals.len() == 1 {
                    r.value = Some(vals[0]);
                    r.ignored = ignored.first().map(|i| Ignored::Why(i.why));
                } else {
                    r.values = Some(vals);
                    if !ignored.is_empty() {
                        r.ignored = Some(Ignored::Registers(ignored));
                    }
                }
                error_fields(plc, before, &mut r);
                Step::Next(Some(r))
            }
            Command::Copy { count, from, to } => {
                let n = value(plc, now, *count);
                if !(0..=10_000).contains(&n) {
                    let why = format!("count {n} is outside 0..=10000");
                    return Step::Next(Some(Reply::failed("copy", why)));
                }
                let before = plc.module.error_count();
                let mut ignored = 0;
                for i in 0..n as u32 {
                    let v = plc.read(now, from + i);
                    if plc.write(now, to + i, v as i64) != WriteEffect::Applied {
                        ignored += 1;
                    }
                }
                let mut r = Reply {
                    count: Some(n),
                    from: Some(*from),
                    to: Some(*to),
                    ignored: (ignored > 0).then_some(Ignored::Count(ignored)),
                    ..Reply::new("copy", ignored == 0)
                };
                error_fields(plc, before, &mut r);
                Step::Next(Some(r))
            }
            Command::Calc { dest, a, rest } => {
                let a = value(plc, now, *a);
                let v = match rest {
                    None => a,
                    Some((op, b)) => {
                        let b = value(plc, now, *b);
                        match op {
                            Op::Add => a.wrapping_add(b),
                            Op::Sub => a.wrapping_sub(b),
                            Op::Mul => a.wrapping_mul(b),
                            Op::Div => a.checked_div(b).unwrap_or(0),
                            Op::Rem => a.checked_rem(b).unwrap_or(0),
                            Op::And => a & b,
                            Op::Or => a | b,
                        }
                    }
                };
                let ok = plc.write(now, *dest, v) == WriteEffect::Applied;
                Step::Next(Some(Reply {
                    reg: Some(*dest),
                    value: Some(v),
                    ..Reply::new("calc", ok)
                }))
            }
            Command::WaitBit {
                reg,
                bits,
                set,
                timeout,
            } => {
                let v = plc.read(now, *reg);
                let hit = if *set {
                    v as u32 & bits
                } else {
                    !(v as u32) & bits
                };
                let state = if *set { "set" } else { "clear" };
                let list: Vec<u32> = (0..24).filter(|b| bits & 1 << b != 0).collect();
                let which: Vec<u32> = (0..24).filter(|b| hit & 1 << b != 0).collect();
                self.wait_step(now, *timeout, hit != 0, |waited, ok| {
                    let mut r = Reply {
                        reg: Some(*reg),
                        state: Some(state),
                        value: Some(v as i64),
                        timeout: Some(!ok),
                        waited_ms: Some(waited),
                        ..Reply::new("wait-bit", ok)
                    };
                    if list.len() == 1 {
                        r.bit = Some(list[0]);
                    } else {
                        r.bits = Some(Bits::Numbers(list));
                        r.hit = Some(which);
                    }
                    r
                })
            }
            Command::IfBit {
                reg,
                bit,
                set,
                then,
            } => {
                let v = plc.read(now, *reg);
                if (v & (1 << bit) != 0) != *set {
                    return Step::Next(Some(Reply {
                        taken: Some(false),
                        ..Reply::new("if-bit", true)
                    }));
                }
                self.exec(plc, now, then)
            }
            Command::Wait { a, cmp, b, timeout } => {
                let (x, y) = (value(plc, now, *a), value(plc, now, *b));
                self.wait_step(now, *timeout, holds(x, *cmp, y), |waited, ok| Reply {
                    a: Some(x),
                    b: Some(y),
                    timeout: Some(!ok),
                    waited_ms: Some(waited),
                    ..Reply::new("wait", ok)
                })
            }
            Command::Delay(d) => {
                let (start, until) = *self.wait.get_or_insert((now, now + *d));
                if now < until {
                    return Step::Blocked(until);
                }
                self.wait = None;
                Step::Next(Some(Reply {
                    waited_ms: Some(now.saturating_duration_since(start).as_millis() as u64),
                    ..Reply::new("delay", true)
                }))
            }
            Command::If { a, cmp, b, then } => {
                let (x, y) = (value(plc, now, *a), value(plc, now, *b));
                if !holds(x, *cmp, y) {
                    return Step::Next(Some(Reply {
                        taken: Some(false),
                        ..Reply::new("if", true)
                    }));
                }
                self.exec(plc, now, then)
            }
            Command::Label(_) => Step::Next(None),
            Command::Goto(n) => match self.labels.get(n) {
                Some(&to) => Step::Jump(
                    to,
                    Reply {
                        label: Some(n.clone()),
                        ..Reply::new("goto", true)
                    },
                ),
                None => Step::Next(Some(Reply::failed("goto", format!("no label `{n}`")))),
            },
            Command::Status => {
                let m = &mut plc.module;
                let s = m.read(now, super::reg::STATUS);
                let e = m.error();
                let (dx, err) = m.leds();
                Step::Next(Some(Reply {
                    leds: Some(Leds { dx, err }),
                    status: Some(s),
                    bits: Some(Bits::Names(status_bits(s))),
                    error: Some(ErrorField::Number(e.map_or(0, |e| e.number()))),
                    error_text: Some(e.map(|e| e.as_str())),
                    init_error: Some(m.read(now, super::reg::INIT_ERROR)),
                    dp_state: Some(m.read(now, super::reg::DP_STATE)),
                    address: Some(m.station_address()),
                    diag_pending: Some(m.read(now, super::reg::DIAG_PENDING)),
                    ..Reply::new("status", true)
                }))
            }
            Command::FailMemoryTest => {
                plc.module.fail_memory_test();
                Step::Next(Some(Reply::new("fail-memory-test", true)))
            }
        }
    }

    fn wait_step(
        &mut self,
        now: Instant,
        timeout: Duration,
        done: bool,
        reply: impl FnOnce(u64, bool) -> Reply,
    ) -> Step {
        let (start, deadline) = *self.wait.get_or_insert((now, now + timeout));
        let waited = now.saturating_duration_since(start).as_millis() as u64;
        if done || now >= deadline {
            self.wait = None;
            return Step::Next(Some(reply(waited, done)));
        }
        Step::Blocked(deadline)
    }
}

fn error_fields(plc: &Plc, before: u64, r: &mut Reply) {
    if plc.module.error_count() != before {
        if let Some(e) = plc.module.error() {
            r.error = Some(ErrorField::Number(e.number()));
            r.error_text = Some(Some(e.as_str()));
            r.ok = false;
        }
    }
}

enum Step {
    Next(Option<Reply>),
    Jump(usize, Reply),
    Blocked(Instant),
}

/// The error numbers 1..=12 with their meaning (for documentation and
/// `status`).
pub fn error_text(n: u8) -> Option<&'static str> {
    [
        ErrorNumber::Address,
        ErrorNumber::CyclicArea,
        ErrorNumber::AcyclicArea,
        ErrorNumber::ControllerInit,
        ErrorNumber::Prm,
        ErrorNumber::Cfg,
        ErrorNumber::DiagLength,
        ErrorNumber::DiagPending,
        ErrorNumber::MemoryTest,
        ErrorNumber::ConsistentArea,
    ]
    .into_iter()
    .find(|e| e.number() == n)
    .map(|e| e.as_str())
}
