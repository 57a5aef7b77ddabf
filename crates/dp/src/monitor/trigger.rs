//! Trigger expressions and a triggered recorder: what a bus analyser
//! watches for, and the telegrams it keeps around each firing.
//!
//! A [`Trigger`] is a boolean expression over what one telegram (or one
//! run of skipped bytes) shows: its addresses, service, SAPs, function
//! code, the Slave_Diag bits it carries, the errors around it and the
//! state changes it causes, and the time. [`Watch`] turns a stream of
//! [`TapEvent`]s into [`Observation`]s (it follows the traffic with a
//! [`Monitor`] and pairs responses with requests with
//! [`Exchanges`], so a short acknowledge or a diagnosis answer is read
//! by its request); [`Trigger::matches`] says whether an observation
//! fires it. [`Recorder`] keeps a ring of the last `pre` records and
//! hands out segments: `pre` records before a firing, the firing, and
//! `post` after; a firing inside a window extends it (overlapping
//! windows merge into one segment). Everything here is sans-IO: events
//! in, decisions out (`dpctl sniff --trigger` writes the segments to
//! pcapng).
//!
//! # Syntax
//!
//! ```text
//! expr   := term ("or" term)*
//! term   := factor ("and" factor)*
//! factor := "not" factor | "(" expr ")" | flag | field OP value
//! OP     := "==" | "!=" | "<" | "<=" | ">" | ">="
//! ```
//!
//! Names are case-insensitive. Fields (compared with a value):
//!
//! - `addr` (source or destination), `src`, `dst`: station addresses;
//! - `sap` (either SAP), `dsap`, `ssap`: service access points
//!   (without the segment bit);
//! - `fc`: the function code (FC bits 3..0) as a number or a name as
//!   `dpctl decode` prints it (`srd_high`, `fdl_status`, `dl`, `dh`, …);
//! - `service`: the DP service as `dpctl decode` and `dpctl sniff`
//!   name it (`set_prm`, `chk_cfg`, `slave_diag`, `data_exchange`, …),
//!   also `token` and `short_ack`;
//! - `len`: bytes of the data unit;
//! - `state`: the DP state a slave enters (`data_exchange`, `offline`,
//!   names of [`SlaveState::name`]);
//! - `t`: time since the start, with a unit `s`, `ms` or `us` (`t > 10s`).
//!
//! Flags (true or false on their own):
//!
//! - diagnosis bits of a Slave_Diag response (IEC 61158-6-3
//!   Station_Status_1..3): `non_existent`, `not_ready`, `cfg_fault`,
//!   `ext_diag`, `not_supported`, `invalid_response`, `prm_fault`,
//!   `master_lock`, `prm_req`, `stat_diag`, `wd_on`, `freeze_mode`,
//!   `sync_mode`, `deactivated`, `ext_diag_overflow`; `diag` for any
//!   Slave_Diag response;
//! - errors: `fcs` (bytes dropped for a bad FCS), `corrupt` (any bytes
//!   the framer skipped: FCS, length, delimiter, garbage), `no_answer`
//!   (a request that needed a reply got none before the next telegram),
//!   `negative` (a negative acknowledge: UE, RR, RS, RDL, RDH), `retry`
//!   (a request repeated with the same FCB);
//! - state changes: `state_change` (a slave's DP state changed),
//!   `restart` (a slave left Data_Exchange for a new Prm/Cfg cycle);
//! - kinds: `request`, `response`, `token`, `broadcast`.
//!
//! A fault found only by what follows (`no_answer`, and state changes
//! the monitor notices when time passes) is observed with the telegram
//! that reveals it.
//!
//! ```
//! use profibus_dp::monitor::trigger::Trigger;
//!
//! let t: Trigger = "cfg_fault or (addr == 5 and service == set_prm)".parse().unwrap();
//! // The canonical form leaves out parentheses that precedence makes
//! // redundant (`and` binds tighter than `or`).
//! assert_eq!(t.to_string(), "cfg_fault or addr == 5 and service == set_prm");
//! let e = "cfg_falt".parse::<Trigger>().unwrap_err();
//! assert_eq!(e.to_string(), "column 1: unknown name `cfg_falt`; did you mean `cfg_fault`?");
//! ```

