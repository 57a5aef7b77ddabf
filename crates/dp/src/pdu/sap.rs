//! Service access points of DP (EN 50170 part 3).
//!
//! Every DP service except Data_Exchange is addressed to a slave SAP; the
//! master sends from SSAP 62 (MS0), DP-V1 class-1 services from SSAP 51.

/// DP-V1 MSAC_C2 Initiate (class-2 connection set-up).
pub const MSAC_C2_INITIATE: u8 = 49;
/// DP-V1 MSAC_C1 Alarm_Ack.
pub const ALARM_ACK: u8 = 50;
/// DP-V1 MSAC_C1 Read / Write (slave DSAP and master SSAP).
pub const MSAC_C1: u8 = 51;
/// Set_Slave_Add: change the station address.
pub const SET_SLAVE_ADD: u8 = 55;
/// Rd_Inp: read the slave's inputs (class 2).
pub const RD_INP: u8 = 56;
/// Rd_Outp: read the slave's outputs (class 2).
pub const RD_OUTP: u8 = 57;
/// Global_Control: sync/freeze/clear to a group (broadcast SDN).
pub const GLOBAL_CONTROL: u8 = 58;
/// Get_Cfg: read the slave's real configuration.
pub const GET_CFG: u8 = 59;
/// Slave_Diag: read the diagnosis.
pub const SLAVE_DIAG: u8 = 60;
/// Set_Prm: parameterise.
pub const SET_PRM: u8 = 61;
/// Chk_Cfg: check the configuration.
pub const CHK_CFG: u8 = 62;
/// The master's SAP for DP-V0 services (MS0).
pub const MASTER: u8 = 62;

/// The DP service name of a slave SAP.
pub fn name(sap: u8) -> Option<&'static str> {
    Some(match sap {
        MSAC_C2_INITIATE => "MSAC_C2_Initiate",
        ALARM_ACK => "Alarm_Ack",
        MSAC_C1 => "MSAC_C1",
        SET_SLAVE_ADD => "Set_Slave_Add",
        RD_INP => "Rd_Inp",
        RD_OUTP => "Rd_Outp",
        GLOBAL_CONTROL => "Global_Control",
        GET_CFG => "Get_Cfg",
        SLAVE_DIAG => "Slave_Diag",
        SET_PRM => "Set_Prm",
        CHK_CFG => "Chk_Cfg",
        0..=48 => "MSAC_C2",
        _ => return None,
    })
}
