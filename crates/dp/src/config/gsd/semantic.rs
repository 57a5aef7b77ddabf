//! What a GSD means for a master and a slave: module I/O sizes, module
//! lookup, the Chk_Cfg and User_Prm_Data of a module selection, checks of
//! a selection against the file's limits, MaxTsdr per baud rate.
//!
//! A *selection* is a list of indices into [`Gsd::modules`], in slot
//! order (what the master configures and sends in Chk_Cfg). Build it from
//! names with [`Gsd::select`]. A compact station is configured with
//! exactly one of its modules (several modules in such a file are
//! alternatives) or, as some files mean it, with all of them in file
//! order; [`Gsd::default_selection`] gives the first module.
//!
//! User_Prm_Data follows the standard: when the station-level
//! `Ext_User_Prm_Data_Const`/`Ext_User_Prm_Data_Ref` lines exist they
//! define the station part and the legacy `User_Prm_Data` is not
//! evaluated (ISO 15745-3 / the GSD specification); otherwise the
//! station part is `User_Prm_Data`, padded or cut to
//! `User_Prm_Data_Len`. Each selected module appends its
//! `Ext_Module_Prm_Data_Len` bytes built from its own `Const`/`Ref`
//! lines. Parameters (`ExtUserPrmData`) take their default unless a
//! [`PrmValue`] names them. The result excludes the 7 standard Set_Prm
//! bytes; for a DP-V1 slave its first 3 bytes are the DPV1 status bytes
//! as the file gives them.

use super::model::*;
use crate::config::names::DidYouMean;
use crate::pdu::alarm::{AlarmEnable, AlarmLimit, AlarmMode};
use crate::pdu::cfg::{self, CfgError, CfgTotals};
use crate::pdu::prm::Dpv1Status2;
use profibus_fdl::timing::Baud;
use std::str::FromStr;

/// The most configuration bytes a Chk_Cfg telegram carries.
pub const MAX_CFG_LEN: usize = 244;

/// The most User_Prm_Data bytes a Set_Prm telegram carries (244 − 7).
pub const MAX_USER_PRM_LEN: usize = 237;

/// The most input or output bytes of one DP slave.
pub const MAX_IO_LEN: usize = 244;

/// A module name that is not the name of a module of the GSD.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LookupError {
    /// No module has this name (names match exactly).
    #[error("no module named `{name}`{suggestions}")]
    NotFound {
        /// The name looked for.
        name: String,
        /// The closest module names, if any is close.
        suggestions: DidYouMean,
    },
}

/// A selection or parameter setting that cannot be turned into Chk_Cfg or
/// User_Prm_Data.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SelectionError {
    /// A module index beyond the file's modules.
    #[error("module index {index} is out of range; the file has {count} modules")]
    NoSuchModule {
        /// The index.
        index: usize,
        /// Number of modules in the file.
        count: usize,
    },
    /// A module's identifier bytes do not decode.
    #[error("module `{module}`: {error}")]
    BadIdentifier {
        /// The module name.
        module: String,
        /// What is wrong.
        error: CfgError,
    },
    /// A named parameter that the selection does not have.
    #[error("no parameter `{name}`{} in this configuration{suggestions}", position.map(|p| format!(" at module position {p}")).unwrap_or_default())]
    UnknownParameter {
        /// The name given.
        name: String,
        /// The module position given, if any.
        position: Option<usize>,
        /// The closest parameter names, if any is close.
        suggestions: DidYouMean,
    },
    /// A value the parameter does not allow.
    #[error("parameter `{name}`: {value} is not allowed; allowed: {allowed}")]
    NotAllowed {
        /// The parameter.
        name: String,
        /// The value given.
        value: i64,
        /// What is allowed (its range or values, within its data type).
        allowed: String,
    },
    /// A text that names no value of the parameter.
    #[error("parameter `{name}`: `{text}` is none of its texts ({})", texts.iter().map(|t| format!("`{t}`")).collect::<Vec<_>>().join(", "))]
    UnknownText {
        /// The parameter.
        name: String,
        /// The text given.
        text: String,
        /// Its texts.
        texts: Vec<String>,
    },
    /// User_Prm_Data would reach beyond what Set_Prm can carry.
    #[error("User_Prm_Data would need {needed} bytes; Set_Prm carries at most {MAX_USER_PRM_LEN}")]
    PrmTooLong {
        /// Bytes needed.
        needed: usize,
    },
}