use crate::config::names::DidYouMean;
use crate::master::SlaveState;
use crate::monitor::{ErrorKind, Monitor, MonitorEvent, MonitorOptions};
use crate::pdu::decode::{Detail, DpTelegram, Exchanges};
use profibus_fdl::line::tap::TapEvent;
use profibus_fdl::wire::{FunctionCode, Telegram};
use std::collections::VecDeque;
use std::fmt;
use std::str::FromStr;
use std::time::Duration;

/// A trigger expression that does not parse: where, and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("column {column}: {message}")]
pub struct TriggerError {
    /// 1-based column (in characters) of the offending token.
    pub column: usize,
    /// What is wrong.
    pub message: String,
}

/// A flag: true or false for one observation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flag {
    /// A Slave_Diag status bit, by its name in the standard.
    Diag(&'static str),
    AnyDiag,
    Fcs,
    Corrupt,
    NoAnswer,
    Negative,
    Retry,
    StateChange,
    Restart,
    Request,
    Response,
    Token,
    Broadcast,
}

/// Flags by their trigger names.
const FLAGS: &[(&str, Flag)] = &[
    ("non_existent", Flag::Diag("Station_Non_Existent")),
    ("not_ready", Flag::Diag("Station_Not_Ready")),
    ("cfg_fault", Flag::Diag("Cfg_Fault")),
    ("ext_diag", Flag::Diag("Ext_Diag")),
    ("not_supported", Flag::Diag("Not_Supported")),
    ("invalid_response", Flag::Diag("Invalid_Slave_Response")),
    ("prm_fault", Flag::Diag("Prm_Fault")),
    ("master_lock", Flag::Diag("Master_Lock")),
    ("prm_req", Flag::Diag("Prm_Req")),
    ("stat_diag", Flag::Diag("Stat_Diag")),
    ("wd_on", Flag::Diag("WD_On")),
    ("freeze_mode", Flag::Diag("Freeze_Mode")),
    ("sync_mode", Flag::Diag("Sync_Mode")),
    ("deactivated", Flag::Diag("Deactivated")),
    ("ext_diag_overflow", Flag::Diag("Ext_Diag_Overflow")),
    ("diag", Flag::AnyDiag),
    ("fcs", Flag::Fcs),
    ("corrupt", Flag::Corrupt),
    ("no_answer", Flag::NoAnswer),
    ("negative", Flag::Negative),
    ("retry", Flag::Retry),
    ("state_change", Flag::StateChange),
    ("restart", Flag::Restart),
    ("request", Flag::Request),
    ("response", Flag::Response),
    ("token", Flag::Token),
    ("broadcast", Flag::Broadcast),
];

/// A field: compared with a value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Field {
    Addr,
    Src,
    Dst,
    Sap,
    Dsap,
    Ssap,
    Fc,
    Service,
    Len,
    State,
    T,
}

const FIELDS: &[(&str, Field)] = &[
    ("addr", Field::Addr),
    ("src", Field::Src),
    ("dst", Field::Dst),
    ("sap", Field::Sap),
    ("dsap", Field::Dsap),
    ("ssap", Field::Ssap),
    ("fc", Field::Fc),
    ("service", Field::Service),
    ("len", Field::Len),
    ("state", Field::State),
    ("t", Field::T),
];

/// DP services as [`crate::pdu::decode`] names them, and the FDL kinds
/// without a DP service.
const SERVICES: &[&str] = &[
    "Data_Exchange",
    "Slave_Diag",
    "Set_Prm",
    "Chk_Cfg",
    "Get_Cfg",
    "Global_Control",
    "Set_Slave_Add",
    "Rd_Inp",
    "Rd_Outp",
    "MSAC_C1",
    "Alarm_Ack",
    "MSAC_C2_Initiate",
    "MSAC_C2",
    "token",
    "short_ack",
];

const STATES: &[SlaveState] = &[
    SlaveState::Offline,
    SlaveState::Diag,
    SlaveState::SetPrm,
    SlaveState::ChkCfg,
    SlaveState::CheckDiag,
    SlaveState::DataExchange,
    SlaveState::Locked,
];

