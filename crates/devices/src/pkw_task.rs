//! One PKW job on a slave of a bus file, as `dpctl pkw` runs it: read,
//! write or describe a parameter named as people write it (`218`, `P218`,
//! `0x7E`, `P5[2]`, or a name the device gives a parameter such as a
//! BM4-O-PRO-01 variable module), through the slave's PKW dialect from
//! the registry ([`crate::pkw_dialect`], [`crate::pkw_parameter`]).
//! [`PkwTask`] is a [`SlaveTask`]: a write without a stated width reads
//! the parameter first to learn it. The result is a [`PkwAnswered`] or a
//! [`PkwRefused`] (`Display` for people, `Serialize` for the JSON line).

use crate::pkw::client::{PkwClient, PkwError, StartError};
use crate::pkw::{Command, Dialect, Reply};
use crate::PkwLookupError;
use profibus_dp::config::busfile::BusSlave;
use profibus_dp::master::{DpMaster, SlaveTask, StartupTimeout};
use profibus_fdl::Instant;
use serde::Serialize;
use std::collections::VecDeque;
use std::fmt;
use std::time::Duration;

/// Why a PKW job cannot be built or run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PkwTaskError {
    /// The slave has no PKW dialect.
    #[error("slave {0}: {1}")]
    Dialect(u8, PkwLookupError),
    /// `P[i]` with a bad index.
    #[error("bad array index in `{0}`")]
    Index(String),
    /// `P[i]` outside the Omega's array (a dialect without array
    /// element commands).
    #[error("`{0}`: the {1} has no array element commands; `P[i]` is parameter P+i of the DINT array P1000..P2047")]
    NoArray(String, &'static str),
    /// A parameter number above 2047.
    #[error("parameter number {0} is outside 0..=2047")]
    Pnu(i64),
    /// A name the device does not know.
    #[error("`{0}` is neither a parameter number nor a variable module of {1}")]
    Name(String, String),
    /// An unknown description element.
    #[error("unknown description element `{0}` (attribute, info, min, max)")]
    Element(String),
    /// The dialect has no description command.
    #[error("the {0} has no parameter description (PBE) command")]
    NoDescribe(&'static str),
    /// A write without `=`.
    #[error("write takes P=V")]
    Assignment,
    /// A value that is not a number.
    #[error("`{0}` is not a number")]
    Value(String),
    /// A value outside 32 bits.
    #[error("{0} does not fit 32 bits")]
    Range(i64),
    /// The job cannot start.
    #[error(transparent)]
    Start(#[from] StartError),
    /// The slave did not reach Data_Exchange.
    #[error(transparent)]
    Startup(#[from] StartupTimeout),
}

/// A number as people write it: decimal, `0x…`, `16#…`, negative.
pub fn parse_num(s: &str) -> Option<i64> {
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

/// A parameter: its number and, for `P[i]`, the array element.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamRef {
    /// Parameter number.
    pub pnu: u16,
    /// Array element.
    pub index: Option<u16>,
}

impl ParamRef {
    /// `text` as a parameter of `slave` (see the module docs).
    pub fn parse(text: &str, slave: &BusSlave) -> Result<ParamRef, PkwTaskError> {
        let (name, index) = match text.split_once('[') {
            Some((n, i)) => {
                let i = (i.strip_suffix(']').and_then(parse_num))
                    .filter(|i| (0..=0xFFFF).contains(i))
                    .ok_or_else(|| PkwTaskError::Index(text.to_string()))?;
                (n, Some(i as u16))
            }
            None => (text, None),
        };
        let num = name.strip_prefix(['P', 'p']).unwrap_or(name);
        let pnu = match parse_num(num) {
            Some(n) if (0..=2047).contains(&n) => n as u16,
            Some(n) => return Err(PkwTaskError::Pnu(n)),
            None => crate::pkw_parameter(slave.params.ident_number, &slave.gsd, name).ok_or_else(
                || {
                    let file = slave.gsd_path.display().to_string();
                    PkwTaskError::Name(name.to_string(), file)
                },
            )?,
        };
        Ok(ParamRef { pnu, index })
    }

    /// The read command of this parameter or element.
    fn read(self) -> Command {
        self.index.map_or(Command::Read, Command::ReadElement)
    }
}

impl fmt::Display for ParamRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.index {
            Some(i) => write!(f, "P{}[{i}]", self.pnu),
            None => write!(f, "P{}", self.pnu),
        }
    }
}

#[derive(Debug, Clone, Copy)]
enum Step {
    /// Read to learn the format (word or double word).
    Probe(Command),
    Run(Command),
    Write {
        value: u32,
        dword: Option<bool>,
    },
}

/// One PKW job on one slave; see the module docs.
#[derive(Debug)]
pub struct PkwTask {
    address: u8,
    client: PkwClient,
    op: &'static str,
    /// `P5` or `P5 min`: what the answer is about.
    what: String,
    param: ParamRef,
    steps: VecDeque<Step>,
    inflight: Option<Step>,
    probe: Option<Reply>,
    outcome: Option<Result<crate::pkw::client::PkwAnswer, PkwError>>,
}

impl PkwTask {
    fn new(slave: &BusSlave, op: &'static str, timeout: Duration) -> Result<Self, PkwTaskError> {
        let (address, p) = (slave.params.address, &slave.params);
        let dialect = crate::pkw_dialect(p.ident_number, &p.cfg)
            .map_err(|e| PkwTaskError::Dialect(address, e))?;
        let client = PkwClient::new(dialect, timeout.max(Duration::from_millis(1)));
        Ok(PkwTask {
            address,
            client,
            op,
            what: String::new(),
            param: ParamRef {
                pnu: 0,
                index: None,
            },
            steps: VecDeque::new(),
            inflight: None,
            probe: None,
            outcome: None,
        })
    }

    /// `P[i]` for a dialect without array element commands (the Omega):
    /// element i of the Omega's DINT array from P, PNU P + i (manual
    /// L404-420: a_ParValues[1000..2047], the index is the PNU).
    fn flatten(&self, p: ParamRef, text: &str) -> Result<ParamRef, PkwTaskError> {
        let d = self.client.dialect();
        match p.index {
            Some(i) if d.read_element.is_none() => {
                let pnu = p.pnu as u32 + i as u32;
                if p.pnu < 1000 || pnu > 2047 {
                    return Err(PkwTaskError::NoArray(text.to_string(), d.name));
                }
                Ok(ParamRef {
                    pnu: pnu as u16,
                    index: None,
                })
            }
            _ => Ok(p),
        }
    }

    fn with(mut self, param: ParamRef, steps: &[Step]) -> Self {
        self.param = param;
        self.what = param.to_string();
        self.steps = steps.iter().copied().collect();
        self
    }

    /// Read `param` (or its array element).
    pub fn read(slave: &BusSlave, param: &str, timeout: Duration) -> Result<Self, PkwTaskError> {
        let t = PkwTask::new(slave, "read", timeout)?;
        let p = t.flatten(ParamRef::parse(param, slave)?, param)?;
        Ok(t.with(p, &[Step::Run(p.read())]))
    }

    /// Read the description element `attr` (attribute, info, min, max)
    /// of `param` (Omega: PBE).
    pub fn describe(
        slave: &BusSlave,
        param: &str,
        attr: &str,
        timeout: Duration,
    ) -> Result<Self, PkwTaskError> {
        let t = PkwTask::new(slave, "describe", timeout)?;
        let p = t.flatten(ParamRef::parse(param, slave)?, param)?;
        let ind = match attr {
            "attribute" => 1,
            "info" => 2,
            "min" => 5,
            "max" => 6,
            other => return Err(PkwTaskError::Element(other.to_string())),
        };
        let dialect = t.client.dialect();
        if dialect.describe.is_none() {
            return Err(PkwTaskError::NoDescribe(dialect.name));
        }
        let mut t = t.with(p, &[Step::Run(Command::Describe(ind))]);
        t.what = format!("{p} {attr}");
        Ok(t)
    }

    /// Write `P=V` (V decimal, 0x hex or negative): as a double word when
    /// `dword` says so, or when the dialect has a description command and
    /// P ≥ 1000; otherwise as the parameter is (read first).
    pub fn write(
        slave: &BusSlave,
        assignment: &str,
        dword: Option<bool>,
        timeout: Duration,
    ) -> Result<Self, PkwTaskError> {
        let t = PkwTask::new(slave, "write", timeout)?;
        let (ps, vs) = assignment.split_once('=').ok_or(PkwTaskError::Assignment)?;
        let p = t.flatten(ParamRef::parse(ps.trim(), slave)?, ps.trim())?;
        let v = parse_num(vs).ok_or_else(|| PkwTaskError::Value(vs.to_string()))?;
        if !(-(1i64 << 31)..=0xFFFF_FFFF).contains(&v) {
            return Err(PkwTaskError::Range(v));
        }
        let long = p.pnu >= 1000 && t.client.dialect().describe.is_some();
        let dword = dword.or(long.then_some(true));
        let write = Step::Write {
            value: v as u32,
            dword,
        };
        Ok(match dword {
            Some(_) => t.with(p, &[write]),
            None => t.with(p, &[Step::Probe(p.read()), write]),
        })
    }

    /// How the job ended, once it has.
    pub fn outcome(&self) -> Option<Result<PkwAnswered, PkwRefused>> {
        let (p, slave) = (self.param, self.address);
        Some(match self.outcome.as_ref()? {
            Ok(a) => Ok(PkwAnswered::new(self, self.client.dialect(), a)),
            Err(e) => Err(PkwRefused {
                slave,
                pnu: p.pnu,
                index: p.index,
                ok: false,
                error: e.to_string(),
                code: match e {
                    PkwError::Refused { code, .. } => Some(*code),
                    _ => None,
                },
            }),
        })
    }
}

impl SlaveTask for PkwTask {
    type Error = PkwTaskError;

    fn busy(&self) -> bool {
        !self.client.is_idle()
    }

    fn step(&mut self, m: &mut DpMaster, now: Instant, in_dx: bool) -> Result<bool, PkwTaskError> {
        if !in_dx && self.client.is_idle() {
            return Ok(false);
        }
        let Some(h) = m.handle(self.address) else {
            return Ok(false);
        };
        if let Some(r) = self.client.drive(now, m, h) {
            match (r, self.inflight.take()) {
                (Ok(a), Some(Step::Probe(_))) => self.probe = Some(a.reply),
                (r, _) => {
                    self.outcome = Some(r);
                    self.steps.clear();
                }
            }
        }
        if !self.client.is_idle() {
            return Ok(false);
        }
        let Some(step) = self.steps.pop_front() else {
            return Ok(true);
        };
        let cmd = match step {
            Step::Probe(c) | Step::Run(c) => c,
            Step::Write { value, dword } => {
                let dword = dword.unwrap_or_else(|| self.probe.is_some_and(|p| p.is_dword()));
                write_command(value, dword, self.param.index)
            }
        };
        self.client.start(now, self.param.pnu, cmd)?;
        self.inflight = Some(step);
        Ok(false)
    }
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

/// A description element (`ind` 1: attribute, 2: info) in words.
fn element_words(ind: u16, v: u16) -> Option<String> {
    Some(match ind {
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
            let decimals = v >> 12;
            format!("{len} bytes, {ty}, {num}, {el}, display {disp}, {decimals} decimals")
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
        _ => return None,
    })
}

/// The slave refused a PKW job or did not answer: `Display` is the
/// one-line reason, `Serialize` the `dpctl pkw --json` object.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PkwRefused {
    /// Station address.
    pub slave: u8,
    /// Parameter number.
    pub pnu: u16,
    /// Array element.
    pub index: Option<u16>,
    /// Always false.
    pub ok: bool,
    /// Why, in words.
    pub error: String,
    /// The slave's error number, if it answered one.
    pub code: Option<u16>,
}

impl fmt::Display for PkwRefused {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "slave {} P{}: {}", self.slave, self.pnu, self.error)
    }
}