/// Something wrong with a module selection, in words.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Problem {
    /// A module index beyond the file's modules.
    #[error("module index {index} is out of range; the file has {count} modules")]
    NoSuchModule {
        /// The index.
        index: usize,
        /// Number of modules.
        count: usize,
    },
    /// A modular station with no modules selected.
    #[error("no modules are selected; a modular station needs at least one")]
    Empty,
    /// A compact station configured with other than exactly one of its
    /// modules or all of them in file order.
    #[error(
        "this is a compact station (no Modular_Station=1): it is configured with exactly {expected}"
    )]
    FixedConfiguration {
        /// What is allowed, in words (the module, or the alternatives).
        expected: String,
    },
    /// More modules than `Max_Module`.
    #[error("{count} modules selected; the device takes at most {max} (Max_Module)")]
    TooManyModules {
        /// Modules selected.
        count: usize,
        /// `Max_Module`.
        max: usize,
    },
    /// More input bytes than allowed.
    #[error("{bytes} input bytes; the limit is {max} ({limit})")]
    InputTooLong {
        /// Input bytes of the selection.
        bytes: usize,
        /// The limit.
        max: usize,
        /// Where the limit comes from.
        limit: &'static str,
    },
    /// More output bytes than allowed.
    #[error("{bytes} output bytes; the limit is {max} ({limit})")]
    OutputTooLong {
        /// Output bytes of the selection.
        bytes: usize,
        /// The limit.
        max: usize,
        /// Where the limit comes from.
        limit: &'static str,
    },
    /// More input plus output bytes than `Max_Data_Len`.
    #[error(
        "{bytes} input and output bytes together; the device takes at most {max} (Max_Data_Len)"
    )]
    DataTooLong {
        /// Input plus output bytes.
        bytes: usize,
        /// `Max_Data_Len`.
        max: usize,
    },
    /// A Chk_Cfg longer than a telegram carries.
    #[error("{bytes} configuration bytes; Chk_Cfg carries at most {MAX_CFG_LEN}")]
    CfgTooLong {
        /// Identifier bytes of the selection.
        bytes: usize,
    },
    /// User_Prm_Data longer than allowed.
    #[error("{bytes} bytes of User_Prm_Data; the limit is {max} ({limit})")]
    PrmTooLong {
        /// Bytes of the selection's User_Prm_Data.
        bytes: usize,
        /// The limit.
        max: usize,
        /// Where the limit comes from.
        limit: &'static str,
    },
    /// A module whose identifiers do not decode, or parameters that cannot
    /// be built.
    #[error("{0}")]
    Selection(SelectionError),
}

/// A value for a named parameter: `[position:]name=value`, where the
/// optional position (0-based index in the module selection) limits it
/// to one module and the value is a number or one of the parameter's
/// texts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PrmValue {
    /// Module position in the selection (0-based); `None` for every
    /// occurrence of the name (station and modules).
    pub position: Option<usize>,
    /// The parameter name (`ExtUserPrmData` name; case and repeated
    /// blanks do not matter).
    pub name: String,
    /// The value.
    pub value: PrmInput,
}

/// The value of a [`PrmValue`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PrmInput {
    /// A number.
    Int(i64),
    /// A text from the parameter's `PrmText`.
    Text(String),
}

/// A `[position:]name=value` string that does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is no parameter setting; expected `name=value` or `position:name=value`")]
pub struct PrmValueParseError(pub String);

