//! The [`Device`] trait: what a device profile implements so that
//! [`DpSlave`](super::DpSlave) can run it, and the small types it uses.
//!
//! The slave core keeps the DP state machine (Wait_Prm → Wait_Cfg →
//! Data_Exch), the watchdog, ownership, sync/freeze, the diagnosis header
//! and the DP-V1 polling protocol. The device decides everything that is
//! specific to a product: its ident number and features, which parameters
//! and configurations it accepts, what its outputs do, what its inputs
//! are, its extended diagnosis and its DP-V1 records.

use crate::pdu::diag::ChannelIo;
use crate::pdu::dpv1::{AccessError, ApplicationError, Dpv1Error, ErrorClass, FN_READ, FN_WRITE};
use crate::pdu::prm::SetPrm;
use crate::slave::{Reason, SlaveState};
use profibus_fdl::Instant;

/// The optional DP functions a device supports (the matching GSD keys in
/// brackets). The slave core refuses what is not supported: a Set_Prm
/// asking for sync or freeze gets Not_Supported, a Set_Slave_Add is
/// refused, the DP-V1 SAPs stay deactivated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Features {
    /// Sync mode (`Sync_Mode_supp`).
    pub sync: bool,
    /// Freeze mode (`Freeze_Mode_supp`).
    pub freeze: bool,
    /// Set_Slave_Add (`Set_Slave_Add_supp`).
    pub set_slave_add: bool,
    /// A DP-V1 slave (`DPV1_Slave`): User_Prm_Data starts with the three
    /// DPV1_Status bytes, WD_Base_1ms is honoured.
    pub dpv1: bool,
    /// MSAC_C1 read/write (`C1_Read_Write_supp`); needs `dpv1`.
    pub c1_read_write: bool,
    /// DP-V1 alarms with Alarm_Ack (any `*_Alarm_supp`); needs `dpv1`.
    pub alarms: bool,
    /// Fail-safe (`Fail_Safe`): in the master's clear state Data_Exchange
    /// carries no output data.
    pub fail_safe: bool,
    /// Longest Slave_Diag response (`Max_Diag_Data_Len`, 6..=244).
    pub max_diag_len: u8,
    /// Longest data block of an MSAC_C1 Read or Write (`C1_Max_Data_Len`,
    /// 1..=240). The core answers a Read of 0 or more bytes, and a Write of
    /// 0 or more bytes, with a DP-V1 error before the device sees it.
    pub c1_max_data_len: u8,
    /// MSAC_C2 class-2 connections (`C2_Read_Write_supp`); needs `dpv1`.
    /// Without it the resource manager's SAP 49 stays deactivated (RS).
    pub c2_read_write: bool,
    /// Longest data block of a class-2 Read, Write or Data_Transport
    /// (`C2_Max_Data_Len`, 1..=240).
    pub c2_max_data_len: u8,
    /// Class-2 connections open at once (`C2_Max_Count_Channels`,
    /// 1..=49).
    pub c2_max_count_channels: u8,
    /// Longest Initiate.req accepted (`Max_Initiate_PDU_Length`); 0: only
    /// the 20-byte Initiate.req without network/MAC address extensions.
    pub max_initiate_pdu_length: u8,
    /// I&M identification: I&M0..I&M4 on slot 0, index 255 through the
    /// call header (`08 00 FI_Index`), answered by the core from
    /// [`Device::im_read`] / [`Device::im_write`]; needs `dpv1`.
    pub im: bool,
}

impl Default for Features {
    /// A plain DP-V0 slave: nothing optional, 244 bytes of diagnosis.
    fn default() -> Features {
        Features {
            sync: false,
            freeze: false,
            set_slave_add: false,
            dpv1: false,
            c1_read_write: false,
            alarms: false,
            fail_safe: false,
            max_diag_len: 244,
            c1_max_data_len: 240,
            c2_read_write: false,
            c2_max_data_len: 240,
            c2_max_count_channels: 1,
            max_initiate_pdu_length: 0,
            im: false,
        }
    }
}

