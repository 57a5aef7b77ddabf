//! Set_Prm: the parameter telegram (DSAP 61; IEC 61158-6-3).
//!
//! ```text
//! byte 0  Station_Status: b7 Lock_Req, b6 Unlock_Req, b5 Sync_Req,
//!         b4 Freeze_Req, b3 WD_On
//! byte 1  WD_Fact_1    byte 2  WD_Fact_2
//! byte 3  min TSDR (bit times; 0 = keep the current value)
//! byte 4-5 Ident_Number (high byte first)
//! byte 6  Group_Ident (bit n = group n+1)
//! byte 7… User_Prm_Data; for DP-V1 slaves it starts with DPV1_Status_1..3
//! ```

use std::time::Duration;

bitflags::bitflags! {
    /// Set_Prm byte 0, "Station_Status" of the parameter telegram.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub struct PrmStationStatus: u8 {
        /// Lock_Req: lock the slave to this master.
        const LOCK_REQ = 0x80;
        /// Unlock_Req: release the slave for other masters.
        const UNLOCK_REQ = 0x40;
        /// Sync_Req: the slave is to operate in sync mode.
        const SYNC_REQ = 0x20;
        /// Freeze_Req: the slave is to operate in freeze mode.
        const FREEZE_REQ = 0x10;
        /// WD_On: the response monitoring (watchdog) is on.
        const WD_ON = 0x08;
    }
}

bitflags::bitflags! {
    /// DPV1_Status_1 (Set_Prm byte 7 of a DP-V1 slave).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub struct Dpv1Status1: u8 {
        /// DPV1_Enable: DP-V1 services and alarms are on.
        const DPV1_ENABLE = 0x80;
        /// Fail_Safe: the master sends empty Data_Exchange telegrams in the
        /// clear state instead of zeroed outputs.
        const FAIL_SAFE = 0x40;
        /// Publisher_Enable (DP-V2).
        const PUBLISHER_ENABLE = 0x20;
        /// WD_Base_1ms: the watchdog factors count 1 ms instead of 10 ms.
        const WD_BASE_1MS = 0x04;
        /// Dis_Stop_Control (DP-V2).
        const DIS_STOP_CONTROL = 0x02;
        /// Dis_Start_Control (DP-V2).
        const DIS_START_CONTROL = 0x01;
    }
}

bitflags::bitflags! {
    /// DPV1_Status_2 (Set_Prm byte 8): alarm enables.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub struct Dpv1Status2: u8 {
        /// Enable_Pull_Plug_Alarm.
        const PULL_PLUG_ALARM = 0x80;
        /// Enable_Process_Alarm.
        const PROCESS_ALARM = 0x40;
        /// Enable_Diagnostic_Alarm.
        const DIAGNOSTIC_ALARM = 0x20;
        /// Enable_Manufacturer_Specific_Alarm.
        const MANUFACTURER_ALARM = 0x10;
        /// Enable_Status_Alarm.
        const STATUS_ALARM = 0x08;
        /// Enable_Update_Alarm.
        const UPDATE_ALARM = 0x04;
        /// Check_Cfg_Mode.
        const CHECK_CFG_MODE = 0x01;
    }
}

/// Offset of User_Prm_Data in the Set_Prm data unit.
pub const USER_PRM_OFFSET: usize = 7;
/// Longest Set_Prm data unit.
pub const MAX_PRM_LEN: usize = 244;

/// A Set_Prm data unit, borrowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SetPrm<'a> {
    /// Byte 0: lock/unlock, sync/freeze requests, watchdog on.
    pub station_status: PrmStationStatus,
    /// Byte 1: WD_Fact_1 (1..=255).
    pub wd_fact_1: u8,
    /// Byte 2: WD_Fact_2 (1..=255).
    pub wd_fact_2: u8,
    /// Byte 3: min TSDR in bit times the slave must wait before answering;
    /// 0 keeps the current value.
    pub min_tsdr: u8,
    /// Bytes 4-5: the slave's ident number.
    pub ident_number: u16,
    /// Byte 6: Group_Ident, bit n = group n+1.
    pub group_ident: u8,
    /// Bytes 7…: User_Prm_Data (for DP-V1 slaves starting with the three
    /// DPV1 status bytes).
    pub user_prm_data: &'a [u8],
}

/// A Set_Prm data unit that cannot be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum PrmError {
    /// Fewer than 7 bytes.
    #[error("Set_Prm of {0} bytes is shorter than the 7 standard bytes")]
    TooShort(usize),
    /// More than 244 bytes.
    #[error("Set_Prm of {0} bytes exceeds 244 bytes")]
    TooLong(usize),
}

