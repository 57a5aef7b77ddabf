//! DP-V1 MSAC_C2 PDUs: the class-2 (engineering, maintenance) master's
//! connection-oriented acyclic services (IEC 61158-6-3; byte layouts as
//! in `shared/reference/dpv1-c2-im-alarms.md` §4.3–4.4, where the profichip
//! VPC3+ and Hilscher/Softing stack headers agree).
//!
//! ```text
//! Initiate.req     57 00 00 00 ST_hi ST_lo F1 F2 PF_hi PF_lo PI_hi PI_lo
//!                  S_Type S_Len D_Type D_Len S_Addr… D_Addr…     (≥ 20 bytes)
//! Initiate.res     57 MaxLen F1 F2 PF_hi PF_lo PI_hi PI_lo
//!                  S_Type S_Len D_Type D_Len S_Addr… D_Addr…     (≥ 16 bytes)
//! RM reply         56 SAP PollTO_hi PollTO_lo
//! Read.req/.res    5E slot index len [data]
//! Write.req/.res   5F slot index len [data]
//! Data_Transport   51 slot index len data        (request and response)
//! Idle             48 00
//! Abort            58 Subnet Instance|Reason Additional_Detail
//! negative         function|0x80 Error_Decode Error_Code_1 Error_Code_2
//! ```
//!
//! Connection: the master sends Initiate.req to the slave's resource
//! manager (DSAP 49, SSAP 50); the RM answers at once with the RM PDU
//! naming the connection SAP (0..=48); the master then polls that SAP
//! until Initiate.res comes back, and every later request on it follows
//! the same request/poll pattern. Idle PDUs keep an idle connection
//! inside Send_Timeout; Abort closes it from either side.
//!
//! Multi-byte fields are big-endian. Where the sources disagree (the
//! second address byte: "reserved" in VPC3, SCL in Softing/Hilscher; the
//! width of the abort reason) this module follows the stack headers:
//! the byte is kept as [`AddrParams::scl`], the reason is bits 3-0 and the
//! instance bits 5-4, and decoding ignores bits 7-6.

use crate::pdu::dpv1::{Dpv1Error, FN_IDLE, FN_READ, FN_WRITE, MAX_DATA_LEN};

/// Function number of Data_Transport (class 2 only).
pub const FN_DATA_TRANSPORT: u8 = 0x51;
/// Function number of the resource manager's reply to Initiate.
pub const FN_RM: u8 = 0x56;
/// Function number of Initiate.
pub const FN_INITIATE: u8 = 0x57;
/// Function number of Abort (request only, no response).
pub const FN_ABORT: u8 = 0x58;
/// The master's SAP of class-2 services (SSAP of every MSAC_C2 request).
pub const MASTER_SAP: u8 = 50;
/// The slave's resource manager SAP (DSAP of Initiate.req).
pub const RM_SAP: u8 = 49;
/// Highest connection SAP a resource manager may assign.
pub const MAX_CONNECTION_SAP: u8 = 48;
/// Shortest Initiate.req: 16 header bytes and two 2-byte addresses.
pub const INITIATE_REQ_MIN_LEN: usize = 20;
/// Shortest Initiate.res: 12 header bytes and two 2-byte addresses.
pub const INITIATE_RES_MIN_LEN: usize = 16;
/// Features_Supported_1 bit 0: MSAC_C2 Read/Write supported.
pub const FEATURE_DPV1_RW: u8 = 0x01;

/// Address parameters of Initiate (S_Addr or D_Addr): API and SCL, and
/// with Type 1 a network and MAC address (for routing through other
/// networks).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AddrParams<'a> {
    /// Application process instance; 0 on a plain PROFIBUS segment.
    pub api: u8,
    /// Access level (SCL; "reserved" in the VPC3 sources). Send 0.
    pub scl: u8,
    /// With Type 1: the network address (6 bytes) and the MAC address.
    pub extension: Option<AddrExtension<'a>>,
}

/// The network part of a Type-1 address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AddrExtension<'a> {
    /// Network_Address.
    pub network_address: [u8; 6],
    /// MAC_Address (Len − 8 bytes).
    pub mac_address: &'a [u8],
}

impl<'a> AddrParams<'a> {
    /// Type byte: 0 plain, 1 with network/MAC extension.
    pub fn addr_type(&self) -> u8 {
        u8::from(self.extension.is_some())
    }

