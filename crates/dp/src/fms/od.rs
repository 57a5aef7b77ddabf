//! Object descriptions of an FMS object dictionary (OD) as Get-OD
//! carries them, the OD header, the static data types, and a value read
//! by its description in words — what a client makes of a server's OD
//! (`dpctl fms get-od`, `dpctl fms read`) and what a server encodes
//! (`profibus_devices::bk3000::fms`).
//!
//! What the sources say: the OD consists of a header, the static type
//! list (ST-OD) and the static object dictionary (S-OD) (BK3000 manual
//! p.60; \[P5\] p.271); the indices of the standard data types are
//! fixed (\[P5\] p.271: 1 Boolean, 2 Integer8, 3 Integer16 …), and the
//! data-type codes 1 Boolean … 9 Visible String of the PROFIdrive
//! parameter channel follow the same numbering (ABB FPBA-01 manual
//! p.159); a description on transmission starts with the index and the
//! object code (\[P5\] p.271, figure 70).
//!
//! (unverified): the octets of a description after the object code
//! ([`Description`]: data type (2), length, access, in the long form the
//! name with a length octet), the object code values ([`ObjectCode`]),
//! 10 = Octet-String, the access octet and the OD header's layout
//! ([`OdHeader`]). Our client and our server (the BK3000) agree on them.

use core::fmt;

/// Object code of a description (unverified values).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ObjectCode {
    /// A static data type (ST-OD).
    DataType = 5,
    /// A data type structure: a record type (ST-OD).
    DataTypeStructure = 6,
    /// Simple variable.
    SimpleVariable = 7,
    /// Array.
    Array = 8,
    /// Record.
    Record = 9,
}

impl ObjectCode {
    /// The code of an octet.
    pub fn from_u8(b: u8) -> Option<ObjectCode> {
        Some(match b {
            5 => ObjectCode::DataType,
            6 => ObjectCode::DataTypeStructure,
            7 => ObjectCode::SimpleVariable,
            8 => ObjectCode::Array,
            9 => ObjectCode::Record,
            _ => return None,
        })
    }

    /// The object code as the standard names it.
    pub fn name(self) -> &'static str {
        match self {
            ObjectCode::DataType => "Data Type",
            ObjectCode::DataTypeStructure => "Data Type Structure",
            ObjectCode::SimpleVariable => "Simple Variable",
            ObjectCode::Array => "Array",
            ObjectCode::Record => "Record",
        }
    }

    /// Whether objects of this code hold a value (variables).
    pub fn is_variable(self) -> bool {
        matches!(
            self,
            ObjectCode::SimpleVariable | ObjectCode::Array | ObjectCode::Record
        )
    }
}

/// Access rights of a variable (the access octet; unverified values).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Access {
    /// Read only (octet 1).
    Read,
    /// Write only (octet 2).
    Write,
    /// Read and write (octet 3).
    ReadWrite,
}

impl Access {
    /// The access octet.
    pub fn to_u8(self) -> u8 {
        match self {
            Access::Read => 1,
            Access::Write => 2,
            Access::ReadWrite => 3,
        }
    }

    /// The access of an octet (0: none, e.g. a type).
    pub fn from_u8(b: u8) -> Option<Access> {
        match b {
            1 => Some(Access::Read),
            2 => Some(Access::Write),
            3 => Some(Access::ReadWrite),
            _ => None,
        }
    }

    /// Short form for tables: `r`, `w`, `rw`.
    pub fn short(self) -> &'static str {
        match self {
            Access::Read => "r",
            Access::Write => "w",
            Access::ReadWrite => "rw",
        }
    }
}

/// The standard data types by their fixed index (\[P5\] p.271; 1…9 also
/// the ABB FPBA-01 manual p.159; 10 Octet-String unverified).
pub fn standard_type(index: u16) -> Option<&'static str> {
    Some(match index {
        1 => "Boolean",
        2 => "Integer8",
        3 => "Integer16",
        4 => "Integer32",
        5 => "Unsigned8",
        6 => "Unsigned16",
        7 => "Unsigned32",
        8 => "Floating-Point",
        9 => "Visible-String",
        10 => "Octet-String",
        _ => return None,
    })
}

/// One object description as Get-OD carries it (layout unverified):
/// index (2, big-endian), object code, data type index (2), length (of
/// the value; of one element of an array), access octet, and in the long
/// form the name with a length octet.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Description {
    /// Index of the object.
    pub index: u16,
    /// Object code octet ([`ObjectCode::from_u8`]).
    pub code: u8,
    /// Data type index (element type of an array).
    pub data_type: u16,
    /// Length in bytes (of the value; an array's whole value).
    pub length: u8,
    /// Access octet ([`Access::from_u8`]; 0 for types).
    pub access: u8,
    /// The name (long form only).
    pub name: Option<String>,
}

