//! FMS PDUs (PROFIBUS-FMS, EN 50170 vol. 2 part 5/6): what a client and
//! a server of the Fieldbus Message Specification exchange inside the
//! data unit of an LLI telegram.
//!
//! ```text
//! Confirmed request    TYPE=1 invoke service body…
//! Confirmed response   TYPE=2 invoke service body…
//! Confirmed error      TYPE=3 invoke service class code additional_hi additional_lo
//! Unconfirmed          TYPE=4 service body…
//! Reject               TYPE=5 original_invoke pdu_type reject_code
//! Initiate request     TYPE=6 version(2) profile(2) protection password groups
//!                             max_send_hi max_send_lo max_recv_hi max_recv_lo features(6)
//! Initiate response    TYPE=7 version(2) profile(2) protection password groups
//! Initiate error       TYPE=8 error_code
//!
//! Status      request: –                 response: logical physical detail(3)
//! Identify    request: –                 response: len vendor len model len revision
//! Read        request: index(2) [sub]    response: data…
//! Write       request: index(2) sub data response: –
//! Get-OD      request: flags index(2)    response: more count {len description}…
//! Info-Report request: index(2) data…    (unconfirmed)
//! ```
//!
//! Multi-byte integers are big-endian.
//!
//! # What is confirmed and what is not
//!
//! Sources (URLs and pages in `docs/fms.md`):
//! - \[P5\] PROFIBUS-Specification-Normative-Parts-5:1997 (PNO): services,
//!   the types of every service parameter (p.310, table 70), the FMS
//!   Features Supported bits (p.206, table 13), the invoke-ID rules of
//!   the client (p.225), the mapping of FMS onto the LLI (p.292).
//! - \[P6\] PROFIBUS-Specification-Normative-Parts-6:1997 (PNO): the
//!   abstract syntax of Initiate-Request/Response (p.341).
//! - \[S505\] SIMATIC 505 PROFIBUS-FMS CP User Manual, A-12…A-14: the
//!   fields of the Status and Identify responses and the Status codes.
//! - \[FF\] the Foundation Fieldbus FMS service numbers (Wireshark's
//!   `packet-ff.c`), FMS's sibling: Status 0, Identify 1, Read 2,
//!   Write 3, Get-OD 4; Information-Report 0 (unconfirmed).
//!
//! Confirmed by two sources: the services and their parameters with
//! their types (\[P5\] p.310 with \[P6\] p.341 for Initiate, with
//! \[S505\] for Status and Identify); the invoke ID is one octet
//! (\[P5\] p.225, p.310 `Original Invoke ID Integer8`); the Status codes
//! (\[S505\] table A-3 with the Unsigned8 types of \[P5\]); Abort is no
//! FMS PDU but the LLI's own abort (\[P5\] p.292; see
//! [`crate::fms::lli`]).
//!
//! (unverified): the transfer syntax of the part-6 encoding rules, which
//! no public source we found shows: the PDU type octet and its values
//! ([`PduType`]), the service numbers (only \[FF\], a sibling protocol),
//! the order of the fields on the wire (we follow the abstract syntax's
//! order), the Get-OD flag bits, the length octets of strings and object
//! descriptions, the Initiate-Error body. Our client and server agree with
//! each other; a third-party FMS device may not agree with them.

use core::fmt;

/// The most bytes an FMS PDU may take: the FDL data unit of an SRD/SDA
/// telegram with SAPs (246 − DSAP − SSAP).
pub const MAX_PDU_LEN: usize = 244;

/// The PDU type octet, the first of every FMS PDU (unverified: values and
/// position chosen by this implementation, see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum PduType {
    /// Confirmed-RequestPDU.
    ConfirmedRequest = 1,
    /// Confirmed-ResponsePDU.
    ConfirmedResponse = 2,
    /// Confirmed-ErrorPDU.
    ConfirmedError = 3,
    /// Unconfirmed-PDU.
    Unconfirmed = 4,
    /// Reject-PDU.
    Reject = 5,
    /// Initiate-RequestPDU.
    InitiateRequest = 6,
    /// Initiate-ResponsePDU.
    InitiateResponse = 7,
    /// Initiate-ErrorPDU.
    InitiateError = 8,
}

impl PduType {
    /// The type of a first octet.
    pub fn from_u8(b: u8) -> Option<PduType> {
        Some(match b {
            1 => PduType::ConfirmedRequest,
            2 => PduType::ConfirmedResponse,
            3 => PduType::ConfirmedError,
            4 => PduType::Unconfirmed,
            5 => PduType::Reject,
            6 => PduType::InitiateRequest,
            7 => PduType::InitiateResponse,
            8 => PduType::InitiateError,
            _ => return None,
        })
    }

    /// The PDU type in words.
    pub fn name(self) -> &'static str {
        match self {
            PduType::ConfirmedRequest => "confirmed request",
            PduType::ConfirmedResponse => "confirmed response",
            PduType::ConfirmedError => "confirmed error",
            PduType::Unconfirmed => "unconfirmed",
            PduType::Reject => "reject",
            PduType::InitiateRequest => "Initiate request",
            PduType::InitiateResponse => "Initiate response",
            PduType::InitiateError => "Initiate error",
        }
    }
}