    /// Length byte: 2, or 8 + MAC length with the extension.
    pub fn len(&self) -> usize {
        match self.extension {
            None => 2,
            Some(e) => 8 + e.mac_address.len(),
        }
    }

    /// Never empty (at least API and SCL).
    pub fn is_empty(&self) -> bool {
        false
    }

    fn parse(kind: u8, bytes: &'a [u8]) -> Result<AddrParams<'a>, C2ParseError> {
        match (kind, bytes.len()) {
            (0, 2) => Ok(AddrParams {
                api: bytes[0],
                scl: bytes[1],
                extension: None,
            }),
            (1, n) if n >= 8 => {
                let mut network_address = [0; 6];
                network_address.copy_from_slice(&bytes[2..8]);
                Ok(AddrParams {
                    api: bytes[0],
                    scl: bytes[1],
                    extension: Some(AddrExtension {
                        network_address,
                        mac_address: &bytes[8..],
                    }),
                })
            }
            (kind, len) => Err(C2ParseError::Address { kind, len }),
        }
    }

    fn emit(&self, out: &mut [u8]) {
        out[0] = self.api;
        out[1] = self.scl;
        if let Some(e) = self.extension {
            out[2..8].copy_from_slice(&e.network_address);
            out[8..8 + e.mac_address.len()].copy_from_slice(e.mac_address);
        }
    }
}

/// Initiate.req: open a class-2 connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InitiateReq<'a> {
    /// Send_Timeout in units of 10 ms: the slave aborts the connection
    /// when nothing arrives for this long.
    pub send_timeout: u16,
    /// Features_Supported_1 (bit 0: [`FEATURE_DPV1_RW`]).
    pub features_supported_1: u8,
    /// Features_Supported_2.
    pub features_supported_2: u8,
    /// Profile_Features_Supported.
    pub profile_features_supported: u16,
    /// Profile_Ident_Number (0: no profile).
    pub profile_ident_number: u16,
    /// S_Addr: the requester's address parameters.
    pub source: AddrParams<'a>,
    /// D_Addr: the responder's address parameters.
    pub destination: AddrParams<'a>,
}

/// Initiate.res: the slave accepts the connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InitiateRes<'a> {
    /// Max_Len_Data_Unit: longest PDU on this connection (e.g. 240).
    pub max_len_data_unit: u8,
    /// Features_Supported_1.
    pub features_supported_1: u8,
    /// Features_Supported_2.
    pub features_supported_2: u8,
    /// Profile_Features_Supported.
    pub profile_features_supported: u16,
    /// Profile_Ident_Number.
    pub profile_ident_number: u16,
    /// S_Addr.
    pub source: AddrParams<'a>,
    /// D_Addr.
    pub destination: AddrParams<'a>,
}

/// The resource manager's reply to Initiate.req: which SAP the
/// connection uses, and how long the slave waits for the master's poll.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RmReply {
    /// The connection SAP (0..=48).
    pub sap: u8,
    /// Poll_Timeout. Its unit is not confirmed by two sources (the
    /// Softing API counts the master's class-2 poll timeout in 1 ms);
    /// this crate reads it as milliseconds.
    pub poll_timeout: u16,
}

profibus_fdl::enum_with_unknown! {
    /// Subnet of an Abort: where the abort was raised.
    pub enum AbortSubnet(u8) {
        /// 0: no subnet.
        NoSubnet = 0 => "no subnet",
        /// 1: the local subnet.
        Local = 1 => "local",
        /// 2: a remote subnet.
        Remote = 2 => "remote",
    }
}

profibus_fdl::enum_with_unknown! {
    /// Instance of an Abort (bits 5-4 of its third byte): which layer
    /// aborted.
    pub enum AbortInstance(u8) {
        /// 0: FDL (layer 2).
        Fdl = 0 => "FDL",
        /// 1: the MSAC_C2 protocol machine.
        MsacC2 = 1 => "MSAC_C2",
        /// 2: the user (application).
        User = 2 => "user",
    }
}

