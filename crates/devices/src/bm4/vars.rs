//! The variable table of the BM4-O-PRO-01: what the manual's
//! "PROFIBUS-PLC-Slave Konfigurator" defines (L757-1067) and the device's
//! configuration follows from. The TOML format is described in
//! `crates/devices/data/bm4_example_vars.toml`.
//!
//! Each variable becomes one module with a 4-byte special-format
//! identifier (BM4 manual L869, GSD L2389-2397):
//!
//! | byte | meaning |
//! |---|---|
//! | 1 | `0x42` INPUT (one input length byte and 2 manufacturer bytes follow) or `0x82` OUTPUT |
//! | 2 | length byte: bit 7 consistent, bit 6 words, bits 5..0 length − 1 in bytes or words |
//! | 3 | element size code: 0 byte, 1 word, 2 double word (an inference from the listings, the manual does not name it) |
//! | 4 | parameter number (PNU) = position in the table, from 0 |
//!
//! BOOL, SINT, USINT and BYTE take one byte per element; INT, UINT and
//! WORD one word; DINT, UDINT, DWORD and REAL two words. A BOOL takes a
//! whole byte (the manual gives no bit packing).

use profibus_dp::config::gsd::{Gsd, Module};
use serde::Deserialize;
use std::fmt;

/// The IEC 61131-3 types the configurator allows (L888).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IecType {
    /// BOOL (one byte, 0 or 1).
    Bool,
    /// SINT.
    Sint,
    /// USINT.
    Usint,
    /// INT.
    Int,
    /// UINT.
    Uint,
    /// DINT.
    Dint,
    /// UDINT.
    Udint,
    /// BYTE.
    Byte,
    /// WORD.
    Word,
    /// DWORD.
    Dword,
    /// REAL (IEEE 754 single).
    Real,
}

impl IecType {
    /// Every type, in the manual's order.
    pub const ALL: [IecType; 11] = [
        IecType::Bool,
        IecType::Sint,
        IecType::Usint,
        IecType::Int,
        IecType::Uint,
        IecType::Dint,
        IecType::Udint,
        IecType::Byte,
        IecType::Word,
        IecType::Dword,
        IecType::Real,
    ];

    /// The type's name.
    pub fn name(self) -> &'static str {
        match self {
            IecType::Bool => "BOOL",
            IecType::Sint => "SINT",
            IecType::Usint => "USINT",
            IecType::Int => "INT",
            IecType::Uint => "UINT",
            IecType::Dint => "DINT",
            IecType::Udint => "UDINT",
            IecType::Byte => "BYTE",
            IecType::Word => "WORD",
            IecType::Dword => "DWORD",
            IecType::Real => "REAL",
        }
    }

    /// Bytes per element on the bus.
    pub fn size(self) -> usize {
        match self {
            IecType::Bool | IecType::Sint | IecType::Usint | IecType::Byte => 1,
            IecType::Int | IecType::Uint | IecType::Word => 2,
            _ => 4,
        }
    }

    /// The size code of the identifier's 3rd byte.
    pub fn size_code(self) -> u8 {
        match self.size() {
            1 => 0,
            2 => 1,
            _ => 2,
        }
    }

    /// Lowest and highest value (REAL: the bit pattern, any).
    pub fn range(self) -> (i64, i64) {
        match self {
            IecType::Bool => (0, 1),
            IecType::Sint => (-128, 127),
            IecType::Usint | IecType::Byte => (0, 255),
            IecType::Int => (-32768, 32767),
            IecType::Uint | IecType::Word => (0, 65535),
            IecType::Dint => (i32::MIN as i64, i32::MAX as i64),
            IecType::Udint | IecType::Dword | IecType::Real => (0, u32::MAX as i64),
        }
    }

    /// Whether the type is signed (SINT, INT, DINT).
    pub fn signed(self) -> bool {
        matches!(self, IecType::Sint | IecType::Int | IecType::Dint)
    }
}

/// A type name that is no IEC type of the module.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown type `{0}` (BOOL SINT USINT INT UINT DINT UDINT BYTE WORD DWORD REAL)")]
pub struct UnknownType(pub String);

impl std::str::FromStr for IecType {
    type Err = UnknownType;
    fn from_str(s: &str) -> Result<IecType, UnknownType> {
        IecType::ALL
            .into_iter()
            .find(|t| t.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| UnknownType(s.to_string()))
    }
}