/// A description that cannot be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DescriptionError {
    /// Shorter than its fixed part or than its name's length octet says.
    #[error("object description is {got} bytes long, needs {needed}")]
    Length {
        /// Bytes needed.
        needed: usize,
        /// Bytes present.
        got: usize,
    },
    /// Bytes after the name.
    #[error("object description has {0} bytes after its end")]
    Trailing(usize),
}

impl Description {
    /// Bytes of the fixed part (index, code, type, length, access).
    pub const FIXED: usize = 7;

    /// The object code, if known.
    pub fn object_code(&self) -> Option<ObjectCode> {
        ObjectCode::from_u8(self.code)
    }

    /// The access rights, if any.
    pub fn access_rights(&self) -> Option<Access> {
        Access::from_u8(self.access)
    }

    /// The encoding (long form when `name` is set; a name is cut to 32
    /// bytes, the limit of \[P5\] table 70's names).
    pub fn encode(&self) -> Vec<u8> {
        let mut v = self.index.to_be_bytes().to_vec();
        v.push(self.code);
        v.extend(self.data_type.to_be_bytes());
        v.extend([self.length, self.access]);
        if let Some(name) = &self.name {
            let mut end = name.len().min(32);
            while !name.is_char_boundary(end) {
                end -= 1;
            }
            v.push(end as u8);
            v.extend_from_slice(&name.as_bytes()[..end]);
        }
        v
    }

    /// Decodes one description (short form: the fixed part only).
    pub fn parse(b: &[u8]) -> Result<Description, DescriptionError> {
        if b.len() < Self::FIXED {
            return Err(DescriptionError::Length {
                needed: Self::FIXED,
                got: b.len(),
            });
        }
        let name = match b.get(Self::FIXED) {
            None => None,
            Some(&n) => {
                let end = Self::FIXED + 1 + n as usize;
                if b.len() < end {
                    return Err(DescriptionError::Length {
                        needed: end,
                        got: b.len(),
                    });
                }
                if b.len() > end {
                    return Err(DescriptionError::Trailing(b.len() - end));
                }
                Some(String::from_utf8_lossy(&b[Self::FIXED + 1..end]).into_owned())
            }
        };
        Ok(Description {
            index: u16::from_be_bytes([b[0], b[1]]),
            code: b[2],
            data_type: u16::from_be_bytes([b[3], b[4]]),
            length: b[5],
            access: b[6],
            name,
        })
    }

    /// The value of one element of this object (a Read or Write with a
    /// subindex) in words, by its data type: like [`Description::decode_value`]
    /// of a simple variable of the element type.
    pub fn decode_element(&self, type_name: &str, data: &[u8]) -> Option<String> {
        Description {
            code: ObjectCode::SimpleVariable as u8,
            ..self.clone()
        }
        .decode_value(type_name, data)
    }

    /// The value of this object in words, by its data type (`type_name`
    /// gives the name of a type index: the OD's own type descriptions,
    /// else [`standard_type`]). `None` when the type is not one of the
    /// standard numbers and strings or the length does not fit it.
    pub fn decode_value(&self, type_name: &str, data: &[u8]) -> Option<String> {
        let elem = |t: &str| -> Option<usize> {
            Some(match t {
                "Boolean" | "Integer8" | "Unsigned8" => 1,
                "Integer16" | "Unsigned16" => 2,
                "Integer32" | "Unsigned32" | "Floating-Point" => 4,
                _ => return None,
            })
        };
        let one = |t: &str, b: &[u8]| -> String {
            match (t, b.len()) {
                ("Boolean", 1) => (if b[0] != 0 { "true" } else { "false" }).into(),
                ("Integer8", 1) => format!("{}", b[0] as i8),
                ("Unsigned8", 1) => format!("{}", b[0]),
                ("Integer16", 2) => format!("{}", i16::from_be_bytes([b[0], b[1]])),
                ("Unsigned16", 2) => format!("{}", u16::from_be_bytes([b[0], b[1]])),
                ("Integer32", 4) => format!("{}", i32::from_be_bytes([b[0], b[1], b[2], b[3]])),
                ("Unsigned32", 4) => format!("{}", u32::from_be_bytes([b[0], b[1], b[2], b[3]])),
                _ => format!("{}", f32::from_be_bytes([b[0], b[1], b[2], b[3]])),
            }
        };
        match type_name {
            "Visible-String" => Some(format!("\"{}\"", String::from_utf8_lossy(data))),
            "Octet-String" => None,
            t => {
                let n = elem(t)?;
                if data.is_empty() || !data.len().is_multiple_of(n) {
                    return None;
                }
                let parts: Vec<String> = data.chunks(n).map(|c| one(t, c)).collect();
                if self.object_code() == Some(ObjectCode::Array) || parts.len() > 1 {
                    Some(format!("[{}]", parts.join(", ")))
                } else {
                    parts.into_iter().next()
                }
            }
        }
    }
}