profibus_fdl::enum_with_unknown! {
    /// Reason code of an Abort raised by the MSAC_C2 instance (bits 3-0).
    pub enum AbortReason(u8) {
        /// 1 SE: sequence error.
        SequenceError = 1 => "sequence error (SE)",
        /// 2 FE: invalid request PDU.
        InvalidRequest = 2 => "invalid request PDU (FE)",
        /// 3 TO: connection timeout (Send_Timeout expired).
        Timeout = 3 => "connection timeout (TO)",
        /// 4 RE: invalid response PDU.
        InvalidResponse = 4 => "invalid response PDU (RE)",
        /// 5 IV: invalid service from the user.
        InvalidService = 5 => "invalid service from the user (IV)",
        /// 6 STO: Send_Timeout requested too small.
        SendTimeoutTooSmall = 6 => "Send_Timeout too small (STO)",
        /// 7 IA: invalid additional address information.
        InvalidAddress = 7 => "invalid additional address information (IA)",
        /// 8 OC: waiting for FDL_DATA_REPLY.con.
        WaitingForReply = 8 => "waiting for FDL_DATA_REPLY.con (OC)",
        /// 15 RES: resource error (e.g. no free connection).
        Resource = 15 => "resource error (RES)",
    }
}

/// An Abort: `58 Subnet Instance|Reason Additional_Detail`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Abort {
    /// Where the abort was raised.
    pub subnet: AbortSubnet,
    /// Which layer aborted.
    pub instance: AbortInstance,
    /// The reason code (bits 3-0); for the MSAC_C2 instance an
    /// [`AbortReason`], for the user instance the application's code.
    pub reason: u8,
    /// Additional_Detail (the fourth byte).
    pub additional_detail: u8,
}

impl Abort {
    /// An abort by the MSAC_C2 instance for `reason`, local subnet.
    pub fn msac_c2(reason: AbortReason) -> Abort {
        Abort {
            subnet: AbortSubnet::NoSubnet,
            instance: AbortInstance::MsacC2,
            reason: reason.code() & 0x0F,
            additional_detail: 0,
        }
    }

    /// An abort by the user (application) with its own reason code.
    pub fn user(reason: u8) -> Abort {
        Abort {
            subnet: AbortSubnet::NoSubnet,
            instance: AbortInstance::User,
            reason: reason & 0x0F,
            additional_detail: 0,
        }
    }

    /// The reason as an MSAC_C2 reason code.
    pub fn msac_c2_reason(&self) -> Option<AbortReason> {
        (self.instance == AbortInstance::MsacC2).then(|| AbortReason::from_code(self.reason))
    }

    /// The abort in words, e.g. "aborted by MSAC_C2: connection timeout
    /// (TO)".
    pub fn describe(&self) -> String {
        let by = self.instance.name().unwrap_or("a reserved instance");
        let why = match self.msac_c2_reason() {
            Some(r) => r
                .name()
                .map(str::to_string)
                .unwrap_or_else(|| format!("reason {}", self.reason)),
            None => format!("reason {}", self.reason),
        };
        let mut s = format!("aborted by {by}: {why}");
        if self.additional_detail != 0 {
            s.push_str(&format!(", detail 0x{:02X}", self.additional_detail));
        }
        s
    }
}

/// A class-2 PDU, borrowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum C2Pdu<'a> {
    /// Initiate.req (master → RM on SAP 49).
    InitiateReq(InitiateReq<'a>),
    /// Initiate.res (slave, on the connection SAP).
    InitiateRes(InitiateRes<'a>),
    /// The resource manager's reply (slave, on SAP 49).
    Rm(RmReply),
    /// Read request.
    ReadReq {
        /// Slot 0..=254.
        slot: u8,
        /// Index 0..=255 (255: the I&M call).
        index: u8,
        /// Bytes wanted (1..=240).
        length: u8,
    },
    /// Positive read response.
    ReadRes {
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// The data read.
        data: &'a [u8],
    },
    /// Write request.
    WriteReq {
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// The data to write.
        data: &'a [u8],
    },
    /// Positive write response.
    WriteRes {
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// Bytes written.
        length: u8,
    },
    /// Data_Transport request (write and read in one exchange).
    DataTransportReq {
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// The data sent.
        data: &'a [u8],
    },
    /// Data_Transport response.
    DataTransportRes {
        /// Slot.
        slot: u8,
        /// Index.
        index: u8,
        /// The data returned.
        data: &'a [u8],
    },
    /// Idle: keep-alive of an idle connection (both directions).
    Idle,
    /// Abort (either direction).
    Abort(Abort),
    /// Negative response.
    Error(Dpv1Error),
}

/// A class-2 PDU that cannot be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum C2ParseError {
    /// Empty PDU.
    #[error("empty MSAC_C2 PDU")]
    Empty,
    /// Too short for its function.
    #[error("MSAC_C2 PDU with function 0x{function:02X} is {got} bytes long, needs {needed}")]
    Length {
        /// Function byte.
        function: u8,
        /// Bytes needed.
        needed: usize,
        /// Bytes received.
        got: usize,
    },
    /// The length byte disagrees with the data carried.
    #[error("MSAC_C2 length byte {length} disagrees with {data} data bytes")]
    LengthByte {
        /// Length byte.
        length: u8,
        /// Data bytes present.
        data: usize,
    },
    /// An address type/length pair of Initiate that is not valid (IA).
    #[error(
        "Initiate address of type {kind} with length {len} (type 0 needs 2, type 1 at least 8)"
    )]
    Address {
        /// S_Type or D_Type.
        kind: u8,
        /// S_Len or D_Len.
        len: usize,
    },
    /// The address lengths of Initiate disagree with the PDU's length.
    #[error("Initiate addresses need {needed} bytes, the PDU has {got}")]
    AddressLength {
        /// Bytes the header announces.
        needed: usize,
        /// Bytes present.
        got: usize,
    },
    /// An unknown function number for this direction.
    #[error("unknown MSAC_C2 function 0x{0:02X}")]
    UnknownFunction(u8),
}