impl<'a> SetPrm<'a> {
    /// Decode a Set_Prm data unit.
    pub fn parse(du: &'a [u8]) -> Result<SetPrm<'a>, PrmError> {
        if du.len() < USER_PRM_OFFSET {
            return Err(PrmError::TooShort(du.len()));
        }
        if du.len() > MAX_PRM_LEN {
            return Err(PrmError::TooLong(du.len()));
        }
        Ok(SetPrm {
            station_status: PrmStationStatus::from_bits_retain(du[0]),
            wd_fact_1: du[1],
            wd_fact_2: du[2],
            min_tsdr: du[3],
            ident_number: u16::from_be_bytes([du[4], du[5]]),
            group_ident: du[6],
            user_prm_data: &du[USER_PRM_OFFSET..],
        })
    }

    /// Length of the encoded data unit.
    pub fn len(&self) -> usize {
        USER_PRM_OFFSET + self.user_prm_data.len()
    }

    /// Always false: a Set_Prm has at least 7 bytes.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Encode into `buf`; returns the length, or `None` if `buf` is too
    /// small or the result would exceed 244 bytes.
    pub fn emit(&self, buf: &mut [u8]) -> Option<usize> {
        let n = self.len();
        if n > MAX_PRM_LEN || buf.len() < n {
            return None;
        }
        let id = self.ident_number.to_be_bytes();
        buf[..USER_PRM_OFFSET].copy_from_slice(&[
            self.station_status.bits(),
            self.wd_fact_1,
            self.wd_fact_2,
            self.min_tsdr,
            id[0],
            id[1],
            self.group_ident,
        ]);
        buf[USER_PRM_OFFSET..n].copy_from_slice(self.user_prm_data);
        Some(n)
    }

    /// The three DPV1 status bytes, when User_Prm_Data holds them.
    pub fn dpv1_status(&self) -> Option<(Dpv1Status1, Dpv1Status2, u8)> {
        match self.user_prm_data {
            [a, b, c, ..] => Some((
                Dpv1Status1::from_bits_retain(*a),
                Dpv1Status2::from_bits_retain(*b),
                *c,
            )),
            _ => None,
        }
    }

    /// The watchdog time when WD_On is set: WD_Fact_1 × WD_Fact_2 × 10 ms,
    /// or × 1 ms when `dpv1` and WD_Base_1ms is set.
    pub fn watchdog(&self, dpv1: bool) -> Option<Duration> {
        if !self.station_status.contains(PrmStationStatus::WD_ON) {
            return None;
        }
        let base_1ms = dpv1
            && self
                .dpv1_status()
                .is_some_and(|(s1, _, _)| s1.contains(Dpv1Status1::WD_BASE_1MS));
        let unit = if base_1ms { 1 } else { 10 };
        Some(Duration::from_millis(
            self.wd_fact_1 as u64 * self.wd_fact_2 as u64 * unit,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trace_example() {
        // trace of pyprofibus issue #19: B8 1E 01 00 0A 35 01 | 00 00 00 | 82 00 00 00
        let du = [
            0xB8, 0x1E, 0x01, 0x00, 0x0A, 0x35, 0x01, 0, 0, 0, 0x82, 0, 0, 0,
        ];
        let p = SetPrm::parse(&du).unwrap();
        assert!(p.station_status.contains(
            PrmStationStatus::LOCK_REQ
                | PrmStationStatus::SYNC_REQ
                | PrmStationStatus::FREEZE_REQ
                | PrmStationStatus::WD_ON
        ));
        assert_eq!(p.ident_number, 0x0A35);
        assert_eq!(p.group_ident, 1);
        assert_eq!(p.watchdog(true), Some(Duration::from_millis(300)));
        let mut out = [0u8; 32];
        assert_eq!(p.emit(&mut out), Some(14));
        assert_eq!(&out[..14], &du);
    }

    #[test]
    fn wd_base_1ms() {
        let du = [0x08, 10, 5, 11, 0, 8, 0, 0x84, 0, 0];
        let p = SetPrm::parse(&du).unwrap();
        assert_eq!(p.watchdog(true), Some(Duration::from_millis(50)));
        assert_eq!(p.watchdog(false), Some(Duration::from_millis(500)));
    }

    #[test]
    fn lengths() {
        assert_eq!(SetPrm::parse(&[0; 6]), Err(PrmError::TooShort(6)));
        assert_eq!(SetPrm::parse(&[0; 245]), Err(PrmError::TooLong(245)));
    }
}
