//! The frame control (FC) byte: request kinds with FCB/FCV, response status
//! and station type. Every one of the 256 byte values decodes, unknown codes
//! as `Unknown(..)`, and [`FunctionCode::to_byte`] restores the exact byte.

/// Bit 6 of FC: set in requests, clear in responses.
const REQUEST_BIT: u8 = 0x40;
/// Bit 5 of a request FC: the frame count bit.
const FCB_BIT: u8 = 0x20;
/// Bit 4 of a request FC: the frame count bit is valid.
const FCV_BIT: u8 = 0x10;

crate::enum_with_unknown! {
    /// The service a request telegram asks for (FC bits 3-0, with bit 7
    /// for Clock Value); `Unknown` keeps the function bits 3-0 with bit 7.
    pub enum RequestKind(u8 & 0x8F) {
        /// 0: Time Event (clock synchronisation).
        TimeEvent = 0x00 => "TE",
        /// 3: Send Data with Acknowledge, low priority.
        SdaLow = 0x03 => "SDA_low",
        /// 4: Send Data with No acknowledge, low priority.
        SdnLow = 0x04 => "SDN_low",
        /// 5: Send Data with Acknowledge, high priority.
        SdaHigh = 0x05 => "SDA_high",
        /// 6: Send Data with No acknowledge, high priority.
        SdnHigh = 0x06 => "SDN_high",
        /// 7: Send and Request Data with multicast reply (MSRD).
        Msrd = 0x07 => "MSRD",
        /// 9: Request FDL Status (live list, GAP polling).
        FdlStatus = 0x09 => "FDL_Status",
        /// 0xC: Send and Request Data, low priority.
        SrdLow = 0x0C => "SRD_low",
        /// 0xD: Send and Request Data, high priority.
        SrdHigh = 0x0D => "SRD_high",
        /// 0xE: Request Ident (with reply).
        Ident = 0x0E => "Ident",
        /// 0xF: Request LSAP status (deprecated).
        LsapStatus = 0x0F => "LSAP_Status",
        /// 0x80: Clock Value (bit 7 set, function 0).
        ClockValue = 0x80 => "CV",
    }
}

impl RequestKind {
    /// Whether the responder answers this request (SRD, SDA, FDL status,
    /// ident, LSAP status) rather than staying silent (SDN, time event).
    pub const fn expects_reply(self) -> bool {
        matches!(
            self,
            Self::SdaLow
                | Self::SdaHigh
                | Self::SrdLow
                | Self::SrdHigh
                | Self::Msrd
                | Self::FdlStatus
                | Self::Ident
                | Self::LsapStatus
        )
    }

    /// Whether the frame count bit is used with this service (SDA and SRD).
    pub const fn uses_fcb(self) -> bool {
        matches!(
            self,
            Self::SdaLow | Self::SdaHigh | Self::SrdLow | Self::SrdHigh | Self::Msrd
        )
    }

    /// Short mnemonic as used in traces (`"unknown"` for an unknown code).
    pub const fn mnemonic(self) -> &'static str {
        match self.name() {
            Some(name) => name,
            None => "unknown",
        }
    }
}

crate::enum_with_unknown! {
    /// Status of a response telegram (FC bits 3-0); `Unknown` keeps FC
    /// bits 3-0 with bit 7.
    pub enum ResponseStatus(u8 & 0x8F) {
        /// 0: OK, positive acknowledge.
        Ok = 0x0 => "OK",
        /// 1: UE, user error (negative acknowledge).
        Ue = 0x1 => "UE",
        /// 2: RR, no resources (negative acknowledge).
        Rr = 0x2 => "RR",
        /// 3: RS, SAP not activated / service not available (negative ack).
        Rs = 0x3 => "RS",
        /// 8: DL, response data low (the normal DP reply).
        Dl = 0x8 => "DL",
        /// 9: NR, no response data.
        Nr = 0x9 => "NR",
        /// 0xA: DH, response data high (a DP slave has new diagnosis).
        Dh = 0xA => "DH",
        /// 0xC: RDL, data not received, response data low.
        Rdl = 0xC => "RDL",
        /// 0xD: RDH, data not received, response data high.
        Rdh = 0xD => "RDH",
    }
}

impl ResponseStatus {
    /// Negative acknowledges: the request was not carried out.
    pub const fn is_negative(self) -> bool {
        matches!(self, Self::Ue | Self::Rr | Self::Rs | Self::Rdl | Self::Rdh)
    }

    /// Short mnemonic as used in traces (`"unknown"` for an unknown code).
    pub const fn mnemonic(self) -> &'static str {
        match self.name() {
            Some(name) => name,
            None => "unknown",
        }
    }
}

/// Station type carried in bits 5-4 of a response FC (the answer to an FDL
/// Status request tells the live list what a station is).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StationType {
    /// 00: passive station (slave).
    Passive,
    /// 01: active station (master), not ready to enter the ring.
    ActiveNotReady,
    /// 10: active station, ready to enter the logical token ring.
    ActiveReady,
    /// 11: active station, in the logical token ring.
    ActiveInRing,
}

impl StationType {
    /// Decode FC bits 5-4 (given as a value 0..=3).
    pub const fn from_bits(bits: u8) -> Self {
        match bits & 3 {
            0 => Self::Passive,
            1 => Self::ActiveNotReady,
            2 => Self::ActiveReady,
            _ => Self::ActiveInRing,
        }
    }

    /// FC bits 5-4 as a value 0..=3.
    pub const fn bits(self) -> u8 {
        match self {
            Self::Passive => 0,
            Self::ActiveNotReady => 1,
            Self::ActiveReady => 2,
            Self::ActiveInRing => 3,
        }
    }

