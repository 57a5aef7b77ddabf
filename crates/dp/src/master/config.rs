//! Configuration of a DP master and of each slave it polls.

use crate::pdu::alarm::AlarmMode;
use crate::pdu::cfg::{self, CfgError};
use crate::pdu::prm::{Dpv1Status2, PrmStationStatus, SetPrm};
use profibus_fdl::timing::BusParams;
use std::time::Duration;

/// How a slave is to be parameterised and configured.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlaveParams {
    /// Station address (0..=125).
    pub address: u8,
    /// A name for people (from the bus file).
    pub name: String,
    /// The slave's ident number (Set_Prm bytes 4-5).
    pub ident_number: u16,
    /// Watchdog time; `None` switches the watchdog off.
    pub watchdog: Option<Duration>,
    /// Group_Ident bits (bit n = group n+1).
    pub group: u8,
    /// Operate the slave in sync mode.
    pub sync: bool,
    /// Operate the slave in freeze mode.
    pub freeze: bool,
    /// min TSDR the slave is to keep (bit times; 0 = keep its value).
    pub min_tsdr: u8,
    /// User_Prm_Data (for DP-V1 slaves starting with DPV1_Status_1..3).
    pub user_prm_data: Vec<u8>,
    /// The Chk_Cfg identifier bytes.
    pub cfg: Vec<u8>,
    /// DP-V1 slave: WD_Base_1ms may be used, MSAC_C1 allowed.
    pub dpv1: bool,
    /// Fail_Safe: in the clear state the slave gets Data_Exchange
    /// telegrams without outputs instead of zeroed outputs.
    pub fail_safe: bool,
    /// Shortest time between two polls of this slave (GSD
    /// Min_Slave_Intervall × 100 µs).
    pub min_slave_interval: Duration,
    /// Outputs sent until the application writes others.
    pub initial_outputs: Vec<u8>,
    /// Time a DP-V1 read/write may take (GSD C1_Response_Timeout).
    pub dpv1_timeout: Duration,
    /// DP-V1 alarms Set_Prm enables (the alarm bits of DPV1_Status_2;
    /// bus file `alarms`, default: those the GSD declares). Any alarm
    /// also sets DPV1_Enable; none clears the alarm bits.
    pub alarms: Dpv1Status2,
    /// Alarm_Mode (DPV1_Status_3 b2-0) sent with alarms.
    pub alarm_mode: AlarmMode,
}

impl SlaveParams {
    /// A slave at `address` with ident number `ident` and configuration
    /// `cfg`; watchdog 1 s, group 0, no sync/freeze, no user parameters.
    pub fn new(address: u8, ident_number: u16, cfg: Vec<u8>) -> SlaveParams {
        SlaveParams {
            address,
            name: format!("slave {address}"),
            ident_number,
            watchdog: Some(Duration::from_secs(1)),
            group: 0,
            sync: false,
            freeze: false,
            min_tsdr: 0,
            user_prm_data: Vec::new(),
            cfg,
            dpv1: false,
            fail_safe: false,
            min_slave_interval: Duration::ZERO,
            initial_outputs: Vec::new(),
            dpv1_timeout: Duration::from_secs(1),
            alarms: Dpv1Status2::empty(),
            alarm_mode: AlarmMode(0),
        }
    }

    /// Input and output bytes of the configuration.
    pub fn io_lengths(&self) -> Result<(usize, usize), CfgError> {
        let t = cfg::totals(&self.cfg)?;
        Ok((t.input_bytes, t.output_bytes))
    }

    /// The watchdog factors for `watchdog`: 10 ms base, or 1 ms base for a
    /// DP-V1 slave (whose User_Prm_Data carries DPV1_Status_1) when the
    /// time is short or not a multiple of 10 ms.
    /// Returns (WD_Fact_1, WD_Fact_2, base_1ms).
    pub fn watchdog_factors(&self) -> Option<(u8, u8, bool)> {
        let wd = self.watchdog?;
        let ms = wd.as_millis().max(1);
        let can_1ms = self.dpv1 && self.user_prm_data.len() >= 3;
        let (units, base_1ms) = if can_1ms && (ms < 100 || ms % 10 != 0) && ms <= 65025 {
            (ms, true)
        } else {
            (ms.div_ceil(10).min(65025), false)
        };
        let f1 = units.div_ceil(255).max(1);
        let f2 = units.div_ceil(f1).clamp(1, 255);
        Some((f1 as u8, f2 as u8, base_1ms))
    }