/// The cyclic data layout a device learned from an accepted Chk_Cfg.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct IoLayout {
    /// Input bytes (slave → master) of every Data_Exchange response.
    pub inputs: usize,
    /// Output bytes (master → slave) of every Data_Exchange request.
    pub outputs: usize,
}

/// Why the outputs go to their safe state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ClearReason {
    /// The watchdog expired.
    Watchdog,
    /// The slave left Data_Exch (new Set_Prm, fault, unlock, bad
    /// Data_Exchange).
    LeftDataExchange,
    /// Global_Control Clear_Data: the master is in its clear state.
    ClearData,
    /// A fail-safe master sent a Data_Exchange without output data.
    FailSafe,
}

#[cfg(feature = "serde")]
impl serde::Serialize for ClearReason {
    /// In words, as [`ClearReason::as_str`].
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl ClearReason {
    /// Words for people.
    pub fn as_str(self) -> &'static str {
        match self {
            ClearReason::Watchdog => "watchdog expired",
            ClearReason::LeftDataExchange => "left Data_Exch",
            ClearReason::ClearData => "Global_Control Clear_Data",
            ClearReason::FailSafe => "fail-safe Data_Exchange without outputs",
        }
    }
}

/// Result of a DP-V1 class-1 read or write handed to the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dpv1Outcome {
    /// Done. For a read: the number of bytes written into the buffer. For a
    /// write: the number of bytes written (the response's length byte).
    Done(usize),
    /// Not ready yet: the slave answers the master's polls with a short
    /// acknowledge and asks again through [`Device::dpv1_poll`].
    Pending,
    /// Refused with a DP-V1 error (see [`Dpv1Error::dpv1`]).
    Error(Dpv1Error),
}

impl Dpv1Outcome {
    /// Refusal of a read with `class`/`code` (DP-V1 error classes, IEC 61158-6-3).
    pub fn read_error(class: u8, code: u8) -> Dpv1Outcome {
        Dpv1Outcome::Error(Dpv1Error::dpv1(FN_READ, class, code))
    }

    /// Refusal of a write with `class`/`code`.
    pub fn write_error(class: u8, code: u8) -> Dpv1Outcome {
        Dpv1Outcome::Error(Dpv1Error::dpv1(FN_WRITE, class, code))
    }
}

/// Error class "application" (Error_Code_1 high nibble 0xA).
pub const ERR_CLASS_APPLICATION: u8 = ErrorClass::Application.code();
/// Error class "access" (0xB).
pub const ERR_CLASS_ACCESS: u8 = ErrorClass::Access.code();
/// Error class "resource" (0xC).
pub const ERR_CLASS_RESOURCE: u8 = ErrorClass::Resource.code();
/// Application error code "feature not supported".
pub const ERR_FEATURE_NOT_SUPPORTED: u8 = ApplicationError::FeatureNotSupported.code();
/// Access error code "invalid index".
pub const ERR_INVALID_INDEX: u8 = AccessError::InvalidIndex.code();
/// Access error code "write length error".
pub const ERR_WRITE_LENGTH: u8 = AccessError::WriteLength.code();
/// Access error code "invalid slot".
pub const ERR_INVALID_SLOT: u8 = AccessError::InvalidSlot.code();
/// Access error code "state conflict".
pub const ERR_STATE_CONFLICT: u8 = AccessError::StateConflict.code();
/// Access error code "invalid range".
pub const ERR_INVALID_RANGE: u8 = AccessError::InvalidRange.code();
/// Access error code "access denied".
pub const ERR_ACCESS_DENIED: u8 = AccessError::AccessDenied.code();
/// Access error code "invalid parameter".
pub const ERR_INVALID_PARAMETER: u8 = AccessError::InvalidParameter.code();