    /// Words for live lists.
    pub const fn describe(self) -> &'static str {
        match self {
            Self::Passive => "passive",
            Self::ActiveNotReady => "active, not ready",
            Self::ActiveReady => "active, ready for ring",
            Self::ActiveInRing => "active, in ring",
        }
    }
}

/// The decoded FC byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FunctionCode {
    /// A request (FC bit 6 set).
    Request {
        /// The requested service.
        kind: RequestKind,
        /// Frame count bit (FC bit 5).
        fcb: bool,
        /// Frame count bit valid (FC bit 4).
        fcv: bool,
    },
    /// A response or acknowledge (FC bit 6 clear).
    Response {
        /// Response status.
        status: ResponseStatus,
        /// Type of the responding station.
        station: StationType,
    },
}

impl FunctionCode {
    /// Decode an FC byte. Total: every byte maps to a value.
    pub const fn from_byte(b: u8) -> Self {
        if b & REQUEST_BIT != 0 {
            Self::Request {
                kind: RequestKind::from_code(b & 0x8F),
                fcb: b & FCB_BIT != 0,
                fcv: b & FCV_BIT != 0,
            }
        } else {
            Self::Response {
                status: ResponseStatus::from_code(b & 0x8F),
                station: StationType::from_bits((b >> 4) & 3),
            }
        }
    }

    /// Encode to the FC byte.
    pub const fn to_byte(self) -> u8 {
        match self {
            Self::Request { kind, fcb, fcv } => {
                REQUEST_BIT
                    | kind.code()
                    | if fcb { FCB_BIT } else { 0 }
                    | if fcv { FCV_BIT } else { 0 }
            }
            Self::Response { status, station } => status.code() | (station.bits() << 4),
        }
    }

    /// A request without frame count (FCB = FCV = 0), as used by SDN,
    /// broadcasts, FDL Status and Ident.
    pub const fn request(kind: RequestKind) -> Self {
        Self::Request {
            kind,
            fcb: false,
            fcv: false,
        }
    }

    /// A response from a passive station (slave) with the given status.
    pub const fn slave_response(status: ResponseStatus) -> Self {
        Self::Response {
            status,
            station: StationType::Passive,
        }
    }

    /// Whether this FC is a request.
    pub const fn is_request(self) -> bool {
        matches!(self, Self::Request { .. })
    }
}

impl From<u8> for FunctionCode {
    fn from(b: u8) -> Self {
        Self::from_byte(b)
    }
}

impl From<FunctionCode> for u8 {
    fn from(fc: FunctionCode) -> u8 {
        fc.to_byte()
    }
}

impl core::fmt::Display for FunctionCode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::Request { kind, fcb, fcv } => {
                match kind {
                    RequestKind::Unknown(c) => write!(f, "request 0x{c:02X}")?,
                    k => f.write_str(k.mnemonic())?,
                }
                if fcv {
                    write!(f, " FCB={}", u8::from(fcb))
                } else if fcb {
                    f.write_str(" FCB=1 (first)")
                } else {
                    Ok(())
                }
            }
            Self::Response { status, station } => {
                match status {
                    ResponseStatus::Unknown(c) => write!(f, "response 0x{c:02X}")?,
                    s => f.write_str(s.mnemonic())?,
                }
                write!(f, " ({})", station.describe())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_byte_round_trips() {
        for b in 0..=255u8 {
            assert_eq!(FunctionCode::from_byte(b).to_byte(), b, "FC 0x{b:02X}");
        }
    }

    #[test]
    fn codes_round_trip_and_unknown_keeps_its_bits() {
        for c in 0..=255u8 {
            assert_eq!(RequestKind::from_code(c).code(), c & 0x8F, "0x{c:02X}");
            assert_eq!(ResponseStatus::from_code(c).code(), c & 0x8F, "0x{c:02X}");
        }
        assert_eq!(RequestKind::from_code(0xFF), RequestKind::Unknown(0x8F));
        assert_eq!(RequestKind::SrdHigh.mnemonic(), "SRD_high");
        assert_eq!(RequestKind::Unknown(1).mnemonic(), "unknown");
        assert_eq!(ResponseStatus::Dh.name(), Some("DH"));
        assert_eq!(ResponseStatus::Unknown(4).name(), None);
    }

    #[test]
    fn known_codes_from_the_reference() {
        // SRD high, first frame: 6D; then 5D/7D.
        assert_eq!(
            FunctionCode::from_byte(0x6D),
            FunctionCode::Request {
                kind: RequestKind::SrdHigh,
                fcb: true,
                fcv: false
            }
        );
        assert_eq!(
            FunctionCode::from_byte(0x7D),
            FunctionCode::Request {
                kind: RequestKind::SrdHigh,
                fcb: true,
                fcv: true
            }
        );
        assert_eq!(
            FunctionCode::from_byte(0x49),
            FunctionCode::request(RequestKind::FdlStatus)
        );
        // Master in ring answering FDL status: 0x30.
        assert_eq!(
            FunctionCode::from_byte(0x30),
            FunctionCode::Response {
                status: ResponseStatus::Ok,
                station: StationType::ActiveInRing
            }
        );
        assert_eq!(
            FunctionCode::from_byte(0x0A),
            FunctionCode::slave_response(ResponseStatus::Dh)
        );
        assert_eq!(
            FunctionCode::from_byte(0xC0),
            FunctionCode::request(RequestKind::ClockValue)
        );
        assert!(matches!(
            FunctionCode::from_byte(0x41),
            FunctionCode::Request {
                kind: RequestKind::Unknown(1),
                ..
            }
        ));
    }
}