/// A PKW job's answer: `Display` is the line `dpctl pkw` prints
/// (`P5 = 3000 (0xBB8, double word)  [request …, response …]`),
/// `Serialize` its `--json` object.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PkwAnswered {
    /// Station address.
    pub slave: u8,
    /// The dialect's device name.
    pub device: &'static str,
    /// `read`, `write` or `describe`.
    pub op: &'static str,
    /// Parameter number.
    pub pnu: u16,
    /// Array element.
    pub index: Option<u16>,
    /// Always true.
    pub ok: bool,
    /// `word` or `dword`.
    pub format: &'static str,
    /// The value.
    pub value: u32,
    /// The value read as signed.
    pub signed: i64,
    /// The value in hex, 4 or 8 digits.
    pub hex: String,
    /// The request words.
    pub request: String,
    /// The response words.
    pub response: String,
    /// The response's PKE, hex.
    pub pke: String,
    /// The response's IND.
    pub ind: u16,
    /// The response's PWE1, hex.
    pub pwe1: String,
    /// The response's PWE2, hex.
    pub pwe2: String,
    /// A description element in words.
    pub words: Option<String>,
    /// What the answer is about (`P5`, `P5 min`).
    #[serde(skip)]
    pub what: String,
}

impl PkwAnswered {
    fn new(t: &PkwTask, dialect: &Dialect, a: &crate::pkw::client::PkwAnswer) -> PkwAnswered {
        let (value, dword) = (a.reply.value(), a.reply.is_dword());
        let r = a.response;
        PkwAnswered {
            slave: t.address,
            device: dialect.name,
            op: t.op,
            pnu: t.param.pnu,
            index: t.param.index,
            ok: true,
            format: if dword { "dword" } else { "word" },
            value,
            signed: if dword {
                value as i32 as i64
            } else {
                value as u16 as i16 as i64
            },
            hex: format!("0x{value:0width$X}", width = if dword { 8 } else { 4 }),
            request: a.request.to_string(),
            response: r.to_string(),
            pke: format!("0x{:04X}", r.pke),
            ind: r.ind,
            pwe1: format!("0x{:04X}", r.pwe1),
            pwe2: format!("0x{:04X}", r.pwe2),
            words: match a.reply {
                Reply::Element(v) => element_words(a.request.ind, v),
                _ => None,
            },
            what: t.what.clone(),
        }
    }
}

