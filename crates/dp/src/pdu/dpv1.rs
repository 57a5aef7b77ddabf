//! DP-V1 MSAC_C1 PDUs (DSAP/SSAP 51, Alarm_Ack on DSAP 50).
//!
//! ```text
//! Read request    5E slot index length
//! Read response   5E slot index length data…
//! Write request   5F slot index length data…
//! Write response  5F slot index length
//! Alarm_Ack       5C slot alarm_type specifier
//! Error response  function|0x80, Error_Decode, Error_Code_1, Error_Code_2
//! ```
//!
//! The class-1 read/write runs as a polled exchange: the slave answers the
//! request with a short acknowledge until its answer is ready, the master
//! keeps polling with empty SRDs on the same SAPs.

/// Function number of Read.
pub const FN_READ: u8 = 0x5E;
/// Function number of Write.
pub const FN_WRITE: u8 = 0x5F;
/// Function number of Alarm_Ack.
pub const FN_ALARM_ACK: u8 = 0x5C;
/// Function number of Idle (class-2 keep-alive).
pub const FN_IDLE: u8 = 0x48;
/// Error_Decode value of DP-V1 errors.
pub const ERROR_DECODE_DPV1: u8 = ErrorDecode::Dpv1.code();
/// Longest data of one read/write (244 − 4 header bytes).
pub const MAX_DATA_LEN: usize = 240;

/// A DP-V1 class-1 PDU, borrowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pdu<'a> {
    /// Read request.
    ReadReq {
        /// Slot number 0..=254.
        slot: u8,
        /// Index 0..=254.
        index: u8,
        /// Bytes wanted.
        length: u8,
    },
    /// Positive read response.
    ReadRes {
        /// Slot number.
        slot: u8,
        /// Index.
        index: u8,
        /// The data read.
        data: &'a [u8],
    },
    /// Write request.
    WriteReq {
        /// Slot number.
        slot: u8,
        /// Index.
        index: u8,
        /// The data to write.
        data: &'a [u8],
    },
    /// Positive write response.
    WriteRes {
        /// Slot number.
        slot: u8,
        /// Index.
        index: u8,
        /// Bytes written.
        length: u8,
    },
    /// Alarm_Ack request (and its positive response, which mirrors it).
    AlarmAck {
        /// Slot of the alarm.
        slot: u8,
        /// Alarm type.
        alarm_type: u8,
        /// Alarm specifier (sequence number in bits 7-3).
        specifier: u8,
    },
    /// Negative response.
    Error(Dpv1Error),
}

/// A DP-V1 error response: function number with bit 7 set, Error_Decode,
/// Error_Code_1 (class in the high nibble, code in the low), Error_Code_2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Dpv1Error {
    /// The function number with bit 7 set (0xDE read, 0xDF write, …).
    pub function: u8,
    /// 0x80 DP-V1, 0xFE FMS, 0xFF HART.
    pub error_decode: u8,
    /// Error class and code.
    pub error_code_1: u8,
    /// Vendor-specific.
    pub error_code_2: u8,
}

/// A DP-V1 PDU that cannot be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Dpv1ParseError {
    /// Too short for its function.
    #[error("DP-V1 PDU with function 0x{function:02X} is {got} bytes long, needs {needed}")]
    Length {
        /// Function byte.
        function: u8,
        /// Bytes needed.
        needed: usize,
        /// Bytes received.
        got: usize,
    },
    /// The length byte disagrees with the data carried.
    #[error("DP-V1 length byte {length} disagrees with {data} data bytes")]
    LengthByte {
        /// Length byte.
        length: u8,
        /// Data bytes present.
        data: usize,
    },
    /// An unknown function number.
    #[error("unknown DP-V1 function 0x{0:02X}")]
    UnknownFunction(u8),
    /// Empty PDU.
    #[error("empty DP-V1 PDU")]
    Empty,
}

