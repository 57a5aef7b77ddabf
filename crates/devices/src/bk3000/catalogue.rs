//! The K-bus terminal catalogue: which terminals the emulated BK3000 knows,
//! their channels, and the process-image variants (DP identifiers and
//! byte layouts) the coupler accepts for each.
//!
//! Sources: manual pages 49-50 (Beckhoff, "PROFIBUS Koppler BK3000 …
//! LC3100", version 2.3 of 27.11.2006; English edition pages 47-48 on azmanual.top / manualsdir.com, document
//! 757242) for KL3xx2, KL1501, KL2502 and KL5001; Beckhoff Information
//! System "Configuration of Complex Modules" (infosys.beckhoff.com,
//! bk3xx0/3028153611) for the two-word alternative 0x51 of KL3xx2.
//! Inferred (not printed in either source): the identifiers of KL4xx2
//! (0x60 per channel compact, 0xB2 per channel complete, by analogy to
//! KL3xx2 with the directions swapped) and the byte layout inside the
//! 6-byte KL1501/KL5001 formats (status byte, one unused byte, 32-bit
//! value).

use std::fmt;

/// What a byte (or bit) field of a terminal's process image carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    /// The process value (digital bit, analog word, counter…).
    Value,
    /// The status byte of a channel (input; register communication).
    Status,
    /// The control byte of a channel (output; register communication).
    Control,
    /// An unused byte (word alignment).
    Reserved,
}

impl Role {
    /// A short suffix for channel names ("" for the value).
    pub fn suffix(self) -> &'static str {
        match self {
            Role::Value => "",
            Role::Status => ".status",
            Role::Control => ".control",
            Role::Reserved => ".reserved",
        }
    }
}

/// One field of a complex terminal's input or output image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Field {
    /// Channel 1.. of the terminal.
    pub channel: u8,
    /// What it carries.
    pub role: Role,
    /// Byte offset inside the terminal's input (or output) bytes.
    pub offset: u8,
    /// Length in bytes (1, 2 or 4).
    pub bytes: u8,
}

const fn f(channel: u8, role: Role, offset: u8, bytes: u8) -> Field {
    Field {
        channel,
        role,
        offset,
        bytes,
    }
}

/// How much of a complex terminal appears in the process image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mapping {
    /// Data only ("kompakt", manual page 37).
    Compact,
    /// Data with control and status bytes ("komplex"/complete).
    Complete,
    /// The terminal's standard format where it has one (KL1501, KL5001).
    Standard,
    /// Data with status in, control out only (the 0xC0 formats).
    StatusControl,
}

impl Mapping {
    /// The name used in terminal lists (`KL3102:complete`).
    pub fn as_str(self) -> &'static str {
        match self {
            Mapping::Compact => "compact",
            Mapping::Complete => "complete",
            Mapping::Standard => "standard",
            Mapping::StatusControl => "status",
        }
    }
}

/// One accepted process-image format of a complex terminal: the DP
/// identifier bytes for the whole terminal and the fields they carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Variant {
    /// Which mapping this is.
    pub mapping: Mapping,
    /// Identifier bytes (Chk_Cfg) of the whole terminal.
    pub cfg: &'static [u8],
    /// Input bytes.
    pub in_len: u8,
    /// Output bytes.
    pub out_len: u8,
    /// Input fields.
    pub inputs: &'static [Field],
    /// Output fields.
    pub outputs: &'static [Field],
    /// Where the format comes from.
    pub source: &'static str,
}

/// A [`Variant`] in one line: mapping, identifier bytes, input bytes and
/// fields, output bytes and fields, source.
const fn v(
    mapping: Mapping,
    cfg: &'static [u8],
    in_len: u8,
    inputs: &'static [Field],
    out_len: u8,
    outputs: &'static [Field],
    source: &'static str,
) -> Variant {
    Variant {
        mapping,
        cfg,
        in_len,
        out_len,
        inputs,
        outputs,
        source,
    }
}

/// How the value of a channel is scaled for people.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scale {
    /// A digital channel (0/1).
    Bit,
    /// A signed 16-bit word, `full` units at 0x7FFF.
    Signed {
        /// The value at 0x7FFF.
        full: f64,
        /// The unit (`"V"`, `"mA"` …).
        unit: &'static str,
    },
    /// A 16-bit word read as unsigned 0..0x7FFF = 0..`full` units
    /// (negative raw values are out of range).
    Positive {
        /// The value at 0x7FFF.
        full: f64,
        /// The unit.
        unit: &'static str,
    },
    /// A signed 16-bit word, `per_digit` units per digit.
    Digit {
        /// Units per digit.
        per_digit: f64,
        /// The unit.
        unit: &'static str,
    },
    /// A plain unsigned number (counter, encoder position).
    Count,
}