impl FromStr for PrmValue {
    type Err = PrmValueParseError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = || PrmValueParseError(s.to_string());
        let (left, right) = s.split_once('=').ok_or_else(err)?;
        let (position, name) = match left.split_once(':') {
            Some((p, n)) if p.trim().parse::<usize>().is_ok() => {
                (Some(p.trim().parse().map_err(|_| err())?), n)
            }
            _ => (None, left),
        };
        let name = name.trim();
        let right = right.trim();
        if name.is_empty() || right.is_empty() {
            return Err(err());
        }
        Ok(PrmValue {
            position,
            name: name.to_string(),
            value: parse_int(right)
                .map_or_else(|| PrmInput::Text(right.to_string()), PrmInput::Int),
        })
    }
}

fn parse_int(s: &str) -> Option<i64> {
    let (neg, body) = match s.strip_prefix('-') {
        Some(b) => (true, b),
        None => (false, s),
    };
    let v = match body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        Some(h) => i64::from_str_radix(h, 16).ok()?,
        None => body.parse::<i64>().ok()?,
    };
    Some(if neg { -v } else { v })
}

/// One parameter of a selection: where its value goes in the
/// User_Prm_Data and how it is defined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamInstance<'g> {
    /// Module position in the selection, or `None` for a station
    /// parameter.
    pub position: Option<usize>,
    /// Byte offset in the User_Prm_Data.
    pub offset: usize,
    /// The definition.
    pub definition: &'g ExtUserPrmData,
}

/// Input and output sizes of a module; see [`Module::io`].
pub type ModuleIo = CfgTotals;

impl Module {
    /// The module's identifiers, decoded.
    pub fn identifiers(&self) -> cfg::CfgIter<'_> {
        cfg::identifiers(&self.cfg)
    }

    /// Total input and output bytes of the module.
    pub fn io(&self) -> Result<ModuleIo, CfgError> {
        cfg::totals(&self.cfg)
    }
}

/// Lower case with runs of blanks folded to one space and no blanks at
/// the ends.
fn normalize(s: &str) -> String {
    s.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .to_lowercase()
}

/// Write `v` as type `t` at `at` (big-endian for 16/32 bits; Bit and
/// BitArea change only their bits).
fn put(data: &mut [u8], at: usize, t: PrmDataType, v: i64) {
    match t {
        PrmDataType::Unsigned8 | PrmDataType::Signed8 => data[at] = v as u8,
        PrmDataType::Unsigned16 | PrmDataType::Signed16 => {
            data[at..at + 2].copy_from_slice(&(v as u16).to_be_bytes())
        }
        PrmDataType::Unsigned32 | PrmDataType::Signed32 => {
            data[at..at + 4].copy_from_slice(&(v as u32).to_be_bytes())
        }
        PrmDataType::Bit(n) => {
            if v & 1 != 0 {
                data[at] |= 1 << n;
            } else {
                data[at] &= !(1 << n);
            }
        }
        PrmDataType::BitArea(a, b) => {
            let mask = (((1u16 << (b - a + 1)) - 1) << a) as u8;
            data[at] = (data[at] & !mask) | (((v as u16) << a) as u8 & mask);
        }
    }
}

/// Copy `bytes` into `data` at `offset`, growing it; fails beyond the
/// Set_Prm limit.
fn write_at(
    data: &mut Vec<u8>,
    base: usize,
    offset: usize,
    bytes: &[u8],
) -> Result<(), SelectionError> {
    let end = base + offset + bytes.len();
    if end > MAX_USER_PRM_LEN {
        return Err(SelectionError::PrmTooLong { needed: end });
    }
    if data.len() < end {
        data.resize(end, 0);
    }
    data[base + offset..end].copy_from_slice(bytes);
    Ok(())
}

/// The value of the first `keyword = value` line of `lines` (the keyword
/// compared without regard to case; a line with an index such as
/// `Keyword(3) = …` does not match).
fn raw_value<'a>(lines: &'a [String], keyword: &str) -> Option<&'a str> {
    lines.iter().find_map(|l| {
        let (k, v) = l.split_once('=')?;
        k.trim().eq_ignore_ascii_case(keyword).then(|| v.trim())
    })
}

impl Module {
    /// The raw value of a module keyword the model keeps as text (in
    /// [`Module::other`]), e.g. `F_ParamDescCRC`.
    pub fn other_value(&self, keyword: &str) -> Option<&str> {
        raw_value(&self.other, keyword)
    }
}