/// Function code names: request kinds and response status, as `dpctl
/// decode` prints them, with their FC bits 3..0.
const FUNCTIONS: &[(&str, u8, bool)] = &[
    ("TE", 0x0, true),
    ("SDA_low", 0x3, true),
    ("SDN_low", 0x4, true),
    ("SDA_high", 0x5, true),
    ("SDN_high", 0x6, true),
    ("MSRD", 0x7, true),
    ("FDL_Status", 0x9, true),
    ("SRD_low", 0xC, true),
    ("SRD_high", 0xD, true),
    ("Ident", 0xE, true),
    ("LSAP_Status", 0xF, true),
    ("OK", 0x0, false),
    ("UE", 0x1, false),
    ("RR", 0x2, false),
    ("RS", 0x3, false),
    ("DL", 0x8, false),
    ("NR", 0x9, false),
    ("DH", 0xA, false),
    ("RDL", 0xC, false),
    ("RDH", 0xD, false),
];

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Op {
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
}

impl Op {
    fn text(self) -> &'static str {
        match self {
            Op::Eq => "==",
            Op::Ne => "!=",
            Op::Lt => "<",
            Op::Le => "<=",
            Op::Gt => ">",
            Op::Ge => ">=",
        }
    }

    fn holds<T: PartialOrd>(self, a: T, b: T) -> bool {
        match self {
            Op::Eq => a == b,
            Op::Ne => a != b,
            Op::Lt => a < b,
            Op::Le => a <= b,
            Op::Gt => a > b,
            Op::Ge => a >= b,
        }
    }
}

