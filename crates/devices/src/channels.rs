//! Named, typed channels of a slave's process images: the master-side
//! view of a device profile ([`crate::Profile::channels`]).
//!
//! A [`ChannelMap`] says where each value sits in the input image (what
//! the slave sends) and the output image (what the master sends), with
//! its type and byte order. The master decodes its images with it and
//! writes outputs by channel name; nothing in it knows a device.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Which process image a channel is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Slave → master (the slave's inputs to the master).
    Input,
    /// Master → slave.
    Output,
}

/// The data type of a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChannelType {
    /// One bit (`bit` 0 = least significant bit of the byte).
    Bool {
        /// Bit number in the byte, 0..=7.
        bit: u8,
    },
    /// Unsigned 8 bit.
    U8,
    /// Signed 8 bit.
    I8,
    /// Unsigned 16 bit.
    U16,
    /// Signed 16 bit.
    I16,
    /// Unsigned 32 bit.
    U32,
    /// Signed 32 bit.
    I32,
    /// IEEE 754 single precision.
    F32,
}

impl ChannelType {
    /// Bytes the value takes.
    pub fn size(self) -> usize {
        match self {
            ChannelType::Bool { .. } | ChannelType::U8 | ChannelType::I8 => 1,
            ChannelType::U16 | ChannelType::I16 => 2,
            ChannelType::U32 | ChannelType::I32 | ChannelType::F32 => 4,
        }
    }

    /// The smallest and largest integer the type holds (`None` for
    /// `F32`).
    pub fn range(self) -> Option<(i64, i64)> {
        Some(match self {
            ChannelType::Bool { .. } => (0, 1),
            ChannelType::U8 => (0, u8::MAX as i64),
            ChannelType::I8 => (i8::MIN as i64, i8::MAX as i64),
            ChannelType::U16 => (0, u16::MAX as i64),
            ChannelType::I16 => (i16::MIN as i64, i16::MAX as i64),
            ChannelType::U32 => (0, u32::MAX as i64),
            ChannelType::I32 => (i32::MIN as i64, i32::MAX as i64),
            ChannelType::F32 => return None,
        })
    }
}

/// The type in words (`bit 3`, `signed 16-bit integer`, …), for
/// messages.
impl fmt::Display for ChannelType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ChannelType::Bool { bit } => write!(f, "bit {bit}"),
            ChannelType::U8 => f.write_str("unsigned 8-bit integer"),
            ChannelType::I8 => f.write_str("signed 8-bit integer"),
            ChannelType::U16 => f.write_str("unsigned 16-bit integer"),
            ChannelType::I16 => f.write_str("signed 16-bit integer"),
            ChannelType::U32 => f.write_str("unsigned 32-bit integer"),
            ChannelType::I32 => f.write_str("signed 32-bit integer"),
            ChannelType::F32 => f.write_str("32-bit float"),
        }
    }
}

/// Byte order of a multi-byte channel.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ByteOrder {
    /// Most significant byte first ("Motorola"; PROFIBUS' default).
    #[default]
    BigEndian,
    /// Least significant byte first ("Intel").
    LittleEndian,
}

/// A channel's value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Value {
    /// A bit.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A floating point number.
    Float(f64),
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{}", *b as u8),
            Value::Int(i) => write!(f, "{i}"),
            Value::Float(x) => write!(f, "{x}"),
        }
    }
}

/// One named value in a process image.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Channel {
    /// Name (unique per direction), e.g. `setpoint1` or `di_MyReadVar3`.
    pub name: String,
    /// Input or output image.
    pub direction: Direction,
    /// Byte offset in the image.
    pub offset: usize,
    /// Type.
    pub ty: ChannelType,
    /// Byte order of multi-byte types.
    #[serde(default)]
    pub order: ByteOrder,
    /// Engineering units of an integer channel, if the device knows its
    /// range: the value read and written is then raw × num / den.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<Scale>,
}

/// Engineering units of an integer channel: value = raw × `num` / `den`
/// in `unit` (a rational factor keeps channels comparable and hashable),
/// e.g. ±10 V in a signed word: num 10, den 32767, unit "V".
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Scale {
    /// Numerator of the factor.
    pub num: i64,
    /// Denominator of the factor (not 0).
    pub den: i64,
    /// The unit.
    pub unit: String,
}

