//! Why a slave refused a telegram ([`Reason`]) and which service it
//! refused ([`Service`]): typed, with the data that explain it, and in
//! words through `Display` for the slave's events.

use crate::pdu::cfg::CfgError;
use crate::pdu::control::LengthError;
use crate::pdu::prm::PrmError;
use crate::pdu::sap::{self, Sap};
use std::borrow::Cow;
use std::fmt;

/// Why a slave refused something: a Set_Prm (Prm_Fault), a Chk_Cfg
/// (Cfg_Fault), a Set_Slave_Add, or a service in the wrong state or from
/// the wrong master. It appears in the slave's events; the master sees
/// only the fault bit or a negative acknowledge.
///
/// The slave core's own checks (EN 50170 part 3, the Set_Prm and
/// Chk_Cfg state machine) have a variant each; a device profile's own
/// words are [`Reason::Device`] (`"…".into()` or `String::into`).
#[derive(Debug, Clone, PartialEq, Eq, Hash, thiserror::Error)]
pub enum Reason {
    // ----- Set_Prm: the standard checks -----------------------------------
    /// The Set_Prm data unit does not decode.
    #[error(transparent)]
    PrmData(#[from] PrmError),
    /// Set_Prm or Set_Slave_Add names another ident number.
    #[error("ident number 0x{got:04X}, this slave is 0x{own:04X}")]
    IdentNumber {
        /// The ident number in the telegram.
        got: u16,
        /// The slave's own.
        own: u16,
    },
    /// Station_Status bits 2-0 (reserved) are set.
    #[error("reserved Station_Status bits set (0x{station_status:02X})")]
    ReservedStationStatus {
        /// The Station_Status byte.
        station_status: u8,
    },
    /// WD_On with a watchdog factor of 0.
    #[error("WD_On with WD_Fact_1 = {wd_fact_1}, WD_Fact_2 = {wd_fact_2} (each must be 1..=255)")]
    WatchdogFactor {
        /// WD_Fact_1.
        wd_fact_1: u8,
        /// WD_Fact_2.
        wd_fact_2: u8,
    },
    /// Sync_Req to a slave without sync mode (Not_Supported).
    #[error("Sync_Req, but the slave does not support sync mode")]
    SyncReqUnsupported,
    /// Freeze_Req to a slave without freeze mode (Not_Supported).
    #[error("Freeze_Req, but the slave does not support freeze mode")]
    FreezeReqUnsupported,
    /// A DP-V1 slave's User_Prm_Data lack the three DPV1_Status bytes.
    #[error("a DP-V1 slave needs the 3 DPV1_Status bytes, User_Prm_Data has {user_prm_len}")]
    Dpv1StatusMissing {
        /// Bytes of User_Prm_Data.
        user_prm_len: usize,
    },
    /// DPV1_Status_1 bits 4-3 (reserved) are set.
    #[error("reserved DPV1_Status_1 bits set (0x{status_1:02X})")]
    ReservedDpv1Status1 {
        /// DPV1_Status_1.
        status_1: u8,
    },
    /// DP-V2 functions asked for (Not_Supported).
    #[error("DP-V2 functions (publisher, start/stop control) are not supported")]
    Dpv2Unsupported,
    /// Fail_Safe to a slave without it (Not_Supported).
    #[error("Fail_Safe, but the slave does not support it")]
    FailSafeUnsupported,
    /// DPV1_Status_2 bit 1 (reserved) is set.
    #[error("reserved DPV1_Status_2 bit 1 set (0x{status_2:02X})")]
    ReservedDpv1Status2 {
        /// DPV1_Status_2.
        status_2: u8,
    },
    /// Alarms enabled on a slave without alarms (Not_Supported).
    #[error("alarms enabled (DPV1_Status_2 0x{status_2:02X}), but the slave has none")]
    AlarmsUnsupported {
        /// DPV1_Status_2.
        status_2: u8,
    },
    /// DPV1_Status_3 bits 6-5 (reserved) are set.
    #[error("reserved DPV1_Status_3 bits set (0x{status_3:02X})")]
    ReservedDpv1Status3 {
        /// DPV1_Status_3.
        status_3: u8,
    },
    /// Isochronous mode or PrmCmd asked for (Not_Supported).
    #[error("isochronous mode and PrmCmd are not supported")]
    IsochronousUnsupported,
    /// User_Prm_Data of another length than the GSD's `User_Prm_Data_Len`.
    #[error("User_Prm_Data has {got} bytes, the GSD gives {expected}")]
    UserPrmLen {
        /// Bytes received.
        got: usize,
        /// `User_Prm_Data_Len`.
        expected: usize,
    },

    // ----- Chk_Cfg ----------------------------------------------------------
    /// A configuration byte differs from the expected configuration.
    #[error(
        "configuration byte {index} is 0x{:02X}, expected 0x{:02X} (expected {}, got {})",
        got[*index], expected[*index], hex(expected), hex(got)
    )]
    CfgByte {
        /// Offset of the first differing byte.
        index: usize,
        /// The expected configuration.
        expected: Vec<u8>,
        /// The configuration received.
        got: Vec<u8>,
    },
    /// The configuration is a prefix of the expected one, or longer.
    #[error(
        "configuration has {} bytes, expected {} (expected {}, got {})",
        got.len(), expected.len(), hex(expected), hex(got)
    )]
    CfgLength {
        /// The expected configuration.
        expected: Vec<u8>,
        /// The configuration received.
        got: Vec<u8>,
    },
    /// The configuration's identifiers do not decode.
    #[error(transparent)]
    CfgData(#[from] CfgError),
    /// The configuration's identifiers add up to more than 244 bytes in a
    /// direction.
    #[error("configuration has {inputs} input and {outputs} output bytes, at most 244 each way")]
    CfgTooLong {
        /// Input bytes.
        inputs: usize,
        /// Output bytes.
        outputs: usize,
    },
    /// The layout a device accepted exceeds 244 bytes in a direction.
    #[error("layout of {inputs} input and {outputs} output bytes exceeds 244")]
    LayoutTooLong {
        /// Input bytes.
        inputs: usize,
        /// Output bytes.
        outputs: usize,
    },

    // ----- state and ownership ----------------------------------------------
    /// Chk_Cfg before Set_Prm.
    #[error("not parameterised (Wait_Prm)")]
    NotParameterised,
    /// A service of Data_Exch in another state.
    #[error("not in Data_Exch")]
    NotInDataExch,
    /// A service from a master that does not own the slave.
    #[error("the slave is locked to another master")]
    LockedToAnother,
    /// Set_Prm from a master that does not own the slave.
    #[error("the slave is locked to master {owner}")]
    LockedTo {
        /// The owning master.
        owner: u8,
    },
    /// Data_Exchange with another output length than configured.
    #[error(
        "{} output bytes than configured",
        if got < configured { "fewer" } else { "more" }
    )]
    OutputLength {
        /// Output bytes received.
        got: usize,
        /// Output bytes configured.
        configured: usize,
    },
    /// A DP service sent other than as SRD.
    #[error("DP services are SRD only")]
    SrdOnly,
    /// Global_Control of another length than 2 bytes.
    #[error("data unit is not 2 bytes")]
    ControlLength,
    /// Global_Control Sync/Unsync to a slave without sync mode.
    #[error("sync mode is not supported")]
    SyncUnsupported,
    /// Global_Control Freeze/Unfreeze to a slave without freeze mode.
    #[error("freeze mode is not supported")]
    FreezeUnsupported,
    /// MSAC_C1 read/write outside its conditions.
    #[error(
        "DP-V1 read/write is active only in Data_Exch with DPV1_Enable, for the owning master"
    )]
    C1Inactive,
    /// Alarm_Ack outside its conditions.
    #[error("alarms are active only in Data_Exch with DPV1_Enable, for the owning master")]
    AlarmsInactive,
    /// An Alarm_Ack that names no outstanding alarm, or not the oldest
    /// one in sequence mode.
    #[error("Alarm_Ack refused: {0}")]
    AlarmAck(crate::slave::AckError),

    // ----- MSAC_C2 ------------------------------------------------------------
    /// A class-2 request to a slave that offers no class-2 connections.
    #[error("the slave offers no class-2 connections (C2_Read_Write_supp)")]
    C2Unsupported,
    /// The resource manager refused an Initiate.req with an Abort.
    #[error("Initiate refused, {abort}")]
    C2InitiateRefused {
        /// The abort in words.
        abort: String,
    },
    /// A request on a connection SAP that has no open connection.
    #[error("no class-2 connection is open on this SAP")]
    C2NoConnection,
    /// A request on another master's class-2 connection.
    #[error("the class-2 connection on this SAP belongs to master {owner}")]
    C2OtherMaster {
        /// The master that opened the connection.
        owner: u8,
    },

    // ----- Set_Slave_Add ----------------------------------------------------
    /// The slave has no Set_Slave_Add.
    #[error("the slave does not support Set_Slave_Add")]
    SetSlaveAddUnsupported,
    /// Set_Slave_Add outside Wait_Prm.
    #[error("only accepted in Wait_Prm")]
    OnlyInWaitPrm,
    /// An earlier Set_Slave_Add set No_Add_Chg.
    #[error("No_Add_Chg was set: the address cannot be changed through the bus")]
    NoAddChg,
    /// The Set_Slave_Add data unit is too short.
    #[error(transparent)]
    SetSlaveAddData(#[from] LengthError),
    /// The new address is not a slave address.
    #[error("new address {address} is above 125")]
    AddressAbove125 {
        /// The address asked for.
        address: u8,
    },

    // ----- a device profile's own -------------------------------------------
    /// A device profile's own reason, in words.
    #[error("{0}")]
    Device(Cow<'static, str>),
}

impl Reason {
    /// Whether the fault is a function the slave does not support: the
    /// Set_Prm fault then also sets Not_Supported in the diagnosis.
    pub fn is_not_supported(&self) -> bool {
        matches!(
            self,
            Reason::SyncReqUnsupported
                | Reason::FreezeReqUnsupported
                | Reason::Dpv2Unsupported
                | Reason::FailSafeUnsupported
                | Reason::AlarmsUnsupported { .. }
                | Reason::IsochronousUnsupported
        )
    }

    /// A device profile's reason from a static or owned string.
    pub fn new(text: impl Into<Cow<'static, str>>) -> Reason {
        Reason::Device(text.into())
    }
}

impl From<&'static str> for Reason {
    fn from(s: &'static str) -> Reason {
        Reason::Device(Cow::Borrowed(s))
    }
}