impl Scale {
    /// The unit, if any.
    pub fn unit(&self) -> Option<&'static str> {
        match *self {
            Scale::Signed { unit, .. }
            | Scale::Positive { unit, .. }
            | Scale::Digit { unit, .. } => Some(unit),
            Scale::Bit | Scale::Count => None,
        }
    }

    /// The factor as a rational number (numerator, denominator) and the
    /// unit, for [`crate::channels::Scale`]; `None` for bits and counts.
    pub fn rational(&self) -> Option<(i64, i64, &'static str)> {
        match *self {
            Scale::Signed { full, unit } | Scale::Positive { full, unit } => {
                Some(((full * 1000.0).round() as i64, 32767 * 1000, unit))
            }
            Scale::Digit { per_digit, unit } => {
                Some(((per_digit * 1000.0).round() as i64, 1000, unit))
            }
            Scale::Bit | Scale::Count => None,
        }
    }

    /// The smallest and largest engineering value.
    pub fn range(&self) -> (f64, f64) {
        match *self {
            Scale::Signed { full, .. } => (-full * 32768.0 / 32767.0, full),
            Scale::Positive { full, .. } => (0.0, full),
            Scale::Digit { per_digit, .. } => (-32768.0 * per_digit, 32767.0 * per_digit),
            Scale::Bit => (0.0, 1.0),
            Scale::Count => (0.0, u32::MAX as f64),
        }
    }

    /// Engineering value of a raw value.
    pub fn to_engineering(&self, raw: i64) -> f64 {
        match *self {
            Scale::Signed { full, .. } | Scale::Positive { full, .. } => {
                raw as f64 * full / 32767.0
            }
            Scale::Digit { per_digit, .. } => raw as f64 * per_digit,
            Scale::Bit | Scale::Count => raw as f64,
        }
    }

    /// Raw value of an engineering value (rounded, clamped to the word).
    pub fn from_engineering(&self, v: f64) -> i64 {
        match *self {
            Scale::Signed { full, .. } => {
                (v * 32767.0 / full).round().clamp(-32768.0, 32767.0) as i64
            }
            Scale::Positive { full, .. } => (v * 32767.0 / full).round().clamp(0.0, 32767.0) as i64,
            Scale::Digit { per_digit, .. } => {
                (v / per_digit).round().clamp(-32768.0, 32767.0) as i64
            }
            Scale::Bit => (v != 0.0) as i64,
            Scale::Count => v.round().clamp(0.0, u32::MAX as f64) as i64,
        }
    }
}

/// What kind of terminal it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Class {
    /// Digital inputs, packed bit by bit after the byte-oriented data.
    DigitalIn,
    /// Digital outputs, packed bit by bit.
    DigitalOut,
    /// A byte-oriented ("complex", "intelligent") terminal.
    Complex,
    /// No process data (power feed, end terminal).
    Passive,
}

/// What the emulation simulates on a terminal's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sim {
    /// Digital inputs: a walking bit pattern.
    Walk,
    /// Analog inputs: a slow sine over part of the range.
    Sine,
    /// Temperature: a slow sine around room temperature.
    Temperature,
    /// A counter counting up.
    Counter,
    /// An encoder position moving up.
    Encoder,
    /// Inputs echo the outputs (PWM read-back).
    Echo,
    /// Nothing to simulate.
    None,
}

/// One terminal type of the catalogue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerminalType {
    /// Order number, e.g. `KL3102`.
    pub name: &'static str,
    /// One line for people.
    pub summary: &'static str,
    /// The kind of terminal.
    pub class: Class,
    /// Number of channels.
    pub channels: u8,
    /// Scaling of the process values.
    pub scale: Scale,
    /// Formats a complex terminal accepts; the first is the default.
    pub variants: &'static [Variant],
    /// What the emulation simulates.
    pub sim: Sim,
}

impl TerminalType {
    /// Whether the terminal has data bits in the packed digital area.
    pub fn is_digital(&self) -> bool {
        matches!(self.class, Class::DigitalIn | Class::DigitalOut)
    }