impl fmt::Display for PkwAnswered {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (what, value) = (&self.what, self.value);
        let verb = if self.op == "write" { ":=" } else { "=" };
        let format = if self.format == "dword" {
            "double word"
        } else {
            "word"
        };
        write!(f, "{what} {verb} {value} (0x{value:X}, {format}")?;
        if self.signed != value as i64 {
            write!(f, ", signed {}", self.signed)?;
        }
        f.write_str(")")?;
        if let Some(e) = &self.words {
            write!(f, ": {e}")?;
        }
        write!(
            f,
            "  [request {}, response {}]",
            self.request, self.response
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pkw::Pkw;
    use profibus_dp::master::SlaveParams;

    fn slave(ident: u16, cfg: Vec<u8>) -> BusSlave {
        BusSlave {
            params: SlaveParams::new(5, ident, cfg),
            gsd_path: "the GSD of device `omega`".into(),
            device: None,
            gsd: Default::default(),
            modules: vec![],
        }
    }

    #[test]
    fn parameters_and_values_as_people_write_them() {
        assert_eq!(parse_num(" 0x7E"), Some(126));
        assert_eq!(parse_num("16#1_0"), Some(16));
        assert_eq!(parse_num("-5"), Some(-5));
        assert_eq!(parse_num("x"), None);
        let s = slave(crate::omega::IDENT, vec![0x73, 0x71, 0x53, 0x63]);
        let p = ParamRef::parse("P5[2]", &s).unwrap();
        assert_eq!(
            (p.pnu, p.index, p.to_string()),
            (5, Some(2), "P5[2]".into())
        );
        assert_eq!(ParamRef::parse("0x7E", &s).unwrap().pnu, 126);
        let e = |t: &str| ParamRef::parse(t, &s).unwrap_err().to_string();
        assert_eq!(e("P2048"), "parameter number 2048 is outside 0..=2047");
        assert_eq!(e("P5[x]"), "bad array index in `P5[x]`");
        assert_eq!(
            e("speed"),
            "`speed` is neither a parameter number nor a variable module of the GSD of device `omega`"
        );
    }

    #[test]
    fn omega_parameters_by_name_and_array_elements() {
        let t = Duration::from_secs(1);
        let omega = slave(crate::omega::IDENT, vec![0x73, 0x71, 0x53, 0x63]);
        // Names of the V-controller table (L1028: P218 "L rev actual
        // value", L1080: P127 "M communication monitoring").
        for name in [
            "L rev actual value",
            "L_rev_actual_value",
            "l-rev-actual-value",
        ] {
            assert_eq!(ParamRef::parse(name, &omega).unwrap().pnu, 218, "{name}");
        }
        let w = PkwTask::write(&omega, "M_communication_monitoring=4", None, t).unwrap();
        assert_eq!(w.param.pnu, 127);
        // P[i] on the Omega: the DINT array from P1000, PNU P + i.
        let r = PkwTask::read(&omega, "P1000[5]", t).unwrap();
        assert_eq!((r.param.pnu, r.param.index), (1005, None));
        let e = PkwTask::read(&omega, "P218[1]", t).unwrap_err().to_string();
        assert!(e.contains("no array element commands"), "{e}");
        assert!(PkwTask::read(&omega, "P2047[1]", t).is_err());
        let list = crate::pkw_parameters(crate::omega::IDENT, &omega.gsd);
        assert!(list
            .iter()
            .any(|p| p.pnu == 218 && p.name == "L rev actual value"));
        assert!(list.iter().any(|p| p.pnu == 1000));
    }

    #[test]
    fn jobs_are_checked_before_they_run() {
        let t = Duration::from_secs(1);
        let omega = slave(crate::omega::IDENT, vec![0x73, 0x71, 0x53, 0x63]);
        let bm4 = slave(crate::bm4::IDENT, vec![0x73]);
        let e = |r: Result<PkwTask, PkwTaskError>| r.unwrap_err().to_string();
        assert_eq!(e(PkwTask::write(&omega, "P5", None, t)), "write takes P=V");
        assert_eq!(
            e(PkwTask::write(&omega, "P5=1x", None, t)),
            "`1x` is not a number"
        );
        assert_eq!(
            e(PkwTask::write(&omega, "P5=0x100000000", None, t)),
            "4294967296 does not fit 32 bits"
        );
        assert!(e(PkwTask::describe(&omega, "P5", "unit", t)).contains("`unit`"));
        assert!(e(PkwTask::describe(&bm4, "P5", "min", t)).contains("no parameter description"));
        let e = e(PkwTask::read(&slave(0x1234, vec![0x73]), "P5", t));
        assert!(e.starts_with("slave 5: ident 0x1234"), "{e}");
        // A write of unknown width reads first; P ≥ 1000 on the Omega is
        // a double word.
        let w = PkwTask::write(&omega, "P5=-1", None, t).unwrap();
        assert!(matches!(w.steps.front(), Some(Step::Probe(Command::Read))));
        let w = PkwTask::write(&omega, "P1000=7", None, t).unwrap();
        assert!(matches!(
            w.steps.front(),
            Some(Step::Write {
                value: 7,
                dword: Some(true)
            })
        ));
    }

    #[test]
    fn answers_in_words_and_json_fields() {
        let omega = slave(crate::omega::IDENT, vec![0x73, 0x71, 0x53, 0x63]);
        let mut task =
            PkwTask::describe(&omega, "P5", "attribute", Duration::from_secs(1)).unwrap();
        task.outcome = Some(Ok(crate::pkw::client::PkwAnswer {
            request: Pkw::new(4, 5, 1, 0),
            response: Pkw::new(3, 5, 1, 0x0105),
            reply: Reply::Element(0x0105),
        }));
        let a = task.outcome().unwrap().unwrap();
        assert_eq!(
            (a.op, a.format, a.hex.as_str()),
            ("describe", "word", "0x0105")
        );
        assert_eq!(
            a.to_string(),
            format!(
                "P5 attribute = 261 (0x105, word): 2 bytes, UNSIGNED, FIXED, DATA, display DEC, 0 decimals  [request {}, response {}]",
                Pkw::new(4, 5, 1, 0),
                Pkw::new(3, 5, 1, 0x0105)
            )
        );
        task.outcome = Some(Err(PkwError::Refused { code: 2, text: "x" }));
        let r = task.outcome().unwrap().unwrap_err();
        assert_eq!((r.ok, r.code), (false, Some(2)));
        assert!(r.to_string().starts_with("slave 5 P5: "), "{r}");
    }
}
