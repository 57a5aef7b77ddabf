//! The emulated V controller's parameter set (PKW parameter numbers
//! 0..999) and the Omega's DINT array (1000..2047), from a TOML table;
//! the default is `crates/devices/data/omega_vparams.toml` (its header
//! describes the format).

use serde::Deserialize;

/// Display format of a parameter (attribute bits 8..11, Omega manual
/// L948-954).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Display {
    /// 0000 binary.
    Bin,
    /// 0001 decimal.
    Dec,
    /// 0010 hexadecimal.
    Hex,
    /// 0100 floating point without exponent.
    Norm,
    /// 0101 floating point with fixed exponent.
    Fix,
    /// 0110 scientific.
    Sci,
    /// 0111 engineering.
    Eng,
    /// 1000 ASCII.
    Ascii,
}

impl Display {
    /// The 4-bit code.
    pub fn code(self) -> u16 {
        match self {
            Display::Bin => 0,
            Display::Dec => 1,
            Display::Hex => 2,
            Display::Norm => 4,
            Display::Fix => 5,
            Display::Sci => 6,
            Display::Eng => 7,
            Display::Ascii => 8,
        }
    }

    fn parse(s: &str) -> Option<Display> {
        Some(match s.to_ascii_uppercase().as_str() {
            "BIN" => Display::Bin,
            "DEC" => Display::Dec,
            "HEX" => Display::Hex,
            "NORM" => Display::Norm,
            "FIX" => Display::Fix,
            "SCI" => Display::Sci,
            "ENG" => Display::Eng,
            "ASCII" => Display::Ascii,
            _ => return None,
        })
    }
}

/// One V-controller parameter.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Parameter {
    /// Parameter number 0..=999.
    pub pnu: u16,
    /// Name.
    pub name: String,
    /// Double word (else word).
    pub dword: bool,
    /// Signed integer.
    pub signed: bool,
    /// Lowest value.
    pub min: i64,
    /// Highest value.
    pub max: i64,
    /// Value at power-on.
    pub default: i64,
    /// Write-protected.
    pub protected: bool,
    /// Stored in the data record.
    pub store: bool,
    /// Display format.
    pub display: Display,
    /// Positions after the comma.
    pub decimals: u8,
}

impl Parameter {
    /// The attribute word (PBE element 1, L948-954): bits 0-1 length
    /// (01 = 2 bytes, 10 = 4 bytes), bits 2-3 type (00 SIGNED, 01
    /// UNSIGNED), bits 4-5 FIXED (one element), bits 6-7 DATA, bits 8-11
    /// display, bits 12-15 decimals.
    pub fn attribute(&self) -> u16 {
        let len = if self.dword { 0b10 } else { 0b01 };
        let ty = if self.signed { 0b00 } else { 0b01 };
        len | ty << 2 | self.display.code() << 8 | (self.decimals as u16 & 0xF) << 12
    }

    /// The info word (PBE element 2, L960-963): bits 0-2 write protection
    /// (001 protected), bit 3 STORE.
    pub fn info(&self) -> u16 {
        self.protected as u16 | (self.store as u16) << 3
    }

    /// The value as it goes into PWE (two's complement, 16 or 32 bits).
    pub fn raw(&self, v: i64) -> u32 {
        if self.dword {
            v as u32
        } else {
            v as u16 as u32
        }
    }

