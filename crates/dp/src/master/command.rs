//! Commands for a running DP master, as scripts send them: one JSON object
//! per line (`dpctl master --input`), or any serde format a gateway uses.
//!
//! ```text
//! {"slave": 8, "outputs": "01 02"}          write a slave's outputs (hex or [1, 2])
//! {"operating": "clear"}                    operate | clear | stop
//! {"global_control": ["sync"], "group": 1}  sync, unsync, freeze, unfreeze
//! {"read_diag": 8} / {"get_cfg": 8} / {"rd_inp": 8} / {"rd_outp": 8}
//! {"dpv1_read": 8, "slot": 0, "index": 1, "length": 4}
//! {"dpv1_write": 8, "slot": 0, "index": 1, "data": "0A 0B"}
//! {"set_slave_add": 126, "new_address": 7, "ident": "0x0008", "no_add_chg": false}
//! ```
//!
//! Every field is range-checked while it is read (station addresses
//! 0..=126, DP-V1 slot 0..=254 and index 0..=255 (255: the I&M call), a
//! read length 1..=240, at most 244 output bytes, …); a bad command is
//! refused as a whole with an error that names the field, and nothing of
//! it is executed. Outputs by channel
//! name (`{"slave": 8, "set": {…}}`) belong to the device profiles, which
//! know the channels; [`MasterCommand::from_json`] leaves them to the
//! caller ([`CommandError::Channels`]).

use super::{DpMaster, Job, JobId, OperatingState};
use crate::pdu::control::ControlCommand;
use serde::de::{self, Deserializer};
use serde::Deserialize;

/// A command for a [`DpMaster`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MasterCommand {
    /// Replace a slave's output image (as many bytes as it has outputs).
    SetOutputs {
        /// Station address.
        slave: u8,
        /// The outputs.
        data: Vec<u8>,
    },
    /// Change the operating state (announced with Global_Control).
    Operating(OperatingState),
    /// A Global_Control (sync, unsync, freeze, unfreeze) to groups.
    GlobalControl {
        /// The commands.
        command: ControlCommand,
        /// Group_Select: 0 = all slaves.
        group: u8,
    },
    /// A class-2 service or DP-V1 request ([`Job`]).
    Job(Job),
}

/// Why a command was refused; nothing of it was executed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    /// Not a JSON object of the command's shape, or a field's value is
    /// wrong (the message names the field).
    #[error("{message}")]
    Json {
        /// serde_json's message, with the position only where it helps.
        message: String,
    },
    /// None of the command keys is given.
    #[error(
        "no command: give one of slave, operating, global_control, read_diag, get_cfg, rd_inp, rd_outp, dpv1_read, dpv1_write, set_slave_add"
    )]
    NoCommand,
    /// More than one command key in one line.
    #[error("one command per line, not {}", given.join(" and "))]
    SeveralCommands {
        /// The command keys given.
        given: Vec<&'static str>,
    },
    /// A field of another command.
    #[error("`{field}` does not belong to `{command}`")]
    ForeignField {
        /// The field.
        field: &'static str,
        /// The command given.
        command: &'static str,
    },
    /// A field the command needs is missing.
    #[error("`{command}` needs `{field}`")]
    MissingField {
        /// The field.
        field: &'static str,
        /// The command given.
        command: &'static str,
    },
    /// `slave` with both `outputs` and `set`.
    #[error("give `outputs` or `set`, not both")]
    OutputsAndSet,
    /// `slave` with neither `outputs` nor `set`.
    #[error("`slave` needs `outputs` (or `set` by channel name)")]
    NoOutputs,
    /// Outputs by channel name: for the device profile layer.
    #[error("outputs by channel name need the slave's device profile")]
    Channels,
    /// The slave is not in the bus file.
    #[error("slave {0} is not in the bus file")]
    UnknownSlave(u8),
    /// The output image has another length than the slave's outputs.
    #[error("slave {slave} has {expected} output bytes, the command gives {given}")]
    OutputLength {
        /// Station address.
        slave: u8,
        /// The slave's output bytes.
        expected: usize,
        /// Bytes in the command.
        given: usize,
    },
    /// The Global_Control or job queue is full; try again later.
    #[error("the {0} queue is full")]
    QueueFull(Queue),
}

