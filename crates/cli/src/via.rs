//! `--via PATH`: a one-shot command (`pkw`, `rfid`, `dpv1`, `im`, `diag`,
//! `get-cfg`) sends its job to the control socket of a running `dpctl
//! master` or `dpctl gateway` (`crate::control`) instead of opening the
//! port, and prints what it prints without `--via`.
//!
//! [`Printed`] is what a command prints (its text, its `--json` lines and
//! its error): the commands whose job runs in the master (`pkw`, `rfid`)
//! build it there, send it back, and the client prints it as it would
//! have; the others (`dpv1`, `im`, `diag`, `get-cfg`) send the master's
//! jobs (`dpv1_read`, `read_diag`, …) and print the answers themselves.

use anyhow::{bail, Context, Result};
use profibus_dp::master::records::{RecordAnswer, RecordOp, RecordOps};
use profibus_dp::pdu::dpv1::Dpv1Error;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};

/// What a command prints: its text (without `--json`), its JSON lines
/// (with `--json`), and the error it ends with, if any.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct Printed {
    /// It ended without error.
    pub ok: bool,
    /// The text printed without `--json` (lines with their newlines).
    pub text: String,
    /// The objects printed with `--json`, one per line.
    pub json: Vec<Value>,
    /// The error it ends with (exit status 1, `dpctl: …` on stderr).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl Printed {
    /// A failure before anything is printed.
    pub fn failed(e: &anyhow::Error) -> Printed {
        Printed {
            ok: false,
            error: Some(format!("{e:#}")),
            ..Printed::default()
        }
    }

    /// One outcome, as `common::SlaveArgs::print` prints it: a success
    /// as its line or JSON; a failure as JSON only (with `--json`), and
    /// its text the error.
    pub fn outcome<T, E>(outcome: std::result::Result<T, E>) -> Printed
    where
        T: Serialize + std::fmt::Display,
        E: Serialize + std::fmt::Display,
    {
        match outcome {
            Ok(a) => Printed {
                ok: true,
                text: format!("{a}\n"),
                json: vec![json_value(&a)],
                error: None,
            },
            Err(r) => Printed {
                ok: false,
                text: String::new(),
                json: vec![json_value(&r)],
                error: Some(r.to_string()),
            },
        }
    }

    /// Print it (its JSON lines with `json`, else its text) and end
    /// with its error.
    pub fn emit(&self, json: bool) -> Result<()> {
        if json {
            for v in &self.json {
                crate::out::outln!("{v}")?;
            }
        } else {
            crate::out::out!("{}", self.text)?;
        }
        match &self.error {
            Some(e) => bail!("{e}"),
            None => Ok(()),
        }
    }
}

/// `v` as the value `common::json_line` prints.
pub fn json_value<T: Serialize + ?Sized>(v: &T) -> Value {
    serde_json::to_value(v).unwrap_or(Value::Null)
}

/// A connection to a control socket.
pub struct Via {
    path: PathBuf,
    reader: BufReader<UnixStream>,
    writer: UnixStream,
}

impl Via {
    /// Connect to the control socket at `path`.
    pub fn connect(path: &Path) -> Result<Via> {
        let stream = UnixStream::connect(path).with_context(|| {
            format!(
                "--via {}: no dpctl master or gateway listens there (start it with --control {0})",
                path.display()
            )
        })?;
        let writer = stream.try_clone()?;
        Ok(Via {
            path: path.to_path_buf(),
            reader: BufReader::new(stream),
            writer,
        })
    }

    /// Send one request, wait for its answer. An answer `{"error": …}`
    /// is the error.
    pub fn request(&mut self, request: &Value) -> Result<Value> {
        let answer = self.ask(request)?;
        if let Some(e) = answer.get("error").and_then(Value::as_str) {
            bail!("{e}");
        }
        Ok(answer)
    }

    /// Send one request, wait for its answer, whatever it says.
    pub fn ask(&mut self, request: &Value) -> Result<Value> {
        let lost = || format!("--via {}", self.path.display());
        writeln!(self.writer, "{request}").with_context(lost)?;
        let mut line = String::new();
        if self.reader.read_line(&mut line).with_context(lost)? == 0 {
            bail!(
                "--via {}: the master closed the connection before it answered",
                self.path.display()
            );
        }
        serde_json::from_str(&line).with_context(|| {
            format!(
                "--via {}: answer not JSON: {}",
                self.path.display(),
                line.trim()
            )
        })
    }

    /// Send a job that runs in the master and answers with a [`Printed`].
    pub fn printed(&mut self, request: &Value) -> Result<Printed> {
        let answer = self.ask(request)?;
        if answer.get("text").is_none() {
            if let Some(e) = answer.get("error").and_then(Value::as_str) {
                bail!("{e}");
            }
        }
        serde_json::from_value(answer).context("--via: not the answer of a job")
    }