impl fmt::Display for Description {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "index {}: ", self.index)?;
        match self.object_code() {
            Some(c) => write!(f, "{}", c.name())?,
            None => write!(f, "object code {}", self.code)?,
        }
        write!(f, ", type {}, length {}", self.data_type, self.length)?;
        if let Some(a) = self.access_rights() {
            write!(f, ", access {}", a.short())?;
        }
        if let Some(n) = &self.name {
            write!(f, ", \"{n}\"")?;
        }
        Ok(())
    }
}

/// The OD header, the answer to Get-OD of index 0 (layout unverified):
/// number of objects, first and last index of the static type list,
/// first index of the static object dictionary, each 2 octets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OdHeader {
    /// Number of objects (types and variables).
    pub objects: u16,
    /// First index of the static type list.
    pub first_type: u16,
    /// Last index of the static type list.
    pub last_type: u16,
    /// First index of the static object dictionary (the variables).
    pub first_object: u16,
}

impl OdHeader {
    /// The encoding.
    pub fn encode(&self) -> Vec<u8> {
        let mut v = Vec::with_capacity(8);
        for x in [
            self.objects,
            self.first_type,
            self.last_type,
            self.first_object,
        ] {
            v.extend(x.to_be_bytes());
        }
        v
    }

    /// Decodes the header (exactly 8 bytes).
    pub fn parse(b: &[u8]) -> Result<OdHeader, DescriptionError> {
        if b.len() < 8 {
            return Err(DescriptionError::Length {
                needed: 8,
                got: b.len(),
            });
        }
        if b.len() > 8 {
            return Err(DescriptionError::Trailing(b.len() - 8));
        }
        let w = |i: usize| u16::from_be_bytes([b[i], b[i + 1]]);
        Ok(OdHeader {
            objects: w(0),
            first_type: w(2),
            last_type: w(4),
            first_object: w(6),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptions_round_trip_in_both_forms() {
        let mut d = Description {
            index: 2022,
            code: ObjectCode::Array as u8,
            data_type: 5,
            length: 3,
            access: Access::Read.to_u8(),
            name: Some("1.KL3102.2 input".into()),
        };
        let long = d.encode();
        assert_eq!(&long[..8], &[0x07, 0xE6, 8, 0, 5, 3, 1, 16]);
        assert_eq!(Description::parse(&long), Ok(d.clone()));
        d.name = None;
        assert_eq!(Description::parse(&d.encode()), Ok(d.clone()));
        assert_eq!(
            d.to_string(),
            "index 2022: Array, type 5, length 3, access r"
        );
        assert_eq!(
            Description::parse(&[0, 1, 5]),
            Err(DescriptionError::Length { needed: 7, got: 3 })
        );
        assert_eq!(
            Description::parse(&[0, 1, 5, 0, 1, 0, 0, 4, b'a']),
            Err(DescriptionError::Length { needed: 12, got: 9 })
        );
        assert_eq!(
            Description::parse(&[0, 1, 5, 0, 1, 0, 0, 0, 9]),
            Err(DescriptionError::Trailing(1))
        );
    }

    #[test]
    fn values_decode_by_their_type() {
        let array = Description {
            index: 2020,
            code: ObjectCode::Array as u8,
            data_type: 5,
            length: 3,
            access: 1,
            name: None,
        };
        assert_eq!(
            array
                .decode_value("Unsigned8", &[0x41, 0x12, 0x34])
                .as_deref(),
            Some("[65, 18, 52]")
        );
        let simple = Description {
            code: ObjectCode::SimpleVariable as u8,
            ..array.clone()
        };
        assert_eq!(
            simple.decode_value("Integer16", &[0xFF, 0xFE]).as_deref(),
            Some("-2")
        );
        assert_eq!(
            simple.decode_value("Visible-String", b"BK3000").as_deref(),
            Some("\"BK3000\"")
        );
        assert_eq!(simple.decode_value("Unsigned16", &[1, 2, 3]), None);
        assert_eq!(simple.decode_value("Octet-String", &[1]), None);
        assert_eq!(simple.decode_value("Record x", &[1]), None);
        assert_eq!(standard_type(5), Some("Unsigned8"));
        assert_eq!(standard_type(11), None);
    }

    #[test]
    fn the_od_header_has_four_words() {
        let h = OdHeader {
            objects: 21,
            first_type: 5,
            last_type: 19,
            first_object: 2020,
        };
        let b = h.encode();
        assert_eq!(b, vec![0, 21, 0, 5, 0, 19, 0x07, 0xE4]);
        assert_eq!(OdHeader::parse(&b), Ok(h));
        assert!(OdHeader::parse(&b[..7]).is_err());
    }
}