/// The master's command queues.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Queue {
    /// Global_Control telegrams to send.
    GlobalControl,
    /// Class-2 and DP-V1 jobs.
    Job,
}

impl std::fmt::Display for Queue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Queue::GlobalControl => "Global_Control",
            Queue::Job => "job",
        })
    }
}

/// What a command did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandOutcome {
    /// Applied at once (outputs, operating state, Global_Control queued).
    Applied,
    /// The job was queued; its result comes as [`super::MasterEvent::JobDone`].
    JobQueued(JobId),
}

impl MasterCommand {
    /// Read one command from a JSON object (one line of `dpctl master
    /// --input`).
    pub fn from_json(text: &str) -> Result<MasterCommand, CommandError> {
        let raw: Raw = serde_json::from_str(text).map_err(|e| CommandError::Json {
            message: json_error(&e),
        })?;
        raw.into_command()
    }
}

impl DpMaster {
    /// Read and execute one command line ([`MasterCommand::from_json`]);
    /// returns what to tell the sender, if anything (`operating state
    /// clear`, `job 3 queued`). A refused command changes nothing.
    pub fn execute_json(&mut self, line: &str) -> Result<Option<String>, CommandError> {
        let command = MasterCommand::from_json(line)?;
        let reply = match &command {
            MasterCommand::Operating(s) => Some(format!("operating state {}", s.as_str())),
            _ => None,
        };
        Ok(match self.apply(command)? {
            CommandOutcome::JobQueued(id) => Some(format!("job {} queued", id.0)),
            CommandOutcome::Applied => reply,
        })
    }

    /// Whether every slave has completed at least `n` Data_Exchange
    /// cycles (however long its start-up took).
    pub fn all_exchanged(&self, n: u64) -> bool {
        self.slave_addresses()
            .all(|a| self.slave_stats(a).is_some_and(|s| s.data_exchanges >= n))
    }

    /// The slaves not in Data_Exchange, by address.
    pub fn not_exchanging(&self) -> Vec<u8> {
        self.slave_addresses()
            .filter(|&a| self.slave_state(a) != Some(super::SlaveState::DataExchange))
            .collect()
    }

    /// Execute a command. Errors leave the master as it was.
    pub fn apply(&mut self, command: MasterCommand) -> Result<CommandOutcome, CommandError> {
        match command {
            MasterCommand::SetOutputs { slave, data } => {
                let expected = self
                    .by_address(slave)
                    .map(|s| s.output_len)
                    .ok_or(CommandError::UnknownSlave(slave))?;
                if data.len() != expected {
                    return Err(CommandError::OutputLength {
                        slave,
                        expected,
                        given: data.len(),
                    });
                }
                self.set_outputs(slave, &data);
                Ok(CommandOutcome::Applied)
            }
            MasterCommand::Operating(state) => {
                self.set_operating_state(state);
                Ok(CommandOutcome::Applied)
            }
            MasterCommand::GlobalControl { command, group } => {
                if self.global_control(command, group) {
                    Ok(CommandOutcome::Applied)
                } else {
                    Err(CommandError::QueueFull(Queue::GlobalControl))
                }
            }
            MasterCommand::Job(job) => self
                .submit(job)
                .map(CommandOutcome::JobQueued)
                .ok_or(CommandError::QueueFull(Queue::Job)),
        }
    }
}

/// serde_json's message, with the position only when it helps.
fn json_error(e: &serde_json::Error) -> String {
    let text = e.to_string();
    match text.find(" at line ") {
        Some(i) if e.is_data() => text[..i].to_string(),
        _ => text,
    }
}