impl Scale {
    /// The value of a raw integer, rounded to 4 decimals.
    pub fn value(&self, raw: i64) -> f64 {
        (raw as f64 * self.num as f64 / self.den as f64 * 1e4).round() / 1e4
    }

    /// The raw integer closest to `value`.
    pub fn raw(&self, value: f64) -> f64 {
        (value * self.den as f64 / self.num as f64).round()
    }
}

/// Why a value cannot be written to a channel.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChannelError {
    /// No output channel has that name.
    #[error("no output channel `{0}`")]
    Unknown(String),
    /// The value does not fit the channel's type.
    #[error("{value} does not fit channel `{name}` ({ty})")]
    OutOfRange {
        /// Channel.
        name: String,
        /// Its type.
        ty: ChannelType,
        /// The value given.
        value: Value,
    },
    /// The image is shorter than the channel needs.
    #[error("channel `{name}` ends at byte {end}, the image has {len}")]
    Short {
        /// Channel.
        name: String,
        /// Its end.
        end: usize,
        /// The image's length.
        len: usize,
    },
}

impl Channel {
    /// A big-endian channel.
    pub fn new(
        name: impl Into<String>,
        direction: Direction,
        offset: usize,
        ty: ChannelType,
    ) -> Channel {
        Channel {
            name: name.into(),
            direction,
            offset,
            ty,
            order: ByteOrder::BigEndian,
            scale: None,
        }
    }

    /// The same channel in engineering units (see [`Scale`]).
    pub fn scaled(mut self, scale: Scale) -> Channel {
        self.scale = Some(scale);
        self
    }

    /// The same channel in little-endian order.
    pub fn little_endian(mut self) -> Channel {
        self.order = ByteOrder::LittleEndian;
        self
    }

    fn bytes<const N: usize>(&self, image: &[u8]) -> Option<[u8; N]> {
        let mut b: [u8; N] = image.get(self.offset..self.offset + N)?.try_into().ok()?;
        if self.order == ByteOrder::LittleEndian {
            b.reverse();
        }
        Some(b)
    }

    /// The channel's value in `image` (in engineering units when the
    /// channel has a [`Scale`]); `None` when the image is shorter.
    pub fn read(&self, image: &[u8]) -> Option<Value> {
        let v = self.read_raw(image)?;
        Some(match (&self.scale, v) {
            (Some(s), Value::Int(i)) => Value::Float(s.value(i)),
            (_, v) => v,
        })
    }

    /// The raw value in `image`, without the scale.
    pub fn read_raw(&self, image: &[u8]) -> Option<Value> {
        Some(match self.ty {
            ChannelType::Bool { bit } => Value::Bool(image.get(self.offset)? >> (bit & 7) & 1 == 1),
            ChannelType::U8 => Value::Int(*image.get(self.offset)? as i64),
            ChannelType::I8 => Value::Int(*image.get(self.offset)? as i8 as i64),
            ChannelType::U16 => Value::Int(u16::from_be_bytes(self.bytes(image)?) as i64),
            ChannelType::I16 => Value::Int(i16::from_be_bytes(self.bytes(image)?) as i64),
            ChannelType::U32 => Value::Int(u32::from_be_bytes(self.bytes(image)?) as i64),
            ChannelType::I32 => Value::Int(i32::from_be_bytes(self.bytes(image)?) as i64),
            ChannelType::F32 => Value::Float(f32::from_be_bytes(self.bytes(image)?) as f64),
        })
    }

    /// Write `value` into `image` (other bits and bytes unchanged); a
    /// scaled channel takes the value in its unit.
    pub fn write(&self, value: Value, image: &mut [u8]) -> Result<(), ChannelError> {
        let raw = match (&self.scale, value) {
            (Some(s), Value::Int(i)) => Value::Float(s.raw(i as f64)),
            (Some(s), Value::Float(x)) => Value::Float(s.raw(x)),
            (_, v) => v,
        };
        self.write_raw(raw, image).map_err(|e| match e {
            ChannelError::OutOfRange { name, ty, .. } => {
                ChannelError::OutOfRange { name, ty, value }
            }
            e => e,
        })
    }

