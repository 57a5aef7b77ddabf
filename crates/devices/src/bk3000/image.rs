//! The terminal strip and the coupler's process image: which byte and bit
//! of the DP inputs and outputs belongs to which terminal channel, the
//! configuration (Chk_Cfg) that describes it, and the check of a
//! master's configuration against the real strip.
//!
//! Layout rules (manual pages 16, 38-40, 46-48; module docs of
//! [`super`]): the optional 2-byte PLC interface first, then the K-bus
//! cycle counter (1 input byte) if enabled, then the byte-oriented
//! (complex) terminals in plug order starting next to the coupler, then
//! the digital channels packed bit by bit in plug order, inputs and
//! outputs separately; a partly used last byte is padded with zeros.

use super::catalogue::{self, Class, Field, Mapping, Role, TerminalType, Variant};
use std::fmt;

/// Most terminals on one coupler, power feed and end terminal included
/// (manual page 7).
pub const MAX_TERMINALS: usize = 64;

/// Most bytes of inputs and of outputs (manual page 25).
pub const MAX_IO: usize = 244;

/// Identifier of the 2-byte PLC interface (manual p. 48; English ed. p. 46).
pub const CFG_PLC_INTERFACE: u8 = 0xB1;

/// Identifier of the K-bus cycle counter (manual p. 47).
pub const CFG_CYCLE_COUNTER: u8 = 0x10;

/// Why a terminal list is not a strip the coupler can run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StripError {
    /// A name that is not in the catalogue.
    #[error("terminal {position}: `{name}` is not in the catalogue{}", if suggestions.is_empty() { format!(" (known: {known})") } else { suggestions.to_string() })]
    Unknown {
        /// 1-based position.
        position: usize,
        /// The name given.
        name: String,
        /// The closest names of the catalogue.
        suggestions: profibus_dp::config::names::DidYouMean,
        /// The catalogue's names.
        known: String,
    },
    /// A mapping the terminal does not have.
    #[error("terminal {position} ({name}): no `{mapping}` mapping (it has: {have})")]
    Mapping {
        /// 1-based position.
        position: usize,
        /// The terminal.
        name: &'static str,
        /// The mapping asked for.
        mapping: String,
        /// The mappings it has.
        have: String,
    },
    /// No terminals at all.
    #[error(
        "the strip is empty: list the terminals in plug order, ending with the end terminal KL9010"
    )]
    Empty,
    /// The last terminal is not the end terminal.
    #[error("the strip must end with the end terminal KL9010 (the last terminal is {0}): without it the K-bus is open")]
    NoEndTerminal(&'static str),
    /// Terminals after the end terminal.
    #[error("terminal {0} follows the end terminal KL9010; nothing can be plugged after it")]
    AfterEnd(usize),
    /// More than 64 terminals.
    #[error("{0} terminals: a BK3000 takes at most 64, power feed and end terminal included")]
    TooMany(usize),
    /// More than 244 bytes in a direction.
    #[error("the strip needs {inputs} input and {outputs} output bytes; PROFIBUS-DP carries at most 244 each way")]
    TooLong {
        /// Input bytes.
        inputs: usize,
        /// Output bytes.
        outputs: usize,
    },
}

/// One plugged terminal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slot {
    /// Its type.
    pub ty: &'static TerminalType,
    /// The mapping asked for in the terminal list (complex terminals;
    /// default: the terminal's first variant).
    pub mapping: Option<Mapping>,
}

/// The terminals plugged into the coupler, in plug order.
#[derive(Debug, Clone, PartialEq)]
pub struct Strip {
    slots: Vec<Slot>,
}

impl Strip {
    /// Parse a terminal list: names separated by commas, blanks or new
    /// lines, each optionally with `:compact`, `:complete`, `:standard`
    /// or `:status`; `#` starts a comment (for terminal files). Checks
    /// the strip's rules (end terminal last, at most 64 terminals, at
    /// most 244 bytes each way in the chosen mappings).
    pub fn parse(list: &str) -> Result<Strip, StripError> {
        Strip::parse_with(list, &[])
    }