/// The value a field is compared with, checked at parse time.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Value {
    Number(u64),
    Time(Duration),
    /// A service name (index into [`SERVICES`]).
    Service(&'static str),
    /// A function code by name: (name, FC bits, request).
    Function(&'static str, u8, bool),
    State(SlaveState),
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Expr {
    Or(Box<Expr>, Box<Expr>),
    And(Box<Expr>, Box<Expr>),
    Not(Box<Expr>),
    Flag(&'static str, Flag),
    Cmp(&'static str, Field, Op, Value, String),
}

/// A parsed trigger expression (see the module docs for the syntax).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Trigger {
    expr: Expr,
}

impl FromStr for Trigger {
    type Err = TriggerError;

    fn from_str(s: &str) -> Result<Trigger, TriggerError> {
        Trigger::parse(s)
    }
}

impl Trigger {
    /// Parse `source`.
    pub fn parse(source: &str) -> Result<Trigger, TriggerError> {
        let tokens = lex(source)?;
        let mut p = Parser {
            tokens: &tokens,
            pos: 0,
            end: source.chars().count() + 1,
            depth: 0,
        };
        let expr = p.or()?;
        if let Some(t) = p.peek() {
            return Err(p.error_at(t.column, format!("unexpected `{}`", t.text)));
        }
        Ok(Trigger { expr })
    }

    /// Whether `o` fires the trigger.
    pub fn matches(&self, o: &Observation) -> bool {
        eval(&self.expr, o)
    }
}

impl fmt::Display for Trigger {
    /// The expression in canonical form: lower-case names, single
    /// spaces, parentheses where the precedence needs them.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        show(&self.expr, f, 0)
    }
}

fn show(e: &Expr, f: &mut fmt::Formatter<'_>, outer: u8) -> fmt::Result {
    match e {
        Expr::Or(a, b) => {
            if outer > 1 {
                f.write_str("(")?;
            }
            show(a, f, 1)?;
            f.write_str(" or ")?;
            // The parser groups to the left: a right operand that is
            // itself an `or` keeps its parentheses.
            show(b, f, 2)?;
            if outer > 1 {
                f.write_str(")")?;
            }
            Ok(())
        }
        Expr::And(a, b) => {
            if outer > 2 {
                f.write_str("(")?;
            }
            show(a, f, 2)?;
            f.write_str(" and ")?;
            show(b, f, 3)?;
            if outer > 2 {
                f.write_str(")")?;
            }
            Ok(())
        }
        Expr::Not(a) => {
            f.write_str("not ")?;
            show(a, f, 3)
        }
        Expr::Flag(name, _) => f.write_str(name),
        Expr::Cmp(name, _, op, _, text) => write!(f, "{name} {} {text}", op.text()),
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Tok {
    Word,
    Op(Op),
    Open,
    Close,
}

#[derive(Debug, Clone)]
struct Token {
    kind: Tok,
    text: String,
    column: usize,
}

fn lex(s: &str) -> Result<Vec<Token>, TriggerError> {
    let chars: Vec<char> = s.chars().collect();
    let mut out = vec![];
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let column = i + 1;
        let start = i;
        let kind = match c {
            c if c.is_whitespace() => {
                i += 1;
                continue;
            }
            '(' => {
                i += 1;
                Tok::Open
            }
            ')' => {
                i += 1;
                Tok::Close
            }
            '=' | '!' | '<' | '>' => {
                let next = chars.get(i + 1).copied();
                let (op, n) = match (c, next) {
                    ('=', Some('=')) => (Op::Eq, 2),
                    ('!', Some('=')) => (Op::Ne, 2),
                    ('<', Some('=')) => (Op::Le, 2),
                    ('>', Some('=')) => (Op::Ge, 2),
                    ('<', _) => (Op::Lt, 1),
                    ('>', _) => (Op::Gt, 1),
                    ('=', _) => {
                        return Err(TriggerError {
                            column,
                            message: "`=` compares nothing; write `==`".into(),
                        })
                    }
                    _ => {
                        return Err(TriggerError {
                            column,
                            message: "`!` alone is no operator; write `not` or `!=`".into(),
                        })
                    }
                };
                i += n;
                Tok::Op(op)
            }
            c if c.is_alphanumeric() || c == '_' || c == '.' || c == '-' => {
                while i < chars.len()
                    && (chars[i].is_alphanumeric() || matches!(chars[i], '_' | '.' | '-'))
                {
                    i += 1;
                }
                Tok::Word
            }
            other => {
                return Err(TriggerError {
                    column,
                    message: format!(
                        "unexpected character `{other}` (operators: == != < <= > >=, \
                         and, or, not, parentheses)"
                    ),
                })
            }
        };
        out.push(Token {
            kind,
            text: chars[start..i].iter().collect(),
            column,
        });
    }
    Ok(out)
}

/// Nesting deeper than this is refused (the parser recurses).
const MAX_DEPTH: usize = 64;

struct Parser<'a> {
    tokens: &'a [Token],
    pos: usize,
    /// Column just past the end, for "expected … at the end".
    end: usize,
    depth: usize,
}

impl Parser<'_> {
    fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.pos)
    }

    fn error_at(&self, column: usize, message: String) -> TriggerError {
        TriggerError { column, message }
    }

    fn keyword(&mut self, word: &str) -> bool {
        match self.peek() {
            Some(t) if t.kind == Tok::Word && t.text.eq_ignore_ascii_case(word) => {
                self.pos += 1;
                true
            }
            _ => false,
        }
    }

    fn or(&mut self) -> Result<Expr, TriggerError> {
        let mut e = self.and()?;
        while self.keyword("or") {
            e = Expr::Or(Box::new(e), Box::new(self.and()?));
        }
        Ok(e)
    }

    fn and(&mut self) -> Result<Expr, TriggerError> {
        let mut e = self.factor()?;
        while self.keyword("and") {
            e = Expr::And(Box::new(e), Box::new(self.factor()?));
        }
        Ok(e)
    }

    fn factor(&mut self) -> Result<Expr, TriggerError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            let column = self.peek().map_or(self.end, |t| t.column);
            return Err(self.error_at(column, format!("nested deeper than {MAX_DEPTH} levels")));
        }
        let r = self.factor_inner();
        self.depth -= 1;
        r
    }

    fn factor_inner(&mut self) -> Result<Expr, TriggerError> {
        let Some(t) = self.peek().cloned() else {
            return Err(self.error_at(self.end, "expected a name or `(` at the end".into()));
        };
        self.pos += 1;
        match t.kind {
            Tok::Open => {
                let e = self.or()?;
                match self.peek() {
                    Some(c) if c.kind == Tok::Close => {
                        self.pos += 1;
                        Ok(e)
                    }
                    Some(c) => Err(self.error_at(
                        c.column,
                        format!(
                            "expected `)` to close column {}, found `{}`",
                            t.column, c.text
                        ),
                    )),
                    None => Err(self.error_at(
                        self.end,
                        format!("`(` at column {} is never closed", t.column),
                    )),
                }
            }
            Tok::Close | Tok::Op(_) => Err(self.error_at(
                t.column,
                format!("expected a name or `(`, found `{}`", t.text),
            )),
            Tok::Word if t.text.eq_ignore_ascii_case("not") => {
                Ok(Expr::Not(Box::new(self.factor()?)))
            }
            Tok::Word if ["and", "or"].iter().any(|k| t.text.eq_ignore_ascii_case(k)) => Err(self
                .error_at(
                    t.column,
                    format!("expected a name or `(` before `{}`", t.text),
                )),
            Tok::Word => self.atom(&t),
        }
    }

    fn atom(&mut self, t: &Token) -> Result<Expr, TriggerError> {
        let lower = t.text.to_ascii_lowercase();
        if let Some(&(name, flag)) = FLAGS.iter().find(|(n, _)| *n == lower) {
            if let Some(op) = self.peek().filter(|o| matches!(o.kind, Tok::Op(_))) {
                return Err(self.error_at(
                    op.column,
                    format!(
                        "`{name}` is a flag, true or false on its own; it compares with nothing"
                    ),
                ));
            }
            return Ok(Expr::Flag(name, flag));
        }
        let Some(&(name, field)) = FIELDS.iter().find(|(n, _)| *n == lower) else {
            let names = FLAGS.iter().map(|f| f.0).chain(FIELDS.iter().map(|f| f.0));
            let hint = DidYouMean::new(&t.text, names);
            return Err(self.error_at(t.column, format!("unknown name `{}`{hint}", t.text)));
        };
        let op = match self.peek() {
            Some(Token {
                kind: Tok::Op(op), ..
            }) => *op,
            Some(o) => {
                return Err(self.error_at(
                    o.column,
                    format!(
                        "expected a comparison (== != < <= > >=) after `{name}`, found `{}`",
                        o.text
                    ),
                ))
            }
            None => {
                return Err(self.error_at(
                    self.end,
                    format!("expected a comparison (== != < <= > >=) after `{name}` at the end"),
                ))
            }
        };
        self.pos += 1;
        let Some(v) = self.peek().cloned().filter(|v| v.kind == Tok::Word) else {
            let column = self.peek().map_or(self.end, |v| v.column);
            return Err(self.error_at(
                column,
                format!("expected a value after `{name} {}`", op.text()),
            ));
        };
        self.pos += 1;
        let value = self.value(field, name, op, &v)?;
        let text = match &value {
            Value::Number(n) => n.to_string(),
            Value::Time(_) => v.text.to_ascii_lowercase(),
            Value::Service(s) | Value::Function(s, _, _) => s.to_ascii_lowercase(),
            Value::State(s) => s.name().to_string(),
        };
        Ok(Expr::Cmp(name, field, op, value, text))
    }

    fn value(&self, field: Field, name: &str, op: Op, v: &Token) -> Result<Value, TriggerError> {
        let named = |what: &str, known: &mut dyn Iterator<Item = &'static str>| {
            if !matches!(op, Op::Eq | Op::Ne) {
                return Err(self.error_at(
                    v.column,
                    format!("`{name}` is a name; compare it with == or !="),
                ));
            }
            let known: Vec<&'static str> = known.collect();
            match known.iter().find(|k| k.eq_ignore_ascii_case(&v.text)) {
                Some(k) => Ok(*k),
                None => {
                    let lower: Vec<String> = known.iter().map(|k| k.to_ascii_lowercase()).collect();
                    let hint = DidYouMean::new(&v.text, lower.iter().map(String::as_str));
                    Err(self.error_at(v.column, format!("unknown {what} `{}`{hint}", v.text)))
                }
            }
        };
        match field {
            Field::Service => named("service", &mut SERVICES.iter().copied()).map(Value::Service),
            Field::State => {
                let n = named("state", &mut STATES.iter().map(|s| s.name()))?;
                let s = STATES.iter().find(|s| s.name() == n).copied();
                Ok(Value::State(s.unwrap_or(SlaveState::Offline)))
            }
            Field::Fc if !v.text.starts_with(|c: char| c.is_ascii_digit()) => {
                let n = named("function code", &mut FUNCTIONS.iter().map(|f| f.0))?;
                let &(n, code, request) =
                    FUNCTIONS.iter().find(|f| f.0 == n).unwrap_or(&FUNCTIONS[0]);
                Ok(Value::Function(n, code, request))
            }
            Field::T => parse_time(&v.text).map(Value::Time).ok_or_else(|| {
                self.error_at(
                    v.column,
                    format!(
                        "`{}` is no time; write a number with s, ms or us (`10s`, `250ms`)",
                        v.text
                    ),
                )
            }),
            _ => {
                let max = match field {
                    Field::Fc => 15,
                    Field::Len => 255,
                    Field::Sap | Field::Dsap | Field::Ssap => 63,
                    _ => 127,
                };
                parse_number(&v.text)
                    .filter(|n| *n <= max)
                    .map(Value::Number)
                    .ok_or_else(|| {
                        self.error_at(
                            v.column,
                            format!("`{name}` takes a number 0..={max}, not `{}`", v.text),
                        )
                    })
            }
        }
    }
}