impl Gsd {
    /// The raw value of a station keyword the model keeps as text (in
    /// [`Gsd::other`]: DP-V2, isochronous mode, I&M, PROFIsafe and
    /// master keywords, …), e.g. `other_value("Fail_Safe_required")`
    /// gives `Some("1")`.
    pub fn other_value(&self, keyword: &str) -> Option<&str> {
        raw_value(&self.other, keyword)
    }

    /// A boolean station keyword kept as text: `Some(true)` for a value
    /// other than 0, `None` when the file does not give it or the value is
    /// no number.
    pub fn other_flag(&self, keyword: &str) -> Option<bool> {
        let v = self.other_value(keyword)?;
        parse_int(v).map(|n| n != 0)
    }

    /// The DP-V1 alarm types the file declares (`Diagnostic_Alarm_supp`,
    /// `Process_Alarm_supp`, `Pull_Plug_Alarm_supp`, `Status_Alarm_supp`,
    /// `Update_Alarm_supp`, `Manufacturer_Specific_Alarm_supp`) as their
    /// enable bits of DPV1_Status_2; empty for a slave that is not
    /// `DPV1_Slave`.
    pub fn declared_alarms(&self) -> Dpv1Status2 {
        if !self.dpv1_slave {
            return Dpv1Status2::empty();
        }
        let mut bits = Dpv1Status2::empty();
        for (supp, e) in [
            (self.diagnostic_alarm_supp, AlarmEnable::Diagnostic),
            (self.process_alarm_supp, AlarmEnable::Process),
            (self.pull_plug_alarm_supp, AlarmEnable::PullPlug),
            (self.status_alarm_supp, AlarmEnable::Status),
            (self.update_alarm_supp, AlarmEnable::Update),
            (
                self.manufacturer_specific_alarm_supp,
                AlarmEnable::Manufacturer,
            ),
        ] {
            bits.set(e.bit(), supp);
        }
        bits
    }

    /// The Alarm_Mode a master asks for (DPV1_Status_3 b2-0): sequence
    /// mode with the most outstanding alarms `Alarm_Sequence_Mode_Count`
    /// allows (the largest of 2, 4, 8, 12, 16, 24, 32 not above it), else
    /// type mode (0, one alarm per type), which every DP-V1 slave with
    /// alarms supports.
    pub fn alarm_mode(&self) -> AlarmMode {
        let n = self.alarm_sequence_mode_count.unwrap_or(0);
        (1..=7u8)
            .rev()
            .map(AlarmMode)
            .find(|m| matches!(m.limit(), AlarmLimit::Total(t) if t <= n))
            .unwrap_or(AlarmMode(0))
    }

    /// `MaxTsdr_<baud>` in bit times, if the file gives it.
    pub fn max_tsdr(&self, baud: Baud) -> Option<u32> {
        self.baud_rates[baud_index(baud)].max_tsdr.map(u32::from)
    }

    /// Whether `<baud>_supp = 1`.
    pub fn supports_baud(&self, baud: Baud) -> bool {
        self.baud_rates[baud_index(baud)].supported
    }

    /// The supported baud rates, slowest first.
    pub fn supported_bauds(&self) -> Vec<Baud> {
        Baud::ALL
            .iter()
            .copied()
            .filter(|&b| self.supports_baud(b))
            .collect()
    }

    /// The module with exactly this name (the first, if several).
    pub fn module(&self, name: &str) -> Option<&Module> {
        self.modules.iter().find(|m| m.name == name)
    }

    /// The index of the module with exactly this name.
    pub fn module_index(&self, name: &str) -> Option<usize> {
        self.modules.iter().position(|m| m.name == name)
    }

    /// The index of the module named `name`: names match exactly (a
    /// module that is not in the file is never replaced by a similar
    /// one); the error names the closest module names.
    pub fn find_module_index(&self, name: &str) -> Result<usize, LookupError> {
        self.module_index(name)
            .ok_or_else(|| LookupError::NotFound {
                name: name.to_string(),
                suggestions: DidYouMean::new(name, self.modules.iter().map(|m| m.name.as_str())),
            })
    }