/// A confirmed service (the service octet; numbers from \[FF\],
/// unverified for PROFIBUS).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Service {
    /// Status: the server's logical and physical state.
    Status = 0,
    /// Identify: vendor, model and revision.
    Identify = 1,
    /// Read: one object's value (by index).
    Read = 2,
    /// Write: one object's value (by index).
    Write = 3,
    /// Get-OD: object descriptions of the object dictionary.
    GetOd = 4,
}

impl Service {
    /// The service of a service octet.
    pub fn from_u8(b: u8) -> Option<Service> {
        Some(match b {
            0 => Service::Status,
            1 => Service::Identify,
            2 => Service::Read,
            3 => Service::Write,
            4 => Service::GetOd,
            _ => return None,
        })
    }

    /// The service's name as the standard writes it.
    pub fn name(self) -> &'static str {
        match self {
            Service::Status => "Status",
            Service::Identify => "Identify",
            Service::Read => "Read",
            Service::Write => "Write",
            Service::GetOd => "Get-OD",
        }
    }
}

/// The service octet of Information-Report in an unconfirmed PDU
/// (\[FF\], unverified for PROFIBUS).
pub const UNCONFIRMED_INFORMATION_REPORT: u8 = 0;

/// Get-OD.req: which object descriptions to send.
///
/// Short form (`long_form == false`): the descriptions without the
/// optional parts (names, extensions); long form: all attributes
/// (\[P5\] table 13 "GetOD (Long form)" is an option of the CRL).
/// `from_index`: the description at `index` and those after it, as many
/// as fit (the response says whether more follow); else only `index`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GetOdRequest {
    /// All attributes (long form).
    pub long_form: bool,
    /// Start index: `index` and the following ones.
    pub from_index: bool,
    /// Object index (0 = the OD header).
    pub index: u16,
}

/// Get-OD flags octet: bit 7 all attributes, bit 6 start index
/// (unverified; \[FF\] has the same two flags in this order).
const GETOD_ALL_ATTRIBUTES: u8 = 0x80;
const GETOD_START_INDEX: u8 = 0x40;

/// A confirmed service request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Request {
    /// Status.req (no parameters).
    Status,
    /// Identify.req (no parameters).
    Identify,
    /// Read.req of an object, or of one element (`subindex`, 1-based).
    Read {
        /// Object index.
        index: u16,
        /// Element of an array or record (1-based), if any.
        subindex: Option<u8>,
    },
    /// Write.req of an object or of one element.
    Write {
        /// Object index.
        index: u16,
        /// Element (1-based), if any.
        subindex: Option<u8>,
        /// The new value.
        data: Vec<u8>,
    },
    /// Get-OD.req.
    GetOd(GetOdRequest),
}

impl Request {
    /// The service this request asks for.
    pub fn service(&self) -> Service {
        match self {
            Request::Status => Service::Status,
            Request::Identify => Service::Identify,
            Request::Read { .. } => Service::Read,
            Request::Write { .. } => Service::Write,
            Request::GetOd(_) => Service::GetOd,
        }
    }
}

/// A positive confirmed service response.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Response {
    /// Status.res.
    Status(StatusResponse),
    /// Identify.res.
    Identify(IdentifyResponse),
    /// Read.res: the value.
    Read(Vec<u8>),
    /// Write.res (no parameters).
    Write,
    /// Get-OD.res.
    GetOd {
        /// More descriptions follow (ask again from the next index).
        more_follows: bool,
        /// The object descriptions, each as its bytes (the BK3000 builds them:
        /// `profibus_devices::bk3000::fms`).
        descriptions: Vec<Vec<u8>>,
    },
}

impl Response {
    /// The service this response answers.
    pub fn service(&self) -> Service {
        match self {
            Response::Status(_) => Service::Status,
            Response::Identify(_) => Service::Identify,
            Response::Read(_) => Service::Read,
            Response::Write => Service::Write,
            Response::GetOd { .. } => Service::GetOd,
        }
    }
}

/// Status.res (\[P5\] p.310 types; \[S505\] A-12 codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StatusResponse {
    /// Logical status ([`LOGICAL_READY`], [`LOGICAL_LIMITED`]).
    pub logical: u8,
    /// Physical status ([`PHYSICAL_OPERATIONAL`] …).
    pub physical: u8,
    /// Local detail: vendor-specific (bit string, 3 octets).
    pub local_detail: [u8; 3],
}

/// Logical status: ready for communication.
pub const LOGICAL_READY: u8 = 0x00;
/// Logical status: limited services.
pub const LOGICAL_LIMITED: u8 = 0x02;
/// Physical status: operational.
pub const PHYSICAL_OPERATIONAL: u8 = 0x10;
/// Physical status: partly operational.
pub const PHYSICAL_PARTLY: u8 = 0x11;
/// Physical status: not operational.
pub const PHYSICAL_NOT_OPERATIONAL: u8 = 0x12;
/// Physical status: maintenance required.
pub const PHYSICAL_MAINTENANCE: u8 = 0x13;