    /// [`Strip::parse`] with terminal types the user described
    /// ([`super::user`]) besides the catalogue.
    pub fn parse_with(list: &str, extra: &[&'static TerminalType]) -> Result<Strip, StripError> {
        let mut names = vec![];
        for line in list.lines() {
            let line = line.split('#').next().unwrap_or("");
            names.extend(
                line.split(|c: char| c == ',' || c.is_whitespace())
                    .filter(|s| !s.is_empty()),
            );
        }
        Strip::from_names_with(&names, extra)
    }

    /// A strip from terminal names (with optional `:mapping`).
    pub fn from_names<S: AsRef<str>>(names: &[S]) -> Result<Strip, StripError> {
        Strip::from_names_with(names, &[])
    }

    /// [`Strip::from_names`] with user terminal types besides the catalogue.
    pub fn from_names_with<S: AsRef<str>>(
        names: &[S],
        extra: &[&'static TerminalType],
    ) -> Result<Strip, StripError> {
        let mut slots = vec![];
        for (i, n) in names.iter().enumerate() {
            let n = n.as_ref().trim();
            let (name, mapping) = match n.split_once(':') {
                Some((a, b)) => (a, Some(b)),
                None => (n, None),
            };
            let user = extra
                .iter()
                .copied()
                .find(|t| t.name.eq_ignore_ascii_case(name));
            let Some(ty) = user.or_else(|| catalogue::lookup(name)) else {
                return Err(StripError::Unknown {
                    position: i + 1,
                    name: name.to_string(),
                    suggestions: profibus_dp::config::names::DidYouMean::new(
                        name,
                        catalogue::CATALOGUE
                            .iter()
                            .chain(extra.iter().copied())
                            .map(|t| t.name),
                    ),
                    known: catalogue::CATALOGUE
                        .iter()
                        .map(|t| t.name)
                        .collect::<Vec<_>>()
                        .join(", "),
                });
            };
            let mapping = match mapping {
                None => None,
                Some(m) => {
                    let found = ty
                        .variants
                        .iter()
                        .map(|v| v.mapping)
                        .find(|v| v.as_str().eq_ignore_ascii_case(m.trim()));
                    if found.is_none() {
                        let mut have: Vec<&str> =
                            ty.variants.iter().map(|v| v.mapping.as_str()).collect();
                        have.dedup();
                        return Err(StripError::Mapping {
                            position: i + 1,
                            name: ty.name,
                            mapping: m.to_string(),
                            have: if have.is_empty() {
                                "none, it has no byte-oriented data".into()
                            } else {
                                have.join(", ")
                            },
                        });
                    }
                    found
                }
            };
            slots.push(Slot { ty, mapping });
        }
        Strip::new(slots)
    }

    /// A strip from slots; checks the rules of [`Strip::parse`].
    pub fn new(slots: Vec<Slot>) -> Result<Strip, StripError> {
        let Some(last) = slots.last() else {
            return Err(StripError::Empty);
        };
        if let Some(i) = slots
            .iter()
            .position(|s| s.ty.name == catalogue::END_TERMINAL)
        {
            if i + 1 != slots.len() {
                return Err(StripError::AfterEnd(i + 2));
            }
        } else {
            return Err(StripError::NoEndTerminal(last.ty.name));
        }
        if slots.len() > MAX_TERMINALS {
            return Err(StripError::TooMany(slots.len()));
        }
        let strip = Strip { slots };
        let img = strip.default_image(Options::default());
        if img.in_len > MAX_IO || img.out_len > MAX_IO {
            return Err(StripError::TooLong {
                inputs: img.in_len,
                outputs: img.out_len,
            });
        }
        Ok(strip)
    }

    /// The terminals.
    pub fn slots(&self) -> &[Slot] {
        &self.slots
    }

    /// Number of terminals (end terminal included).
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Never true for a checked strip.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// The variants the terminal list asks for (defaults where none).
    pub fn default_variants(&self) -> Vec<Option<&'static Variant>> {
        self.slots
            .iter()
            .map(|s| match s.mapping {
                Some(m) => s.ty.variant(m),
                None => s.ty.default_variant(),
            })
            .collect()
    }

    /// The image with the mappings of the terminal list.
    pub fn default_image(&self, opts: Options) -> Image {
        Image::new(self, &self.default_variants(), opts)
    }

    /// The terminal names in plug order (with `:mapping` where given).
    pub fn names(&self) -> Vec<String> {
        self.slots
            .iter()
            .map(|s| match s.mapping {
                Some(m) => format!("{}:{}", s.ty.name, m.as_str()),
                None => s.ty.name.to_string(),
            })
            .collect()
    }
}

/// Coupler functions that add data to the image (User_Prm_Data).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct Options {
    /// The 2-byte PLC interface (User_Prm_Data byte 5 bit 0).
    pub plc_interface: bool,
    /// The K-bus cycle counter (User_Prm_Data byte 3 bit 3).
    pub cycle_counter: bool,
}