    /// The module named `name` (see
    /// [`find_module_index`](Self::find_module_index)).
    pub fn find_module(&self, name: &str) -> Result<&Module, LookupError> {
        self.find_module_index(name).map(|i| &self.modules[i])
    }

    /// A selection from module names (exact names).
    pub fn select<S: AsRef<str>>(&self, names: &[S]) -> Result<Vec<usize>, LookupError> {
        names
            .iter()
            .map(|n| self.find_module_index(n.as_ref()))
            .collect()
    }

    /// The selection a configurator starts from: for a modular station
    /// the `Preset` modules; for a compact station its first module.
    ///
    /// A compact station (no `Modular_Station = 1`) has one fixed
    /// configuration. Where such a file lists several modules they are
    /// normally alternatives (the PPO types of a drive, the classes of an
    /// encoder), of which the master configures exactly one; some files
    /// (pyprofibus's examples) mean all of them together, in file order.
    /// [`check_selection`](Self::check_selection) accepts both; name the
    /// module for any but the first.
    pub fn default_selection(&self) -> Vec<usize> {
        if self.modular_station {
            (0..self.modules.len())
                .filter(|&i| self.modules[i].preset)
                .collect()
        } else {
            (0..self.modules.len().min(1)).collect()
        }
    }

    /// The `ExtUserPrmData` block with this reference number (the first,
    /// if several).
    pub fn prm_definition(&self, reference: u16) -> Option<&ExtUserPrmData> {
        self.ext_user_prm_data
            .iter()
            .find(|p| p.reference == reference)
    }

    /// The `PrmText` block with this reference number.
    pub fn prm_text(&self, reference: u16) -> Option<&PrmText> {
        self.prm_texts.iter().find(|t| t.reference == reference)
    }

    /// The text of value `v` of parameter `p`, if it has one.
    pub fn value_text(&self, p: &ExtUserPrmData, v: i64) -> Option<&str> {
        let t = self.prm_text(p.prm_text_ref?)?;
        t.texts
            .iter()
            .find(|t| t.value == v)
            .map(|t| t.text.as_str())
    }

    /// `Unit_Diag_Bit(bit)` text.
    pub fn unit_diag_bit_text(&self, bit: u32) -> Option<&str> {
        self.unit_diag_bits
            .iter()
            .find(|t| t.bit == bit)
            .map(|t| t.text.as_str())
    }

    /// `Unit_Diag_Not_Bit(bit)` text.
    pub fn unit_diag_not_bit_text(&self, bit: u32) -> Option<&str> {
        self.unit_diag_not_bits
            .iter()
            .find(|t| t.bit == bit)
            .map(|t| t.text.as_str())
    }

    fn selected(&self, selection: &[usize]) -> Result<Vec<&Module>, SelectionError> {
        selection
            .iter()
            .map(|&i| {
                self.modules.get(i).ok_or(SelectionError::NoSuchModule {
                    index: i,
                    count: self.modules.len(),
                })
            })
            .collect()
    }

    /// Chk_Cfg bytes of a selection: the modules' identifier bytes in
    /// order.
    pub fn chk_cfg(&self, selection: &[usize]) -> Result<Vec<u8>, SelectionError> {
        let mut out = Vec::new();
        for m in self.selected(selection)? {
            m.io().map_err(|error| SelectionError::BadIdentifier {
                module: m.name.clone(),
                error,
            })?;
            out.extend_from_slice(&m.cfg);
        }
        Ok(out)
    }