    /// Write the raw `value` into `image`, without the scale.
    pub fn write_raw(&self, value: Value, image: &mut [u8]) -> Result<(), ChannelError> {
        let end = self.offset + self.ty.size();
        if image.len() < end {
            return Err(ChannelError::Short {
                name: self.name.clone(),
                end,
                len: image.len(),
            });
        }
        let out_of_range = || ChannelError::OutOfRange {
            name: self.name.clone(),
            ty: self.ty,
            value,
        };
        let mut b: Vec<u8> = match (self.ty, value) {
            (ChannelType::F32, Value::Int(i)) => (i as f32).to_be_bytes().to_vec(),
            (ChannelType::F32, Value::Float(x)) => (x as f32).to_be_bytes().to_vec(),
            (ChannelType::F32, Value::Bool(_)) => return Err(out_of_range()),
            (ty, v) => {
                let i = match v {
                    Value::Bool(b) => b as i64,
                    Value::Int(i) => i,
                    Value::Float(x) if x.fract() == 0.0 => x as i64,
                    Value::Float(_) => return Err(out_of_range()),
                };
                let (lo, hi) = ty.range().unwrap_or((0, 0));
                if i < lo || i > hi {
                    return Err(out_of_range());
                }
                if let ChannelType::Bool { bit } = ty {
                    let m = 1u8 << (bit & 7);
                    let byte = &mut image[self.offset];
                    *byte = if i == 1 { *byte | m } else { *byte & !m };
                    return Ok(());
                }
                (i as u32).to_be_bytes()[4 - ty.size()..].to_vec()
            }
        };
        if self.order == ByteOrder::LittleEndian {
            b.reverse();
        }
        image[self.offset..end].copy_from_slice(&b);
        Ok(())
    }
}

/// The channels of one slave's configuration.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChannelMap {
    /// The channels, inputs and outputs, in image order.
    pub channels: Vec<Channel>,
}

impl ChannelMap {
    /// An empty map.
    pub fn new() -> ChannelMap {
        ChannelMap::default()
    }

    /// Add a big-endian channel.
    pub fn push(
        &mut self,
        name: impl Into<String>,
        direction: Direction,
        offset: usize,
        ty: ChannelType,
    ) {
        self.channels
            .push(Channel::new(name, direction, offset, ty));
    }

    /// The channels of one image.
    pub fn of(&self, direction: Direction) -> impl Iterator<Item = &Channel> + '_ {
        self.channels
            .iter()
            .filter(move |c| c.direction == direction)
    }

    /// The channel `name` of one image.
    pub fn find(&self, direction: Direction, name: &str) -> Option<&Channel> {
        self.of(direction).find(|c| c.name == name)
    }

    /// Both images decoded, for printing and serialising.
    pub fn values(&self, inputs: &[u8], outputs: &[u8]) -> ImageValues {
        let of = |dir, image| {
            ChannelValues(
                self.decode(dir, image)
                    .map(|(c, v)| NamedValue {
                        name: c.name.clone(),
                        unit: c.scale.as_ref().map(|s| s.unit.clone()),
                        value: v,
                    })
                    .collect(),
            )
        };
        ImageValues {
            inputs: of(Direction::Input, inputs),
            outputs: of(Direction::Output, outputs),
        }
    }

    /// Every channel of one image with its value in `image` (channels
    /// beyond the image's end are left out).
    pub fn decode<'a>(
        &'a self,
        direction: Direction,
        image: &'a [u8],
    ) -> impl Iterator<Item = (&'a Channel, Value)> + 'a {
        self.of(direction)
            .filter_map(move |c| Some((c, c.read(image)?)))
    }

    /// Write `value` to the output channel `name` in `outputs`.
    pub fn write_output(
        &self,
        name: &str,
        value: Value,
        outputs: &mut [u8],
    ) -> Result<(), ChannelError> {
        self.find(Direction::Output, name)
            .ok_or_else(|| ChannelError::Unknown(name.to_string()))?
            .write(value, outputs)
    }
}

impl ChannelMap {
    /// Write several output channels: all of them, or none when one name
    /// or value is wrong.
    pub fn write_outputs<'a>(
        &self,
        values: impl IntoIterator<Item = (&'a str, Value)>,
        outputs: &mut [u8],
    ) -> Result<(), ChannelError> {
        let mut scratch = outputs.to_vec();
        for (name, v) in values {
            self.write_output(name, v, &mut scratch)?;
        }
        outputs.copy_from_slice(&scratch);
        Ok(())
    }
}

