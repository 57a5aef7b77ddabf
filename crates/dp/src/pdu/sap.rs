//! Service access points of DP (EN 50170 part 3).
//!
//! Every DP service except Data_Exchange is addressed to a slave SAP; the
//! master sends from SSAP 62 (MS0), DP-V1 class-1 services from SSAP 51.
//! The table is [`Sap`]; the constants name its codes for `match`
//! patterns.

profibus_fdl::enum_with_unknown! {
    /// A slave's service access point and the DP service behind it.
    /// SAPs 0..=48 are the MSAC_C2 connections (see [`name`]).
    pub enum Sap(u8) {
        /// 49: DP-V1 MSAC_C2 Initiate (class-2 connection set-up).
        MsacC2Initiate = 49 => "MSAC_C2_Initiate",
        /// 50: DP-V1 MSAC_C1 Alarm_Ack.
        AlarmAck = 50 => "Alarm_Ack",
        /// 51: DP-V1 MSAC_C1 Read / Write (slave DSAP and master SSAP).
        MsacC1 = 51 => "MSAC_C1",
        /// 55: Set_Slave_Add: change the station address.
        SetSlaveAdd = 55 => "Set_Slave_Add",
        /// 56: Rd_Inp: read the slave's inputs (class 2).
        RdInp = 56 => "Rd_Inp",
        /// 57: Rd_Outp: read the slave's outputs (class 2).
        RdOutp = 57 => "Rd_Outp",
        /// 58: Global_Control: sync/freeze/clear to a group (broadcast SDN).
        GlobalControl = 58 => "Global_Control",
        /// 59: Get_Cfg: read the slave's real configuration.
        GetCfg = 59 => "Get_Cfg",
        /// 60: Slave_Diag: read the diagnosis.
        SlaveDiag = 60 => "Slave_Diag",
        /// 61: Set_Prm: parameterise.
        SetPrm = 61 => "Set_Prm",
        /// 62: Chk_Cfg: check the configuration.
        ChkCfg = 62 => "Chk_Cfg",
    }
}

/// DP-V1 MSAC_C2 Initiate (class-2 connection set-up).
pub const MSAC_C2_INITIATE: u8 = Sap::MsacC2Initiate.code();
/// DP-V1 MSAC_C1 Alarm_Ack.
pub const ALARM_ACK: u8 = Sap::AlarmAck.code();
/// DP-V1 MSAC_C1 Read / Write (slave DSAP and master SSAP).
pub const MSAC_C1: u8 = Sap::MsacC1.code();
/// Set_Slave_Add: change the station address.
pub const SET_SLAVE_ADD: u8 = Sap::SetSlaveAdd.code();
/// Rd_Inp: read the slave's inputs (class 2).
pub const RD_INP: u8 = Sap::RdInp.code();
/// Rd_Outp: read the slave's outputs (class 2).
pub const RD_OUTP: u8 = Sap::RdOutp.code();
/// Global_Control: sync/freeze/clear to a group (broadcast SDN).
pub const GLOBAL_CONTROL: u8 = Sap::GlobalControl.code();
/// Get_Cfg: read the slave's real configuration.
pub const GET_CFG: u8 = Sap::GetCfg.code();
/// Slave_Diag: read the diagnosis.
pub const SLAVE_DIAG: u8 = Sap::SlaveDiag.code();
/// Set_Prm: parameterise.
pub const SET_PRM: u8 = Sap::SetPrm.code();
/// Chk_Cfg: check the configuration.
pub const CHK_CFG: u8 = Sap::ChkCfg.code();
/// The master's SAP for DP-V0 services (MS0); the same number as Chk_Cfg
/// on the slave side.
pub const MASTER: u8 = 62;

/// The DP service name of a slave SAP (`"MSAC_C2"` for 0..=48).
pub fn name(sap: u8) -> Option<&'static str> {
    match Sap::from_code(sap) {
        Sap::Unknown(0..=48) => Some("MSAC_C2"),
        s => s.name(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        assert_eq!(name(SET_PRM), Some("Set_Prm"));
        assert_eq!(name(MSAC_C1), Some("MSAC_C1"));
        assert_eq!(name(0), Some("MSAC_C2"));
        assert_eq!(name(48), Some("MSAC_C2"));
        assert_eq!(name(52), None);
        assert_eq!(name(63), None);
        assert_eq!(Sap::from_code(CHK_CFG), Sap::ChkCfg);
    }
}