/// Direction of a field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Dir {
    /// Slave → master.
    In,
    /// Master → slave.
    Out,
}

/// Who a field belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Owner {
    /// The coupler's 2-byte PLC interface (byte 0 control/status, byte 1
    /// data).
    PlcInterface,
    /// The K-bus cycle counter.
    CycleCounter,
    /// Terminal at this 1-based position.
    Terminal(usize),
}

/// One field of the process image: where a channel's value (or status,
/// or control byte) sits in the DP data.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Entry {
    /// Whose field it is.
    pub owner: Owner,
    /// Terminal type name (`BK3000` for the coupler's own fields).
    pub terminal: &'static str,
    /// Channel 1.. (0 for the coupler's fields).
    pub channel: u8,
    /// What it carries.
    pub role: Role,
    /// Inputs or outputs.
    pub dir: Dir,
    /// Byte offset in the inputs or outputs.
    pub byte: usize,
    /// Bit in that byte for digital channels.
    pub bit: Option<u8>,
    /// Bytes (0 for a bit).
    pub bytes: u8,
    /// Name for people and for commands: `3.KL3102.1`,
    /// `3.KL3102.1.status`, `plc.status`, `kbus.counter`.
    pub name: String,
}

/// The process image of a strip with given variants and options.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Every field, inputs and outputs, in image order.
    pub entries: Vec<Entry>,
    /// Input bytes.
    pub in_len: usize,
    /// Output bytes.
    pub out_len: usize,
    /// The configuration (Chk_Cfg) that describes this image, with the
    /// digital data as one identifier per 16 bytes and direction.
    pub cfg: Vec<u8>,
    /// Bytes of packed digital inputs and outputs.
    pub digital: (usize, usize),
}