fn parse_number(s: &str) -> Option<u64> {
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16).ok(),
        None => s.parse().ok(),
    }
}

fn parse_time(s: &str) -> Option<Duration> {
    let s = s.to_ascii_lowercase();
    let (num, scale) = if let Some(n) = s.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = s.strip_suffix("us") {
        (n, 1e-6)
    } else if let Some(n) = s.strip_suffix('s') {
        (n, 1.0)
    } else {
        return None;
    };
    let v: f64 = num.parse().ok()?;
    let secs = v * scale;
    (0.0..1e12)
        .contains(&secs)
        .then(|| Duration::from_secs_f64(secs))
}

fn eval(e: &Expr, o: &Observation) -> bool {
    match e {
        Expr::Or(a, b) => eval(a, o) || eval(b, o),
        Expr::And(a, b) => eval(a, o) && eval(b, o),
        Expr::Not(a) => !eval(a, o),
        Expr::Flag(_, f) => flag(*f, o),
        Expr::Cmp(_, field, op, value, _) => compare(*field, *op, value, o),
    }
}

fn flag(f: Flag, o: &Observation) -> bool {
    match f {
        Flag::Diag(bit) => o.diag.iter().any(|s| s == bit),
        Flag::AnyDiag => o.service == Some("Slave_Diag") && o.response,
        Flag::Fcs => o.fcs,
        Flag::Corrupt => o.corrupt,
        Flag::NoAnswer => o.no_answer,
        Flag::Negative => o.negative,
        Flag::Retry => o.retry,
        Flag::StateChange => !o.states.is_empty(),
        Flag::Restart => o.restart,
        Flag::Request => o.request,
        Flag::Response => o.response,
        Flag::Token => o.token,
        Flag::Broadcast => o.broadcast,
    }
}