impl StatusResponse {
    /// The logical status in words.
    pub fn logical_text(&self) -> &'static str {
        match self.logical {
            LOGICAL_READY => "ready for communication",
            LOGICAL_LIMITED => "limited services",
            _ => "unknown logical status",
        }
    }

    /// The physical status in words.
    pub fn physical_text(&self) -> &'static str {
        match self.physical {
            PHYSICAL_OPERATIONAL => "operational",
            PHYSICAL_PARTLY => "partly operational",
            PHYSICAL_NOT_OPERATIONAL => "not operational",
            PHYSICAL_MAINTENANCE => "maintenance required",
            _ => "unknown physical status",
        }
    }
}

/// Identify.res: three visible strings (\[P5\] p.310, \[S505\] A-13).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct IdentifyResponse {
    /// Vendor name.
    pub vendor: String,
    /// Model name.
    pub model: String,
    /// Revision.
    pub revision: String,
}

/// The error of a negative response (Confirmed-ErrorPDU): error class,
/// error code and an additional code (\[P5\]; class/code values below are
/// unverified).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceError {
    /// Error class.
    pub class: u8,
    /// Error code within the class.
    pub code: u8,
    /// Additional (vendor-specific) code.
    pub additional: u16,
}

/// Error class "access" (unverified value).
pub const ERROR_CLASS_ACCESS: u8 = 6;
/// Error class "object dictionary" (unverified value).
pub const ERROR_CLASS_OD: u8 = 7;
/// Error class "service" (unverified value).
pub const ERROR_CLASS_SERVICE: u8 = 5;
/// Access error: object does not exist (unverified value).
pub const ACCESS_OBJECT_NON_EXISTENT: u8 = 7;
/// Access error: hardware fault — the object could not be reached.
/// Class 6 code 2 as in the INTERBUS PCP manuals below (FMS's subset
/// with the same error coding).
pub const ACCESS_HARDWARE_FAULT: u8 = 2;
/// Access error: object access denied (read-only, write-only). Class 6
/// code 3 as in two INTERBUS PCP manuals (Bürkert Type 8644 p.83,
/// "Object Access Denied 06h / 03h"; Nidec SI-Interbus p.57); for
/// PROFIBUS-FMS itself (unverified).
pub const ACCESS_DENIED: u8 = 3;
/// Access error: object access unsupported — the service does not
/// apply to the object (Bürkert Type 8644 p.83, 06h / 06h).
pub const ACCESS_UNSUPPORTED: u8 = 6;
/// Access error: type or length of the value do not fit the object.
pub const ACCESS_TYPE_CONFLICT: u8 = 10;
/// Access error: object attribute inconsistent — a service parameter the
/// object does not allow, e.g. a subindex it has no element for. Class 6
/// code 5 with this meaning is confirmed for INTERBUS PCP, FMS's subset
/// with the same error coding, by two manuals: Bürkert Type 8644 p.87
/// ("an impermissible sub-index") and Nidec SI-Interbus p.57 (sub-index
/// zero access error); for PROFIBUS-FMS itself (unverified).
pub const ACCESS_ATTRIBUTE_INCONSISTENT: u8 = 5;
/// Service error: parameter inconsistent.
pub const SERVICE_PARAMETER_INCONSISTENT: u8 = 3;
/// OD error: index out of the dictionary (Get-OD).
pub const OD_INVALID_INDEX: u8 = 1;

impl ServiceError {
    /// An error of class and code.
    pub fn new(class: u8, code: u8) -> ServiceError {
        ServiceError {
            class,
            code,
            additional: 0,
        }
    }

    /// What the class and code mean, in a few words.
    pub fn meaning(&self) -> &'static str {
        match (self.class, self.code) {
            (ERROR_CLASS_ACCESS, ACCESS_OBJECT_NON_EXISTENT) => "object does not exist",
            (ERROR_CLASS_ACCESS, ACCESS_DENIED) => "object access denied",
            (ERROR_CLASS_ACCESS, ACCESS_HARDWARE_FAULT) => "hardware fault",
            (ERROR_CLASS_ACCESS, ACCESS_UNSUPPORTED) => "object access unsupported",
            (ERROR_CLASS_ACCESS, ACCESS_TYPE_CONFLICT) => "type or length conflict",
            (ERROR_CLASS_ACCESS, ACCESS_ATTRIBUTE_INCONSISTENT) => "object attribute inconsistent",
            (ERROR_CLASS_ACCESS, _) => "access error",
            (ERROR_CLASS_SERVICE, SERVICE_PARAMETER_INCONSISTENT) => "parameter inconsistent",
            (ERROR_CLASS_SERVICE, _) => "service error",
            (ERROR_CLASS_OD, OD_INVALID_INDEX) => "index not in the object dictionary",
            (ERROR_CLASS_OD, _) => "object dictionary error",
            _ => "error",
        }
    }

    /// The error in words.
    pub fn describe(&self) -> String {
        format!(
            "{} (class {}, code {}, additional code {})",
            self.meaning(),
            self.class,
            self.code,
            self.additional
        )
    }
}