/// Where the slave's station address comes from (see
/// [`Device::own_address`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OwnAddress {
    /// The address the slave was created with, or got by Set_Slave_Add.
    Slave,
    /// The device has no address yet: the station does not take part in
    /// the bus (it answers nothing, broadcasts included).
    NoneYet,
    /// The device set this address itself, e.g. its PLC wrote it into a
    /// register.
    Set(u8),
}

/// Something a device reports for people (e.g. "PKW job done"); the slave
/// passes it on as [`SlaveEvent::Device`](super::SlaveEvent::Device).
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct DeviceEvent {
    /// A short machine-readable kind, e.g. `"pkw"`.
    pub kind: &'static str,
    /// What happened, in words (serialised as `detail`: a printed event's
    /// `text` is the whole [`SlaveEvent`](super::SlaveEvent) in words).
    #[cfg_attr(feature = "serde", serde(rename = "detail"))]
    pub text: String,
}

/// Collects the extended diagnosis blocks of a Slave_Diag response for
/// [`Device::diagnosis`]. Blocks that do not fit into the device's
/// `max_diag_len` are dropped and set Ext_Diag_Overflow.
#[derive(Debug)]
pub struct DiagWriter<'a> {
    buf: &'a mut [u8],
    len: usize,
    overflow: bool,
    ext_diag: bool,
    stat_diag: bool,
}

impl<'a> DiagWriter<'a> {
    /// A writer filling `buf` (the space after the 6 standard bytes).
    pub fn new(buf: &'a mut [u8]) -> DiagWriter<'a> {
        DiagWriter {
            buf,
            len: 0,
            overflow: false,
            ext_diag: false,
            stat_diag: false,
        }
    }

    /// Append a raw block (header included). Returns false and sets
    /// Ext_Diag_Overflow when it does not fit.
    pub fn block(&mut self, bytes: &[u8]) -> bool {
        self.with(bytes.len(), |b| b.copy_from_slice(bytes))
    }

    fn with(&mut self, n: usize, fill: impl FnOnce(&mut [u8])) -> bool {
        if self.overflow || self.len + n > self.buf.len() {
            self.overflow = true;
            return false;
        }
        fill(&mut self.buf[self.len..self.len + n]);
        self.len += n;
        true
    }

    /// Append a device-related block (header `00` + length) with `data`
    /// (at most 62 bytes).
    pub fn device(&mut self, data: &[u8]) -> bool {
        self.headed(0x00, &[], data)
    }

    /// Append an identifier-related block (header `01` + length): bit n of
    /// `bits` set = identifier (module) n faulty.
    pub fn identifier(&mut self, bits: &[u8]) -> bool {
        self.headed(0x40, &[], bits)
    }

    /// Append a channel-related block (3 bytes): `identifier` 0..=63,
    /// `channel` 0..=63, `channel_type` 0..=7 (1 bit … 6 two words),
    /// `error_type` 0..=31 (1 short circuit … 9 error, 16..=31 vendor).
    pub fn channel(
        &mut self,
        identifier: u8,
        channel: u8,
        io: ChannelIo,
        channel_type: u8,
        error_type: u8,
    ) -> bool {
        let dir = match io {
            ChannelIo::Reserved => 0,
            ChannelIo::Input => 1,
            ChannelIo::Output => 2,
            ChannelIo::InOut => 3,
        };
        self.block(&[
            0x80 | (identifier & 0x3F),
            (dir << 6) | (channel & 0x3F),
            ((channel_type & 0x07) << 5) | (error_type & 0x1F),
        ])
    }

    /// Append a DP-V1 alarm or status block: a device-related block
    /// `header, type, slot, specifier, data…` (type bit 7 clear = alarm,
    /// set = status).
    pub fn dpv1_block(&mut self, block_type: u8, slot: u8, specifier: u8, data: &[u8]) -> bool {
        self.headed(0x00, &[block_type, slot, specifier], data)
    }

    fn headed(&mut self, kind: u8, head: &[u8], data: &[u8]) -> bool {
        let n = 1 + head.len() + data.len();
        if n > 63 {
            self.overflow = true;
            return false;
        }
        self.with(n, |b| {
            b[0] = kind | n as u8;
            b[1..1 + head.len()].copy_from_slice(head);
            b[1 + head.len()..].copy_from_slice(data);
        })
    }

    /// Set Ext_Diag in Station_Status_1: the blocks describe a fault.
    pub fn set_ext_diag(&mut self) {
        self.ext_diag = true;
    }

    /// Set Stat_Diag in Station_Status_2: the master is to keep fetching
    /// diagnosis instead of exchanging data until the bit clears.
    pub fn set_stat_diag(&mut self) {
        self.stat_diag = true;
    }

    /// Set Ext_Diag_Overflow: the device has more diagnosis than it sent.
    pub fn set_overflow(&mut self) {
        self.overflow = true;
    }

    /// Bytes written so far.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether no block was written.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Bytes still free.
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.len
    }