/// Direction of a variable's module.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum VarModule {
    /// INPUT: an actual value, slave → master (read only for PKW).
    Input,
    /// OUTPUT: a setpoint, master → slave.
    Output,
}

/// One variable of the table.
#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    /// Name (also its GSD module name).
    pub name: String,
    /// IEC type.
    pub ty: IecType,
    /// INPUT or OUTPUT module.
    pub module: VarModule,
    /// Consistent over the whole module.
    pub consistent: bool,
    /// Array length (1 = a single variable).
    pub length: usize,
    /// Start values, one per element (REAL: the value as a number).
    pub initial: Vec<f64>,
}

impl Variable {
    /// Bytes on the bus.
    pub fn bytes(&self) -> usize {
        self.length * self.ty.size()
    }

    /// The variable is an array.
    pub fn is_array(&self) -> bool {
        self.length > 1
    }

    /// The length byte (identifier byte 2).
    pub fn length_byte(&self) -> u8 {
        let words = self.ty.size() >= 2;
        let units = if words {
            self.bytes() / 2
        } else {
            self.bytes()
        };
        (self.consistent as u8) << 7 | (words as u8) << 6 | (units as u8 - 1)
    }

    /// The module's identifier with parameter number `pnu`.
    pub fn identifier(&self, pnu: u8) -> [u8; 4] {
        let first = match self.module {
            VarModule::Input => 0x42,
            VarModule::Output => 0x82,
        };
        [first, self.length_byte(), self.ty.size_code(), pnu]
    }

    /// The variable as one compact identifier byte (for the "all
    /// modules" module), without consistency: `None` when more than 16
    /// bytes or words.
    pub fn compact_identifier(&self) -> Option<u8> {
        let words = self.ty.size() >= 2;
        let units = if words {
            self.bytes() / 2
        } else {
            self.bytes()
        };
        if units == 0 || units > 16 {
            return None;
        }
        let dir = match self.module {
            VarModule::Input => 0x10,
            VarModule::Output => 0x20,
        };
        Some((words as u8) << 6 | dir | (units as u8 - 1))
    }

    /// Encode element value `v` (big-endian, Motorola order on the bus).
    pub fn encode(&self, v: f64, out: &mut [u8]) {
        let n = self.ty.size();
        if self.ty == IecType::Real {
            out[..4].copy_from_slice(&(v as f32).to_be_bytes());
            return;
        }
        let x = v as i64 as u64;
        let b = x.to_be_bytes();
        out[..n].copy_from_slice(&b[8 - n..]);
    }
}

/// Why a variable table cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct VarsError(pub String);