    /// A received raw value as a number of this parameter's type.
    pub fn from_raw(&self, raw: u32) -> i64 {
        match (self.dword, self.signed) {
            (true, true) => raw as i32 as i64,
            (true, false) => raw as i64,
            (false, true) => raw as u16 as i16 as i64,
            (false, false) => raw as u16 as i64,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    parameter: Vec<RawParam>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParam {
    pnu: u16,
    name: String,
    format: String,
    #[serde(default)]
    signed: bool,
    min: i64,
    max: i64,
    #[serde(default)]
    default: i64,
    #[serde(default)]
    protected: bool,
    #[serde(default)]
    store: bool,
    #[serde(default = "dec")]
    display: String,
    #[serde(default)]
    decimals: u8,
    #[serde(default)]
    #[allow(dead_code)]
    source: Option<String>,
}

fn dec() -> String {
    "DEC".into()
}

/// The default table, as shipped.
pub const DEFAULT_TABLE: &str = include_str!("../../data/omega_vparams.toml");

/// The parameters the Omega manual names, which every table must have
/// (P003, P041/P042, P126, P127, P218, P247/P248).
pub const REQUIRED: [u16; 8] = [3, 41, 42, 126, 127, 218, 247, 248];

/// A V-controller parameter table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamTable {
    /// The parameters, by number.
    pub params: Vec<Parameter>,
}

/// Why a parameter table cannot be used: the parameter and what is
/// wrong, in words.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ParamsError(pub String);

impl ParamTable {
    /// The shipped default table.
    pub fn default_table() -> ParamTable {
        ParamTable::parse(DEFAULT_TABLE).expect("built-in parameter table")
    }

    /// Read a table from TOML text; the error names the parameter and
    /// what is wrong.
    pub fn parse(text: &str) -> Result<ParamTable, ParamsError> {
        let raw: RawFile = toml::from_str(text).map_err(|e| ParamsError(e.to_string()))?;
        let mut params: Vec<Parameter> = vec![];
        for r in raw.parameter {
            let at = |m: String| ParamsError(format!("parameter P{:03} `{}`: {m}", r.pnu, r.name));
            if r.pnu > 999 {
                return Err(at(
                    "numbers above 999 belong to the Omega's own array".into()
                ));
            }
            if params.iter().any(|p| p.pnu == r.pnu) {
                return Err(at("the number is used twice".into()));
            }
            let dword = match r.format.as_str() {
                "word" => false,
                "dword" => true,
                f => return Err(at(format!("format `{f}` is not word or dword"))),
            };
            let (lo, hi): (i64, i64) = match (dword, r.signed) {
                (false, false) => (0, 0xFFFF),
                (false, true) => (-0x8000, 0x7FFF),
                (true, false) => (0, 0xFFFF_FFFF),
                (true, true) => (i32::MIN as i64, i32::MAX as i64),
            };
            if !(lo <= r.min && r.min <= r.max && r.max <= hi) {
                return Err(at(format!(
                    "min {} / max {} do not fit {lo}..={hi}",
                    r.min, r.max
                )));
            }
            if r.default < r.min || r.default > r.max {
                return Err(at(format!("default {} outside min/max", r.default)));
            }
            let display = Display::parse(&r.display)
                .ok_or_else(|| at(format!("display `{}` unknown", r.display)))?;
            if r.decimals > 15 {
                return Err(at("decimals must be 0..=15".into()));
            }
            params.push(Parameter {
                pnu: r.pnu,
                name: r.name,
                dword,
                signed: r.signed,
                min: r.min,
                max: r.max,
                default: r.default,
                protected: r.protected,
                store: r.store,
                display,
                decimals: r.decimals,
            });
        }
        for n in REQUIRED {
            if !params.iter().any(|p| p.pnu == n) {
                return Err(ParamsError(format!(
                    "the table lacks P{n:03}, which the manual describes (needed: P003, P041, P042, P126, P127, P218, P247, P248)"
                )));
            }
        }
        params.sort_by_key(|p| p.pnu);
        Ok(ParamTable { params })
    }

    /// Parameter `pnu`.
    pub fn get(&self, pnu: u16) -> Option<&Parameter> {
        self.params
            .binary_search_by_key(&pnu, |p| p.pnu)
            .ok()
            .map(|i| &self.params[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_table_has_the_manuals_parameters() {
        let t = ParamTable::default_table();
        let p3 = t.get(3).unwrap();
        assert_eq!(p3.default, 0x64);
        let p126 = t.get(126).unwrap();
        assert_eq!(p126.max, 0xF);
        assert!(t.get(218).unwrap().dword && t.get(218).unwrap().protected);
        assert!(!t.get(127).unwrap().dword);
        // P127: word (01), unsigned (01 << 2), BIN (0), info: STORE.
        assert_eq!(t.get(127).unwrap().attribute(), 0x0005);
        assert_eq!(t.get(127).unwrap().info(), 0x0008);
        // P010: dword (10), signed, FIX (5), 1 decimal.
        assert_eq!(t.get(10).unwrap().attribute(), 0x1502);
        assert_eq!(t.get(218).unwrap().info(), 0x0001);
    }

    #[test]
    fn bad_tables_name_the_parameter() {
        let e = ParamTable::parse(
            "[[parameter]]\npnu = 5\nname = \"x\"\nformat = \"word\"\nmin = 0\nmax = 70000\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("P005 `x`"), "{e}");
        let e = ParamTable::parse(
            "[[parameter]]\npnu = 5\nname = \"x\"\nformat = \"word\"\nmin = 0\nmax = 7\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("lacks P003"), "{e}");
        assert!(ParamTable::parse("nonsense").is_err());
    }
}