    /// (length, Ext_Diag, Stat_Diag, Ext_Diag_Overflow).
    pub(crate) fn finish(&self) -> (usize, bool, bool, bool) {
        (self.len, self.ext_diag, self.stat_diag, self.overflow)
    }
}

/// A product that a [`DpSlave`](super::DpSlave) emulates: its identity,
/// which parameters and configurations it accepts, its process data, its
/// diagnosis and its DP-V1 records.
///
/// Every method except the first five has a default, so a simple device
/// is short:
///
/// ```
/// use profibus_dp::pdu::prm::SetPrm;
/// use profibus_dp::slave::{Device, IoLayout, Reason, expect_cfg};
/// use profibus_fdl::Instant;
///
/// /// 2 bytes out, 2 bytes in; the inputs echo the outputs inverted.
/// struct Inverter { last: [u8; 2] }
///
/// impl Device for Inverter {
///     fn ident_number(&self) -> u16 { 0x1234 }
///     fn real_cfg(&self) -> &[u8] { &[0x31] } // 2 bytes in + out
///     fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
///         if prm.user_prm_data.is_empty() { Ok(()) } else { Err("no User_Prm_Data expected".into()) }
///     }
///     fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
///         expect_cfg(self.real_cfg(), cfg)
///     }
///     fn write_outputs(&mut self, _now: Instant, outputs: &[u8]) {
///         self.last.copy_from_slice(outputs);
///     }
///     fn read_inputs(&mut self, _now: Instant, inputs: &mut [u8]) {
///         inputs[0] = !self.last[0];
///         inputs[1] = !self.last[1];
///     }
///     fn clear_outputs(&mut self, _now: Instant, _why: profibus_dp::slave::ClearReason) {
///         self.last = [0; 2];
///     }
/// }
/// ```
pub trait Device {
    /// The ident number (GSD `Ident_Number`); a Set_Prm with another one
    /// is a parameter fault.
    fn ident_number(&self) -> u16;

    /// The real configuration, answered to Get_Cfg. A modular device
    /// returns what it learned from the last accepted Chk_Cfg.
    fn real_cfg(&self) -> &[u8];

    /// Check a Set_Prm the core found valid (ident number, lengths, lock
    /// bits, watchdog, sync/freeze support and DP-V1 status bytes are
    /// checked already). Look at `prm.user_prm_data` (for DP-V1 devices
    /// it starts with the three DPV1_Status bytes) and keep what the
    /// device needs. `Err` sets Prm_Fault and keeps the slave in Wait_Prm.
    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason>;

    /// Check the configuration of a Chk_Cfg and learn the cyclic layout.
    /// A device may accept several equivalent configurations. `Err` sets
    /// Cfg_Fault and returns the slave to Wait_Prm. [`expect_cfg`] does
    /// the common exact comparison.
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason>;

    /// Outputs from the master, as many bytes as the accepted
    /// configuration has, after the sync semantics (in sync mode they
    /// arrive at the Sync command, not with each Data_Exchange).
    fn write_outputs(&mut self, now: Instant, outputs: &[u8]);