/// The variable table; see the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct VarTable {
    /// The variables; the index is the parameter number.
    pub vars: Vec<Variable>,
    /// Offer the default GSD's "all modules" module (all variables in one
    /// compact configuration, in table order).
    pub all_modules: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTable {
    #[serde(default)]
    all_modules: bool,
    #[serde(default)]
    variable: Vec<RawVar>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVar {
    name: String,
    #[serde(rename = "type")]
    ty: String,
    module: String,
    #[serde(default)]
    consistent: bool,
    #[serde(default)]
    initial: Option<toml::Value>,
    #[serde(default)]
    length: Option<usize>,
}

/// Most variables: the parameter number is one byte (identifier byte 4),
/// and the GSD allows 64 modules (Max_Module=64), one of them PKW.
pub const MAX_VARIABLES: usize = 63;

const EXAMPLE: &str = include_str!("../../data/bm4_example_vars.toml");
const DEFAULT: &str = include_str!("../../data/bm4_default_vars.toml");

impl VarTable {
    /// The manual's example table (MyGSDFile.gsd).
    pub fn example() -> VarTable {
        VarTable::parse(EXAMPLE).expect("built-in example table")
    }

    /// The default configuration (BM4OPRO1.GSD).
    pub fn default_table() -> VarTable {
        VarTable::parse(DEFAULT).expect("built-in default table")
    }

    /// Read a table from TOML text.
    pub fn parse(text: &str) -> Result<VarTable, VarsError> {
        let raw: RawTable = toml::from_str(text).map_err(|e| VarsError(e.to_string()))?;
        if raw.variable.is_empty() {
            return Err(VarsError("the table has no [[variable]]".into()));
        }
        if raw.variable.len() > MAX_VARIABLES {
            return Err(VarsError(format!(
                "{} variables, at most {MAX_VARIABLES}",
                raw.variable.len()
            )));
        }
        let mut vars: Vec<Variable> = Vec::with_capacity(raw.variable.len());
        for (i, r) in raw.variable.into_iter().enumerate() {
            let at = |m: String| VarsError(format!("variable {i} (`{}`): {m}", r.name));
            if r.name.trim().is_empty() || r.name.contains('"') {
                return Err(at("the name must be non-empty and without quotes".into()));
            }
            if vars.iter().any(|v| v.name == r.name) {
                return Err(at("the name is used twice".into()));
            }
            let ty: IecType = r.ty.parse().map_err(|e: UnknownType| at(e.to_string()))?;
            let module = match r.module.to_ascii_uppercase().as_str() {
                "INPUT" => VarModule::Input,
                "OUTPUT" => VarModule::Output,
                other => return Err(at(format!("module `{other}` is not INPUT or OUTPUT"))),
            };
            let length = r.length.unwrap_or(1);
            let units = if ty.size() >= 2 {
                length * ty.size() / 2
            } else {
                length
            };
            if length == 0 || units > 64 {
                return Err(at(format!(
                    "length {length} does not fit one module (1..=64 bytes or words)"
                )));
            }
            let initial = match r.initial {
                None => vec![0.0; length],
                Some(toml::Value::Array(a)) if a.len() == length => a
                    .iter()
                    .map(|x| value(x).ok_or_else(|| at("initial values must be numbers".into())))
                    .collect::<Result<_, _>>()?,
                Some(toml::Value::Array(a)) => {
                    return Err(at(format!(
                        "{} initial values for {length} elements",
                        a.len()
                    )))
                }
                Some(x) => {
                    vec![value(&x).ok_or_else(|| at("`initial` must be a number".into()))?; length]
                }
            };
            let (lo, hi) = ty.range();
            for v in &initial {
                if ty != IecType::Real && (v.fract() != 0.0 || *v < lo as f64 || *v > hi as f64) {
                    return Err(at(format!(
                        "initial value {v} outside {}'s range {lo}..={hi}",
                        ty.name()
                    )));
                }
            }
            vars.push(Variable {
                name: r.name,
                ty,
                module,
                consistent: r.consistent,
                length,
                initial,
            });
        }
        let t = VarTable {
            vars,
            all_modules: raw.all_modules,
        };
        if t.all_modules && t.all_modules_cfg().is_none() {
            return Err(VarsError(
                "`all_modules` needs every variable to fit a compact identifier (at most 16 bytes or words)"
                    .into(),
            ));
        }
        Ok(t)
    }

    /// The identifier of the variable with parameter number `pnu`.
    pub fn identifier(&self, pnu: usize) -> [u8; 4] {
        self.vars[pnu].identifier(pnu as u8)
    }

    /// The "all modules" configuration: outputs first, then inputs, each
    /// in table order (as in BM4OPRO1.GSD L2260), with the variables'
    /// parameter numbers in that order.
    pub fn all_modules_cfg(&self) -> Option<(Vec<u8>, Vec<usize>)> {
        let mut order: Vec<usize> = (0..self.vars.len())
            .filter(|&i| self.vars[i].module == VarModule::Output)
            .collect();
        order.extend((0..self.vars.len()).filter(|&i| self.vars[i].module == VarModule::Input));
        let cfg = order
            .iter()
            .map(|&i| self.vars[i].compact_identifier())
            .collect::<Option<Vec<u8>>>()?;
        Some((cfg, order))
    }

    /// Input and output bytes of all variables.
    pub fn totals(&self) -> (usize, usize) {
        let sum = |m| {
            self.vars
                .iter()
                .filter(|v| v.module == m)
                .map(Variable::bytes)
                .sum()
        };
        (sum(VarModule::Input), sum(VarModule::Output))
    }

    /// The GSD the configurator generates for this table: the default
    /// file's identity, timing and features, the PKW module ("Bedarfsdaten
    /// PKW", 0x73) and one module per variable named after it
    /// (MyGSDFile.gsd L2385-2397). The length limits include the PKW
    /// module's 8 bytes each way (the manual's example file leaves them
    /// out, so a master would refuse PKW together with all variables;
    /// an ambiguity of the manual), capped at 244.
    pub fn gsd(&self, default_gsd: &Gsd) -> Gsd {
        let mut g = default_gsd.clone();
        g.modules.clear();
        g.modules.push(Module {
            name: "Bedarfsdaten PKW".into(),
            cfg: vec![crate::pkw::PKW_MODULE],
            ..Module::default()
        });
        if let Some((cfg, _)) = self.all_modules_cfg().filter(|_| self.all_modules) {
            g.modules.push(Module {
                name: "all modules".into(),
                cfg,
                ..Module::default()
            });
        }
        for (i, v) in self.vars.iter().enumerate() {
            g.modules.push(Module {
                name: v.name.clone(),
                cfg: v.identifier(i as u8).to_vec(),
                ..Module::default()
            });
        }
        let (i, o) = self.totals();
        g.max_input_len = Some((i + 8).min(244) as u8);
        g.max_output_len = Some((o + 8).min(244) as u8);
        g.max_data_len = Some((i + o + 16).min(488) as u16);
        g.max_module = Some(64);
        g
    }
}

fn value(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(f) => Some(*f),
        toml::Value::Boolean(b) => Some(*b as u8 as f64),
        _ => None,
    }
}