impl Image {
    /// Lay out `strip` with `variants` (one per slot; `None` for digital
    /// and passive terminals) and `opts`.
    pub fn new(strip: &Strip, variants: &[Option<&'static Variant>], opts: Options) -> Image {
        let mut entries = vec![];
        let mut cfg = vec![];
        let (mut i, mut o) = (0usize, 0usize);
        if opts.plc_interface {
            cfg.push(CFG_PLC_INTERFACE);
            for (dir, role, name) in [
                (Dir::In, Role::Status, "plc.status"),
                (Dir::Out, Role::Control, "plc.control"),
            ] {
                entries.push(coupler_entry(Owner::PlcInterface, role, dir, 0, 1, name));
            }
            entries.push(coupler_entry(
                Owner::PlcInterface,
                Role::Value,
                Dir::In,
                1,
                1,
                "plc.data",
            ));
            entries.push(coupler_entry(
                Owner::PlcInterface,
                Role::Value,
                Dir::Out,
                1,
                1,
                "plc.data",
            ));
            i += 2;
            o += 2;
        }
        if opts.cycle_counter {
            cfg.push(CFG_CYCLE_COUNTER);
            entries.push(coupler_entry(
                Owner::CycleCounter,
                Role::Value,
                Dir::In,
                i,
                1,
                "kbus.counter",
            ));
            i += 1;
        }
        for (k, (slot, v)) in strip.slots.iter().zip(variants).enumerate() {
            let (Class::Complex, Some(v)) = (slot.ty.class, v) else {
                continue;
            };
            let pos = k + 1;
            cfg.extend_from_slice(v.cfg);
            let mut push = |fields: &[Field], dir: Dir, base: usize| {
                for fl in fields {
                    entries.push(Entry {
                        owner: Owner::Terminal(pos),
                        terminal: slot.ty.name,
                        channel: fl.channel,
                        role: fl.role,
                        dir,
                        byte: base + fl.offset as usize,
                        bit: None,
                        bytes: fl.bytes,
                        name: format!("{pos}.{}.{}{}", slot.ty.name, fl.channel, fl.role.suffix()),
                    });
                }
            };
            push(v.inputs, Dir::In, i);
            push(v.outputs, Dir::Out, o);
            i += v.in_len as usize;
            o += v.out_len as usize;
        }
        let (mut ib, mut ob) = (0usize, 0usize);
        for (k, slot) in strip.slots.iter().enumerate() {
            let (nin, nout) = slot.ty.digital_bits();
            for (dir, base, bits, n) in [(Dir::In, i, &mut ib, nin), (Dir::Out, o, &mut ob, nout)] {
                for ch in 1..=n {
                    entries.push(Entry {
                        owner: Owner::Terminal(k + 1),
                        terminal: slot.ty.name,
                        channel: ch,
                        role: Role::Value,
                        dir,
                        byte: base + *bits / 8,
                        bit: Some((*bits % 8) as u8),
                        bytes: 0,
                        name: format!("{}.{}.{ch}", k + 1, slot.ty.name),
                    });
                    *bits += 1;
                }
            }
        }
        let (din, dout) = (ib.div_ceil(8), ob.div_ceil(8));
        push_digital(&mut cfg, 0x10, din);
        push_digital(&mut cfg, 0x20, dout);
        Image {
            entries,
            in_len: i + din,
            out_len: o + dout,
            cfg,
            digital: (din, dout),
        }
    }

    /// The entry named `name`: the full name (`2.KL2134.1`), or position
    /// and channel (`2.1`), with an optional role suffix; case-insensitive.
    pub fn find(&self, name: &str, dir: Option<Dir>) -> Option<&Entry> {
        let name = name.trim();
        let ok = |e: &&Entry| dir.is_none_or(|d| e.dir == d);
        if let Some(e) = self
            .entries
            .iter()
            .filter(ok)
            .find(|e| e.name.eq_ignore_ascii_case(name))
        {
            return Some(e);
        }
        // Short form: POS.CH[.role]
        let mut parts = name.split('.');
        let pos: usize = parts.next()?.parse().ok()?;
        let ch: u8 = parts.next()?.parse().ok()?;
        let role = match parts.next() {
            None => Role::Value,
            Some(r) if r.eq_ignore_ascii_case("status") => Role::Status,
            Some(r) if r.eq_ignore_ascii_case("control") => Role::Control,
            _ => return None,
        };
        self.entries
            .iter()
            .filter(ok)
            .find(|e| e.owner == Owner::Terminal(pos) && e.channel == ch && e.role == role)
    }

    /// The raw value of `e` in `data` (inputs or outputs as `e.dir`
    /// says): a bit, a byte, a signed big-endian word, an unsigned
    /// big-endian double word.
    pub fn get(e: &Entry, data: &[u8]) -> i64 {
        if let Some(bit) = e.bit {
            return data.get(e.byte).map_or(0, |b| (b >> bit) as i64 & 1);
        }
        let Some(b) = data.get(e.byte..e.byte + e.bytes as usize) else {
            return 0;
        };
        match b.len() {
            1 => b[0] as i64,
            2 => i16::from_be_bytes([b[0], b[1]]) as i64,
            4 => u32::from_be_bytes([b[0], b[1], b[2], b[3]]) as i64,
            _ => 0,
        }
    }

    /// Write the raw value `v` of `e` into `data`.
    pub fn put(e: &Entry, data: &mut [u8], v: i64) {
        if let Some(bit) = e.bit {
            if let Some(b) = data.get_mut(e.byte) {
                if v != 0 {
                    *b |= 1 << bit;
                } else {
                    *b &= !(1 << bit);
                }
            }
            return;
        }
        let Some(b) = data.get_mut(e.byte..e.byte + e.bytes as usize) else {
            return;
        };
        match b.len() {
            1 => b[0] = v as u8,
            2 => b.copy_from_slice(&(v as i16).to_be_bytes()),
            4 => b.copy_from_slice(&(v as u32).to_be_bytes()),
            _ => {}
        }
    }
}

fn coupler_entry(owner: Owner, role: Role, dir: Dir, byte: usize, bytes: u8, name: &str) -> Entry {
    Entry {
        owner,
        terminal: "BK3000",
        channel: 0,
        role,
        dir,
        byte,
        bit: None,
        bytes,
        name: name.to_string(),
    }
}

/// Append general identifiers `kind | (n-1)` for `bytes` bytes, 16 at most
/// each.
fn push_digital(cfg: &mut Vec<u8>, kind: u8, mut bytes: usize) {
    while bytes > 0 {
        let n = bytes.min(16);
        cfg.push(kind | (n as u8 - 1));
        bytes -= n;
    }
}

/// The CfgData error of the coupler's diagnosis (manufacturer byte 4) and
/// the first faulty byte (byte 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CfgError {
    /// 1: too few configuration bytes.
    TooFew,
    /// 2: configuration byte n (0-based) is wrong.
    FaultyByte(usize),
}