    /// A master job (`read_diag`, `get_cfg`, `dpv1_read`, …): the data it
    /// returned, or why it failed ([`JobFailure`]).
    pub fn job(&mut self, request: &Value) -> Result<std::result::Result<JobAnswer, JobFailure>> {
        let answer = self.request(request)?;
        let a: JobAnswer =
            serde_json::from_value(answer).context("--via: not the answer of a job")?;
        if a.ok {
            return Ok(Ok(a));
        }
        Ok(Err(match a.dpv1_error {
            Some(e) => JobFailure::Dpv1(e.into()),
            None => JobFailure::Other(a.result),
        }))
    }
}

/// The control socket's answer to a master job.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct JobAnswer {
    /// The job's number.
    pub job: u32,
    /// Data returned, or done.
    pub ok: bool,
    /// `ok`, else the result in words (`JobResult::describe`).
    pub result: String,
    /// The data returned, hex.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<String>,
    /// A DP-V1 error response.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dpv1_error: Option<Dpv1ErrorJson>,
}

impl JobAnswer {
    /// The data returned (none: empty).
    pub fn bytes(&self) -> Result<Vec<u8>> {
        match &self.data {
            Some(h) => Ok(profibus_fdl::wire::parse_hex(h)?),
            None => Ok(vec![]),
        }
    }
}

/// A DP-V1 error response's four bytes.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
pub struct Dpv1ErrorJson {
    /// Function number with bit 7 set.
    pub function: u8,
    /// Error_Decode.
    pub error_decode: u8,
    /// Error_Code_1.
    pub error_code_1: u8,
    /// Error_Code_2.
    pub error_code_2: u8,
}

impl From<Dpv1Error> for Dpv1ErrorJson {
    fn from(e: Dpv1Error) -> Self {
        Dpv1ErrorJson {
            function: e.function,
            error_decode: e.error_decode,
            error_code_1: e.error_code_1,
            error_code_2: e.error_code_2,
        }
    }
}

impl From<Dpv1ErrorJson> for Dpv1Error {
    fn from(e: Dpv1ErrorJson) -> Self {
        Dpv1Error {
            function: e.function,
            error_decode: e.error_decode,
            error_code_1: e.error_code_1,
            error_code_2: e.error_code_2,
        }
    }
}

/// Why a master job through the socket gave no data.
#[derive(Debug, Clone)]
pub enum JobFailure {
    /// A DP-V1 error response.
    Dpv1(Dpv1Error),
    /// Anything else, in words (`JobResult::describe`).
    Other(String),
}

/// Why [`Via::records`] stopped: a request failed other than with a
/// DP-V1 error response (no response, timeout, …).
#[derive(Debug)]
pub struct RecordFailure {
    /// The request.
    pub op: RecordOp,
    /// In words.
    pub why: String,
}

impl Via {
    /// Run `ops` on `slave` as the master's MSAC_C1 jobs (`dpv1_read`,
    /// `dpv1_write`), as `profibus_dp::master::records::C1Records` runs
    /// them in a master of its own.
    pub fn records<O: RecordOps>(
        &mut self,
        slave: u8,
        mut ops: O,
    ) -> Result<std::result::Result<O, (RecordFailure, O)>> {
        while let Some(op) = ops.next_op() {
            op.check()?;
            let request = match &op {
                RecordOp::Read {
                    slot,
                    index,
                    length,
                } => json!({"dpv1_read": slave, "slot": slot, "index": index, "length": length}),
                RecordOp::Write { slot, index, data } => json!({
                    "dpv1_write": slave, "slot": slot, "index": index,
                    "data": profibus_fdl::wire::Hex(data).to_string(),
                }),
                RecordOp::Transport { .. } => {
                    bail!(
                        "Data_Transport is a class-2 service (MSAC_C2): use --class2 without --via"
                    )
                }
            };
            let answer = match self.job(&request)? {
                Ok(a) => match &op {
                    RecordOp::Read { .. } => RecordAnswer::Read(a.bytes()?),
                    _ => RecordAnswer::Written(op.len() as u8),
                },
                Err(JobFailure::Dpv1(e)) => RecordAnswer::Negative(e),
                Err(JobFailure::Other(why)) => return Ok(Err((RecordFailure { op, why }, ops))),
            };
            ops.answered(&op, &answer);
        }
        Ok(Ok(ops))
    }
}

/// The error `C1Records` ends with when a request fails: `slave 8 slot
/// 1 index 2: read failed: no response`.
pub fn record_failure(slave: u8, f: &RecordFailure) -> anyhow::Error {
    let (slot, index) = f.op.record();
    anyhow::anyhow!(
        "slave {slave} slot {slot} index {index}: {} failed: {}",
        f.op.name(),
        f.why
    )
}

/// `--via` with `--class2`: the master runs class-1 jobs only.
pub fn no_class2(path: &Path) -> anyhow::Error {
    anyhow::anyhow!(
        "--via {} runs the job as the master's own MSAC_C1 request; a class-2 \
         connection (--class2) needs a master of its own: leave out --via or --class2",
        path.display()
    )
}