    /// Produce the inputs (the buffer has the configured length). Called
    /// for each Data_Exchange response and Rd_Inp, and once at each Freeze
    /// command (the frozen values are then repeated by the core).
    fn read_inputs(&mut self, now: Instant, inputs: &mut [u8]);

    /// The optional functions the device supports. Default: none.
    fn features(&self) -> Features {
        Features::default()
    }

    /// The outputs go to their safe state (watchdog, clear, leaving
    /// Data_Exch, fail-safe). The device decides what that means for it
    /// (typically all zero). Default: nothing.
    fn clear_outputs(&mut self, _now: Instant, _why: ClearReason) {}

    /// Write the extended diagnosis (the bytes after the 6 standard ones)
    /// for a Slave_Diag response, and set Ext_Diag / Stat_Diag / overflow
    /// as needed. Default: none.
    fn diagnosis(&mut self, _now: Instant, _diag: &mut DiagWriter<'_>) {}

    /// Whether the diagnosis changed since the last call. When it returns
    /// true, the slave answers Data_Exchange with "data high" (DH) until
    /// the master has fetched the diagnosis. Polled once per
    /// Data_Exchange; must not allocate. Default: never.
    fn take_new_diag(&mut self) -> bool {
        false
    }

    /// DP-V1 Read of `out.len()` bytes (the requested length, at most
    /// 240) from `slot`/`index`, from a class-1 master (MSAC_C1) or over a
    /// class-2 connection (MSAC_C2): the records are the same. Default: "feature not supported".
    fn dpv1_read(&mut self, _now: Instant, _slot: u8, _index: u8, _out: &mut [u8]) -> Dpv1Outcome {
        Dpv1Outcome::read_error(ERR_CLASS_APPLICATION, ERR_FEATURE_NOT_SUPPORTED)
    }

    /// DP-V1 Write of `data` to `slot`/`index` (class 1 or class 2). Default: "feature not
    /// supported".
    fn dpv1_write(&mut self, _now: Instant, _slot: u8, _index: u8, _data: &[u8]) -> Dpv1Outcome {
        Dpv1Outcome::write_error(ERR_CLASS_APPLICATION, ERR_FEATURE_NOT_SUPPORTED)
    }

    /// MSAC_C2 Data_Transport of `data` to `slot`/`index` (class 2 only):
    /// write the answer into `out` (at most C2_Max_Data_Len bytes) and
    /// return [`Dpv1Outcome::Done`] with its length. Default: "feature not
    /// supported".
    fn dpv1_data_transport(
        &mut self,
        _now: Instant,
        _slot: u8,
        _index: u8,
        _data: &[u8],
        _out: &mut [u8],
    ) -> Dpv1Outcome {
        Dpv1Outcome::Error(Dpv1Error::dpv1(
            crate::pdu::c2::FN_DATA_TRANSPORT,
            ERR_CLASS_APPLICATION,
            ERR_FEATURE_NOT_SUPPORTED,
        ))
    }

    /// The I&M record I&M`number` (0..=4): fill `out` with its 64 bytes
    /// and return true, or false when the device has no such record.
    /// Asked only when [`Features::im`] is set. Default: none.
    fn im_read(&mut self, _number: u8, _out: &mut [u8; 64]) -> bool {
        false
    }

    /// A master writes I&M`number` (1..=4; the core refuses writes of
    /// I&M0). Keep it (and persist it where the device keeps state), or
    /// refuse. Default: "access denied".
    fn im_write(
        &mut self,
        _now: Instant,
        _number: u8,
        _record: &[u8; 64],
    ) -> Result<(), Dpv1Error> {
        Err(Dpv1Error::dpv1(
            FN_WRITE,
            ERR_CLASS_ACCESS,
            ERR_ACCESS_DENIED,
        ))
    }

    /// Called for each poll of the master while a read or write answered
    /// [`Dpv1Outcome::Pending`]; `out` is the read buffer again (ignored
    /// for writes). Default: "state conflict" (a device that never answers
    /// `Pending` is never asked).
    fn dpv1_poll(&mut self, _now: Instant, _out: &mut [u8]) -> Dpv1Outcome {
        Dpv1Outcome::read_error(ERR_CLASS_ACCESS, ERR_STATE_CONFLICT)
    }

    /// MSAC_C1 Alarm_Ack of the alarm `alarm_type` in `slot` with sequence
    /// number `seq` (0..=31) that is not one of the core's queue (see
    /// [`Device::take_alarm`]): for a device that writes its own alarm
    /// blocks. Default: refused ("feature not supported").
    fn alarm_ack(
        &mut self,
        _now: Instant,
        _slot: u8,
        _alarm_type: u8,
        _seq: u8,
    ) -> Result<(), Dpv1Error> {
        Err(Dpv1Error::dpv1(
            crate::pdu::dpv1::FN_ALARM_ACK,
            ERR_CLASS_APPLICATION,
            ERR_FEATURE_NOT_SUPPORTED,
        ))
    }

    /// An alarm the device raises: the core takes them (before each
    /// request and after each timeout) into its alarm queue
    /// ([`DpSlave::raise_alarm`](super::DpSlave::raise_alarm)), which
    /// reports them in Slave_Diag until the master acknowledges them.
    /// Default: none.
    fn take_alarm(&mut self) -> Option<super::Alarm> {
        None
    }

    /// Set_Slave_Add accepted by the core (supported, in Wait_Prm, ident
    /// number right, No_Add_Chg not set before): persist `new_address`
    /// (and `no_add_chg`, and the optional `rem_slave_data`) where the
    /// device keeps it, or refuse. Default: accept without persisting.
    fn set_address(
        &mut self,
        _new_address: u8,
        _no_add_chg: bool,
        _rem_slave_data: &[u8],
    ) -> Result<(), Reason> {
        Ok(())
    }

    /// The station address when the device decides it at run time
    /// (asked for every received telegram, so it must be cheap). Default:
    /// [`OwnAddress::Slave`].
    fn own_address(&self) -> OwnAddress {
        OwnAddress::Slave
    }

    /// Whether the device restarted its bus interface since the last call
    /// (a reset, a newly set address). The slave then forgets the master,
    /// the parameters and the configuration and returns to Wait_Prm.
    /// Asked before each request and at each timeout. Default: never.
    fn take_restart(&mut self) -> bool {
        false
    }

    /// The DP state changed to `state` (Wait_Prm, Wait_Cfg, Data_Exch).
    /// Default: nothing.
    fn state_changed(&mut self, _now: Instant, _state: SlaveState) {}

    /// The slave refused a Set_Prm in its own checks (ident number, lock
    /// bits, watchdog, DP-V1 status bytes) or in [`Device::check_prm`].
    /// Default: nothing.
    fn prm_refused(&mut self, _now: Instant, _reason: &Reason) {}

    /// An SRD request to a SAP no DP service of this slave uses (the
    /// LSAPs of an FMS communication relationship list, for one): write
    /// the response's data unit into `out` and return its length, or
    /// `None` to answer "SAP not activated" (RS) as before. Requests to
    /// the class-2 connection SAPs 0..=48 come here only while MSAC_C2 is
    /// not offered. Default: `None`.
    fn fdl_request(
        &mut self,
        _now: Instant,
        _from: u8,
        _dsap: u8,
        _ssap: u8,
        _data: &[u8],
        _out: &mut [u8],
    ) -> Option<usize> {
        None
    }

    /// Something for people (polled after every request and timeout).
    fn poll_event(&mut self) -> Option<DeviceEvent> {
        None
    }

    /// When the device next needs [`Device::handle_timeout`].
    fn poll_timeout(&self) -> Option<Instant> {
        None
    }

    /// Time has advanced (device-internal timers).
    fn handle_timeout(&mut self, _now: Instant) {}
}

impl<D: Device + ?Sized> Device for Box<D> {
    fn ident_number(&self) -> u16 {
        (**self).ident_number()
    }
    fn real_cfg(&self) -> &[u8] {
        (**self).real_cfg()
    }
    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        (**self).check_prm(prm)
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        (**self).check_cfg(cfg)
    }
    fn write_outputs(&mut self, now: Instant, outputs: &[u8]) {
        (**self).write_outputs(now, outputs)
    }
    fn read_inputs(&mut self, now: Instant, inputs: &mut [u8]) {
        (**self).read_inputs(now, inputs)
    }
    fn features(&self) -> Features {
        (**self).features()
    }
    fn clear_outputs(&mut self, now: Instant, why: ClearReason) {
        (**self).clear_outputs(now, why)
    }
    fn diagnosis(&mut self, now: Instant, diag: &mut DiagWriter<'_>) {
        (**self).diagnosis(now, diag)
    }
    fn take_new_diag(&mut self) -> bool {
        (**self).take_new_diag()
    }
    fn dpv1_read(&mut self, now: Instant, slot: u8, index: u8, out: &mut [u8]) -> Dpv1Outcome {
        (**self).dpv1_read(now, slot, index, out)
    }
    fn dpv1_write(&mut self, now: Instant, slot: u8, index: u8, data: &[u8]) -> Dpv1Outcome {
        (**self).dpv1_write(now, slot, index, data)
    }
    fn dpv1_poll(&mut self, now: Instant, out: &mut [u8]) -> Dpv1Outcome {
        (**self).dpv1_poll(now, out)
    }
    fn dpv1_data_transport(
        &mut self,
        now: Instant,
        slot: u8,
        index: u8,
        data: &[u8],
        out: &mut [u8],
    ) -> Dpv1Outcome {
        (**self).dpv1_data_transport(now, slot, index, data, out)
    }
    fn im_read(&mut self, number: u8, out: &mut [u8; 64]) -> bool {
        (**self).im_read(number, out)
    }
    fn im_write(&mut self, now: Instant, number: u8, record: &[u8; 64]) -> Result<(), Dpv1Error> {
        (**self).im_write(now, number, record)
    }
    fn alarm_ack(
        &mut self,
        now: Instant,
        slot: u8,
        alarm_type: u8,
        seq: u8,
    ) -> Result<(), Dpv1Error> {
        (**self).alarm_ack(now, slot, alarm_type, seq)
    }
    fn take_alarm(&mut self) -> Option<super::Alarm> {
        (**self).take_alarm()
    }
    fn set_address(
        &mut self,
        new_address: u8,
        no_add_chg: bool,
        rem_slave_data: &[u8],
    ) -> Result<(), Reason> {
        (**self).set_address(new_address, no_add_chg, rem_slave_data)
    }
    fn own_address(&self) -> OwnAddress {
        (**self).own_address()
    }
    fn take_restart(&mut self) -> bool {
        (**self).take_restart()
    }
    fn state_changed(&mut self, now: Instant, state: SlaveState) {
        (**self).state_changed(now, state)
    }
    fn prm_refused(&mut self, now: Instant, reason: &Reason) {
        (**self).prm_refused(now, reason)
    }
    fn fdl_request(
        &mut self,
        now: Instant,
        from: u8,
        dsap: u8,
        ssap: u8,
        data: &[u8],
        out: &mut [u8],
    ) -> Option<usize> {
        (**self).fdl_request(now, from, dsap, ssap, data, out)
    }
    fn poll_event(&mut self) -> Option<DeviceEvent> {
        (**self).poll_event()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        (**self).poll_timeout()
    }
    fn handle_timeout(&mut self, now: Instant) {
        (**self).handle_timeout(now)
    }
}