impl CfgError {
    /// The CfgData error code (1 too few, 2 faulty byte).
    pub fn code(self) -> u8 {
        match self {
            CfgError::TooFew => 1,
            CfgError::FaultyByte(_) => 2,
        }
    }

    /// The first faulty byte (0 for "too few").
    pub fn byte(self) -> u8 {
        match self {
            CfgError::TooFew => 0,
            CfgError::FaultyByte(n) => n.min(255) as u8,
        }
    }

    /// The I/O-ERR blink code: 6 pulses, then 0 for too few configuration
    /// data or n for faulty byte n (counted from 1; inferred, since n = 0
    /// is taken by "too few").
    pub fn blink(self) -> (u8, u8) {
        match self {
            CfgError::TooFew => (6, 0),
            CfgError::FaultyByte(n) => (6, (n + 1).min(255) as u8),
        }
    }
}

impl fmt::Display for CfgError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (p, n) = self.blink();
        match self {
            CfgError::TooFew => write!(f, "too few CfgData"),
            CfgError::FaultyByte(b) => write!(f, "CfgData byte {b} faulty"),
        }?;
        write!(f, " (I/O-ERR: {p} pulses, then {n})")
    }
}

/// A configuration the coupler rejected: the error and why, in words.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{error}: {reason}")]
pub struct CfgReject {
    /// The diagnosis code and byte.
    pub error: CfgError,
    /// What was expected, for people.
    pub reason: String,
}