fn need(du: &[u8], n: usize) -> Result<(), C2ParseError> {
    if du.len() < n {
        Err(C2ParseError::Length {
            function: du.first().copied().unwrap_or(0),
            needed: n,
            got: du.len(),
        })
    } else {
        Ok(())
    }
}

fn with_data(du: &[u8]) -> Result<(u8, u8, &[u8]), C2ParseError> {
    need(du, 4)?;
    let data = &du[4..];
    if du[3] as usize != data.len() {
        return Err(C2ParseError::LengthByte {
            length: du[3],
            data: data.len(),
        });
    }
    Ok((du[1], du[2], data))
}

fn be(du: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([du[at], du[at + 1]])
}

/// The four type/length bytes at `at` and the two addresses after them.
fn addresses(
    du: &[u8],
    at: usize,
) -> Result<(AddrParams<'_>, AddrParams<'_>, usize), C2ParseError> {
    let (s_type, s_len, d_type, d_len) =
        (du[at], du[at + 1] as usize, du[at + 2], du[at + 3] as usize);
    let start = at + 4;
    let needed = start + s_len + d_len;
    if du.len() < needed {
        return Err(C2ParseError::AddressLength {
            needed,
            got: du.len(),
        });
    }
    let source = AddrParams::parse(s_type, &du[start..start + s_len])?;
    let destination = AddrParams::parse(d_type, &du[start + s_len..needed])?;
    Ok((source, destination, needed))
}

fn abort(du: &[u8]) -> Result<C2Pdu<'_>, C2ParseError> {
    need(du, 3)?;
    Ok(C2Pdu::Abort(Abort {
        subnet: AbortSubnet::from_code(du[1]),
        instance: AbortInstance::from_code((du[2] >> 4) & 0x03),
        reason: du[2] & 0x0F,
        additional_detail: du.get(3).copied().unwrap_or(0),
    }))
}

