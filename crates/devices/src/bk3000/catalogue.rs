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
    /// A 16-bit word, 0..0x7FFF = `lo`..`hi` units (e.g. 4..20 mA);
    /// negative raw values are out of range.
    Span {
        /// The value at 0.
        lo: f64,
        /// The value at 0x7FFF.
        hi: f64,
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
            | Scale::Digit { unit, .. }
            | Scale::Span { unit, .. } => Some(unit),
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
            // An offset is no factor: shown raw on the master side.
            Scale::Span { .. } | Scale::Bit | Scale::Count => None,
        }
    }

    /// The smallest and largest engineering value.
    pub fn range(&self) -> (f64, f64) {
        match *self {
            Scale::Signed { full, .. } => (-full * 32768.0 / 32767.0, full),
            Scale::Positive { full, .. } => (0.0, full),
            Scale::Digit { per_digit, .. } => (-32768.0 * per_digit, 32767.0 * per_digit),
            Scale::Span { lo, hi, .. } => (lo, hi),
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
            Scale::Span { lo, hi, .. } => lo + raw as f64 * (hi - lo) / 32767.0,
            Scale::Bit | Scale::Count => raw as f64,
        }
    }

    /// Raw value of an engineering value (rounded, clamped to the word).
    pub fn from_engineering(&self, v: f64) -> i64 {
        match *self {
            Scale::Span { lo, hi, .. } => {
                ((v - lo) * 32767.0 / (hi - lo)).round().clamp(0.0, 32767.0) as i64
            }
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

    /// Raw value of an engineering value without clamping (a value out of
    /// the terminal's range gives a raw value outside the word: the
    /// terminal reports over- or underrange).
    pub fn from_engineering_unclamped(&self, v: f64) -> i64 {
        let raw = match *self {
            Scale::Signed { full, .. } | Scale::Positive { full, .. } => v * 32767.0 / full,
            Scale::Span { lo, hi, .. } => (v - lo) * 32767.0 / (hi - lo),
            Scale::Digit { per_digit, .. } => v / per_digit,
            Scale::Bit | Scale::Count => return self.from_engineering(v),
        };
        raw.round().clamp(-1e9, 1e9) as i64
    }

    /// Whether raw values below 0 are out of the range (unipolar ranges).
    pub fn is_unipolar(&self) -> bool {
        matches!(self, Scale::Positive { .. } | Scale::Span { .. })
    }
}

/// What kind of terminal it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Class {
    /// Digital inputs, packed bit by bit after the byte-oriented data.
    DigitalIn,
    /// Digital outputs, packed bit by bit.
    DigitalOut,
    /// Digital inputs and outputs on one terminal (`channels` of each,
    /// e.g. KL1859: 8 in, 8 out), packed with the other digital bits.
    DigitalInOut,
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
    /// Register values that differ from the family's defaults
    /// ([`super::registers`]), the same for every channel.
    pub registers: &'static [(u8, u16)],
    /// Where the terminal's process-image sizes come from.
    pub source: Source,
}

/// Where a catalogue entry's facts come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// The BK3000 manual (its page or the English edition's).
    Manual,
    /// Beckhoff's terminal documentation (infosys.beckhoff.com), **not
    /// from the manual**: channel counts and process-image sizes of the
    /// terminal's data sheet; identifiers by analogy with the manual's
    /// KL3xx2 table (p. 49).
    Datasheet,
    /// Described by the user (`terminal_types`).
    User,
}

impl TerminalType {
    /// Whether the terminal has data bits in the packed digital area.
    pub fn is_digital(&self) -> bool {
        matches!(
            self.class,
            Class::DigitalIn | Class::DigitalOut | Class::DigitalInOut
        )
    }

    /// Digital input and output bits of the terminal (0, 0 for a complex
    /// or passive terminal).
    pub fn digital_bits(&self) -> (u8, u8) {
        match self.class {
            Class::DigitalIn => (self.channels, 0),
            Class::DigitalOut => (0, self.channels),
            Class::DigitalInOut => (self.channels, self.channels),
            Class::Complex | Class::Passive => (0, 0),
        }
    }

    /// The type number of register R8 (`KL3102` → 3102; 0 where the name
    /// has no number), unless the terminal's registers give another.
    pub fn type_number(&self) -> u16 {
        self.registers
            .iter()
            .find(|(r, _)| *r == 8)
            .map(|(_, v)| *v)
            .unwrap_or_else(|| {
                let digits: String = self
                    .name
                    .chars()
                    .skip_while(|c| !c.is_ascii_digit())
                    .take_while(|c| c.is_ascii_digit())
                    .collect();
                digits.parse().unwrap_or(0)
            })
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
        sim: if matches!(class, Class::DigitalIn | Class::DigitalInOut) {
            Sim::Walk
        } else {
            Sim::None
        },
        registers: &[],
        source: Source::Manual,
    }
}

