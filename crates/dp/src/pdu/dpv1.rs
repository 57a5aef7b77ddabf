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
pub const ERROR_DECODE_DPV1: u8 = 0x80;
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

    /// The error in words.
    pub fn describe(&self) -> String {
        let op = match self.function & 0x7F {
            FN_READ => "read",
            FN_WRITE => "write",
            FN_ALARM_ACK => "alarm ack",
            _ => "request",
        };
        let decode = match self.error_decode {
            ERROR_DECODE_DPV1 => "DP-V1",
            0xFE => "FMS",
            0xFF => "HART",
            _ => "unknown decode",
        };
        let (class, code) = (self.error_code_1 >> 4, self.error_code_1 & 0x0F);
        let text = if self.error_decode == ERROR_DECODE_DPV1 {
            match (class, code) {
                (0xA, 0) => "application: read error",
                (0xA, 1) => "application: write error",
                (0xA, 2) => "application: module failure",
                (0xA, 8) => "application: version conflict",
                (0xA, 9) => "application: feature not supported",
                (0xA, _) => "application: user-specific",
                (0xB, 0) => "access: invalid index",
                (0xB, 1) => "access: write length error",
                (0xB, 2) => "access: invalid slot",
                (0xB, 3) => "access: type conflict",
                (0xB, 4) => "access: invalid area",
                (0xB, 5) => "access: state conflict",
                (0xB, 6) => "access: access denied",
                (0xB, 7) => "access: invalid range",
                (0xB, 8) => "access: invalid parameter",
                (0xB, 9) => "access: invalid type",
                (0xB, _) => "access: user-specific",
                (0xC, 0) => "resource: read constraint conflict",
                (0xC, 1) => "resource: write constraint conflict",
                (0xC, 2) => "resource: busy",
                (0xC, 3) => "resource: unavailable",
                (0xC, _) => "resource: user-specific",
                (0xD..=0xF, _) => "user-specific",
                _ => "reserved",
            }
        } else {
            "not a DP-V1 error"
        };
        format!(
            "{op} failed: {text} ({decode}, Error_Code_1 0x{:02X}, Error_Code_2 0x{:02X})",
            self.error_code_1, self.error_code_2
        )
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
    }

    #[test]
    fn bad_pdus() {
        assert_eq!(Pdu::parse_request(&[]), Err(Dpv1ParseError::Empty));
        assert!(Pdu::parse_request(&[0x5F, 0, 0, 5, 1]).is_err());
        assert!(Pdu::parse_request(&[0x5E, 0]).is_err());
        assert!(Pdu::parse_request(&[0x11, 0, 0, 0]).is_err());
    }
}