/// Initiate-Request (\[P6\] p.341, fields in that order).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InitiateRequest {
    /// Version of the client's object dictionary (Integer16).
    pub version_od: i16,
    /// Profile number (2 octets, \[P5\] p.310).
    pub profile: [u8; 2],
    /// Access protection supported.
    pub access_protection: bool,
    /// Password.
    pub password: u8,
    /// Access groups (bit string).
    pub access_groups: u8,
    /// Max PDU sending, high priority.
    pub max_pdu_send_high: u8,
    /// Max PDU sending, low priority.
    pub max_pdu_send_low: u8,
    /// Max PDU receiving, high priority.
    pub max_pdu_recv_high: u8,
    /// Max PDU receiving, low priority.
    pub max_pdu_recv_low: u8,
    /// FMS Features Supported (\[P5\] table 13; bits 0..23 the client's
    /// .req/.con, 24..47 the server's .ind/.res).
    pub features: [u8; 6],
}

/// Initiate-Response (\[P6\] p.341).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InitiateResponse {
    /// Version of the server's object dictionary.
    pub version_od: i16,
    /// Profile number.
    pub profile: [u8; 2],
    /// Access protection supported.
    pub access_protection: bool,
    /// Password.
    pub password: u8,
    /// Access groups.
    pub access_groups: u8,
}

/// An FMS PDU.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FmsPdu {
    /// A confirmed service request.
    Request {
        /// Invoke ID (pairs the response with its request).
        invoke_id: u8,
        /// The request.
        request: Request,
    },
    /// A positive confirmed service response.
    Response {
        /// Invoke ID of the request.
        invoke_id: u8,
        /// The response.
        response: Response,
    },
    /// A negative confirmed service response.
    Error {
        /// Invoke ID of the request.
        invoke_id: u8,
        /// The service that failed.
        service: Service,
        /// Why.
        error: ServiceError,
    },
    /// Information-Report (unconfirmed): a server publishes an object.
    InformationReport {
        /// Object index.
        index: u16,
        /// The value.
        data: Vec<u8>,
    },
    /// Reject: a PDU that could not be handled.
    Reject {
        /// Invoke ID of the rejected PDU (0 when it had none).
        original_invoke_id: u8,
        /// PDU type octet of the rejected PDU.
        pdu_type: u8,
        /// Reject code ([`REJECT_PDU_SIZE`], …).
        code: u8,
    },
    /// Initiate-Request (rides on the LLI's connect).
    InitiateRequest(InitiateRequest),
    /// Initiate-Response.
    InitiateResponse(InitiateResponse),
    /// Initiate-Error.
    InitiateError {
        /// Error code (unverified).
        code: u8,
    },
}

/// Reject code: other (\[P5\] p.225 treats 0 and 5 alike).
pub const REJECT_OTHER: u8 = 0;
/// Reject code: invalid PDU size (\[P5\] p.225: reject code 5 is the one
/// the client reports).
pub const REJECT_PDU_SIZE: u8 = 5;

/// A reject code in words (the two codes of \[P5\] p.225; others by
/// number).
pub fn reject_code_text(code: u8) -> &'static str {
    match code {
        REJECT_OTHER => "other reason",
        REJECT_PDU_SIZE => "invalid PDU size",
        _ => "reject code without words",
    }
}

/// An FMS PDU that cannot be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FmsParseError {
    /// Nothing to decode.
    #[error("empty FMS PDU")]
    Empty,
    /// Unknown first octet.
    #[error("unknown FMS PDU type {0}")]
    UnknownType(u8),
    /// Unknown service octet.
    #[error("unknown FMS service {service} in a {kind} PDU")]
    UnknownService {
        /// The PDU type in words.
        kind: &'static str,
        /// Service octet.
        service: u8,
    },
    /// Too short.
    #[error("FMS {what} is {got} bytes long, needs {needed}")]
    Length {
        /// What was decoded.
        what: &'static str,
        /// Bytes needed.
        needed: usize,
        /// Bytes present.
        got: usize,
    },
    /// Bytes after the end of a fixed-length PDU.
    #[error("FMS {what} has {extra} bytes too many")]
    Trailing {
        /// What was decoded.
        what: &'static str,
        /// Extra bytes.
        extra: usize,
    },
    /// A string that is not visible ASCII.
    #[error("FMS {what} holds a byte 0x{byte:02X} that is no visible character")]
    NotVisible {
        /// Which string.
        what: &'static str,
        /// The byte.
        byte: u8,
    },
    /// Longer than an FDL telegram carries.
    #[error("FMS PDU of {0} bytes (at most {MAX_PDU_LEN})")]
    TooLong(usize),
    /// A BOOLEAN that is neither 0 nor 0xFF.
    #[error("FMS {what} is 0x{byte:02X}, neither 0x00 (false) nor 0xFF (true)")]
    Boolean {
        /// Which field.
        what: &'static str,
        /// The byte.
        byte: u8,
    },
}

/// A cursor over a PDU's bytes.
struct Rd<'a> {
    du: &'a [u8],
    at: usize,
    what: &'static str,
}