/// Check a Chk_Cfg configuration against `strip` (auto configuration,
/// manual pages 48-50): the PLC interface and cycle counter identifiers
/// if `opts` enables them, then each complex terminal in plug order with
/// one of its formats, then digital identifiers `0x1n`/`0x2n`/`0x3n` in
/// any split whose totals equal the digital input and output bytes. On
/// success, the image of the formats the master chose.
pub fn check_cfg(strip: &Strip, opts: Options, cfg: &[u8]) -> Result<Image, CfgReject> {
    let mut at = 0usize;
    let faulty = |at: usize, reason: String| CfgReject {
        error: if at >= cfg.len() {
            CfgError::TooFew
        } else {
            CfgError::FaultyByte(at)
        },
        reason,
    };
    let expect_byte = |at: &mut usize, b: u8, what: &str| -> Result<(), CfgReject> {
        match cfg.get(*at) {
            Some(&x) if x == b => {
                *at += 1;
                Ok(())
            }
            _ => Err(faulty(
                *at,
                format!("expected 0x{b:02X} ({what}) at byte {at}"),
            )),
        }
    };
    if opts.plc_interface {
        expect_byte(&mut at, CFG_PLC_INTERFACE, "2-byte PLC interface")?;
    }
    if opts.cycle_counter {
        expect_byte(&mut at, CFG_CYCLE_COUNTER, "K-bus cycle counter")?;
    }
    let mut chosen: Vec<Option<&'static Variant>> = vec![None; strip.len()];
    for (k, slot) in strip.slots.iter().enumerate() {
        if slot.ty.class != Class::Complex {
            continue;
        }
        let rest = &cfg[at..];
        let hit = slot.ty.variants.iter().find(|v| rest.starts_with(v.cfg));
        match hit {
            Some(v) => {
                chosen[k] = Some(v);
                at += v.cfg.len();
            }
            None => {
                let common = slot
                    .ty
                    .variants
                    .iter()
                    .map(|v| v.cfg.iter().zip(rest).take_while(|(a, b)| a == b).count())
                    .max()
                    .unwrap_or(0);
                let forms: Vec<String> = slot
                    .ty
                    .variants
                    .iter()
                    .map(|v| {
                        let cfg = profibus_fdl::wire::Hex(v.cfg);
                        format!("{} {cfg}", v.mapping.as_str())
                    })
                    .collect();
                return Err(faulty(
                    at + common,
                    format!(
                        "terminal {} ({}) expects one of: {}",
                        k + 1,
                        slot.ty.name,
                        forms.join(", ")
                    ),
                ));
            }
        }
    }
    // Digital identifiers.
    let img = Image::new(strip, &chosen, opts);
    let (din, dout) = img.digital;
    let (mut gi, mut go) = (0usize, 0usize);
    while at < cfg.len() {
        let b = cfg[at];
        let n = (b & 0x0F) as usize + 1;
        let (ai, ao) = match b & 0xF0 {
            0x10 => (n, 0),
            0x20 => (0, n),
            0x30 => (n, n),
            _ => {
                return Err(faulty(
                    at,
                    format!(
                        "byte {at} (0x{b:02X}) is not a digital identifier 0x1n/0x2n/0x3n; \
                         the strip has {din} digital input and {dout} digital output bytes"
                    ),
                ))
            }
        };
        if gi + ai > din || go + ao > dout {
            return Err(faulty(
                at,
                format!(
                    "byte {at} (0x{b:02X}) exceeds the digital data: {din} input and {dout} output bytes"
                ),
            ));
        }
        gi += ai;
        go += ao;
        at += 1;
    }
    if gi != din || go != dout {
        return Err(faulty(
            at,
            format!(
                "the digital identifiers give {gi} input and {go} output bytes, the strip has {din} and {dout}"
            ),
        ));
    }
    Ok(Image {
        cfg: cfg.to_vec(),
        ..img
    })
}

/// Where a programmed configuration puts one terminal (manual p. 51:
/// "Mit dem Konfigurator können die Klemmen beliebig in das lokale
/// Prozeßabbild gelegt werden"): the input and output address of its
/// first byte (complex terminals) or first bit (digital terminals).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Placement {
    /// Terminal position (1-based).
    pub position: usize,
    /// Input byte and bit, if placed.
    pub input: Option<(usize, u8)>,
    /// Output byte and bit, if placed.
    pub output: Option<(usize, u8)>,
}

impl Placement {
    /// Parse `POS@IN/OUT` entries separated by commas or `;`: `IN` and
    /// `OUT` are `BYTE` or `BYTE.BIT`, `-` keeps the automatic address
    /// (`1@0.0/-, 3@1/-`).
    pub fn parse_list(text: &str) -> Result<Vec<Placement>, String> {
        let addr = |s: &str, item: &str| -> Result<Option<(usize, u8)>, String> {
            let s = s.trim();
            if s == "-" {
                return Ok(None);
            }
            let bad =
                || format!("placement `{item}`: `{s}` is not BYTE or BYTE.BIT (bit 0-7) or -");
            let (b, bit) = match s.split_once('.') {
                Some((b, bit)) => (
                    b,
                    bit.parse::<u8>().ok().filter(|b| *b < 8).ok_or_else(bad)?,
                ),
                None => (s, 0),
            };
            Ok(Some((b.parse().map_err(|_| bad())?, bit)))
        };
        let mut out = vec![];
        for item in text
            .split([',', ';'])
            .map(str::trim)
            .filter(|s| !s.is_empty())
        {
            let (pos, rest) = item
                .split_once('@')
                .ok_or_else(|| format!("placement `{item}`: write POS@IN/OUT, e.g. 3@0/-"))?;
            let position = pos
                .trim()
                .parse()
                .map_err(|_| format!("placement `{item}`: `{pos}` is no terminal position"))?;
            let (i, o) = rest
                .split_once('/')
                .ok_or_else(|| format!("placement `{item}`: write POS@IN/OUT, e.g. 3@0/-"))?;
            out.push(Placement {
                position,
                input: addr(i, item)?,
                output: addr(o, item)?,
            });
        }
        Ok(out)
    }
}