impl From<String> for Reason {
    fn from(s: String) -> Reason {
        Reason::Device(Cow::Owned(s))
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for Reason {
    /// In words, as `Display`.
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

fn hex(bytes: &[u8]) -> String {
    super::device::hex(bytes)
}

/// The DP service a slave refused: Data_Exchange (the default SAP) or the
/// service of a slave SAP.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Service {
    /// Data_Exchange (no SAP).
    DataExchange,
    /// The service of this slave SAP (Set_Prm, Chk_Cfg, MSAC_C1, …).
    Sap(Sap),
}

impl Service {
    /// The standard's name (`"Data_Exchange"`, `"Set_Prm"`, …; `"?"` for
    /// a SAP without a DP service).
    pub fn as_str(self) -> &'static str {
        match self {
            Service::DataExchange => "Data_Exchange",
            Service::Sap(s) => sap::name(s.code()).unwrap_or("?"),
        }
    }

    /// The service of a request's DSAP (`None`: Data_Exchange).
    pub fn of_dsap(dsap: Option<u8>) -> Service {
        match dsap {
            None => Service::DataExchange,
            Some(s) => Service::Sap(Sap::from_code(s)),
        }
    }
}

impl fmt::Display for Service {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for Service {
    /// The standard's name, as [`Service::as_str`].
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_stay_as_they_were() {
        let r = Reason::CfgByte {
            index: 1,
            expected: vec![0x31, 0x20],
            got: vec![0x31, 0x21],
        };
        assert_eq!(
            r.to_string(),
            "configuration byte 1 is 0x21, expected 0x20 (expected 31 20, got 31 21)"
        );
        let r = Reason::CfgLength {
            expected: vec![],
            got: vec![0x31],
        };
        assert_eq!(
            r.to_string(),
            "configuration has 1 bytes, expected 0 (expected (none), got 31)"
        );
        assert_eq!(
            Reason::OutputLength {
                got: 1,
                configured: 2
            }
            .to_string(),
            "fewer output bytes than configured"
        );
        assert_eq!(
            Reason::IdentNumber {
                got: 0x1234,
                own: 0xBECF
            }
            .to_string(),
            "ident number 0x1234, this slave is 0xBECF"
        );
        assert_eq!(Reason::from("own words").to_string(), "own words");
        assert_eq!(Service::of_dsap(None).as_str(), "Data_Exchange");
        assert_eq!(Service::of_dsap(Some(sap::SET_PRM)).as_str(), "Set_Prm");
        assert_eq!(Service::of_dsap(Some(3)).as_str(), "MSAC_C2");
        assert_eq!(Service::of_dsap(Some(53)).as_str(), "?");
    }
}

#[cfg(all(test, feature = "serde"))]
mod json {
    use super::*;
    use crate::slave::SlaveEvent;

    #[test]
    fn events_serialise_service_and_reason_as_words() {
        let e = SlaveEvent::Refused {
            master: 2,
            service: Service::Sap(Sap::ChkCfg),
            reason: Reason::LockedToAnother,
        };
        assert_eq!(
            serde_json::to_value(&e).unwrap(),
            serde_json::json!({
                "event": "refused",
                "master": 2,
                "service": "Chk_Cfg",
                "reason": "the slave is locked to another master",
            })
        );
        let e = SlaveEvent::CfgFault {
            master: 2,
            reason: Reason::from("own words"),
        };
        assert_eq!(serde_json::to_value(&e).unwrap()["reason"], "own words");
    }
}
