//! A slave as a Sparkplug device: its metrics (names, datatypes, values
//! from the master's view of it) and the output writes of a DCMD.

use super::proto::{DataType, Metric, MetricValue};
use crate::slave::SlaveInfo;
use profibus_devices::channels::{Channel, ChannelMap, ChannelType, Direction, Value};
use profibus_dp::master::SlaveView;
use profibus_dp::pdu::alarm::AlarmType;
use profibus_dp::pdu::prm::Dpv1Status2;

/// Metric name of the whole input image (Bytes).
pub const INPUT_IMAGE: &str = "Image/Inputs";
/// Metric name of the whole output image (Bytes; writable by DCMD).
pub const OUTPUT_IMAGE: &str = "Image/Outputs";
/// Metric name of the last diagnosis, raw (Bytes).
pub const DIAG_BYTES: &str = "Diagnosis/Bytes";
/// Metric name of the last diagnosis, decoded (String, one line per
/// finding).
pub const DIAG_TEXT: &str = "Diagnosis/Text";
/// Folder of the alarm metrics: `Alarms/diagnostic`, `Alarms/process`,
/// `Alarms/pull`, `Alarms/plug`, `Alarms/status`, `Alarms/update`,
/// `Alarms/manufacturer` (String): one per DP-V1 alarm type the slave's
/// GSD declares, the last alarm of that type as the JSON of `dpctl
/// master`'s alarm event (null until the first).
pub const ALARMS: &str = "Alarms";
/// Metric name of the station address (UInt8).
pub const ADDRESS: &str = "Properties/Address";
/// Metric name of the bus file's name of the slave (String).
pub const NAME: &str = "Properties/Name";
/// Metric name of the ident number (UInt16; slaves with a GSD).
pub const IDENT: &str = "Properties/Ident Number";

/// The folder of a channel's metric: `Inputs/` or `Outputs/`.
pub fn channel_metric(c: &Channel) -> String {
    let folder = match c.direction {
        Direction::Input => "Inputs",
        Direction::Output => "Outputs",
    };
    // `/` separates folders in Sparkplug names: keep a channel one metric.
    format!("{folder}/{}", c.name.replace('/', "_"))
}

/// The Sparkplug datatype of a channel: the integer types as they are,
/// `Boolean` for bits, `Float` for F32, `Double` for a channel in
/// engineering units (a [`profibus_devices::channels::Scale`]).
pub fn channel_datatype(c: &Channel) -> DataType {
    if c.scale.is_some() {
        return DataType::Double;
    }
    match c.ty {
        ChannelType::Bool { .. } => DataType::Boolean,
        ChannelType::U8 => DataType::UInt8,
        ChannelType::I8 => DataType::Int8,
        ChannelType::U16 => DataType::UInt16,
        ChannelType::I16 => DataType::Int16,
        ChannelType::U32 => DataType::UInt32,
        ChannelType::I32 => DataType::Int32,
        ChannelType::F32 => DataType::Float,
    }
}

/// A channel value on the wire as `datatype`. Signed types up to 32 bits
/// go into `int_value` as two's complement, 64-bit ones into
/// `long_value`.
pub fn encode_value(datatype: DataType, v: Value) -> Option<MetricValue> {
    let int = |v: Value| match v {
        Value::Bool(b) => b as i64,
        Value::Int(i) => i,
        Value::Float(x) => x as i64,
    };
    let float = |v: Value| match v {
        Value::Bool(b) => b as u8 as f64,
        Value::Int(i) => i as f64,
        Value::Float(x) => x,
    };
    Some(match datatype {
        DataType::Boolean => MetricValue::BooleanValue(int(v) != 0),
        DataType::Int8
        | DataType::Int16
        | DataType::Int32
        | DataType::UInt8
        | DataType::UInt16
        | DataType::UInt32 => MetricValue::IntValue(int(v) as i32 as u32),
        DataType::Int64 | DataType::UInt64 => MetricValue::LongValue(int(v) as u64),
        DataType::Float => MetricValue::FloatValue(float(v) as f32),
        DataType::Double => MetricValue::DoubleValue(float(v)),
        _ => return None,
    })
}

/// A value from the wire as a channel value, read as `datatype` (the
/// metric's type from the birth). `None` when the value does not fit
/// the type (e.g. a string for an integer).
pub fn decode_value(datatype: DataType, v: &MetricValue) -> Option<Value> {
    let signed = matches!(
        datatype,
        DataType::Int8 | DataType::Int16 | DataType::Int32 | DataType::Int64
    );
    Some(match v {
        MetricValue::BooleanValue(b) => Value::Bool(*b),
        MetricValue::IntValue(u) if signed => Value::Int(*u as i32 as i64),
        MetricValue::IntValue(u) => Value::Int(*u as i64),
        MetricValue::LongValue(u) if signed => Value::Int(*u as i64),
        MetricValue::LongValue(u) => Value::Int(i64::try_from(*u).ok()?),
        MetricValue::FloatValue(x) => Value::Float(*x as f64),
        MetricValue::DoubleValue(x) => Value::Float(*x),
        _ => return None,
    })
}