    /// The Set_Prm data unit this master sends: Lock_Req, WD_On with the
    /// watchdog factors, Sync/Freeze_Req, min TSDR, ident, group, then
    /// User_Prm_Data (with WD_Base_1ms set in DPV1_Status_1 when needed).
    pub fn set_prm(&self) -> Vec<u8> {
        let mut status = PrmStationStatus::LOCK_REQ;
        let (f1, f2, base_1ms) = match self.watchdog_factors() {
            Some(f) => {
                status |= PrmStationStatus::WD_ON;
                f
            }
            None => (1, 1, false),
        };
        if self.sync {
            status |= PrmStationStatus::SYNC_REQ;
        }
        if self.freeze {
            status |= PrmStationStatus::FREEZE_REQ;
        }
        let mut user = self.user_prm_data.clone();
        if self.dpv1 && !user.is_empty() {
            if base_1ms {
                user[0] |= crate::pdu::prm::Dpv1Status1::WD_BASE_1MS.bits();
            } else {
                user[0] &= !crate::pdu::prm::Dpv1Status1::WD_BASE_1MS.bits();
            }
        }
        if self.dpv1 && user.len() >= 3 {
            // The alarm enables (DPV1_Status_2) and Alarm_Mode
            // (DPV1_Status_3 b2-0) are the master's, whatever the GSD's
            // constant User_Prm_Data says; alarms need DPV1_Enable.
            let alarm_bits = Dpv1Status2::all().difference(Dpv1Status2::CHECK_CFG_MODE);
            user[1] = (user[1] & !alarm_bits.bits()) | self.alarms.bits();
            if !self.alarms.is_empty() {
                user[0] |= crate::pdu::prm::Dpv1Status1::DPV1_ENABLE.bits();
                user[2] = (user[2] & !0x07) | (self.alarm_mode.0 & 0x07);
            }
        }
        let prm = SetPrm {
            station_status: status,
            wd_fact_1: f1,
            wd_fact_2: f2,
            min_tsdr: self.min_tsdr,
            ident_number: self.ident_number,
            group_ident: self.group,
            user_prm_data: &user,
        };
        let mut out = vec![0u8; prm.len()];
        prm.emit(&mut out);
        out
    }
}

/// Behaviour of the master's poll cycle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MasterOptions {
    /// Consecutive cycles without answer before a slave counts as lost.
    pub lost_after: u8,
    /// How often a lost slave is probed with Slave_Diag.
    pub reprobe_interval: Duration,
    /// Read every slave's diagnosis this often even without DH.
    pub diag_interval: Option<Duration>,
    /// Repeat the operate/clear Global_Control this often; `None`: only on
    /// changes. A class-1 master announces its operating state (Operate or
    /// Clear) to its slaves cyclically, at least once per
    /// Data_Control_Time (EN 50170 Vol. 2, DDLM_Global_Control; the
    /// masters in real traces do so several times a second). Default:
    /// [`DEFAULT_GLOBAL_CONTROL_INTERVAL`].
    pub global_control_interval: Option<Duration>,
    /// Cycles a slave may stay Station_Not_Ready after Chk_Cfg before it
    /// is parameterised again.
    pub not_ready_limit: u16,
    /// Alone in the ring (no other master), a token visit starts further
    /// poll cycles while one more cycle as long as the last ends within
    /// the token hold time TTH (TTR minus the real rotation time,
    /// IEC 61158-4-3: requests may be sent while TTH remains) instead of
    /// passing the token to itself after every poll cycle; the token to
    /// itself with its idle times (about 70 bit) and the visit's GAP poll
    /// (up to a slot time) are then spent once per visit. `None` (the
    /// default, [`DEFAULT_ALONE_HOLD_BITS`]): TTH (from the bus file's
    /// TTR) bounds the visit, and so that the GAP sweep (one address per
    /// visit: the live list, and how a new master joins) keeps its pace
    /// at any TTR and rate, so does [`ALONE_VISIT_MAX`]; a new master
    /// joins within [`join_bound`], and a few rotations after it is ready
    /// when it was switched on just before its GAP poll (the station
    /// polls a "not ready" master again, `profibus_fdl` active station).
    /// `Some(n)`: the override, a visit ends once it has lasted `n` bit
    /// times (or TTH is used); `Some(0)` passes the token after every
    /// poll cycle, as masters that ignore TTH do. With other masters in
    /// the ring the token passes after every poll cycle whatever this
    /// says (their rotation is kept).
    pub alone_hold_bits: Option<u32>,
}

/// The longest token visit of a lone master by default
/// ([`MasterOptions::alone_hold_bits`] `None`): 10 ms, within which TTH
/// also bounds it. At 1.5 Mbit/s about 60 poll cycles of a small slave
/// on a pty, so the token to itself costs under 2 % of the line; at
/// 19.2 kbit/s shorter than one poll cycle (the token after every cycle,
/// as before); the GAP sweep of 126 addresses then takes about 1.3 s.
pub const ALONE_VISIT_MAX: Duration = Duration::from_millis(10);