fn need(du: &[u8], n: usize) -> Result<(), Dpv1ParseError> {
    if du.len() < n {
        Err(Dpv1ParseError::Length {
            function: du.first().copied().unwrap_or(0),
            needed: n,
            got: du.len(),
        })
    } else {
        Ok(())
    }
}

/// `function slot index length data…`: slot, index and the data, whose
/// length must match the length byte.
fn with_data(du: &[u8]) -> Result<(u8, u8, &[u8]), Dpv1ParseError> {
    need(du, 4)?;
    let data = &du[4..];
    if du[3] as usize != data.len() {
        return Err(Dpv1ParseError::LengthByte {
            length: du[3],
            data: data.len(),
        });
    }
    Ok((du[1], du[2], data))
}

/// `function slot alarm_type specifier`: an Alarm_Ack, the same PDU in
/// the request and in the response.
fn alarm_ack(du: &[u8]) -> Result<Pdu<'_>, Dpv1ParseError> {
    need(du, 4)?;
    Ok(Pdu::AlarmAck {
        slot: du[1],
        alarm_type: du[2],
        specifier: du[3],
    })
}

impl<'a> Pdu<'a> {
    /// Decode a PDU sent by a master.
    pub fn parse_request(du: &'a [u8]) -> Result<Pdu<'a>, Dpv1ParseError> {
        let &f = du.first().ok_or(Dpv1ParseError::Empty)?;
        match f {
            FN_READ => {
                need(du, 4)?;
                Ok(Pdu::ReadReq {
                    slot: du[1],
                    index: du[2],
                    length: du[3],
                })
            }
            FN_WRITE => {
                let (slot, index, data) = with_data(du)?;
                Ok(Pdu::WriteReq { slot, index, data })
            }
            FN_ALARM_ACK => alarm_ack(du),
            other => Err(Dpv1ParseError::UnknownFunction(other)),
        }
    }

    /// Decode a PDU sent by a slave.
    pub fn parse_response(du: &'a [u8]) -> Result<Pdu<'a>, Dpv1ParseError> {
        let &f = du.first().ok_or(Dpv1ParseError::Empty)?;
        if f & 0x80 != 0 {
            need(du, 4)?;
            return Ok(Pdu::Error(Dpv1Error {
                function: f,
                error_decode: du[1],
                error_code_1: du[2],
                error_code_2: du[3],
            }));
        }
        match f {
            FN_READ => {
                let (slot, index, data) = with_data(du)?;
                Ok(Pdu::ReadRes { slot, index, data })
            }
            FN_WRITE => {
                need(du, 4)?;
                Ok(Pdu::WriteRes {
                    slot: du[1],
                    index: du[2],
                    length: du[3],
                })
            }
            FN_ALARM_ACK => alarm_ack(du),
            other => Err(Dpv1ParseError::UnknownFunction(other)),
        }
    }

    /// Encode into `buf`; returns the length or `None` when `buf` is too
    /// small or the data exceed 240 bytes.
    pub fn emit(&self, buf: &mut [u8]) -> Option<usize> {
        let (head, data): ([u8; 4], &[u8]) = match *self {
            Pdu::ReadReq {
                slot,
                index,
                length,
            } => ([FN_READ, slot, index, length], &[]),
            Pdu::ReadRes { slot, index, data } => {
                ([FN_READ, slot, index, data.len().min(255) as u8], data)
            }
            Pdu::WriteReq { slot, index, data } => {
                ([FN_WRITE, slot, index, data.len().min(255) as u8], data)
            }
            Pdu::WriteRes {
                slot,
                index,
                length,
            } => ([FN_WRITE, slot, index, length], &[]),
            Pdu::AlarmAck {
                slot,
                alarm_type,
                specifier,
            } => ([FN_ALARM_ACK, slot, alarm_type, specifier], &[]),
            Pdu::Error(e) => (
                [e.function, e.error_decode, e.error_code_1, e.error_code_2],
                &[],
            ),
        };
        let n = 4 + data.len();
        if data.len() > MAX_DATA_LEN || buf.len() < n {
            return None;
        }
        buf[..4].copy_from_slice(&head);
        buf[4..n].copy_from_slice(data);
        Some(n)
    }
}

impl Dpv1Error {
    /// A DP-V1 error (Error_Decode 0x80) answering `function` with
    /// class/code (`Error_Code_1 = class << 4 | code`).
    pub fn dpv1(function: u8, class: u8, code: u8) -> Dpv1Error {
        Dpv1Error {
            function: function | 0x80,
            error_decode: ERROR_DECODE_DPV1,
            error_code_1: (class << 4) | (code & 0x0F),
            error_code_2: 0,
        }
    }

    /// Error_Decode: which protocol's error codes follow.
    pub fn decode(&self) -> ErrorDecode {
        ErrorDecode::from_code(self.error_decode)
    }

    /// The error class (high nibble of Error_Code_1).
    pub fn class(&self) -> ErrorClass {
        ErrorClass::from_code(self.error_code_1 >> 4)
    }

    /// The error in words.
    pub fn describe(&self) -> String {
        let op = match self.function & 0x7F {
            FN_READ => "read",
            FN_WRITE => "write",
            FN_ALARM_ACK => "alarm ack",
            FN_IDLE => "idle",
            0x51 => "data transport",
            0x56 => "connection set-up (resource manager)",
            0x57 => "initiate",
            _ => "request",
        };
        let decode = self.decode().name().unwrap_or("unknown decode");
        let code = self.error_code_1 & 0x0F;
        let text = if self.decode() == ErrorDecode::Dpv1 {
            let class = self.class();
            let name = match class {
                ErrorClass::Application => ApplicationError::from_code(code).name(),
                ErrorClass::Access => AccessError::from_code(code).name(),
                ErrorClass::Resource => ResourceError::from_code(code).name(),
                ErrorClass::Unknown(_) => None,
            };
            match (class.name(), name) {
                (Some(class), Some(name)) => format!("{class}: {name}"),
                (Some(class), None) => format!("{class}: user-specific"),
                (None, _) if class.code() >= 0xD => "user-specific".into(),
                (None, _) => "reserved".into(),
            }
        } else {
            "not a DP-V1 error".into()
        };
        format!(
            "{op} failed: {text} ({decode}, Error_Code_1 0x{:02X}, Error_Code_2 0x{:02X})",
            self.error_code_1, self.error_code_2
        )
    }
}

profibus_fdl::enum_with_unknown! {
    /// Error_Decode of a DP-V1 error response (IEC 61158-6-3): whose
    /// error codes Error_Code_1/2 carry.
    pub enum ErrorDecode(u8) {
        /// 0x80: DP-V1 error classes and codes.
        Dpv1 = 0x80 => "DP-V1",
        /// 0xFE: FMS error codes.
        Fms = 0xFE => "FMS",
        /// 0xFF: HART error codes.
        Hart = 0xFF => "HART",
    }
}

profibus_fdl::enum_with_unknown! {
    /// The error class of a DP-V1 error (Error_Code_1 bits 7-4). 0xD..=0xF
    /// are user-specific, 0..=9 reserved.
    pub enum ErrorClass(u8) {
        /// 0xA: the application failed.
        Application = 0xA => "application",
        /// 0xB: the access was refused.
        Access = 0xB => "access",
        /// 0xC: a resource is missing.
        Resource = 0xC => "resource",
    }
}

profibus_fdl::enum_with_unknown! {
    /// Error codes of class "application" (Error_Code_1 bits 3-0); the
    /// others are user-specific.
    pub enum ApplicationError(u8) {
        /// 0: read error.
        ReadError = 0 => "read error",
        /// 1: write error.
        WriteError = 1 => "write error",
        /// 2: module failure.
        ModuleFailure = 2 => "module failure",
        /// 8: version conflict.
        VersionConflict = 8 => "version conflict",
        /// 9: feature not supported.
        FeatureNotSupported = 9 => "feature not supported",
    }
}

profibus_fdl::enum_with_unknown! {
    /// Error codes of class "access" (Error_Code_1 bits 3-0); the others
    /// are user-specific.
    pub enum AccessError(u8) {
        /// 0: invalid index.
        InvalidIndex = 0 => "invalid index",
        /// 1: write length error.
        WriteLength = 1 => "write length error",
        /// 2: invalid slot.
        InvalidSlot = 2 => "invalid slot",
        /// 3: type conflict.
        TypeConflict = 3 => "type conflict",
        /// 4: invalid area.
        InvalidArea = 4 => "invalid area",
        /// 5: state conflict.
        StateConflict = 5 => "state conflict",
        /// 6: access denied.
        AccessDenied = 6 => "access denied",
        /// 7: invalid range.
        InvalidRange = 7 => "invalid range",
        /// 8: invalid parameter.
        InvalidParameter = 8 => "invalid parameter",
        /// 9: invalid type.
        InvalidType = 9 => "invalid type",
    }
}

profibus_fdl::enum_with_unknown! {
    /// Error codes of class "resource" (Error_Code_1 bits 3-0); the others
    /// are user-specific.
    pub enum ResourceError(u8) {
        /// 0: read constraint conflict.
        ReadConstraintConflict = 0 => "read constraint conflict",
        /// 1: write constraint conflict.
        WriteConstraintConflict = 1 => "write constraint conflict",
        /// 2: resource busy.
        Busy = 2 => "busy",
        /// 3: resource unavailable.
        Unavailable = 3 => "unavailable",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips() {
        let mut buf = [0u8; 300];
        let data = [1, 2, 3];
        for (p, req) in [
            (
                Pdu::ReadReq {
                    slot: 1,
                    index: 2,
                    length: 10,
                },
                true,
            ),
            (
                Pdu::WriteReq {
                    slot: 1,
                    index: 5,
                    data: &data,
                },
                true,
            ),
            (
                Pdu::ReadRes {
                    slot: 1,
                    index: 2,
                    data: &data,
                },
                false,
            ),
            (
                Pdu::WriteRes {
                    slot: 0,
                    index: 5,
                    length: 3,
                },
                false,
            ),
            (Pdu::Error(Dpv1Error::dpv1(FN_READ, 0xB, 0)), false),
        ] {
            let n = p.emit(&mut buf).unwrap();
            let back = if req {
                Pdu::parse_request(&buf[..n])
            } else {
                Pdu::parse_response(&buf[..n])
            };
            assert_eq!(back, Ok(p));
        }
    }

    #[test]
    fn error_words() {
        let e = Dpv1Error::dpv1(FN_WRITE, 0xB, 0);
        assert_eq!(e.function, 0xDF);
        assert!(e.describe().contains("write failed: access: invalid index"));
        let words = |decode: u8, code_1: u8| {
            Dpv1Error {
                function: 0xDE,
                error_decode: decode,
                error_code_1: code_1,
                error_code_2: 0,
            }
            .describe()
        };
        assert!(words(0x80, 0xA9).contains("application: feature not supported"));
        assert!(words(0x80, 0xA5).contains("application: user-specific"));
        assert!(words(0x80, 0xC2).contains("resource: busy"));
        assert!(words(0x80, 0xBF).contains("access: user-specific"));
        assert!(words(0x80, 0xE0).contains("read failed: user-specific (DP-V1"));
        assert!(words(0x80, 0x10).contains(": reserved (DP-V1"));
        assert!(words(0xFE, 0xB0).contains("not a DP-V1 error (FMS"));
        assert!(words(0x12, 0xB0).contains("(unknown decode,"));
    }

    #[test]
    fn bad_pdus() {
        assert_eq!(Pdu::parse_request(&[]), Err(Dpv1ParseError::Empty));
        assert!(Pdu::parse_request(&[0x5F, 0, 0, 5, 1]).is_err());
        assert!(Pdu::parse_request(&[0x5E, 0]).is_err());
        assert!(Pdu::parse_request(&[0x11, 0, 0, 0]).is_err());
    }
}