fn compare(field: Field, op: Op, value: &Value, o: &Observation) -> bool {
    let num = |x: Option<u8>| match (x, value) {
        (Some(x), Value::Number(n)) => op.holds(u64::from(x), *n),
        _ => false,
    };
    match field {
        // `addr != 5`: neither address is 5.
        Field::Addr if op == Op::Ne => !compare(Field::Addr, Op::Eq, value, o) && o.src.is_some(),
        Field::Addr => num(o.src) || num(o.dst),
        Field::Src => num(o.src),
        Field::Dst => num(o.dst),
        Field::Sap if op == Op::Ne => !compare(Field::Sap, Op::Eq, value, o) && o.dsap.is_some(),
        Field::Sap => num(o.dsap) || num(o.ssap),
        Field::Dsap => num(o.dsap),
        Field::Ssap => num(o.ssap),
        Field::Len => match (o.len, value) {
            (Some(l), Value::Number(n)) => op.holds(l as u64, *n),
            _ => false,
        },
        Field::Fc => match (o.fc, value) {
            (Some((code, _)), Value::Number(n)) => op.holds(u64::from(code), *n),
            (Some((code, req)), Value::Function(_, c, r)) => {
                let same = code == *c && req == *r;
                if op == Op::Ne {
                    !same
                } else {
                    same
                }
            }
            _ => false,
        },
        Field::Service => match (o.service, value) {
            (Some(s), Value::Service(v)) => op.holds(s, *v),
            (None, Value::Service(_)) => op == Op::Ne,
            _ => false,
        },
        Field::State => match value {
            Value::State(v) => match op {
                Op::Ne => !o.states.is_empty() && !o.states.contains(v),
                _ => o.states.contains(v),
            },
            _ => false,
        },
        Field::T => match value {
            Value::Time(v) => op.holds(o.t, *v),
            _ => false,
        },
    }
}