/// The command as written: exactly one command key, plus its fields.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    #[serde(default, deserialize_with = "address")]
    slave: Option<u8>,
    #[serde(default, deserialize_with = "outputs")]
    outputs: Option<Vec<u8>>,
    #[serde(default)]
    set: Option<de::IgnoredAny>,
    #[serde(default, deserialize_with = "operating")]
    operating: Option<OperatingState>,
    #[serde(default, deserialize_with = "global_control")]
    global_control: Option<ControlCommand>,
    #[serde(default, deserialize_with = "group")]
    group: Option<u8>,
    #[serde(default, deserialize_with = "address")]
    read_diag: Option<u8>,
    #[serde(default, deserialize_with = "address")]
    get_cfg: Option<u8>,
    #[serde(default, deserialize_with = "address")]
    rd_inp: Option<u8>,
    #[serde(default, deserialize_with = "address")]
    rd_outp: Option<u8>,
    #[serde(default, deserialize_with = "address")]
    dpv1_read: Option<u8>,
    #[serde(default, deserialize_with = "address")]
    dpv1_write: Option<u8>,
    #[serde(default, deserialize_with = "slot_index")]
    slot: Option<u8>,
    #[serde(default, deserialize_with = "record_index")]
    index: Option<u8>,
    #[serde(default, deserialize_with = "read_length")]
    length: Option<u8>,
    #[serde(default, deserialize_with = "record")]
    data: Option<Vec<u8>>,
    #[serde(default, deserialize_with = "address")]
    set_slave_add: Option<u8>,
    #[serde(default, deserialize_with = "address")]
    new_address: Option<u8>,
    #[serde(default, deserialize_with = "ident")]
    ident: Option<u16>,
    #[serde(default, deserialize_with = "flag")]
    no_add_chg: Option<bool>,
}

fn need<T>(v: Option<T>, field: &'static str, command: &'static str) -> Result<T, CommandError> {
    v.ok_or(CommandError::MissingField { field, command })
}

impl Raw {
    fn into_command(self) -> Result<MasterCommand, CommandError> {
        let keys = [
            ("slave", self.slave.is_some()),
            ("operating", self.operating.is_some()),
            ("global_control", self.global_control.is_some()),
            ("read_diag", self.read_diag.is_some()),
            ("get_cfg", self.get_cfg.is_some()),
            ("rd_inp", self.rd_inp.is_some()),
            ("rd_outp", self.rd_outp.is_some()),
            ("dpv1_read", self.dpv1_read.is_some()),
            ("dpv1_write", self.dpv1_write.is_some()),
            ("set_slave_add", self.set_slave_add.is_some()),
        ];
        let given: Vec<&'static str> = keys.iter().filter(|k| k.1).map(|k| k.0).collect();
        let command = match given[..] {
            [one] => one,
            [] => return Err(CommandError::NoCommand),
            _ => return Err(CommandError::SeveralCommands { given }),
        };
        // Fields that belong to other commands are mistakes, not noise.
        let fields = [
            ("outputs", self.outputs.is_some(), &["slave"][..]),
            ("set", self.set.is_some(), &["slave"]),
            ("group", self.group.is_some(), &["global_control"]),
            ("slot", self.slot.is_some(), &["dpv1_read", "dpv1_write"]),
            ("index", self.index.is_some(), &["dpv1_read", "dpv1_write"]),
            ("length", self.length.is_some(), &["dpv1_read"]),
            ("data", self.data.is_some(), &["dpv1_write"]),
            (
                "new_address",
                self.new_address.is_some(),
                &["set_slave_add"],
            ),
            ("ident", self.ident.is_some(), &["set_slave_add"]),
            ("no_add_chg", self.no_add_chg.is_some(), &["set_slave_add"]),
        ];
        for (field, present, owners) in fields {
            if present && !owners.contains(&command) {
                return Err(CommandError::ForeignField { field, command });
            }
        }
        let job = |j| Ok(MasterCommand::Job(j));
        match command {
            "slave" => {
                let slave = self.slave.unwrap_or_default();
                match (self.outputs, self.set) {
                    (Some(data), None) => Ok(MasterCommand::SetOutputs { slave, data }),
                    (None, Some(_)) => Err(CommandError::Channels),
                    (Some(_), Some(_)) => Err(CommandError::OutputsAndSet),
                    (None, None) => Err(CommandError::NoOutputs),
                }
            }
            "operating" => Ok(MasterCommand::Operating(
                self.operating.unwrap_or(OperatingState::Operate),
            )),
            "global_control" => Ok(MasterCommand::GlobalControl {
                command: self.global_control.unwrap_or(ControlCommand::empty()),
                group: self.group.unwrap_or(0),
            }),
            "read_diag" => job(Job::ReadDiag {
                address: self.read_diag.unwrap_or_default(),
            }),
            "get_cfg" => job(Job::GetCfg {
                address: self.get_cfg.unwrap_or_default(),
            }),
            "rd_inp" => job(Job::RdInp {
                address: self.rd_inp.unwrap_or_default(),
            }),
            "rd_outp" => job(Job::RdOutp {
                address: self.rd_outp.unwrap_or_default(),
            }),
            "dpv1_read" => job(Job::Dpv1Read {
                address: self.dpv1_read.unwrap_or_default(),
                slot: need(self.slot, "slot", command)?,
                index: need(self.index, "index", command)?,
                length: need(self.length, "length", command)?,
            }),
            "dpv1_write" => job(Job::Dpv1Write {
                address: self.dpv1_write.unwrap_or_default(),
                slot: need(self.slot, "slot", command)?,
                index: need(self.index, "index", command)?,
                data: need(self.data, "data", command)?,
            }),
            _ => job(Job::SetSlaveAdd {
                address: self.set_slave_add.unwrap_or_default(),
                new_address: need(self.new_address, "new_address", command)?,
                ident_number: need(self.ident, "ident", command)?,
                no_add_chg: self.no_add_chg.unwrap_or(false),
            }),
        }
    }
}