impl Image {
    /// The image of a programmed configuration `cfg` with terminals
    /// placed freely: the automatic image of `strip` (its mappings,
    /// `opts`), each terminal of `places` moved to its addresses, the
    /// lengths of `cfg`'s identifiers. Refused: a position that is not a
    /// terminal with data in that direction, a digital terminal at a byte
    /// boundary it cannot have, data beyond the lengths, overlapping data.
    pub fn placed(
        strip: &Strip,
        opts: Options,
        places: &[Placement],
        cfg: &[u8],
    ) -> Result<Image, String> {
        let totals = profibus_dp::pdu::cfg::totals(cfg)
            .map_err(|e| format!("programmed configuration: {e}"))?;
        let mut img = strip.default_image(opts);
        for p in places {
            if p.position == 0 || p.position > strip.len() {
                return Err(format!(
                    "placement: terminal {} is not on the strip (1..={})",
                    p.position,
                    strip.len()
                ));
            }
            for (dir, to) in [(Dir::In, p.input), (Dir::Out, p.output)] {
                let Some((byte, bit)) = to else { continue };
                let mine = |e: &Entry| e.owner == Owner::Terminal(p.position) && e.dir == dir;
                let Some(first) = img.entries.iter().filter(|e| mine(e)).map(bit_addr).min() else {
                    return Err(format!(
                        "placement: terminal {} ({}) has no {} data",
                        p.position,
                        strip.slots()[p.position - 1].ty.name,
                        if dir == Dir::In { "input" } else { "output" }
                    ));
                };
                let digital = img.entries.iter().any(|e| mine(e) && e.bit.is_some());
                if !digital && bit != 0 {
                    return Err(format!(
                        "placement: terminal {} is byte-oriented; give a byte, not a bit",
                        p.position
                    ));
                }
                let shift = (byte * 8 + bit as usize) as i64 - first as i64;
                for e in img.entries.iter_mut().filter(|e| mine(e)) {
                    let a = (bit_addr(e) as i64 + shift) as usize;
                    e.byte = a / 8;
                    if e.bit.is_some() {
                        e.bit = Some((a % 8) as u8);
                    }
                }
            }
        }
        let (mut used_in, mut used_out) = (
            vec![false; totals.input_bytes * 8],
            vec![false; totals.output_bytes * 8],
        );
        for e in &img.entries {
            let used = if e.dir == Dir::In {
                &mut used_in
            } else {
                &mut used_out
            };
            let start = bit_addr(e);
            let len = if e.bit.is_some() {
                1
            } else {
                e.bytes as usize * 8
            };
            if start + len > used.len() {
                return Err(format!(
                    "placement: {} lies beyond the {} bytes of the programmed configuration",
                    e.name,
                    used.len() / 8
                ));
            }
            if let Some(k) = (start..start + len).find(|&k| used[k]) {
                return Err(format!(
                    "placement: {} overlaps other data at byte {}, bit {}",
                    e.name,
                    k / 8,
                    k % 8
                ));
            }
            used[start..start + len].fill(true);
        }
        img.in_len = totals.input_bytes;
        img.out_len = totals.output_bytes;
        img.cfg = cfg.to_vec();
        Ok(img)
    }
}

fn bit_addr(e: &Entry) -> usize {
    e.byte * 8 + e.bit.unwrap_or(0) as usize
}