/// What one telegram, or one run of skipped bytes, shows: the facts a
/// [`Trigger`] tests. Built by [`Watch::hear`]; public so that other
/// sources (a capture file) can build one.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Observation {
    /// Time of its first byte since the start.
    pub t: Duration,
    /// Source address (`None`: a short acknowledge, skipped bytes).
    pub src: Option<u8>,
    /// Destination address.
    pub dst: Option<u8>,
    /// Destination SAP, without the segment bit.
    pub dsap: Option<u8>,
    /// Source SAP, without the segment bit.
    pub ssap: Option<u8>,
    /// Function code bits 3..0, and whether it is a request.
    pub fc: Option<(u8, bool)>,
    /// Bytes of the data unit.
    pub len: Option<usize>,
    /// The DP service ([`DpTelegram::service`]), `token` or `short_ack`.
    pub service: Option<&'static str>,
    /// A request.
    pub request: bool,
    /// A response or short acknowledge.
    pub response: bool,
    /// A token telegram.
    pub token: bool,
    /// Sent to the broadcast address 127.
    pub broadcast: bool,
    /// The Slave_Diag status bits set, by their names in the standard.
    pub diag: Vec<String>,
    /// Skipped bytes with a bad FCS.
    pub fcs: bool,
    /// Skipped bytes (any reason).
    pub corrupt: bool,
    /// A request before this went unanswered.
    pub no_answer: bool,
    /// A negative acknowledge.
    pub negative: bool,
    /// A request repeated with the same FCB.
    pub retry: bool,
    /// DP states slaves entered with this telegram.
    pub states: Vec<SlaveState>,
    /// A slave left Data_Exchange for a new start-up.
    pub restart: bool,
}

/// Follows a stream of tap events and observes each: see the module
/// docs.
pub struct Watch {
    monitor: Monitor,
    exchanges: Exchanges,
    /// The addresses of the last data telegram (a short acknowledge
    /// answers its request).
    last_pair: [u8; 2],
}

impl Default for Watch {
    fn default() -> Self {
        Watch::new(Monitor::new(vec![], MonitorOptions::default()))
    }
}

impl fmt::Debug for Watch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Watch").finish_non_exhaustive()
    }
}

impl Watch {
    /// A watch following the traffic with `monitor` (one that knows the
    /// bus file's slaves, or an empty one).
    pub fn new(monitor: Monitor) -> Watch {
        Watch {
            monitor,
            exchanges: Exchanges::default(),
            last_pair: [0, 0],
        }
    }

    /// The next event of the stream, observed; also its DP layer (what
    /// `dpctl sniff --json` prints in `"dp"`).
    pub fn hear(&mut self, ev: &TapEvent) -> (Observation, Option<DpTelegram>) {
        let mut o = Observation::default();
        let (at, telegram) = match ev {
            TapEvent::Telegram { at, bytes } => (*at, Telegram::parse(bytes).ok().map(|t| t.0)),
            TapEvent::Skipped { at, errors, .. } => {
                o.corrupt = true;
                o.fcs = errors.bad_fcs > 0;
                (*at, None)
            }
        };
        o.t = Duration::from_nanos(at.as_nanos());
        let mut dp = None;
        let mut slaves: &[u8] = &[];
        if let Some(t) = &telegram {
            match t {
                Telegram::Token { da, sa } => {
                    o.token = true;
                    o.src = Some(*sa);
                    o.dst = Some(*da);
                    o.service = Some("token");
                }
                Telegram::ShortAck => {
                    o.response = true;
                    slaves = &self.last_pair;
                }
                Telegram::Data(d) => {
                    o.src = Some(d.sa);
                    o.dst = Some(d.da);
                    o.dsap = d.dsap.map(|s| s & 0x3F);
                    o.ssap = d.ssap.map(|s| s & 0x3F);
                    o.len = Some(d.data.len());
                    o.broadcast = d.is_broadcast();
                    match d.fc {
                        FunctionCode::Request { kind, .. } => {
                            o.request = true;
                            o.fc = Some((kind.code() & 0x0F, true));
                        }
                        FunctionCode::Response { status, .. } => {
                            o.response = true;
                            o.negative = status.is_negative();
                            o.fc = Some((status.code() & 0x0F, false));
                        }
                    }
                    self.last_pair = [d.sa, d.da];
                    slaves = &self.last_pair;
                }
            }
            dp = self.exchanges.decode(t);
        }
        if let Some(p) = &dp {
            o.service = Some(p.service);
            if let Some(Detail::SlaveDiag { status, .. }) = &p.detail {
                o.diag = status.clone();
            }
        } else if matches!(telegram, Some(Telegram::ShortAck)) {
            o.service = Some("short_ack");
        }
        let slaves: Vec<u8> = slaves.to_vec();
        let before: Vec<_> = slaves
            .iter()
            .map(|a| self.monitor.slave_counters(*a).unwrap_or_default())
            .collect();
        self.monitor.hear(ev);
        for (a, b) in slaves.iter().zip(&before) {
            if let Some(c) = self.monitor.slave_counters(*a) {
                o.retry |= c.retries > b.retries;
                o.restart |= c.restarts > b.restarts;
            }
        }
        while let Some(e) = self.monitor.poll_event() {
            match e {
                MonitorEvent::SlaveState { to, .. } => o.states.push(to),
                MonitorEvent::Fault {
                    reason: ErrorKind::NoReply,
                    ..
                } => o.no_answer = true,
                _ => {}
            }
        }
        (o, dp)
    }
}