/// Compare a Chk_Cfg configuration with the one a device expects, byte for
/// byte, and return the layout. The reason names the first difference.
pub fn expect_cfg(expected: &[u8], got: &[u8]) -> Result<IoLayout, Reason> {
    if let Some(index) = expected.iter().zip(got).position(|(a, b)| a != b) {
        return Err(Reason::CfgByte {
            index,
            expected: expected.to_vec(),
            got: got.to_vec(),
        });
    }
    if expected.len() != got.len() {
        return Err(Reason::CfgLength {
            expected: expected.to_vec(),
            got: got.to_vec(),
        });
    }
    layout_of(got)
}

/// Check that a Set_Prm carries the `len` bytes of User_Prm_Data the
/// device's GSD gives (`User_Prm_Data_Len`).
pub fn expect_user_prm_len(prm: &SetPrm<'_>, len: usize) -> Result<(), Reason> {
    if prm.user_prm_data.len() == len {
        Ok(())
    } else {
        Err(Reason::UserPrmLen {
            got: prm.user_prm_data.len(),
            expected: len,
        })
    }
}

/// The cyclic layout of a configuration (sum of its identifiers), or why
/// it cannot be decoded or exceeds 244 bytes in a direction.
pub fn layout_of(cfg: &[u8]) -> Result<IoLayout, Reason> {
    let t = crate::pdu::cfg::totals(cfg)?;
    if t.input_bytes > super::MAX_IO_LEN || t.output_bytes > super::MAX_IO_LEN {
        return Err(Reason::CfgTooLong {
            inputs: t.input_bytes,
            outputs: t.output_bytes,
        });
    }
    Ok(IoLayout {
        inputs: t.input_bytes,
        outputs: t.output_bytes,
    })
}