/// A number in `range`, or an error that says which.
fn number_in<'de, D: Deserializer<'de>>(
    d: D,
    what: &str,
    range: std::ops::RangeInclusive<u64>,
) -> Result<Option<u8>, D::Error> {
    let v =
        u64::deserialize(d).map_err(|_| de::Error::custom(format!("{what} must be a number")))?;
    if range.contains(&v) {
        Ok(Some(v as u8))
    } else {
        Err(de::Error::custom(format!(
            "{what} must be {}..={}, not {v}",
            range.start(),
            range.end()
        )))
    }
}

fn address<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u8>, D::Error> {
    number_in(d, "a station address", 0..=126)
}

fn group<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u8>, D::Error> {
    number_in(d, "`group` (Group_Select)", 0..=255)
}

fn flag<'de, D: Deserializer<'de>>(d: D) -> Result<Option<bool>, D::Error> {
    bool::deserialize(d)
        .map(Some)
        .map_err(|_| de::Error::custom("`no_add_chg` must be true or false"))
}

fn slot_index<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u8>, D::Error> {
    number_in(d, "a DP-V1 slot or index", 0..=254)
}

/// Index 255 too: the I&M call (`crate::pdu::im::CALL_INDEX`).
fn record_index<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u8>, D::Error> {
    number_in(d, "a DP-V1 index", 0..=255)
}

fn read_length<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u8>, D::Error> {
    number_in(d, "`length` (bytes of a DP-V1 read)", 1..=240)
}

/// Bytes as a hex string (`"01 0A"`, `"010A"`) or an array of numbers.
#[derive(Deserialize)]
#[serde(untagged)]
enum RawBytes {
    Hex(String),
    List(Vec<u64>),
}

fn bytes<'de, D: Deserializer<'de>>(
    d: D,
    what: &str,
    max: usize,
) -> Result<Option<Vec<u8>>, D::Error> {
    let raw = RawBytes::deserialize(d).map_err(|_| {
        de::Error::custom(format!(
            "{what} must be a hex string or an array of numbers"
        ))
    })?;
    let bytes = match raw {
        RawBytes::Hex(s) => profibus_fdl::wire::parse_hex(&s)
            .map_err(|e| de::Error::custom(format!("{what}: `{s}` is not hex bytes ({e})")))?,
        RawBytes::List(v) => v
            .into_iter()
            .map(|b| {
                u8::try_from(b).map_err(|_| {
                    de::Error::custom(format!("{what}: byte values are 0..=255, not {b}"))
                })
            })
            .collect::<Result<Vec<u8>, D::Error>>()?,
    };
    if bytes.len() > max {
        return Err(de::Error::custom(format!(
            "{what}: at most {max} bytes, not {}",
            bytes.len()
        )));
    }
    Ok(Some(bytes))
}

fn outputs<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<u8>>, D::Error> {
    bytes(d, "`outputs`", 244)
}

fn record<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<u8>>, D::Error> {
    let data = bytes(d, "`data` (a DP-V1 record)", crate::pdu::dpv1::MAX_DATA_LEN)?;
    if data.as_ref().is_some_and(Vec::is_empty) {
        return Err(de::Error::custom("`data` (a DP-V1 record) is empty"));
    }
    Ok(data)
}