    /// The variant with `mapping`, if the terminal has it.
    pub fn variant(&self, mapping: Mapping) -> Option<&'static Variant> {
        self.variants.iter().find(|v| v.mapping == mapping)
    }

    /// The default variant of a complex terminal.
    pub fn default_variant(&self) -> Option<&'static Variant> {
        self.variants.first()
    }
}

impl fmt::Display for TerminalType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

use Role::*;

const P49: &str = "manual p. 49";
const P50: &str = "manual p. 50";
const INFOSYS: &str = "Beckhoff infosys bk3xx0 'Configuration of Complex Modules'";
const INFERRED: &str = "inferred (KL3xx2 formats with the directions swapped)";

// Two 16-bit channels, data only.
const WORDS2: &[Field] = &[f(1, Value, 0, 2), f(2, Value, 2, 2)];
// Two channels of status/control byte + 16-bit word.
const SB_WORD2: &[Field] = &[
    f(1, Status, 0, 1),
    f(1, Value, 1, 2),
    f(2, Status, 3, 1),
    f(2, Value, 4, 2),
];
const CB_WORD2: &[Field] = &[
    f(1, Control, 0, 1),
    f(1, Value, 1, 2),
    f(2, Control, 3, 1),
    f(2, Value, 4, 2),
];
const CB2: &[Field] = &[f(1, Control, 0, 1), f(2, Control, 1, 1)];
const SB2: &[Field] = &[f(1, Status, 0, 1), f(2, Status, 1, 1)];

/// KL3xx2: two analog input channels (manual p. 49).
#[rustfmt::skip]
const ANALOG_IN2: &[Variant] = &[
    v(Mapping::Compact, &[0x50, 0x50], 4, WORDS2, 0, &[], P49),
    v(Mapping::Compact, &[0x51], 4, WORDS2, 0, &[], INFOSYS),
    v(Mapping::Complete, &[0xB2, 0xB2], 6, SB_WORD2, 6, CB_WORD2, P49),
    v(Mapping::StatusControl, &[0xC0, 0x00, 0x82, 0xC0, 0x00, 0x82], 6, SB_WORD2, 2, CB2, P49),
];

/// KL4xx2: two analog output channels (inferred from KL3xx2).
#[rustfmt::skip]
const ANALOG_OUT2: &[Variant] = &[
    v(Mapping::Compact, &[0x60, 0x60], 0, &[], 4, WORDS2, INFERRED),
    v(Mapping::Compact, &[0x61], 0, &[], 4, WORDS2, INFERRED),
    v(Mapping::Complete, &[0xB2, 0xB2], 6, SB_WORD2, 6, CB_WORD2, INFERRED),
    v(Mapping::StatusControl, &[0xC0, 0x82, 0x00, 0xC0, 0x82, 0x00], 2, SB2, 6, CB_WORD2, INFERRED),
];

const SB_DW: &[Field] = &[f(1, Status, 0, 1), f(1, Value, 1, 4)];
const CB_DW: &[Field] = &[f(1, Control, 0, 1), f(1, Value, 1, 4)];
const DW: &[Field] = &[f(1, Value, 0, 4)];
const SB_PAD_DW: &[Field] = &[f(1, Status, 0, 1), f(1, Reserved, 1, 1), f(1, Value, 2, 4)];
const CB_PAD_DW: &[Field] = &[f(1, Control, 0, 1), f(1, Reserved, 1, 1), f(1, Value, 2, 4)];
const CB: &[Field] = &[f(1, Control, 0, 1)];

/// KL1501 up/down counter (manual p. 50).
#[rustfmt::skip]
const COUNTER: &[Variant] = &[
    v(Mapping::Standard, &[0xB4], 5, SB_DW, 5, CB_DW, P50),
    v(Mapping::Compact, &[0xB3], 4, DW, 4, DW, P50),
    v(Mapping::Complete, &[0xB5], 6, SB_PAD_DW, 6, CB_PAD_DW, P50),
];

/// KL2502 two PWM channels (manual p. 50): 0xB2 per channel or 0xB5 for
/// both, the same bytes either way.
#[rustfmt::skip]
const PWM2: &[Variant] = &[
    v(Mapping::Complete, &[0xB2, 0xB2], 6, SB_WORD2, 6, CB_WORD2, P50),
    v(Mapping::Standard, &[0xB5], 6, SB_WORD2, 6, CB_WORD2, P50),
];