impl<'a> C2Pdu<'a> {
    /// Decode a PDU sent by a class-2 master (Initiate.req, Read/Write/
    /// Data_Transport requests, Idle, Abort).
    pub fn parse_request(du: &'a [u8]) -> Result<C2Pdu<'a>, C2ParseError> {
        let &f = du.first().ok_or(C2ParseError::Empty)?;
        match f {
            FN_INITIATE => {
                need(du, INITIATE_REQ_MIN_LEN)?;
                let (source, destination, _) = addresses(du, 12)?;
                Ok(C2Pdu::InitiateReq(InitiateReq {
                    send_timeout: be(du, 4),
                    features_supported_1: du[6],
                    features_supported_2: du[7],
                    profile_features_supported: be(du, 8),
                    profile_ident_number: be(du, 10),
                    source,
                    destination,
                }))
            }
            FN_READ => {
                need(du, 4)?;
                Ok(C2Pdu::ReadReq {
                    slot: du[1],
                    index: du[2],
                    length: du[3],
                })
            }
            FN_WRITE => {
                let (slot, index, data) = with_data(du)?;
                Ok(C2Pdu::WriteReq { slot, index, data })
            }
            FN_DATA_TRANSPORT => {
                let (slot, index, data) = with_data(du)?;
                Ok(C2Pdu::DataTransportReq { slot, index, data })
            }
            FN_IDLE => Ok(C2Pdu::Idle),
            FN_ABORT => abort(du),
            other => Err(C2ParseError::UnknownFunction(other)),
        }
    }

    /// Decode a PDU sent by a slave (RM reply, Initiate.res, responses,
    /// Idle, Abort, negative responses).
    pub fn parse_response(du: &'a [u8]) -> Result<C2Pdu<'a>, C2ParseError> {
        let &f = du.first().ok_or(C2ParseError::Empty)?;
        if f & 0x80 != 0 {
            need(du, 4)?;
            return Ok(C2Pdu::Error(Dpv1Error {
                function: f,
                error_decode: du[1],
                error_code_1: du[2],
                error_code_2: du[3],
            }));
        }
        match f {
            FN_RM => {
                need(du, 4)?;
                Ok(C2Pdu::Rm(RmReply {
                    sap: du[1],
                    poll_timeout: be(du, 2),
                }))
            }
            FN_INITIATE => {
                need(du, INITIATE_RES_MIN_LEN)?;
                let (source, destination, _) = addresses(du, 8)?;
                Ok(C2Pdu::InitiateRes(InitiateRes {
                    max_len_data_unit: du[1],
                    features_supported_1: du[2],
                    features_supported_2: du[3],
                    profile_features_supported: be(du, 4),
                    profile_ident_number: be(du, 6),
                    source,
                    destination,
                }))
            }
            FN_READ => {
                let (slot, index, data) = with_data(du)?;
                Ok(C2Pdu::ReadRes { slot, index, data })
            }
            FN_WRITE => {
                need(du, 4)?;
                Ok(C2Pdu::WriteRes {
                    slot: du[1],
                    index: du[2],
                    length: du[3],
                })
            }
            FN_DATA_TRANSPORT => {
                let (slot, index, data) = with_data(du)?;
                Ok(C2Pdu::DataTransportRes { slot, index, data })
            }
            FN_IDLE => Ok(C2Pdu::Idle),
            FN_ABORT => abort(du),
            other => Err(C2ParseError::UnknownFunction(other)),
        }
    }

    /// The function byte of this PDU.
    pub fn function(&self) -> u8 {
        match self {
            C2Pdu::InitiateReq(_) | C2Pdu::InitiateRes(_) => FN_INITIATE,
            C2Pdu::Rm(_) => FN_RM,
            C2Pdu::ReadReq { .. } | C2Pdu::ReadRes { .. } => FN_READ,
            C2Pdu::WriteReq { .. } | C2Pdu::WriteRes { .. } => FN_WRITE,
            C2Pdu::DataTransportReq { .. } | C2Pdu::DataTransportRes { .. } => FN_DATA_TRANSPORT,
            C2Pdu::Idle => FN_IDLE,
            C2Pdu::Abort(_) => FN_ABORT,
            C2Pdu::Error(e) => e.function,
        }
    }

    /// Encode into `buf`; returns the length, or `None` when `buf` is too
    /// small or data exceed 240 bytes.
    pub fn emit(&self, buf: &mut [u8]) -> Option<usize> {
        let head = |buf: &mut [u8], f: u8, slot: u8, index: u8, data: &[u8]| {
            let n = 4 + data.len();
            if data.len() > MAX_DATA_LEN || buf.len() < n {
                return None;
            }
            buf[..4].copy_from_slice(&[f, slot, index, data.len() as u8]);
            buf[4..n].copy_from_slice(data);
            Some(n)
        };
        let fixed = |buf: &mut [u8], bytes: &[u8]| {
            let out = buf.get_mut(..bytes.len())?;
            out.copy_from_slice(bytes);
            Some(bytes.len())
        };
        match *self {
            C2Pdu::InitiateReq(r) => {
                let mut h = [0u8; 16];
                h[0] = FN_INITIATE;
                h[4..6].copy_from_slice(&r.send_timeout.to_be_bytes());
                h[6] = r.features_supported_1;
                h[7] = r.features_supported_2;
                h[8..10].copy_from_slice(&r.profile_features_supported.to_be_bytes());
                h[10..12].copy_from_slice(&r.profile_ident_number.to_be_bytes());
                emit_initiate(buf, &h, 12, &r.source, &r.destination)
            }
            C2Pdu::InitiateRes(r) => {
                let mut h = [0u8; 12];
                h[0] = FN_INITIATE;
                h[1] = r.max_len_data_unit;
                h[2] = r.features_supported_1;
                h[3] = r.features_supported_2;
                h[4..6].copy_from_slice(&r.profile_features_supported.to_be_bytes());
                h[6..8].copy_from_slice(&r.profile_ident_number.to_be_bytes());
                emit_initiate(buf, &h, 8, &r.source, &r.destination)
            }
            C2Pdu::Rm(r) => {
                let t = r.poll_timeout.to_be_bytes();
                fixed(buf, &[FN_RM, r.sap, t[0], t[1]])
            }
            C2Pdu::ReadReq {
                slot,
                index,
                length,
            } => fixed(buf, &[FN_READ, slot, index, length]),
            C2Pdu::ReadRes { slot, index, data } => head(buf, FN_READ, slot, index, data),
            C2Pdu::WriteReq { slot, index, data } => head(buf, FN_WRITE, slot, index, data),
            C2Pdu::WriteRes {
                slot,
                index,
                length,
            } => fixed(buf, &[FN_WRITE, slot, index, length]),
            C2Pdu::DataTransportReq { slot, index, data }
            | C2Pdu::DataTransportRes { slot, index, data } => {
                head(buf, FN_DATA_TRANSPORT, slot, index, data)
            }
            C2Pdu::Idle => fixed(buf, &[FN_IDLE, 0]),
            C2Pdu::Abort(a) => fixed(
                buf,
                &[
                    FN_ABORT,
                    a.subnet.code(),
                    ((a.instance.code() & 0x03) << 4) | (a.reason & 0x0F),
                    a.additional_detail,
                ],
            ),
            C2Pdu::Error(e) => fixed(
                buf,
                &[e.function, e.error_decode, e.error_code_1, e.error_code_2],
            ),
        }
    }
}

/// Header `h` (with the type/length bytes at `at` still zero), then the
/// two addresses.
fn emit_initiate(
    buf: &mut [u8],
    h: &[u8],
    at: usize,
    s: &AddrParams<'_>,
    d: &AddrParams<'_>,
) -> Option<usize> {
    let n = h.len() + s.len() + d.len();
    if buf.len() < n || s.len() > 255 || d.len() > 255 {
        return None;
    }
    buf[..h.len()].copy_from_slice(h);
    buf[at] = s.addr_type();
    buf[at + 1] = s.len() as u8;
    buf[at + 2] = d.addr_type();
    buf[at + 3] = d.len() as u8;
    s.emit(&mut buf[h.len()..h.len() + s.len()]);
    d.emit(&mut buf[h.len() + s.len()..n]);
    Some(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference's minimal Initiate.req: Send_Timeout 1 s, R/W
    /// supported, no profile (dpv1-c2-im-alarms.md §4.4).
    const INITIATE_REQ: [u8; 20] = [
        0x57, 0x00, 0x00, 0x00, 0x00, 0x64, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00,
        0x02, 0x00, 0x00, 0x00, 0x00,
    ];
    /// The reference's Initiate.res example.
    const INITIATE_RES: [u8; 16] = [
        0x57, 0xF0, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x02, 0x00, 0x00, 0x00,
        0x00,
    ];

    #[test]
    fn reference_initiate_request() {
        let C2Pdu::InitiateReq(r) = C2Pdu::parse_request(&INITIATE_REQ).unwrap() else {
            panic!("not an Initiate.req");
        };
        assert_eq!(r.send_timeout, 100);
        assert_eq!(r.features_supported_1, FEATURE_DPV1_RW);
        assert_eq!(r.profile_ident_number, 0);
        assert_eq!(r.source, AddrParams::default());
        let mut buf = [0; 64];
        let n = C2Pdu::InitiateReq(r).emit(&mut buf).unwrap();
        assert_eq!(&buf[..n], &INITIATE_REQ);
    }

    #[test]
    fn reference_initiate_response() {
        let C2Pdu::InitiateRes(r) = C2Pdu::parse_response(&INITIATE_RES).unwrap() else {
            panic!("not an Initiate.res");
        };
        assert_eq!(r.max_len_data_unit, 240);
        assert_eq!(r.features_supported_1, 1);
        let mut buf = [0; 64];
        let n = C2Pdu::InitiateRes(r).emit(&mut buf).unwrap();
        assert_eq!(&buf[..n], &INITIATE_RES);
    }

    #[test]
    fn rm_idle_abort_transport() {
        assert_eq!(
            C2Pdu::parse_response(&[0x56, 0x30, 0x00, 0x64]),
            Ok(C2Pdu::Rm(RmReply {
                sap: 48,
                poll_timeout: 100
            }))
        );
        assert_eq!(C2Pdu::parse_request(&[0x48, 0x00]), Ok(C2Pdu::Idle));
        let a = C2Pdu::parse_request(&[0x58, 0x00, 0x13, 0x00]).unwrap();
        let C2Pdu::Abort(abort) = a else { panic!() };
        assert_eq!(abort.msac_c2_reason(), Some(AbortReason::Timeout));
        assert_eq!(
            abort.describe(),
            "aborted by MSAC_C2: connection timeout (TO)"
        );
        let mut buf = [0; 8];
        assert_eq!(a.emit(&mut buf), Some(4));
        assert_eq!(&buf[..4], &[0x58, 0x00, 0x13, 0x00]);
        let user = C2Pdu::parse_response(&[0x58, 0x01, 0x25, 0x07]).unwrap();
        let C2Pdu::Abort(user) = user else { panic!() };
        assert_eq!(user.instance, AbortInstance::User);
        assert_eq!(user.describe(), "aborted by user: reason 5, detail 0x07");
        assert_eq!(
            C2Pdu::parse_request(&[0x51, 1, 2, 2, 0xAA, 0xBB]),
            Ok(C2Pdu::DataTransportReq {
                slot: 1,
                index: 2,
                data: &[0xAA, 0xBB]
            })
        );
        assert_eq!(
            C2Pdu::parse_response(&[0xD1, 0x80, 0xA9, 0x00]),
            Ok(C2Pdu::Error(Dpv1Error::dpv1(FN_DATA_TRANSPORT, 0xA, 9)))
        );
    }

    #[test]
    fn every_abort_reason_has_words() {
        for (code, short) in [
            (1, "SE"),
            (2, "FE"),
            (3, "TO"),
            (4, "RE"),
            (5, "IV"),
            (6, "STO"),
            (7, "IA"),
            (8, "OC"),
            (15, "RES"),
        ] {
            let words = AbortReason::from_code(code).name().unwrap();
            assert!(words.ends_with(&format!("({short})")), "{words}");
        }
    }

    #[test]
    fn type_one_address_round_trips() {
        let mac = [7, 8];
        let r = InitiateReq {
            send_timeout: 300,
            destination: AddrParams {
                api: 1,
                scl: 0,
                extension: Some(AddrExtension {
                    network_address: [1, 2, 3, 4, 5, 6],
                    mac_address: &mac,
                }),
            },
            ..InitiateReq::default()
        };
        let mut buf = [0; 64];
        let n = C2Pdu::InitiateReq(r).emit(&mut buf).unwrap();
        assert_eq!(n, 16 + 2 + 10);
        assert_eq!(&buf[12..16], &[0, 2, 1, 10]);
        assert_eq!(C2Pdu::parse_request(&buf[..n]), Ok(C2Pdu::InitiateReq(r)));
    }

    #[test]
    fn bad_pdus() {
        assert_eq!(C2Pdu::parse_request(&[]), Err(C2ParseError::Empty));
        assert!(matches!(
            C2Pdu::parse_request(&INITIATE_REQ[..19]),
            Err(C2ParseError::Length { needed: 20, .. })
        ));
        let mut bad = INITIATE_REQ;
        bad[13] = 3;
        assert_eq!(
            C2Pdu::parse_request(&bad),
            Err(C2ParseError::AddressLength {
                needed: 21,
                got: 20
            })
        );
        let mut bad = INITIATE_REQ;
        bad[12] = 2;
        assert_eq!(
            C2Pdu::parse_request(&bad),
            Err(C2ParseError::Address { kind: 2, len: 2 })
        );
        assert!(C2Pdu::parse_request(&[0x51, 0, 0, 3, 1]).is_err());
        assert_eq!(
            C2Pdu::parse_request(&[0x56, 0, 0, 0]),
            Err(C2ParseError::UnknownFunction(0x56))
        );
        assert!(C2Pdu::parse_response(&[0x56, 0]).is_err());
    }
}