/// What a [`Recorder`] hands out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Output<R> {
    /// A segment begins (numbered from 1); its records follow.
    Start {
        /// Its number.
        segment: u32,
    },
    /// A record of the current segment.
    Record {
        /// The record.
        record: R,
        /// It fired a trigger.
        fired: bool,
    },
    /// The segment ends.
    End {
        /// Its number.
        segment: u32,
    },
}

/// A triggered recorder: keeps the last `pre` records in a ring and,
/// when a record fires a trigger, hands out a segment with them, the
/// firing record and the `post` records after it. A firing within a
/// segment extends it by `post` records from there: overlapping windows
/// make one segment.
#[derive(Debug, Clone)]
pub struct Recorder<R> {
    pre: usize,
    post: usize,
    ring: VecDeque<R>,
    /// Records still to hand out in the open segment (`None`: none open).
    left: Option<usize>,
    segments: u32,
}

impl<R> Recorder<R> {
    /// `pre` records before each firing, `post` after.
    pub fn new(pre: usize, post: usize) -> Recorder<R> {
        Recorder {
            pre,
            post,
            ring: VecDeque::with_capacity(pre.min(1 << 16)),
            left: None,
            segments: 0,
        }
    }

    /// Segments begun so far.
    pub fn segments(&self) -> u32 {
        self.segments
    }

    /// The number of the open segment.
    pub fn open_segment(&self) -> Option<u32> {
        self.left.map(|_| self.segments)
    }

    /// The next record; `fired`: it fires a trigger. Outputs go to `out`
    /// in order.
    pub fn push(&mut self, record: R, fired: bool, mut out: impl FnMut(Output<R>)) {
        match self.left {
            Some(left) => {
                out(Output::Record { record, fired });
                let left = if fired {
                    self.post
                } else {
                    left.saturating_sub(1)
                };
                self.left = Some(left);
                if left == 0 {
                    self.left = None;
                    out(Output::End {
                        segment: self.segments,
                    });
                }
            }
            None if fired => {
                self.segments += 1;
                out(Output::Start {
                    segment: self.segments,
                });
                for r in self.ring.drain(..) {
                    out(Output::Record {
                        record: r,
                        fired: false,
                    });
                }
                out(Output::Record { record, fired });
                if self.post == 0 {
                    out(Output::End {
                        segment: self.segments,
                    });
                } else {
                    self.left = Some(self.post);
                }
            }
            None => {
                if self.pre == 0 {
                    return;
                }
                if self.ring.len() == self.pre {
                    self.ring.pop_front();
                }
                self.ring.push_back(record);
            }
        }
    }

    /// The stream ends: an open segment ends short.
    pub fn finish(&mut self, mut out: impl FnMut(Output<R>)) {
        if self.left.take().is_some() {
            out(Output::End {
                segment: self.segments,
            });
        }
    }
}

#[cfg(test)]
mod tests;