impl<'a> Rd<'a> {
    fn need(&self, n: usize) -> Result<(), FmsParseError> {
        if self.du.len() < self.at + n {
            Err(FmsParseError::Length {
                what: self.what,
                needed: self.at + n,
                got: self.du.len(),
            })
        } else {
            Ok(())
        }
    }
    fn u8(&mut self) -> Result<u8, FmsParseError> {
        self.need(1)?;
        self.at += 1;
        Ok(self.du[self.at - 1])
    }
    fn u16(&mut self) -> Result<u16, FmsParseError> {
        Ok(u16::from_be_bytes([self.u8()?, self.u8()?]))
    }
    fn bytes(&mut self, n: usize) -> Result<&'a [u8], FmsParseError> {
        self.need(n)?;
        self.at += n;
        Ok(&self.du[self.at - n..self.at])
    }
    fn rest(&mut self) -> &'a [u8] {
        let r = &self.du[self.at..];
        self.at = self.du.len();
        r
    }
    fn boolean(&mut self, what: &'static str) -> Result<bool, FmsParseError> {
        match self.u8()? {
            0 => Ok(false),
            0xFF => Ok(true),
            byte => Err(FmsParseError::Boolean { what, byte }),
        }
    }
    fn string(&mut self, what: &'static str) -> Result<String, FmsParseError> {
        let n = self.u8()? as usize;
        let b = self.bytes(n)?;
        if let Some(&byte) = b.iter().find(|b| !(0x20..0x7F).contains(*b)) {
            return Err(FmsParseError::NotVisible { what, byte });
        }
        Ok(b.iter().map(|&b| b as char).collect())
    }
    fn end(&self) -> Result<(), FmsParseError> {
        if self.at < self.du.len() {
            Err(FmsParseError::Trailing {
                what: self.what,
                extra: self.du.len() - self.at,
            })
        } else {
            Ok(())
        }
    }
}

fn boolean(b: bool) -> u8 {
    if b {
        0xFF
    } else {
        0
    }
}