    /// The User_Prm_Data bytes with every parameter at its default, and
    /// where the parameters are.
    fn prm_layout(
        &self,
        selection: &[usize],
    ) -> Result<(Vec<u8>, Vec<ParamInstance<'_>>), SelectionError> {
        let modules = self.selected(selection)?;
        // The definitions by reference number (the first of each), looked
        // up once per reference instead of a search through all of them.
        let mut defs: Vec<(u16, &ExtUserPrmData)> = self
            .ext_user_prm_data
            .iter()
            .map(|p| (p.reference, p))
            .collect();
        defs.sort_by_key(|&(r, _)| r);
        defs.dedup_by_key(|&mut (r, _)| r);
        let definition = |reference: u16| {
            defs.binary_search_by_key(&reference, |&(r, _)| r)
                .ok()
                .map(|i| defs[i].1)
        };
        let mut data = Vec::new();
        let mut params = Vec::new();
        let mut add_refs = |data: &mut Vec<u8>,
                            base: usize,
                            limit: Option<usize>,
                            refs: &[PrmRef],
                            position: Option<usize>|
         -> Result<(), SelectionError> {
            for r in refs {
                let Some(def) = definition(r.reference) else {
                    continue;
                };
                let size = def.data_type.size();
                if limit.is_some_and(|l| r.offset as usize + size > l) {
                    continue;
                }
                let offset = base + r.offset as usize;
                if offset + size > MAX_USER_PRM_LEN {
                    return Err(SelectionError::PrmTooLong {
                        needed: offset + size,
                    });
                }
                if data.len() < offset + size {
                    data.resize(offset + size, 0);
                }
                params.push(ParamInstance {
                    position,
                    offset,
                    definition: def,
                });
            }
            Ok(())
        };
        if self.ext_user_prm_data_const.is_empty() && self.ext_user_prm_data_ref.is_empty() {
            data = self.user_prm_data.clone().unwrap_or_default();
            if let Some(n) = self.user_prm_data_len {
                data.resize(n as usize, 0);
            }
            if data.len() > MAX_USER_PRM_LEN {
                return Err(SelectionError::PrmTooLong { needed: data.len() });
            }
        } else {
            for c in &self.ext_user_prm_data_const {
                write_at(&mut data, 0, c.offset as usize, &c.data)?;
            }
            add_refs(&mut data, 0, None, &self.ext_user_prm_data_ref, None)?;
        }
        for (pos, m) in modules.iter().enumerate() {
            let base = data.len();
            let limit = m.ext_module_prm_data_len.map(usize::from);
            let mut block = vec![0u8; limit.unwrap_or(0)];
            if base + block.len() > MAX_USER_PRM_LEN {
                return Err(SelectionError::PrmTooLong {
                    needed: base + block.len(),
                });
            }
            for c in &m.ext_user_prm_data_const {
                let bytes = match limit {
                    Some(l) => &c.data[..c.data.len().min(l.saturating_sub(c.offset as usize))],
                    None => &c.data[..],
                };
                if bytes.is_empty() {
                    continue;
                }
                if base + c.offset as usize + bytes.len() > MAX_USER_PRM_LEN {
                    return Err(SelectionError::PrmTooLong {
                        needed: base + c.offset as usize + bytes.len(),
                    });
                }
                let end = c.offset as usize + bytes.len();
                if block.len() < end {
                    block.resize(end, 0);
                }
                block[c.offset as usize..end].copy_from_slice(bytes);
            }
            data.extend_from_slice(&block);
            add_refs(&mut data, base, limit, &m.ext_user_prm_data_ref, Some(pos))?;
        }
        for p in &params {
            put(
                &mut data,
                p.offset,
                p.definition.data_type,
                p.definition.default,
            );
        }
        Ok((data, params))
    }