fn operating<'de, D: Deserializer<'de>>(d: D) -> Result<Option<OperatingState>, D::Error> {
    let s = String::deserialize(d)?;
    match s.as_str() {
        "operate" => Ok(Some(OperatingState::Operate)),
        "clear" => Ok(Some(OperatingState::Clear)),
        "stop" => Ok(Some(OperatingState::Stop)),
        other => Err(de::Error::custom(format!(
            "`operating` is operate, clear or stop, not `{other}`"
        ))),
    }
}

#[derive(Deserialize)]
#[serde(untagged)]
enum OneOrMany {
    One(String),
    Many(Vec<String>),
}

fn global_control<'de, D: Deserializer<'de>>(d: D) -> Result<Option<ControlCommand>, D::Error> {
    let names = match OneOrMany::deserialize(d)
        .map_err(|_| de::Error::custom("`global_control` takes a name or a list of names"))?
    {
        OneOrMany::One(s) => vec![s],
        OneOrMany::Many(v) => v,
    };
    let mut c = ControlCommand::empty();
    for name in names {
        c |= match name.as_str() {
            "sync" => ControlCommand::SYNC,
            "unsync" => ControlCommand::UNSYNC,
            "freeze" => ControlCommand::FREEZE,
            "unfreeze" => ControlCommand::UNFREEZE,
            other => {
                return Err(de::Error::custom(format!(
                    "`global_control`: `{other}` is none of sync, unsync, freeze, unfreeze"
                )))
            }
        };
    }
    Ok(Some(c))
}