/// Where a metric's value comes from.
#[derive(Debug, Clone)]
enum Source {
    Address,
    Name,
    Ident(u16),
    Image(Direction),
    Channel(usize),
    DiagBytes,
    DiagText,
    /// The last alarm of a type (its word).
    Alarm(&'static str),
}

/// One metric of a device.
#[derive(Debug, Clone)]
pub struct MetricDef {
    /// Its name.
    pub name: String,
    /// Its datatype.
    pub datatype: DataType,
    source: Source,
}

impl MetricDef {
    /// Whether the metric is one of the device's named channels (a
    /// member of its template instance, [`super::template`]).
    pub fn is_channel(&self) -> bool {
        matches!(self.source, Source::Channel(_))
    }

    /// The process image the metric's value comes from (`channels`: the
    /// device's), if any: the image metrics and the channels.
    pub fn image(&self, channels: &ChannelMap) -> Option<Direction> {
        match &self.source {
            Source::Image(d) => Some(*d),
            Source::Channel(i) => channels.channels.get(*i).map(|c| c.direction),
            _ => None,
        }
    }
}

/// A slave as a Sparkplug device: its metrics, in birth order.
#[derive(Debug, Clone)]
pub struct Device {
    /// The slave.
    pub info: SlaveInfo,
    /// Its named channels (from the profile, or one byte per GSD module).
    pub channels: ChannelMap,
    /// Its metrics.
    pub metrics: Vec<MetricDef>,
    /// The last alarm of each type (by [`AlarmType::word`]), as JSON.
    pub alarms: std::collections::BTreeMap<&'static str, String>,
    /// The device type: the name of its template definition
    /// ([`super::template`]): the bus file's `device` profile, else the
    /// GSD's `Model_Name` (`/` as `_`), else `Slave`.
    pub kind: String,
}

/// Why a DCMD was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// Not a Sparkplug payload.
    #[error("DCMD payload is not a Sparkplug B payload: {0}")]
    Decode(String),
    /// A metric with neither a name nor an alias of this device.
    #[error("DCMD metric without a name or a known alias")]
    NoName,
    /// A metric the device does not have, or one that cannot be written.
    #[error(
        "device {device}: metric `{name}` is not writable (write `Outputs/…` or `{OUTPUT_IMAGE}`)"
    )]
    NotWritable {
        /// Device id.
        device: String,
        /// Metric name.
        name: String,
    },
    /// A value of the wrong type, or out of the channel's range.
    #[error("device {device}: metric `{name}`: {problem}")]
    Value {
        /// Device id.
        device: String,
        /// Metric name.
        name: String,
        /// What is wrong.
        problem: String,
    },
    /// The bus file's `[mqtt] writable` does not list the slave.
    #[error("slave {0} is not writable over MQTT (see [mqtt] writable)")]
    Unauthorised(u8),
    /// A DCMD for a device this edge node does not have.
    #[error("no device `{0}` on this edge node")]
    UnknownDevice(String),
}

/// The writes of one DCMD, checked against the device.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputWrite {
    /// The whole output image, if the command sets it.
    pub image: Option<Vec<u8>>,
    /// Named output channels, applied after the image.
    pub channels: Vec<(String, Value)>,
}

impl Device {
    /// The device of a slave with its own channels (none if it has
    /// none).
    pub fn of_info(info: SlaveInfo) -> Device {
        let channels = info.channels.clone().unwrap_or_default();
        Device::new(info, channels)
    }