/// A write of a slave's outputs as a person or a client asks for it (the
/// terminal view's `w`, MQTT `outputs/set`, `dpctl master`'s `"set"`
/// lines): the whole output image, or named output channels. Every
/// interface checks it with the same rule, [`OutputWrite::check`] and
/// [`OutputWrite::apply`]: a part of the image is never written by
/// position, so a short write cannot leave bytes the writer did not mean
/// (a drive's PKW header in front of its process data) to chance.
#[derive(Debug, Clone, PartialEq)]
pub enum OutputWrite {
    /// The whole output image: exactly as many bytes as the slave has
    /// outputs.
    Image(Vec<u8>),
    /// Named output channels; the rest of the image keeps its values.
    Channels(Vec<(String, Value)>),
}

/// Why an [`OutputWrite`] was refused; nothing of it was written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OutputWriteError {
    /// A whole image of another length than the slave's outputs.
    #[error(
        "slave {address} has {expected} output bytes, the write has {given}: \
         give the whole image or named channels"
    )]
    Length {
        /// Station address.
        address: u8,
        /// The slave's output bytes.
        expected: usize,
        /// Bytes given.
        given: usize,
    },
    /// Channel names for a slave without named channels.
    #[error("slave {0} has no named channels: give the whole image in hex")]
    NoChannels(u8),
    /// The writer may write only some named channels (a permission such
    /// as `[mqtt] writable`), and asked for more or for the whole image.
    #[error(
        "slave {address}: only the output channels {} are writable",
        names(allowed)
    )]
    ChannelsOnly {
        /// Station address.
        address: u8,
        /// The channels that may be written.
        allowed: Vec<String>,
    },
    /// A name that is no output channel, or a value that does not fit.
    #[error("slave {address}: {error}")]
    Channel {
        /// Station address.
        address: u8,
        /// What is wrong (in the message; not also `source()`, so that
        /// a printed error chain names it once).
        error: ChannelError,
    },
}

/// `a`, `b`, `c` as words: `` `a`, `b` and `c` ``.
fn names(list: &[String]) -> String {
    let quoted: Vec<String> = list.iter().map(|n| format!("`{n}`")).collect();
    match quoted.split_last() {
        None => "(none)".into(),
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
    }
}

impl OutputWrite {
    /// Check the write to the slave at `address` as far as it can be
    /// checked without its image: channel names need the slave's channels
    /// (`map`) and must name output channels; with `allowed` (the only
    /// channels this writer may write, `None`: all) the write must be
    /// named channels among those.
    pub fn check(
        &self,
        address: u8,
        map: Option<&ChannelMap>,
        allowed: Option<&[String]>,
    ) -> Result<(), OutputWriteError> {
        if let Some(allowed) = allowed {
            let ok = match self {
                OutputWrite::Image(_) => false,
                OutputWrite::Channels(values) => values.iter().all(|(n, _)| allowed.contains(n)),
            };
            if !ok {
                return Err(OutputWriteError::ChannelsOnly {
                    address,
                    allowed: allowed.to_vec(),
                });
            }
        }
        if let OutputWrite::Channels(values) = self {
            let map = map.ok_or(OutputWriteError::NoChannels(address))?;
            if let Some((n, _)) = values
                .iter()
                .find(|(n, _)| map.find(Direction::Output, n).is_none())
            {
                return Err(OutputWriteError::Channel {
                    address,
                    error: ChannelError::Unknown(n.clone()),
                });
            }
        }
        Ok(())
    }

    /// The slave's new output image: the write [checked](Self::check),
    /// then applied to `current` (its output image now). A whole image
    /// must have exactly `current.len()` bytes; every channel value must
    /// fit its channel. All of it or nothing.
    pub fn apply(
        &self,
        address: u8,
        current: &[u8],
        map: Option<&ChannelMap>,
        allowed: Option<&[String]>,
    ) -> Result<Vec<u8>, OutputWriteError> {
        self.check(address, map, allowed)?;
        match self {
            OutputWrite::Image(b) if b.len() != current.len() => Err(OutputWriteError::Length {
                address,
                expected: current.len(),
                given: b.len(),
            }),
            OutputWrite::Image(b) => Ok(b.clone()),
            OutputWrite::Channels(values) => {
                let map = map.ok_or(OutputWriteError::NoChannels(address))?;
                let mut image = current.to_vec();
                map.write_outputs(values.iter().map(|(n, v)| (n.as_str(), *v)), &mut image)
                    .map_err(|error| OutputWriteError::Channel { address, error })?;
                Ok(image)
            }
        }
    }
}