impl fmt::Display for Variable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let dir = match self.module {
            VarModule::Input => "INPUT",
            VarModule::Output => "OUTPUT",
        };
        if self.is_array() {
            write!(
                f,
                "{}: ARRAY[0..{}] OF {} {dir}",
                self.name,
                self.length - 1,
                self.ty.name()
            )
        } else {
            write!(f, "{}: {} {dir}", self.name, self.ty.name())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_identifiers_are_the_manuals() {
        let t = VarTable::example();
        let ids: Vec<[u8; 4]> = (0..t.vars.len()).map(|i| t.identifier(i)).collect();
        assert_eq!(
            ids,
            [
                [0x42, 0xC1, 0x02, 0x00],
                [0x42, 0xC1, 0x02, 0x01],
                [0x82, 0xC1, 0x02, 0x02],
                [0x82, 0xC0, 0x01, 0x03],
                [0x42, 0xC1, 0x02, 0x04],
            ]
        );
        assert_eq!(t.totals(), (12, 6));
        assert_eq!(t.vars[4].initial, vec![3000.0]);
    }

    #[test]
    fn default_identifiers_are_the_default_gsds() {
        let t = VarTable::default_table();
        let ids: Vec<[u8; 4]> = (0..8).map(|i| t.identifier(i)).collect();
        assert_eq!(ids[0], [0x82, 0x0F, 0x00, 0x00]);
        assert_eq!(ids[1], [0x82, 0x4F, 0x01, 0x01]);
        assert_eq!(ids[2], [0x82, 0x4F, 0x02, 0x02]);
        assert_eq!(ids[7], [0x42, 0x4F, 0x02, 0x07]);
        let (cfg, order) = t.all_modules_cfg().unwrap();
        assert_eq!(cfg, [0x2F, 0x6F, 0x6F, 0x6F, 0x1F, 0x5F, 0x5F, 0x5F]);
        assert_eq!(order, (0..8).collect::<Vec<_>>());
    }

    #[test]
    fn bad_tables_are_refused_with_the_variable_named() {
        let e = VarTable::parse("[[variable]]\nname=\"x\"\ntype=\"LREAL\"\nmodule=\"INPUT\"\n")
            .unwrap_err();
        assert!(e.0.contains("`x`") && e.0.contains("unknown type"), "{e}");
        let e = VarTable::parse(
            "[[variable]]\nname=\"x\"\ntype=\"USINT\"\nmodule=\"INPUT\"\ninitial=300\n",
        )
        .unwrap_err();
        assert!(e.0.contains("outside"), "{e}");
        let e = VarTable::parse(
            "[[variable]]\nname=\"x\"\ntype=\"DWORD\"\nmodule=\"OUTPUT\"\nlength=33\n",
        )
        .unwrap_err();
        assert!(e.0.contains("does not fit"), "{e}");
        assert!(VarTable::parse("").is_err());
        assert!(
            VarTable::parse("[[variable]]\nname=\"x\"\ntype=\"INT\"\nmodule=\"IN\"\n").is_err()
        );
    }

    #[test]
    fn encode_is_motorola_order() {
        let mut t = VarTable::example();
        t.vars[4].ty = IecType::Dint;
        let mut b = [0u8; 4];
        t.vars[4].encode(-2.0, &mut b);
        assert_eq!(b, [0xFF, 0xFF, 0xFF, 0xFE]);
        t.vars[4].ty = IecType::Real;
        t.vars[4].encode(1.0, &mut b);
        assert_eq!(b, [0x3F, 0x80, 0, 0]);
    }
}