    /// The device of a slave; `channels` as [`SlaveInfo::channels`] or
    /// derived from its GSD modules.
    pub fn new(info: SlaveInfo, channels: ChannelMap) -> Device {
        let mut metrics = vec![
            MetricDef {
                name: ADDRESS.into(),
                datatype: DataType::UInt8,
                source: Source::Address,
            },
            MetricDef {
                name: NAME.into(),
                datatype: DataType::String,
                source: Source::Name,
            },
        ];
        if let Some(g) = &info.layout.gsd {
            metrics.push(MetricDef {
                name: IDENT.into(),
                datatype: DataType::UInt16,
                source: Source::Ident(g.ident_number),
            });
        }
        for (name, dir) in [
            (INPUT_IMAGE, Direction::Input),
            (OUTPUT_IMAGE, Direction::Output),
        ] {
            metrics.push(MetricDef {
                name: name.into(),
                datatype: DataType::Bytes,
                source: Source::Image(dir),
            });
        }
        for (i, c) in channels.channels.iter().enumerate() {
            metrics.push(MetricDef {
                name: channel_metric(c),
                datatype: channel_datatype(c),
                source: Source::Channel(i),
            });
        }
        metrics.push(MetricDef {
            name: DIAG_BYTES.into(),
            datatype: DataType::Bytes,
            source: Source::DiagBytes,
        });
        metrics.push(MetricDef {
            name: DIAG_TEXT.into(),
            datatype: DataType::String,
            source: Source::DiagText,
        });
        let declared = match &info.layout.gsd {
            Some(g) if info.layout.dpv1 => g.declared_alarms(),
            _ => Dpv1Status2::empty(),
        };
        let types = [
            AlarmType::Diagnostic,
            AlarmType::Process,
            AlarmType::Pull,
            AlarmType::Plug,
            AlarmType::Status,
            AlarmType::Update,
            AlarmType::from_code(32),
        ];
        for t in types {
            if t.enable().is_some_and(|e| declared.contains(e.bit())) {
                metrics.push(MetricDef {
                    name: format!("{ALARMS}/{}", t.word()),
                    datatype: DataType::String,
                    source: Source::Alarm(t.word()),
                });
            }
        }
        let kind = (info.layout.gsd.as_ref())
            .and_then(|g| g.model_name.as_deref())
            .map(|m| m.trim().replace('/', "_"))
            .filter(|m| !m.is_empty())
            .unwrap_or_else(|| "Slave".into());
        Device {
            info,
            channels,
            metrics,
            alarms: Default::default(),
            kind,
        }
    }

    /// The Sparkplug device id: the station address in decimal.
    pub fn id(&self) -> String {
        self.info.layout.address.to_string()
    }

    /// The value of every metric (in [`Device::metrics`] order) in the
    /// master's view of the slave; `None` is a null value (a channel
    /// beyond a short image).
    pub fn values(&self, v: &SlaveView<'_>) -> Vec<Option<MetricValue>> {
        self.metrics
            .iter()
            .map(|m| match &m.source {
                Source::Address => Some(MetricValue::IntValue(self.info.layout.address as u32)),
                Source::Name => Some(MetricValue::StringValue(self.info.layout.name.clone())),
                Source::Ident(n) => Some(MetricValue::IntValue(*n as u32)),
                Source::Image(Direction::Input) => Some(MetricValue::BytesValue(v.inputs.to_vec())),
                Source::Image(Direction::Output) => {
                    Some(MetricValue::BytesValue(v.outputs.to_vec()))
                }
                Source::Channel(i) => {
                    let c = &self.channels.channels[*i];
                    let img = match c.direction {
                        Direction::Input => v.inputs,
                        Direction::Output => v.outputs,
                    };
                    encode_value(m.datatype, c.read(img)?)
                }
                Source::DiagBytes => Some(MetricValue::BytesValue(v.diag.to_vec())),
                Source::DiagText => Some(MetricValue::StringValue(if v.diag.is_empty() {
                    String::new()
                } else {
                    profibus_dp::pdu::diag::describe(
                        v.diag,
                        self.info.layout.gsd.as_ref(),
                        self.info.layout.dpv1,
                    )
                    .join("\n")
                })),
                Source::Alarm(word) => self
                    .alarms
                    .get(word)
                    .map(|a| MetricValue::StringValue(a.clone())),
            })
            .collect()
    }

    /// Check the metrics of a DCMD: each must name an output channel
    /// (`Outputs/…`) or the output image, with a value of its type.
    /// Nothing is written here.
    /// The output image's length is checked when the write is applied.
    pub fn check_command(&self, metrics: &[Metric]) -> Result<OutputWrite, CommandError> {
        let mut w = OutputWrite {
            image: None,
            channels: vec![],
        };
        for m in metrics {
            let name = m.name.as_deref().ok_or(CommandError::NoName)?;
            let not_writable = || CommandError::NotWritable {
                device: self.id(),
                name: name.to_string(),
            };
            let bad = |problem: String| CommandError::Value {
                device: self.id(),
                name: name.to_string(),
                problem,
            };
            let def = self
                .metrics
                .iter()
                .find(|d| d.name == name)
                .ok_or_else(not_writable)?;
            let value = m.value.as_ref().ok_or_else(|| bad("no value".into()))?;
            match &def.source {
                Source::Image(Direction::Output) => {
                    let MetricValue::BytesValue(b) = value else {
                        return Err(bad("takes a Bytes value".into()));
                    };
                    w.image = Some(b.clone());
                }
                Source::Channel(i) if self.channels.channels[*i].direction == Direction::Output => {
                    let c = &self.channels.channels[*i];
                    let v = decode_value(def.datatype, value)
                        .ok_or_else(|| bad(format!("not a {:?} value", def.datatype)))?;
                    // Range and type: try it on a scratch image.
                    let mut scratch = vec![0u8; c.offset + c.ty.size()];
                    c.write(v, &mut scratch).map_err(|e| bad(e.to_string()))?;
                    w.channels.push((c.name.clone(), v));
                }
                _ => return Err(not_writable()),
            }
        }
        Ok(w)
    }
}