/// The bus monitor decodes a profile's images with its channels.
impl profibus_dp::monitor::ImageDecoder for ChannelMap {
    fn decode(
        &self,
        image: profibus_dp::monitor::Image,
        bytes: &[u8],
    ) -> Vec<profibus_dp::monitor::Reading> {
        use profibus_dp::monitor::{Image, Reading, ReadingValue};
        let dir = match image {
            Image::Inputs => Direction::Input,
            Image::Outputs => Direction::Output,
        };
        ChannelMap::decode(self, dir, bytes)
            .map(|(c, v)| Reading {
                name: c.name.clone(),
                value: match v {
                    Value::Bool(b) => ReadingValue::Bool(b),
                    Value::Int(i) => ReadingValue::Int(i),
                    Value::Float(x) => ReadingValue::Float(x),
                },
                unit: c.scale.as_ref().map(|s| s.unit.clone()),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_and_write_each_type() {
        let mut m = ChannelMap::new();
        m.push("b", Direction::Output, 0, ChannelType::Bool { bit: 3 });
        m.push("w", Direction::Output, 1, ChannelType::I16);
        m.push("d", Direction::Output, 3, ChannelType::U32);
        m.push("f", Direction::Output, 7, ChannelType::F32);
        m.channels
            .push(Channel::new("le", Direction::Output, 11, ChannelType::U16).little_endian());
        let mut img = [0u8; 13];
        m.write_output("b", Value::Bool(true), &mut img).unwrap();
        m.write_output("w", Value::Int(-2), &mut img).unwrap();
        m.write_output("d", Value::Int(0x1234_5678), &mut img)
            .unwrap();
        m.write_output("f", Value::Float(1.5), &mut img).unwrap();
        m.write_output("le", Value::Int(0x0102), &mut img).unwrap();
        assert_eq!(
            img,
            [0x08, 0xFF, 0xFE, 0x12, 0x34, 0x56, 0x78, 0x3F, 0xC0, 0, 0, 0x02, 0x01]
        );
        let values: Vec<(String, Value)> = m
            .decode(Direction::Output, &img)
            .map(|(c, v)| (c.name.clone(), v))
            .collect();
        assert_eq!(values[0].1, Value::Bool(true));
        assert_eq!(values[1].1, Value::Int(-2));
        assert_eq!(values[2].1, Value::Int(0x1234_5678));
        assert_eq!(values[3].1, Value::Float(1.5));
        assert_eq!(values[4].1, Value::Int(0x0102));
        assert!(matches!(
            m.write_output("w", Value::Int(40000), &mut img),
            Err(ChannelError::OutOfRange { .. })
        ));
        assert!(matches!(
            m.write_output("x", Value::Int(1), &mut img),
            Err(ChannelError::Unknown(_))
        ));
        assert_eq!(m.decode(Direction::Output, &img[..5]).count(), 2);
        let before = img;
        assert!(m
            .write_outputs([("w", Value::Int(1)), ("d", Value::Float(0.5))], &mut img)
            .is_err());
        assert_eq!(img, before, "nothing written");
        m.write_outputs([("w", Value::Int(1)), ("b", Value::Bool(false))], &mut img)
            .unwrap();
        assert_eq!(&img[..3], &[0, 0, 1]);
        assert_eq!(m.decode(Direction::Input, &img).count(), 0);
    }

    /// A drive's outputs: a 4-byte PKW header in front of one setpoint.
    fn drive() -> ChannelMap {
        let mut m = ChannelMap::new();
        m.push("setpoint1", Direction::Output, 4, ChannelType::I16);
        m.push("enable", Direction::Output, 6, ChannelType::Bool { bit: 0 });
        m.push("actual1", Direction::Input, 4, ChannelType::I16);
        m
    }

    #[test]
    fn an_output_write_is_the_whole_image_or_named_channels() {
        let (m, current) = (drive(), [0xAA, 0xBB, 0xCC, 0xDD, 0, 0, 0]);
        let image = |b: &[u8]| OutputWrite::Image(b.to_vec());
        let set = |n: &str, v| OutputWrite::Channels(vec![(n.to_string(), v)]);
        // The whole image, exactly.
        let whole = [1, 2, 3, 4, 5, 6, 7];
        assert_eq!(
            image(&whole).apply(25, &current, Some(&m), None),
            Ok(whole.to_vec())
        );
        // A short image would overwrite the PKW header by position: refused.
        let e = image(&[1, 2])
            .apply(25, &current, Some(&m), None)
            .unwrap_err();
        assert_eq!(
            e,
            OutputWriteError::Length {
                address: 25,
                expected: 7,
                given: 2
            }
        );
        assert_eq!(
            e.to_string(),
            "slave 25 has 7 output bytes, the write has 2: give the whole image or named channels"
        );
        assert!(image(&[0; 8]).apply(25, &current, Some(&m), None).is_err());
        // A channel: the header stays.
        assert_eq!(
            set("setpoint1", Value::Int(-2)).apply(25, &current, Some(&m), None),
            Ok(vec![0xAA, 0xBB, 0xCC, 0xDD, 0xFF, 0xFE, 0])
        );
        // Names need channels, output channels, values that fit.
        let e = set("setpoint1", Value::Int(1)).apply(8, &[0; 7], None, None);
        assert_eq!(e, Err(OutputWriteError::NoChannels(8)));
        let e = set("actual1", Value::Int(1))
            .check(25, Some(&m), None)
            .unwrap_err();
        assert_eq!(e.to_string(), "slave 25: no output channel `actual1`");
        let e = set("setpoint1", Value::Int(40000))
            .apply(25, &current, Some(&m), None)
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "slave 25: 40000 does not fit channel `setpoint1` (signed 16-bit integer)"
        );
        let e = set("enable", Value::Int(2)).apply(25, &current, Some(&m), None);
        assert!(e.unwrap_err().to_string().ends_with("(bit 0)"));
    }

    #[test]
    fn a_writer_limited_to_some_channels_writes_only_those() {
        let (m, current) = (drive(), [0u8; 7]);
        let allowed = ["setpoint1".to_string()];
        let only = Some(&allowed[..]);
        let set = |n: &str| OutputWrite::Channels(vec![(n.to_string(), Value::Int(1))]);
        assert!(set("setpoint1").apply(25, &current, Some(&m), only).is_ok());
        let refused = OutputWriteError::ChannelsOnly {
            address: 25,
            allowed: allowed.to_vec(),
        };
        assert_eq!(
            set("enable").check(25, Some(&m), only),
            Err(refused.clone())
        );
        let whole = OutputWrite::Image(vec![0; 7]);
        assert_eq!(whole.check(25, Some(&m), only), Err(refused.clone()));
        assert_eq!(
            refused.to_string(),
            "slave 25: only the output channels `setpoint1` are writable"
        );
        let two = ["a".to_string(), "b".into(), "c".into()];
        assert_eq!(names(&two), "`a`, `b` and `c`");
    }
}

/// A channel's value with its name and unit.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedValue {
    /// The channel's name.
    pub name: String,
    /// Its engineering unit, if scaled.
    pub unit: Option<String>,
    /// Its value.
    pub value: Value,
}

/// The decoded channels of one image, in image order. Serialises as an
/// object `{"name": value, …}`; `Display` gives `name=value [unit]` words.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ChannelValues(pub Vec<NamedValue>);

impl Serialize for ChannelValues {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(self.0.iter().map(|n| (&n.name, n.value)))
    }
}

impl fmt::Display for ChannelValues {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, n) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{}={}", n.name, n.value)?;
            if let Some(u) = &n.unit {
                write!(f, " {u}")?;
            }
        }
        Ok(())
    }
}

/// Both images of a slave decoded ([`ChannelMap::values`]). `Display`:
/// `in: … out: …`.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct ImageValues {
    /// The input channels.
    pub inputs: ChannelValues,
    /// The output channels.
    pub outputs: ChannelValues,
}

impl fmt::Display for ImageValues {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "in: {}  out: {}", self.inputs, self.outputs)
    }
}