/// How long a master switched on beside a lone master with the default
/// token use waits at most until it is in the ring (when it was switched
/// on just after the holder polled its address): its own
/// Listen_Token (two rotations) and the holder's whole GAP sweep, one
/// address per visit, up to HSA, plus the G rotations the GAP factor
/// waits after a sweep, each rotation at most two visits (a long one of
/// at most [`ALONE_VISIT_MAX`] or TTR, its GAP poll of a slot time and
/// the token; and a short one of a single cycle when the long one used
/// TTH): `(HSA + G + 4) × 2 × (min(TTR, ALONE_VISIT_MAX) + 2 TSL)`. At
/// 1.5 Mbit/s with the defaults (HSA 126, G 10) 2.9 s; at 19.2 kbit/s
/// (TTR 1.7 s) 5.7 s. The test on the simulator
/// (tests/sim_master_slave.rs) measures a join against it.
pub fn join_bound(params: &profibus_fdl::BusParams) -> Duration {
    let visit = params.bits(u64::from(params.ttr)).min(ALONE_VISIT_MAX)
        + params.bits(2 * u64::from(params.slot_time));
    visit * (2 * (u32::from(params.hsa) + u32::from(params.gap_factor) + 4))
}

/// The default period of the cyclic operate/clear Global_Control: 100 ms,
/// well inside the usual Data_Control_Time (a multiple of the slaves'
/// watchdog time) and a negligible share of the bus at any baud rate.
pub const DEFAULT_GLOBAL_CONTROL_INTERVAL: Duration = Duration::from_millis(100);

/// The back-off after the first failed start-up of a slave (a Prm/Cfg
/// fault, a negative answer to Set_Prm or Chk_Cfg, Station_Not_Ready for
/// too long). The standard's masters retry a failed start-up for as long
/// as the slave is configured (IEC 61158-6-3, the master's slave handler
/// goes back to reading the diagnosis); this master doubles the wait with
/// each failure in a row, from 10 ms up to [`STARTUP_RETRY_MAX`], so a
/// persistent fault costs a few telegrams a second instead of the bus,
/// and a fixed slave is in Data_Exchange within a second.
pub const STARTUP_RETRY_FIRST: Duration = Duration::from_millis(10);

/// The longest back-off between two start-ups of a faulty slave: 1 s.
pub const STARTUP_RETRY_MAX: Duration = Duration::from_secs(1);

/// The default of [`MasterOptions::alone_hold_bits`]: `None`, the token
/// hold rule (poll cycles while TTH lasts, at most [`ALONE_VISIT_MAX`]
/// per visit).
pub const DEFAULT_ALONE_HOLD_BITS: Option<u32> = None;

/// A [`MasterOptions::alone_hold_bits`] override for a master that is
/// alone, wants its slaves polled often and a quick GAP sweep: 3000 bit
/// times (2 ms at 1.5 Mbit/s, 156 ms at 19.2 kbit/s). A poll cycle of one
/// slave with 2 bytes each way costs about 290 bit, its token to itself
/// and GAP poll up to 370 more: with 3000 that slave is polled about twice
/// as often as with the token after every cycle, while the GAP sweep takes
/// about 4.5 times as long. Poll cycles of 3000 bit or more (e.g. 32 such
/// slaves) are not affected.
pub const ALONE_HOLD_BITS_FAST: u32 = 3000;

impl Default for MasterOptions {
    fn default() -> Self {
        MasterOptions {
            lost_after: 3,
            reprobe_interval: Duration::from_millis(100),
            diag_interval: None,
            global_control_interval: Some(DEFAULT_GLOBAL_CONTROL_INTERVAL),
            not_ready_limit: 100,
            alone_hold_bits: DEFAULT_ALONE_HOLD_BITS,
        }
    }
}

/// A DP master's configuration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MasterConfig {
    /// The master's station address.
    pub address: u8,
    /// Bus parameters.
    pub params: BusParams,
    /// The slaves, polled in this order.
    pub slaves: Vec<SlaveParams>,
    /// Poll-cycle behaviour.
    pub options: MasterOptions,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn watchdog_factors() {
        let mut s = SlaveParams::new(5, 0x0008, vec![0x73]);
        s.watchdog = Some(Duration::from_millis(300));
        assert_eq!(s.watchdog_factors(), Some((1, 30, false)));
        s.watchdog = Some(Duration::from_secs(100));
        let (f1, f2, _) = s.watchdog_factors().unwrap();
        assert!(f1 as u32 * f2 as u32 * 10 >= 100_000);
        s.dpv1 = true;
        s.user_prm_data = vec![0x80, 0, 0];
        s.watchdog = Some(Duration::from_millis(25));
        assert_eq!(s.watchdog_factors(), Some((1, 25, true)));
    }

    #[test]
    fn set_prm_bytes() {
        let mut s = SlaveParams::new(5, 0x0A35, vec![0x10]);
        s.watchdog = Some(Duration::from_millis(300));
        s.sync = true;
        s.group = 1;
        s.user_prm_data = vec![0x82, 0, 0];
        let p = s.set_prm();
        assert_eq!(p, vec![0xA8, 1, 30, 0, 0x0A, 0x35, 1, 0x82, 0, 0]);
    }
}