fn ident<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u16>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum HexOrNumber {
        Hex(String),
        Number(u64),
    }
    let v = match HexOrNumber::deserialize(d)
        .map_err(|_| de::Error::custom("`ident` must be hex like \"0x0008\" or a number"))?
    {
        HexOrNumber::Hex(s) => {
            let digits = s.trim_start_matches("0x").trim_start_matches("0X");
            u64::from_str_radix(digits, 16)
                .map_err(|_| de::Error::custom(format!("`ident`: `{s}` is not hex")))?
        }
        HexOrNumber::Number(n) => n,
    };
    u16::try_from(v)
        .map(Some)
        .map_err(|_| de::Error::custom(format!("`ident` must be 0..=0xFFFF, not {v}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_lines_execute_with_a_reply_in_words() {
        use crate::master::{MasterConfig, MasterOptions, SlaveParams};
        use profibus_fdl::{Baud, BusParams};
        let mut m = DpMaster::new(&MasterConfig {
            address: 2,
            params: BusParams::defaults(Baud::B1500000),
            slaves: vec![SlaveParams::new(8, 0x1234, vec![0x11, 0x21])],
            options: MasterOptions::default(),
        })
        .unwrap();
        let reply = m.execute_json(r#"{"operating": "clear"}"#).unwrap();
        assert_eq!(reply.as_deref(), Some("operating state clear"));
        assert_eq!(
            m.execute_json(r#"{"slave": 8, "outputs": "01 02"}"#)
                .unwrap(),
            None
        );
        assert_eq!(m.outputs(8).unwrap(), [1, 2]);
        let reply = m.execute_json(r#"{"read_diag": 8}"#).unwrap().unwrap();
        assert!(
            reply.starts_with("job ") && reply.ends_with(" queued"),
            "{reply}"
        );
        assert!(m.execute_json(r#"{"slave": 8, "outputs": "01"}"#).is_err());
        assert_eq!(m.outputs(8).unwrap(), [1, 2]);
    }

    fn ok(text: &str) -> MasterCommand {
        MasterCommand::from_json(text).unwrap_or_else(|e| panic!("{text}: {e}"))
    }

    fn err(text: &str) -> String {
        match MasterCommand::from_json(text) {
            Err(e) => e.to_string(),
            Ok(c) => panic!("{text} was taken: {c:?}"),
        }
    }

    #[test]
    fn every_command_reads() {
        assert_eq!(
            ok(r#"{"slave": 8, "outputs": "01 0a"}"#),
            MasterCommand::SetOutputs {
                slave: 8,
                data: vec![1, 10]
            }
        );
        assert_eq!(
            ok(r#"{"slave": 8, "outputs": [1, 255]}"#),
            MasterCommand::SetOutputs {
                slave: 8,
                data: vec![1, 255]
            }
        );
        assert_eq!(
            ok(r#"{"operating": "clear"}"#),
            MasterCommand::Operating(OperatingState::Clear)
        );
        assert_eq!(
            ok(r#"{"global_control": ["sync", "freeze"], "group": 3}"#),
            MasterCommand::GlobalControl {
                command: ControlCommand::SYNC | ControlCommand::FREEZE,
                group: 3
            }
        );
        assert_eq!(
            ok(r#"{"dpv1_read": 10, "slot": 1, "index": 7, "length": 2}"#),
            MasterCommand::Job(Job::Dpv1Read {
                address: 10,
                slot: 1,
                index: 7,
                length: 2
            })
        );
        assert_eq!(
            ok(r#"{"dpv1_write": 10, "slot": 1, "index": 7, "data": "CA FE"}"#),
            MasterCommand::Job(Job::Dpv1Write {
                address: 10,
                slot: 1,
                index: 7,
                data: vec![0xCA, 0xFE]
            })
        );
        assert_eq!(
            ok(r#"{"set_slave_add": 126, "new_address": 7, "ident": "0x0008"}"#),
            MasterCommand::Job(Job::SetSlaveAdd {
                address: 126,
                new_address: 7,
                ident_number: 8,
                no_add_chg: false
            })
        );
        assert_eq!(
            ok(r#"{"rd_inp": 3}"#),
            MasterCommand::Job(Job::RdInp { address: 3 })
        );
    }

    #[test]
    fn bad_fields_are_refused_by_name_and_never_truncated() {
        // Slot 300 used to become 44.
        assert_eq!(
            err(r#"{"dpv1_read": 10, "slot": 300, "index": 1, "length": 4}"#),
            "a DP-V1 slot or index must be 0..=254, not 300"
        );
        assert!(
            err(r#"{"dpv1_read": 10, "slot": 1, "index": 1, "length": 0}"#)
                .contains("`length` (bytes of a DP-V1 read) must be 1..=240, not 0")
        );
        assert!(err(r#"{"dpv1_read": 10, "slot": 1, "index": 1}"#).contains("needs `length`"));
        // Index 255 is the I&M call (select a record, then read it).
        assert!(matches!(
            MasterCommand::from_json(
                r#"{"dpv1_write": 10, "slot": 0, "index": 255, "data": "08 00 FD E8"}"#
            ),
            Ok(MasterCommand::Job(Job::Dpv1Write { index: 255, .. }))
        ));
        assert!(err(r#"{"read_diag": 127}"#).contains("station address must be 0..=126"));
        assert!(err(r#"{"slave": 8, "outputs": [1, 256]}"#).contains("0..=255, not 256"));
        assert!(err(r#"{"slave": 8, "outputs": "0g"}"#).contains("not hex bytes"));
        assert!(err(r#"{"operating": "run"}"#).contains("not `run`"));
        assert!(err(r#"{"global_control": "sync", "group": 256}"#)
            .contains("`group` (Group_Select) must be 0..=255"));
        assert!(err(r#"{"global_control": "jump"}"#).contains("`jump` is none of"));
        assert!(
            err(r#"{"set_slave_add": 126, "new_address": 7, "ident": 70000}"#)
                .contains("0..=0xFFFF")
        );
        assert!(err(r#"{"rd_inp": 3, "get_cfg": 3}"#).contains("one command per line"));
        assert!(err(r#"{"rd_inp": 3, "slot": 1}"#).contains("`slot` does not belong to `rd_inp`"));
        assert!(err(r#"{"rdinp": 3}"#).contains("unknown field `rdinp`"));
        assert!(err(r#"{}"#).starts_with("no command"));
        assert!(err("not json").contains("expected"));
        let long = format!(
            r#"{{"dpv1_write": 1, "slot": 0, "index": 0, "data": {:?}}}"#,
            vec![0; 241]
        );
        assert!(err(&long).contains("at most 240 bytes"));
        assert_eq!(
            MasterCommand::from_json(r#"{"slave": 8, "set": {"a": 1}}"#),
            Err(CommandError::Channels)
        );
    }
}