/// KL5001 SSI encoder (manual p. 50; English edition p. 48 lists the
/// 0xC0/0x40 formats).
#[rustfmt::skip]
const SSI: &[Variant] = &[
    v(Mapping::Compact, &[0x93], 4, DW, 0, &[], P50),
    v(Mapping::Complete, &[0xB4], 5, SB_DW, 5, CB_DW, P50),
    v(Mapping::StatusControl, &[0xC0, 0x00, 0x84], 5, SB_DW, 1, CB, "manual (English ed.) p. 48"),
    v(Mapping::Standard, &[0x40, 0x84], 5, SB_DW, 0, &[], "manual (English ed.) p. 48"),
];

const fn digital(
    name: &'static str,
    summary: &'static str,
    class: Class,
    channels: u8,
) -> TerminalType {
    TerminalType {
        name,
        summary,
        class,
        channels,
        scale: Scale::Bit,
        variants: &[],
        sim: if matches!(class, Class::DigitalIn) {
            Sim::Walk
        } else {
            Sim::None
        },
    }
}

const fn passive(name: &'static str, summary: &'static str) -> TerminalType {
    TerminalType {
        name,
        summary,
        class: Class::Passive,
        channels: 0,
        scale: Scale::Count,
        variants: &[],
        sim: Sim::None,
    }
}

const VOLT10: Scale = Scale::Signed {
    full: 10.0,
    unit: "V",
};

/// A complex terminal (its own bytes in the process image).
const fn complex(
    name: &'static str,
    summary: &'static str,
    channels: u8,
    scale: Scale,
    variants: &'static [Variant],
    sim: Sim,
) -> TerminalType {
    TerminalType {
        name,
        summary,
        class: Class::Complex,
        channels,
        scale,
        variants,
        sim,
    }
}

const VOLT10_POSITIVE: Scale = Scale::Positive {
    full: 10.0,
    unit: "V",
};
const PT100: Scale = Scale::Digit {
    per_digit: 0.1,
    unit: "°C",
};
const PERCENT: Scale = Scale::Positive {
    full: 100.0,
    unit: "%",
};

/// Every terminal the emulation knows.
#[rustfmt::skip]
pub const CATALOGUE: &[TerminalType] = &[
    digital("KL1002", "2 digital inputs 24 V DC, 3 ms", Class::DigitalIn, 2),
    digital("KL1104", "4 digital inputs 24 V DC, 3 ms", Class::DigitalIn, 4),
    digital("KL1408", "8 digital inputs 24 V DC, 3 ms", Class::DigitalIn, 8),
    digital("KL2012", "2 digital outputs 24 V DC, 0.5 A", Class::DigitalOut, 2),
    digital("KL2134", "4 digital outputs 24 V DC, 0.5 A", Class::DigitalOut, 4),
    digital("KL2408", "8 digital outputs 24 V DC, 0.5 A", Class::DigitalOut, 8),
    complex("KL3002", "2 analog inputs -10..+10 V, differential", 2, VOLT10, ANALOG_IN2, Sim::Sine),
    complex("KL3102", "2 analog inputs -10..+10 V, differential, 16 bit", 2, VOLT10, ANALOG_IN2, Sim::Sine),
    complex("KL3202", "2 analog inputs PT100 (RTD), 0.1 °C per digit", 2, PT100, ANALOG_IN2, Sim::Temperature),
    complex("KL4002", "2 analog outputs 0..10 V", 2, VOLT10_POSITIVE, ANALOG_OUT2, Sim::None),
    complex("KL4032", "2 analog outputs -10..+10 V", 2, VOLT10, ANALOG_OUT2, Sim::None),
    complex("KL1501", "32-bit up/down counter, 100 kHz", 1, Scale::Count, COUNTER, Sim::Counter),
    complex("KL2502", "2 PWM outputs 24 V DC (duty cycle 0..0x7FFF = 0..100 %)", 2, PERCENT, PWM2, Sim::Echo),
    complex("KL5001", "SSI encoder interface, 32-bit position", 1, Scale::Count, SSI, Sim::Encoder),
    passive("KL9100", "power feed terminal 24 V DC (no process data)"),
    passive("KL9400", "K-bus power supply terminal (no process data)"),
    passive("KL9010", "end terminal"),
];

/// The end terminal every strip must finish with.
pub const END_TERMINAL: &str = "KL9010";

/// The terminal type named `name` (case-insensitive).
pub fn lookup(name: &str) -> Option<&'static TerminalType> {
    CATALOGUE.iter().find(|t| t.name.eq_ignore_ascii_case(name))
}