    /// The parameters of a selection, in User_Prm_Data order of their
    /// references (station parameters first).
    pub fn parameters(
        &self,
        selection: &[usize],
    ) -> Result<Vec<ParamInstance<'_>>, SelectionError> {
        self.prm_layout(selection).map(|(_, p)| p)
    }

    /// The User_Prm_Data of a selection (without the 7 standard Set_Prm
    /// bytes), with the named parameter values and every other parameter
    /// at its default.
    pub fn user_prm_data(
        &self,
        selection: &[usize],
        values: &[PrmValue],
    ) -> Result<Vec<u8>, SelectionError> {
        let (mut data, params) = self.prm_layout(selection)?;
        for v in values {
            let want = normalize(&v.name);
            let mut hit = false;
            for p in &params {
                if normalize(&p.definition.name) != want
                    || v.position.is_some_and(|pos| p.position != Some(pos))
                {
                    continue;
                }
                hit = true;
                let def = p.definition;
                let value = match &v.value {
                    PrmInput::Int(i) => *i,
                    PrmInput::Text(t) => {
                        let texts = def.prm_text_ref.and_then(|r| self.prm_text(r));
                        let t_norm = normalize(t);
                        match texts
                            .and_then(|ts| ts.texts.iter().find(|x| normalize(&x.text) == t_norm))
                        {
                            Some(x) => x.value,
                            None => {
                                return Err(SelectionError::UnknownText {
                                    name: def.name.clone(),
                                    text: t.clone(),
                                    texts: texts
                                        .map(|ts| ts.texts.iter().map(|x| x.text.clone()).collect())
                                        .unwrap_or_default(),
                                });
                            }
                        }
                    }
                };
                let (lo, hi) = def.data_type.limits();
                if value < lo || value > hi || !def.allowed.contains(value) {
                    let allowed = match &def.allowed {
                        Allowed::Any => format!("{lo}..={hi} ({})", def.data_type.gsd_name()),
                        a => a.to_string(),
                    };
                    return Err(SelectionError::NotAllowed {
                        name: def.name.clone(),
                        value,
                        allowed,
                    });
                }
                put(&mut data, p.offset, def.data_type, value);
            }
            if !hit {
                let names: Vec<&str> = params.iter().map(|p| p.definition.name.as_str()).collect();
                let suggestions = DidYouMean::new(&v.name, names.iter().copied());
                return Err(SelectionError::UnknownParameter {
                    name: v.name.clone(),
                    position: v.position,
                    suggestions,
                });
            }
        }
        Ok(data)
    }

    /// Everything wrong with a selection: module count, I/O lengths,
    /// configuration and parameter lengths against the file's `Max_*`
    /// keywords and the protocol's limits. Empty when the selection is
    /// fine.
    pub fn check_selection(&self, selection: &[usize]) -> Vec<Problem> {
        let modules = match self.selected(selection) {
            Ok(m) => m,
            Err(SelectionError::NoSuchModule { index, count }) => {
                return vec![Problem::NoSuchModule { index, count }];
            }
            Err(e) => return vec![Problem::Selection(e)],
        };
        let mut problems = Vec::new();
        if modules.is_empty() && self.modular_station {
            problems.push(Problem::Empty);
        }
        let every: Vec<usize> = (0..self.modules.len()).collect();
        if !self.modular_station && selection.len() != 1 && selection != every.as_slice() {
            // Name a few modules; a long list helps nobody.
            const NAMED: usize = 6;
            let mut names: Vec<String> = self
                .modules
                .iter()
                .take(NAMED)
                .map(|m| format!("`{}`", m.name))
                .collect();
            if self.modules.len() > NAMED {
                names.push(format!("… {} in all", self.modules.len()));
            }
            let expected = match self.modules.len() {
                0 => "no module (the file defines none)".to_string(),
                1 => names[0].clone(),
                _ => format!(
                    "one of its modules ({}), or all of them in file order",
                    names.join(", ")
                ),
            };
            // The modules' sizes would be added for a configuration the
            // station cannot have: that is the one problem.
            return vec![Problem::FixedConfiguration { expected }];
        }
        if let Some(max) = self.max_module.map(usize::from) {
            if modules.len() > max {
                problems.push(Problem::TooManyModules {
                    count: modules.len(),
                    max,
                });
            }
        }
        let (mut input, mut output, mut cfg_len) = (0, 0, 0);
        for m in &modules {
            cfg_len += m.cfg.len();
            match m.io() {
                Ok(t) => {
                    input += t.input_bytes;
                    output += t.output_bytes;
                }
                Err(error) => problems.push(Problem::Selection(SelectionError::BadIdentifier {
                    module: m.name.clone(),
                    error,
                })),
            }
        }
        // The limit of one direction (the GSD key's, else the protocol's)
        // and where it comes from, when `bytes` exceed it.
        let exceeded = |bytes: usize, v: Option<u8>, key: &'static str| {
            let (max, limit) = match v {
                Some(v) if usize::from(v) < MAX_IO_LEN => (usize::from(v), key),
                _ => (MAX_IO_LEN, "the protocol's limit"),
            };
            (bytes > max).then_some((max, limit))
        };
        if let Some((max, limit)) = exceeded(input, self.max_input_len, "Max_Input_Len") {
            let bytes = input;
            problems.push(Problem::InputTooLong { bytes, max, limit });
        }
        if let Some((max, limit)) = exceeded(output, self.max_output_len, "Max_Output_Len") {
            let bytes = output;
            problems.push(Problem::OutputTooLong { bytes, max, limit });
        }
        if let Some(max) = self.max_data_len.map(usize::from) {
            if input + output > max {
                problems.push(Problem::DataTooLong {
                    bytes: input + output,
                    max,
                });
            }
        }
        if cfg_len > MAX_CFG_LEN {
            problems.push(Problem::CfgTooLong { bytes: cfg_len });
        }
        match self.user_prm_data(selection, &[]) {
            Ok(prm) => {
                let (max, lim) = match self.max_user_prm_data_len {
                    Some(m) if usize::from(m) < MAX_USER_PRM_LEN => {
                        (usize::from(m), "Max_User_Prm_Data_Len")
                    }
                    _ => (MAX_USER_PRM_LEN, "Set_Prm's limit"),
                };
                if prm.len() > max {
                    problems.push(Problem::PrmTooLong {
                        bytes: prm.len(),
                        max,
                        limit: lim,
                    });
                }
            }
            Err(e) => problems.push(Problem::Selection(e)),
        }
        problems
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn module_names_match_exactly() {
        let mut g = Gsd::default();
        for (name, id) in [
            ("1 word in/out", 0x70),
            ("2 words in/out", 0x71),
            ("4 words in/out", 0x73),
        ] {
            g.modules.push(Module {
                name: name.into(),
                cfg: vec![id],
                ..Module::default()
            });
        }
        assert_eq!(g.find_module_index("2 words in/out"), Ok(1));
        // Never a similar module instead: the closest names in the error.
        for near in ["3 words in/out", "2 Words in/out", "2 words"] {
            let e = g.find_module_index(near).unwrap_err();
            assert!(
                e.to_string().contains("did you mean `2 words in/out`"),
                "{e}"
            );
        }
        let e = g
            .find_module_index("3 words in/out")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "no module named `3 words in/out`; did you mean `2 words in/out` or `4 words in/out`?"
        );
        let e = g.find_module_index("temperature").unwrap_err().to_string();
        assert_eq!(e, "no module named `temperature`");
    }

    #[test]
    fn put_types() {
        let mut d = [0u8; 4];
        put(&mut d, 0, PrmDataType::Signed16, -100);
        assert_eq!(&d[..2], &[0xFF, 0x9C]);
        put(&mut d, 0, PrmDataType::Unsigned32, 0x0102_0304);
        assert_eq!(d, [1, 2, 3, 4]);
        let mut d = [0xFFu8];
        put(&mut d, 0, PrmDataType::BitArea(2, 4), 0b010);
        assert_eq!(d[0], 0b1110_1011);
        put(&mut d, 0, PrmDataType::Bit(0), 0);
        assert_eq!(d[0], 0b1110_1010);
        put(&mut d, 0, PrmDataType::BitArea(0, 7), 0x5A);
        assert_eq!(d[0], 0x5A);
    }

    #[test]
    fn prm_value_syntax() {
        let v: PrmValue = "Mode=2".parse().unwrap();
        assert_eq!(
            (v.position, v.name.as_str(), v.value),
            (None, "Mode", PrmInput::Int(2))
        );
        let v: PrmValue = "3: Offset = -0x10".parse().unwrap();
        assert_eq!((v.position, v.value), (Some(3), PrmInput::Int(-16)));
        let v: PrmValue = "Mode=fast".parse().unwrap();
        assert_eq!(v.value, PrmInput::Text("fast".into()));
        assert!("Mode".parse::<PrmValue>().is_err());
        assert!("=3".parse::<PrmValue>().is_err());
    }
}