impl FmsPdu {
    /// Decodes an FMS PDU (the data unit of an LLI data telegram).
    pub fn parse(du: &[u8]) -> Result<FmsPdu, FmsParseError> {
        let &t = du.first().ok_or(FmsParseError::Empty)?;
        if du.len() > MAX_PDU_LEN {
            return Err(FmsParseError::TooLong(du.len()));
        }
        let kind = PduType::from_u8(t).ok_or(FmsParseError::UnknownType(t))?;
        let mut r = Rd {
            du,
            at: 1,
            what: kind.name(),
        };
        let service = |r: &mut Rd<'_>| -> Result<Service, FmsParseError> {
            let s = r.u8()?;
            Service::from_u8(s).ok_or(FmsParseError::UnknownService {
                kind: kind.name(),
                service: s,
            })
        };
        let pdu = match kind {
            PduType::ConfirmedRequest => {
                let invoke_id = r.u8()?;
                let request = match service(&mut r)? {
                    Service::Status => Request::Status,
                    Service::Identify => Request::Identify,
                    Service::Read => {
                        r.what = "Read request";
                        let index = r.u16()?;
                        let subindex = match r.rest() {
                            [] => None,
                            [s] => Some(*s),
                            more => {
                                return Err(FmsParseError::Trailing {
                                    what: "Read request",
                                    extra: more.len() - 1,
                                })
                            }
                        };
                        Request::Read { index, subindex }
                    }
                    Service::Write => {
                        r.what = "Write request";
                        let index = r.u16()?;
                        let sub = r.u8()?;
                        Request::Write {
                            index,
                            subindex: (sub != 0).then_some(sub),
                            data: r.rest().to_vec(),
                        }
                    }
                    Service::GetOd => {
                        r.what = "Get-OD request";
                        let flags = r.u8()?;
                        let index = r.u16()?;
                        Request::GetOd(GetOdRequest {
                            long_form: flags & GETOD_ALL_ATTRIBUTES != 0,
                            from_index: flags & GETOD_START_INDEX != 0,
                            index,
                        })
                    }
                };
                FmsPdu::Request { invoke_id, request }
            }
            PduType::ConfirmedResponse => {
                let invoke_id = r.u8()?;
                let response = match service(&mut r)? {
                    Service::Status => {
                        r.what = "Status response";
                        let logical = r.u8()?;
                        let physical = r.u8()?;
                        let d = r.bytes(3)?;
                        Response::Status(StatusResponse {
                            logical,
                            physical,
                            local_detail: [d[0], d[1], d[2]],
                        })
                    }
                    Service::Identify => {
                        r.what = "Identify response";
                        Response::Identify(IdentifyResponse {
                            vendor: r.string("vendor name")?,
                            model: r.string("model name")?,
                            revision: r.string("revision")?,
                        })
                    }
                    Service::Read => Response::Read(r.rest().to_vec()),
                    Service::Write => Response::Write,
                    Service::GetOd => {
                        r.what = "Get-OD response";
                        let more_follows = r.boolean("more-follows")?;
                        let n = r.u8()? as usize;
                        let mut descriptions = Vec::with_capacity(n.min(MAX_PDU_LEN));
                        for _ in 0..n {
                            let len = r.u8()? as usize;
                            descriptions.push(r.bytes(len)?.to_vec());
                        }
                        Response::GetOd {
                            more_follows,
                            descriptions,
                        }
                    }
                };
                FmsPdu::Response {
                    invoke_id,
                    response,
                }
            }
            PduType::ConfirmedError => {
                let invoke_id = r.u8()?;
                let service = service(&mut r)?;
                let class = r.u8()?;
                let code = r.u8()?;
                let additional = r.u16()?;
                FmsPdu::Error {
                    invoke_id,
                    service,
                    error: ServiceError {
                        class,
                        code,
                        additional,
                    },
                }
            }
            PduType::Unconfirmed => {
                let s = r.u8()?;
                if s != UNCONFIRMED_INFORMATION_REPORT {
                    return Err(FmsParseError::UnknownService {
                        kind: kind.name(),
                        service: s,
                    });
                }
                r.what = "Information-Report";
                let index = r.u16()?;
                FmsPdu::InformationReport {
                    index,
                    data: r.rest().to_vec(),
                }
            }
            PduType::Reject => FmsPdu::Reject {
                original_invoke_id: r.u8()?,
                pdu_type: r.u8()?,
                code: r.u8()?,
            },
            PduType::InitiateRequest => {
                let version_od = r.u16()? as i16;
                let p = r.bytes(2)?;
                let profile = [p[0], p[1]];
                let access_protection = r.boolean("access-protection-supported")?;
                let password = r.u8()?;
                let access_groups = r.u8()?;
                let m = r.bytes(4)?;
                let f = r.bytes(6)?;
                FmsPdu::InitiateRequest(InitiateRequest {
                    version_od,
                    profile,
                    access_protection,
                    password,
                    access_groups,
                    max_pdu_send_high: m[0],
                    max_pdu_send_low: m[1],
                    max_pdu_recv_high: m[2],
                    max_pdu_recv_low: m[3],
                    features: [f[0], f[1], f[2], f[3], f[4], f[5]],
                })
            }
            PduType::InitiateResponse => {
                let version_od = r.u16()? as i16;
                let p = r.bytes(2)?;
                FmsPdu::InitiateResponse(InitiateResponse {
                    version_od,
                    profile: [p[0], p[1]],
                    access_protection: r.boolean("access-protection-supported")?,
                    password: r.u8()?,
                    access_groups: r.u8()?,
                })
            }
            PduType::InitiateError => FmsPdu::InitiateError { code: r.u8()? },
        };
        r.end()?;
        Ok(pdu)
    }

    /// The PDU type.
    pub fn pdu_type(&self) -> PduType {
        match self {
            FmsPdu::Request { .. } => PduType::ConfirmedRequest,
            FmsPdu::Response { .. } => PduType::ConfirmedResponse,
            FmsPdu::Error { .. } => PduType::ConfirmedError,
            FmsPdu::InformationReport { .. } => PduType::Unconfirmed,
            FmsPdu::Reject { .. } => PduType::Reject,
            FmsPdu::InitiateRequest(_) => PduType::InitiateRequest,
            FmsPdu::InitiateResponse(_) => PduType::InitiateResponse,
            FmsPdu::InitiateError { .. } => PduType::InitiateError,
        }
    }

    /// The invoke ID of a confirmed PDU.
    pub fn invoke_id(&self) -> Option<u8> {
        match self {
            FmsPdu::Request { invoke_id, .. }
            | FmsPdu::Response { invoke_id, .. }
            | FmsPdu::Error { invoke_id, .. } => Some(*invoke_id),
            _ => None,
        }
    }

    /// The encoding, or `None` when it would exceed [`MAX_PDU_LEN`] (or a
    /// string or description is longer than 255 bytes).
    pub fn to_vec(&self) -> Option<Vec<u8>> {
        let mut v = vec![self.pdu_type() as u8];
        let string = |v: &mut Vec<u8>, s: &str| -> Option<()> {
            v.push(u8::try_from(s.len()).ok()?);
            v.extend_from_slice(s.as_bytes());
            Some(())
        };
        match self {
            FmsPdu::Request { invoke_id, request } => {
                v.extend([*invoke_id, request.service() as u8]);
                match request {
                    Request::Status | Request::Identify => {}
                    Request::Read { index, subindex } => {
                        v.extend(index.to_be_bytes());
                        v.extend(subindex);
                    }
                    Request::Write {
                        index,
                        subindex,
                        data,
                    } => {
                        v.extend(index.to_be_bytes());
                        v.push(subindex.unwrap_or(0));
                        v.extend_from_slice(data);
                    }
                    Request::GetOd(g) => {
                        let mut flags = 0;
                        if g.long_form {
                            flags |= GETOD_ALL_ATTRIBUTES;
                        }
                        if g.from_index {
                            flags |= GETOD_START_INDEX;
                        }
                        v.push(flags);
                        v.extend(g.index.to_be_bytes());
                    }
                }
            }
            FmsPdu::Response {
                invoke_id,
                response,
            } => {
                v.extend([*invoke_id, response.service() as u8]);
                match response {
                    Response::Status(s) => {
                        v.extend([s.logical, s.physical]);
                        v.extend(s.local_detail);
                    }
                    Response::Identify(i) => {
                        for s in [&i.vendor, &i.model, &i.revision] {
                            string(&mut v, s)?;
                        }
                    }
                    Response::Read(data) => v.extend_from_slice(data),
                    Response::Write => {}
                    Response::GetOd {
                        more_follows,
                        descriptions,
                    } => {
                        v.push(boolean(*more_follows));
                        v.push(u8::try_from(descriptions.len()).ok()?);
                        for d in descriptions {
                            v.push(u8::try_from(d.len()).ok()?);
                            v.extend_from_slice(d);
                        }
                    }
                }
            }
            FmsPdu::Error {
                invoke_id,
                service,
                error,
            } => {
                v.extend([*invoke_id, *service as u8, error.class, error.code]);
                v.extend(error.additional.to_be_bytes());
            }
            FmsPdu::InformationReport { index, data } => {
                v.push(UNCONFIRMED_INFORMATION_REPORT);
                v.extend(index.to_be_bytes());
                v.extend_from_slice(data);
            }
            FmsPdu::Reject {
                original_invoke_id,
                pdu_type,
                code,
            } => v.extend([*original_invoke_id, *pdu_type, *code]),
            FmsPdu::InitiateRequest(i) => {
                v.extend(i.version_od.to_be_bytes());
                v.extend(i.profile);
                v.extend([
                    boolean(i.access_protection),
                    i.password,
                    i.access_groups,
                    i.max_pdu_send_high,
                    i.max_pdu_send_low,
                    i.max_pdu_recv_high,
                    i.max_pdu_recv_low,
                ]);
                v.extend(i.features);
            }
            FmsPdu::InitiateResponse(i) => {
                v.extend(i.version_od.to_be_bytes());
                v.extend(i.profile);
                v.extend([boolean(i.access_protection), i.password, i.access_groups]);
            }
            FmsPdu::InitiateError { code } => v.push(*code),
        }
        (v.len() <= MAX_PDU_LEN).then_some(v)
    }

    /// The PDU in words (sniffer lines, logs).
    pub fn describe(&self) -> String {
        self.to_string()
    }
}