/// A digital terminal from Beckhoff's data sheets (not from the manual).
const fn digital_ds(
    name: &'static str,
    summary: &'static str,
    class: Class,
    channels: u8,
) -> TerminalType {
    TerminalType {
        source: Source::Datasheet,
        ..digital(name, summary, class, channels)
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
        registers: &[],
        source: Source::Manual,
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
        registers: &[],
        source: Source::Manual,
    }
}

/// A complex terminal from Beckhoff's data sheets (not from the manual).
const fn complex_ds(
    name: &'static str,
    summary: &'static str,
    channels: u8,
    scale: Scale,
    variants: &'static [Variant],
    sim: Sim,
) -> TerminalType {
    TerminalType {
        source: Source::Datasheet,
        ..complex(name, summary, channels, scale, variants, sim)
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

// One analog channel, by analogy with KL3xx2 (manual p. 49): 0x50,
// 0xB2 or 0xC0,0x00,0x82 per channel (not from the manual).
const WORD1: &[Field] = &[f(1, Value, 0, 2)];
const SB_WORD1: &[Field] = &[f(1, Status, 0, 1), f(1, Value, 1, 2)];
const CB_WORD1: &[Field] = &[f(1, Control, 0, 1), f(1, Value, 1, 2)];
const DS: &str =
    "Beckhoff data sheet (not from the manual); identifiers by analogy with KL3xx2, manual p. 49";

#[rustfmt::skip]
const ANALOG_IN1: &[Variant] = &[
    v(Mapping::Compact, &[0x50], 2, WORD1, 0, &[], DS),
    v(Mapping::Complete, &[0xB2], 3, SB_WORD1, 3, CB_WORD1, DS),
    v(Mapping::StatusControl, &[0xC0, 0x00, 0x82], 3, SB_WORD1, 1, CB, DS),
];

#[rustfmt::skip]
const ANALOG_OUT1: &[Variant] = &[
    v(Mapping::Compact, &[0x60], 0, &[], 2, WORD1, DS),
    v(Mapping::Complete, &[0xB2], 3, SB_WORD1, 3, CB_WORD1, DS),
    v(Mapping::StatusControl, &[0xC0, 0x82, 0x00], 1, SB1, 3, CB_WORD1, DS),
];
const SB1: &[Field] = &[f(1, Status, 0, 1)];

const WORDS4: &[Field] = &[
    f(1, Value, 0, 2),
    f(2, Value, 2, 2),
    f(3, Value, 4, 2),
    f(4, Value, 6, 2),
];
const SB_WORD4: &[Field] = &[
    f(1, Status, 0, 1),
    f(1, Value, 1, 2),
    f(2, Status, 3, 1),
    f(2, Value, 4, 2),
    f(3, Status, 6, 1),
    f(3, Value, 7, 2),
    f(4, Status, 9, 1),
    f(4, Value, 10, 2),
];
const CB_WORD4: &[Field] = &[
    f(1, Control, 0, 1),
    f(1, Value, 1, 2),
    f(2, Control, 3, 1),
    f(2, Value, 4, 2),
    f(3, Control, 6, 1),
    f(3, Value, 7, 2),
    f(4, Control, 9, 1),
    f(4, Value, 10, 2),
];

#[rustfmt::skip]
const ANALOG_IN4: &[Variant] = &[
    v(Mapping::Compact, &[0x50, 0x50, 0x50, 0x50], 8, WORDS4, 0, &[], DS),
    v(Mapping::Complete, &[0xB2, 0xB2, 0xB2, 0xB2], 12, SB_WORD4, 12, CB_WORD4, DS),
];

#[rustfmt::skip]
const ANALOG_OUT4: &[Variant] = &[
    v(Mapping::Compact, &[0x60, 0x60, 0x60, 0x60], 0, &[], 8, WORDS4, DS),
    v(Mapping::Complete, &[0xB2, 0xB2, 0xB2, 0xB2], 12, SB_WORD4, 12, CB_WORD4, DS),
];

/// Encoder/counter terminals with status/control byte and a 16-bit word
/// per direction, 0xB2 (KL5101, KL5111, KL1512 per channel; data sheet,
/// not from the manual).
#[rustfmt::skip]
const ONE_B2: &[Variant] = &[
    v(Mapping::Complete, &[0xB2], 3, SB_WORD1, 3, CB_WORD1, DS),
];
#[rustfmt::skip]
const TWO_B2: &[Variant] = &[
    v(Mapping::Complete, &[0xB2, 0xB2], 6, SB_WORD2, 6, CB_WORD2, DS),
];

/// Serial interfaces KL6001/KL6011/KL6021: status/control byte and
/// 3 data bytes... modelled as 0xB3 (4 bytes each way; data sheet, not
/// from the manual): status/control byte, unused byte, one data word.
#[rustfmt::skip]
const SERIAL: &[Variant] = &[
    v(Mapping::Complete, &[0xB3], 4, &[f(1, Status, 0, 1), f(1, Reserved, 1, 1), f(1, Value, 2, 2)],
      4, &[f(1, Control, 0, 1), f(1, Reserved, 1, 1), f(1, Value, 2, 2)], DS),
];

/// The fields of the `126 Byte Data-Area` (manual p. 51): the status
/// (or control) byte, one unused byte, then 63 data words (channels
/// 1..=63).
const fn data_area(control: bool) -> [Field; 65] {
    let mut out = [f(0, Reserved, 1, 1); 65];
    out[0] = f(0, if control { Control } else { Status }, 0, 1);
    let mut k = 1;
    while k < 64 {
        out[k + 1] = f(k as u8, Value, 2 * k as u8, 2);
        k += 1;
    }
    out
}
const AREA_IN: [Field; 65] = data_area(false);
const AREA_OUT: [Field; 65] = data_area(true);

/// `126 Byte Data-Area: 0xC0,0xFF` (manual p. 51, the terminal's name is
/// cut off in the summary). Our reading: the special identifier 0xC0 with
/// an output and an input length byte 0xFF each (64 words, consistent
/// over the whole length): a status/control byte, one unused byte and
/// the 126-byte data area (63 words), both ways. The summary keeps one
/// 0xFF; the coupler accepts `C0 FF FF` and `C0 FF` followed by nothing
/// else is refused as too few CfgData.
#[rustfmt::skip]
const DATA_AREA_126: &[Variant] = &[
    v(Mapping::Standard, &[0xC0, 0xFF, 0xFF], 128, &AREA_IN, 128, &AREA_OUT, "manual p. 51 (0xC0,0xFF; the second length byte is our reading)"),
];

const MA20: Scale = Scale::Positive {
    full: 20.0,
    unit: "mA",
};
const MA4_20: Scale = Scale::Span {
    lo: 4.0,
    hi: 20.0,
    unit: "mA",
};
const VOLT10_UNI: Scale = Scale::Positive {
    full: 10.0,
    unit: "V",
};
const CELSIUS: Scale = Scale::Digit {
    per_digit: 0.1,
    unit: "°C",
};
const DIGITS: Scale = Scale::Digit {
    per_digit: 1.0,
    unit: "digit",
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
    // Named in the manual (p. 49-50, p. 63), identifiers from p. 49-51.
    complex("KL3012", "2 analog inputs 0..20 mA", 2, MA20, ANALOG_IN2, Sim::Sine),
    complex("KL3022", "2 analog inputs 4..20 mA", 2, MA4_20, ANALOG_IN2, Sim::Sine),
    complex("KL3032", "2 analog inputs 0..20 mA, differential", 2, MA20, ANALOG_IN2, Sim::Sine),
    complex("KL3042", "2 analog inputs 0..20 mA, single-ended", 2, MA20, ANALOG_IN2, Sim::Sine),
    complex("KL3052", "2 analog inputs 4..20 mA, single-ended", 2, MA4_20, ANALOG_IN2, Sim::Sine),
    complex("KL3062", "2 analog inputs 0..10 V, single-ended", 2, VOLT10_UNI, ANALOG_IN2, Sim::Sine),
    complex("KL3302", "2 thermocouple inputs, 0.1 °C per digit", 2, CELSIUS, ANALOG_IN2, Sim::Temperature),
    complex("KL3351", "resistor bridge (strain gauge) input, 2 words", 2, DIGITS, ANALOG_IN2, Sim::Sine),
    complex("KL5302", "2-channel interface (same identifiers as KL2502)", 2, DIGITS, PWM2, Sim::Echo),
    TerminalType {
        name: "DATA126",
        summary: "the manual's `126 Byte Data-Area` (0xC0,0xFF; name cut off): 126 data bytes each way, read back",
        class: Class::Complex,
        channels: 63,
        scale: Scale::Count,
        variants: DATA_AREA_126,
        sim: Sim::Echo,
        registers: &[(8, 0)],
        source: Source::Manual,
    },
    // Common KL terminals from Beckhoff's data sheets (not from the manual).
    digital_ds("KL1012", "2 digital inputs 24 V DC, 0.2 ms", Class::DigitalIn, 2),
    digital_ds("KL1052", "2 digital inputs 24 V DC, negative switching", Class::DigitalIn, 2),
    digital_ds("KL1114", "4 digital inputs 24 V DC, 0.2 ms", Class::DigitalIn, 4),
    digital_ds("KL1124", "4 digital inputs 5 V DC", Class::DigitalIn, 4),
    digital_ds("KL1184", "4 digital inputs 24 V DC, negative switching", Class::DigitalIn, 4),
    digital_ds("KL1304", "4 digital inputs 24 V DC, type 2", Class::DigitalIn, 4),
    digital_ds("KL1404", "4 digital inputs 24 V DC, 2-wire", Class::DigitalIn, 4),
    digital_ds("KL1418", "8 digital inputs 24 V DC, 0.2 ms", Class::DigitalIn, 8),
    digital_ds("KL1488", "8 digital inputs 24 V DC, negative switching", Class::DigitalIn, 8),
    digital_ds("KL1702", "2 digital inputs 230 V AC", Class::DigitalIn, 2),
    digital_ds("KL1712", "2 digital inputs 120 V AC/DC", Class::DigitalIn, 2),
    digital_ds("KL1808", "8 digital inputs 24 V DC, 1-wire", Class::DigitalIn, 8),
    digital_ds("KL1809", "16 digital inputs 24 V DC", Class::DigitalIn, 16),
    digital_ds("KL1814", "4 digital inputs and 4 digital outputs 24 V DC", Class::DigitalInOut, 4),
    digital_ds("KL1859", "8 digital inputs and 8 digital outputs 24 V DC", Class::DigitalInOut, 8),
    digital_ds("KL2022", "2 digital outputs 24 V DC, 2 A", Class::DigitalOut, 2),
    digital_ds("KL2032", "2 digital outputs 24 V DC, short-circuit proof", Class::DigitalOut, 2),
    digital_ds("KL2114", "4 digital outputs 24 V DC, 0.5 A", Class::DigitalOut, 4),
    digital_ds("KL2124", "4 digital outputs 5 V DC", Class::DigitalOut, 4),
    digital_ds("KL2184", "4 digital outputs 24 V DC, negative switching", Class::DigitalOut, 4),
    digital_ds("KL2404", "4 digital outputs 24 V DC, 0.5 A, 2-wire", Class::DigitalOut, 4),
    digital_ds("KL2424", "4 digital outputs 24 V DC, 2 A", Class::DigitalOut, 4),
    digital_ds("KL2488", "8 digital outputs 24 V DC, negative switching", Class::DigitalOut, 8),
    digital_ds("KL2602", "2 relay outputs 230 V AC", Class::DigitalOut, 2),
    digital_ds("KL2612", "2 relay outputs 125 V AC", Class::DigitalOut, 2),
    digital_ds("KL2622", "2 relay outputs, make contacts", Class::DigitalOut, 2),
    digital_ds("KL2702", "2 solid-state outputs 230 V AC", Class::DigitalOut, 2),
    digital_ds("KL2712", "2 triac outputs 12..230 V AC", Class::DigitalOut, 2),
    digital_ds("KL2808", "8 digital outputs 24 V DC, 0.5 A", Class::DigitalOut, 8),
    digital_ds("KL2809", "16 digital outputs 24 V DC", Class::DigitalOut, 16),
    complex_ds("KL3001", "1 analog input -10..+10 V", 1, VOLT10, ANALOG_IN1, Sim::Sine),
    complex_ds("KL3011", "1 analog input 0..20 mA", 1, MA20, ANALOG_IN1, Sim::Sine),
    complex_ds("KL3021", "1 analog input 4..20 mA", 1, MA4_20, ANALOG_IN1, Sim::Sine),
    complex_ds("KL3041", "1 analog input 0..20 mA, single-ended", 1, MA20, ANALOG_IN1, Sim::Sine),
    complex_ds("KL3051", "1 analog input 4..20 mA, single-ended", 1, MA4_20, ANALOG_IN1, Sim::Sine),
    complex_ds("KL3061", "1 analog input 0..10 V", 1, VOLT10_UNI, ANALOG_IN1, Sim::Sine),
    complex_ds("KL3112", "2 analog inputs 0..20 mA, 16 bit", 2, MA20, ANALOG_IN2, Sim::Sine),
    complex_ds("KL3122", "2 analog inputs 4..20 mA, 16 bit", 2, MA4_20, ANALOG_IN2, Sim::Sine),
    complex_ds("KL3162", "2 analog inputs 0..10 V, 16 bit", 2, VOLT10_UNI, ANALOG_IN2, Sim::Sine),
    complex_ds("KL3201", "1 analog input PT100 (RTD)", 1, PT100, ANALOG_IN1, Sim::Temperature),
    complex_ds("KL3204", "4 analog inputs PT100 (RTD)", 4, PT100, ANALOG_IN4, Sim::Temperature),
    complex_ds("KL3301", "1 thermocouple input", 1, CELSIUS, ANALOG_IN1, Sim::Temperature),
    complex_ds("KL3312", "2 thermocouple inputs with open-circuit detection", 2, CELSIUS, ANALOG_IN2, Sim::Temperature),
    complex_ds("KL3314", "4 thermocouple inputs", 4, CELSIUS, ANALOG_IN4, Sim::Temperature),
    complex_ds("KL3404", "4 analog inputs -10..+10 V", 4, VOLT10, ANALOG_IN4, Sim::Sine),
    complex_ds("KL3454", "4 analog inputs 4..20 mA", 4, MA4_20, ANALOG_IN4, Sim::Sine),
    complex_ds("KL3464", "4 analog inputs 0..10 V", 4, VOLT10_UNI, ANALOG_IN4, Sim::Sine),
    complex_ds("KL4001", "1 analog output 0..10 V", 1, VOLT10_POSITIVE, ANALOG_OUT1, Sim::None),
    complex_ds("KL4011", "1 analog output 0..20 mA", 1, MA20, ANALOG_OUT1, Sim::None),
    complex_ds("KL4012", "2 analog outputs 0..20 mA", 2, MA20, ANALOG_OUT2, Sim::None),
    complex_ds("KL4021", "1 analog output 4..20 mA", 1, MA4_20, ANALOG_OUT1, Sim::None),
    complex_ds("KL4022", "2 analog outputs 4..20 mA", 2, MA4_20, ANALOG_OUT2, Sim::None),
    complex_ds("KL4031", "1 analog output -10..+10 V", 1, VOLT10, ANALOG_OUT1, Sim::None),
    complex_ds("KL4034", "4 analog outputs -10..+10 V", 4, VOLT10, ANALOG_OUT4, Sim::None),
    complex_ds("KL4404", "4 analog outputs 0..10 V", 4, VOLT10_POSITIVE, ANALOG_OUT4, Sim::None),
    complex_ds("KL4424", "4 analog outputs 4..20 mA", 4, MA4_20, ANALOG_OUT4, Sim::None),
    complex_ds("KL4434", "4 analog outputs 0..20 mA", 4, MA20, ANALOG_OUT4, Sim::None),
    complex_ds("KL1512", "2 up/down counters 16 bit", 2, DIGITS, TWO_B2, Sim::Counter),
    complex_ds("KL5101", "incremental encoder interface, 16-bit counter", 1, DIGITS, ONE_B2, Sim::Encoder),
    complex_ds("KL5111", "incremental encoder interface, 16-bit counter, 24 V", 1, DIGITS, ONE_B2, Sim::Encoder),
    complex_ds("KL6001", "serial interface RS232 (data word read back)", 1, DIGITS, SERIAL, Sim::Echo),
    complex_ds("KL6011", "serial interface TTY (data word read back)", 1, DIGITS, SERIAL, Sim::Echo),
    complex_ds("KL6021", "serial interface RS422/RS485 (data word read back)", 1, DIGITS, SERIAL, Sim::Echo),
    passive("KL9100", "power feed terminal 24 V DC (no process data)"),
    TerminalType { source: Source::Datasheet, ..passive("KL9110", "power feed terminal 24 V DC with diagnosis (no process data on the BK3000)") },
    TerminalType { source: Source::Datasheet, ..passive("KL9150", "power feed terminal 230 V AC (no process data)") },
    TerminalType { source: Source::Datasheet, ..passive("KL9200", "power feed terminal 24 V DC with fuse (no process data)") },
    TerminalType { source: Source::Datasheet, ..passive("KL9505", "power supply terminal 5 V (no process data)") },
    passive("KL9400", "K-bus power supply terminal (no process data)"),
    passive("KL9010", "end terminal"),
];

/// The end terminal every strip must finish with.
pub const END_TERMINAL: &str = "KL9010";

/// The terminal type named `name` (case-insensitive).
pub fn lookup(name: &str) -> Option<&'static TerminalType> {
    CATALOGUE.iter().find(|t| t.name.eq_ignore_ascii_case(name))
}