pub(crate) fn hex(bytes: &[u8]) -> String {
    if bytes.is_empty() {
        "(none)".into()
    } else {
        profibus_fdl::wire::Hex(bytes).to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pdu::diag::{ext_blocks, ExtDiagBlock, LINE_BREAK_3_2};

    #[test]
    fn diag_writer_blocks_and_overflow() {
        let mut buf = [0u8; 10];
        let mut w = DiagWriter::new(&mut buf);
        assert!(w.device(&[0xAA, 0xBB]));
        assert!(w.channel(3, 2, ChannelIo::Input, 5, 6));
        assert!(
            !w.identifier(&[1, 2, 3, 4]),
            "5 bytes do not fit into 4 left"
        );
        assert!(!w.device(&[]), "nothing after an overflow");
        let (len, ext, stat, ovf) = w.finish();
        assert_eq!((len, ext, stat, ovf), (6, false, false, true));
        let blocks: Vec<_> = ext_blocks(&buf[..len]).collect();
        assert_eq!(
            blocks[0],
            ExtDiagBlock::Device {
                data: &[0xAA, 0xBB]
            }
        );
        assert_eq!(blocks[1], LINE_BREAK_3_2);
    }

    #[test]
    fn dpv1_block_layout() {
        let mut buf = [0u8; 32];
        let mut w = DiagWriter::new(&mut buf);
        w.dpv1_block(0x01, 2, 0x0D, &[9]);
        assert_eq!(w.len(), 5);
        assert_eq!(&buf[..5], &[0x05, 0x01, 0x02, 0x0D, 0x09]);
    }

    #[test]
    fn expect_cfg_words() {
        assert_eq!(
            expect_cfg(&[0x31, 0x20], &[0x31, 0x20]),
            Ok(IoLayout {
                inputs: 2,
                outputs: 3
            })
        );
        let e = expect_cfg(&[0x31, 0x20], &[0x31, 0x21]).unwrap_err();
        assert!(e
            .to_string()
            .starts_with("configuration byte 1 is 0x21, expected 0x20"));
        let e = expect_cfg(&[0x31], &[0x31, 0x21]).unwrap_err();
        assert!(e
            .to_string()
            .starts_with("configuration has 2 bytes, expected 1"));
        assert!(layout_of(&[0x42]).is_err());
    }
}