fn hex(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

impl fmt::Display for FmsPdu {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FmsPdu::Request { invoke_id, request } => {
                write!(f, "FMS {}.req id {invoke_id}", request.service().name())?;
                match request {
                    Request::Read { index, subindex } => {
                        write!(f, " index {index}")?;
                        if let Some(s) = subindex {
                            write!(f, " subindex {s}")?;
                        }
                    }
                    Request::Write {
                        index,
                        subindex,
                        data,
                    } => {
                        write!(f, " index {index}")?;
                        if let Some(s) = subindex {
                            write!(f, " subindex {s}")?;
                        }
                        write!(f, " data {}", hex(data))?;
                    }
                    Request::GetOd(g) => write!(
                        f,
                        " index {}{} ({} form)",
                        g.index,
                        if g.from_index { " onwards" } else { "" },
                        if g.long_form { "long" } else { "short" }
                    )?,
                    Request::Status | Request::Identify => {}
                }
                Ok(())
            }
            FmsPdu::Response {
                invoke_id,
                response,
            } => {
                write!(f, "FMS {}.res id {invoke_id}", response.service().name())?;
                match response {
                    Response::Status(s) => {
                        write!(f, ": {}, {}", s.logical_text(), s.physical_text())
                    }
                    Response::Identify(i) => {
                        write!(f, ": {} {} {}", i.vendor, i.model, i.revision)
                    }
                    Response::Read(d) => write!(f, " data {}", hex(d)),
                    Response::Write => Ok(()),
                    Response::GetOd {
                        more_follows,
                        descriptions,
                    } => write!(
                        f,
                        ": {} descriptions{}",
                        descriptions.len(),
                        if *more_follows { ", more follow" } else { "" }
                    ),
                }
            }
            FmsPdu::Error {
                invoke_id,
                service,
                error,
            } => write!(
                f,
                "FMS {} error id {invoke_id}: {}",
                service.name(),
                error.describe()
            ),
            FmsPdu::InformationReport { index, data } => {
                write!(f, "FMS Information-Report index {index} data {}", hex(data))
            }
            FmsPdu::Reject {
                original_invoke_id,
                pdu_type,
                code,
            } => write!(
                f,
                "FMS Reject of id {original_invoke_id} (PDU type {pdu_type}), reject code {code}"
            ),
            FmsPdu::InitiateRequest(i) => write!(
                f,
                "FMS Initiate.req OD version {}, max PDU send {}/{} receive {}/{}",
                i.version_od,
                i.max_pdu_send_high,
                i.max_pdu_send_low,
                i.max_pdu_recv_high,
                i.max_pdu_recv_low
            ),
            FmsPdu::InitiateResponse(i) => {
                write!(f, "FMS Initiate.res OD version {}", i.version_od)
            }
            FmsPdu::InitiateError { code } => write!(f, "FMS Initiate error code {code}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round(pdu: FmsPdu, bytes: &[u8]) {
        assert_eq!(pdu.to_vec().as_deref(), Some(bytes), "{pdu}");
        assert_eq!(FmsPdu::parse(bytes), Ok(pdu));
    }

    #[test]
    fn confirmed_requests_carry_invoke_id_service_and_index() {
        round(
            FmsPdu::Request {
                invoke_id: 7,
                request: Request::Read {
                    index: 2021,
                    subindex: None,
                },
            },
            &[1, 7, 2, 0x07, 0xE5],
        );
        round(
            FmsPdu::Request {
                invoke_id: 8,
                request: Request::Read {
                    index: 2021,
                    subindex: Some(2),
                },
            },
            &[1, 8, 2, 0x07, 0xE5, 2],
        );
        round(
            FmsPdu::Request {
                invoke_id: 9,
                request: Request::Write {
                    index: 2041,
                    subindex: None,
                    data: vec![0x00, 0x12, 0x34],
                },
            },
            &[1, 9, 3, 0x07, 0xF9, 0, 0x00, 0x12, 0x34],
        );
        round(
            FmsPdu::Request {
                invoke_id: 1,
                request: Request::GetOd(GetOdRequest {
                    long_form: true,
                    from_index: true,
                    index: 0,
                }),
            },
            &[1, 1, 4, 0xC0, 0, 0],
        );
        round(
            FmsPdu::Request {
                invoke_id: 2,
                request: Request::Identify,
            },
            &[1, 2, 1],
        );
    }

    #[test]
    fn responses_decode_status_identify_and_get_od() {
        round(
            FmsPdu::Response {
                invoke_id: 3,
                response: Response::Status(StatusResponse {
                    logical: LOGICAL_READY,
                    physical: PHYSICAL_OPERATIONAL,
                    local_detail: [0, 0, 0],
                }),
            },
            &[2, 3, 0, 0x00, 0x10, 0, 0, 0],
        );
        round(
            FmsPdu::Response {
                invoke_id: 4,
                response: Response::Identify(IdentifyResponse {
                    vendor: "Beckhoff".into(),
                    model: "BK3000".into(),
                    revision: "B9".into(),
                }),
            },
            b"\x02\x04\x01\x08Beckhoff\x06BK3000\x02B9",
        );
        round(
            FmsPdu::Response {
                invoke_id: 5,
                response: Response::GetOd {
                    more_follows: true,
                    descriptions: vec![vec![1, 2], vec![]],
                },
            },
            &[2, 5, 4, 0xFF, 2, 2, 1, 2, 0],
        );
        let s = FmsPdu::parse(&[2, 3, 0, 0x02, 0x13, 0, 0, 0]).unwrap();
        assert_eq!(
            s.to_string(),
            "FMS Status.res id 3: limited services, maintenance required"
        );
    }

    #[test]
    fn errors_reject_and_initiate_round_trip() {
        let e = FmsPdu::Error {
            invoke_id: 6,
            service: Service::Write,
            error: ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_DENIED),
        };
        round(e.clone(), &[3, 6, 3, 6, 3, 0, 0]);
        assert_eq!(
            e.to_string(),
            "FMS Write error id 6: object access denied (class 6, code 3, additional code 0)"
        );
        round(
            FmsPdu::Reject {
                original_invoke_id: 9,
                pdu_type: 1,
                code: REJECT_PDU_SIZE,
            },
            &[5, 9, 1, 5],
        );
        let init = InitiateRequest {
            version_od: 1,
            profile: [0, 0],
            access_protection: false,
            password: 0,
            access_groups: 0,
            max_pdu_send_high: 0,
            max_pdu_send_low: 241,
            max_pdu_recv_high: 0,
            max_pdu_recv_low: 241,
            features: [0, 0x30, 0, 0, 0x30, 0],
        };
        let bytes = FmsPdu::InitiateRequest(init).to_vec().unwrap();
        assert_eq!(bytes.len(), 18);
        assert_eq!(FmsPdu::parse(&bytes), Ok(FmsPdu::InitiateRequest(init)));
        round(
            FmsPdu::InformationReport {
                index: 1000,
                data: vec![1, 2],
            },
            &[4, 0, 0x03, 0xE8, 1, 2],
        );
    }

    #[test]
    fn bad_pdus_name_their_fault() {
        assert_eq!(FmsPdu::parse(&[]), Err(FmsParseError::Empty));
        assert_eq!(
            FmsPdu::parse(&[0x99]),
            Err(FmsParseError::UnknownType(0x99))
        );
        let e = FmsPdu::parse(&[1, 1, 2, 0x07]).unwrap_err();
        assert_eq!(e.to_string(), "FMS Read request is 4 bytes long, needs 5");
        let e = FmsPdu::parse(&[1, 1, 9]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown FMS service 9 in a confirmed request PDU"
        );
        assert!(matches!(
            FmsPdu::parse(&[1, 1, 0, 5]),
            Err(FmsParseError::Trailing { extra: 1, .. })
        ));
        assert!(matches!(
            FmsPdu::parse(b"\x02\x04\x01\x01\x07\x00\x00"),
            Err(FmsParseError::NotVisible { byte: 7, .. })
        ));
        assert!(matches!(
            FmsPdu::parse(&[2, 5, 4, 0x01, 0]),
            Err(FmsParseError::Boolean { .. })
        ));
        let long = FmsPdu::InformationReport {
            index: 1,
            data: vec![0; MAX_PDU_LEN],
        };
        assert_eq!(long.to_vec(), None);
    }
}
