//! A generic DP slave built from a description (usually a GSD file and a
//! module list): what `dpctl slave --gsd FILE --module NAME …` emulates.
//!
//! - Configuration: the selected modules' identifier bytes, exactly
//!   (Get_Cfg answers them, Chk_Cfg must match them byte for byte).
//! - Parameters: the User_Prm_Data must have the length the description
//!   gives, and every described parameter (`ExtUserPrmData`) must hold an
//!   allowed value.
//! - Inputs: an echo of the outputs, or a counter ([`InputPattern`]), so a
//!   master sees data move.
//! - DP-V1 (when the description says `C1_Read_Write_supp`): a small
//!   record store; any slot/index can be written (up to 240 bytes,
//!   [`MAX_RECORDS`] records) and read back; reading a record never
//!   written is "invalid index".
//! - Class 2 (when the description says `C2_Read_Write_supp`): the same
//!   records over MSAC_C2 connections (`C2_Max_Data_Len`,
//!   `C2_Max_Count_Channels`, `Max_Initiate_PDU_Length`); Data_Transport
//!   writes the record and answers with it.
//! - I&M (every DP-V1 device): I&M0 from the GSD ([`ImIdentity::im0_from_gsd`]),
//!   I&M1..I&M4 writable, kept in the state file of `state_dir`
//!   ([`crate::im`]).
//! - Set_Slave_Add (when supported): accepted unless No_Add_Chg was
//!   stored before ([`GenericDevice::with_stored_address`]); the program
//!   running the slave keeps the address ([`crate::address`]).
//! - DP-V1 alarms (when the description declares any `*_Alarm_supp`):
//!   the control command `alarm TYPE SLOT appears|disappears [HEX]`
//!   ([`GenericDevice::control`], `dpctl slave --control`) raises one;
//!   the slave core queues it, reports it in Slave_Diag and waits for the
//!   master's Alarm_Ack.
//!
//! [`GenericProfile`] is the `generic` entry of the profile registry: the
//! options `gsd`, `modules`, `lenient`, `inputs`, `address_file`,
//! `state_dir`, `order_id`, `serial_number`, `manufacturer_id`.

use crate::kit::{EventQueue, InboxSchedule};
use crate::profile::ControlError;
use profibus_dp::config::gsd::{Gsd, LookupError, PrmDataType, SelectionError};
use profibus_dp::pdu::alarm::{AlarmChange, AlarmType};
use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::Alarm;
use profibus_dp::slave::{
    expect_cfg, expect_user_prm_len, ClearReason, Device, DeviceEvent, DiagWriter, Dpv1Outcome,
    Features, IoLayout, Reason, ERR_CLASS_ACCESS, ERR_CLASS_RESOURCE, ERR_INVALID_INDEX,
    ERR_INVALID_SLOT,
};
use profibus_fdl::Instant;
use std::collections::BTreeMap;
use std::collections::VecDeque;
use std::path::PathBuf;

use crate::address::StoredAddress;
use crate::channels::{ChannelMap, ChannelType, Direction};
use crate::im::{ImIdentity, ImStore, IM_STATE_FILE};
use crate::profile::{ControlInbox, Profile, ProfileError};
use crate::BoxedDevice;
use profibus_dp::config::gsd::ParseOptions;
use profibus_dp::pdu::dpv1::Dpv1Error;
use serde::Deserialize;

/// Most DP-V1 records the generic device stores.
pub const MAX_RECORDS: usize = 16;

/// What the inputs of the generic device carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum InputPattern {
    /// Inputs repeat the outputs received with the same Data_Exchange
    /// (byte i of the inputs = byte i of the outputs; inputs beyond the
    /// outputs are 0).
    #[default]
    Echo,
    /// A 32-bit counter, big-endian, incremented with every
    /// Data_Exchange and repeated over the input bytes.
    Counter,
}

/// An input pattern name that is neither `echo` nor `counter`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown input pattern `{0}` (echo, counter)")]
pub struct UnknownPattern(pub String);

impl std::str::FromStr for InputPattern {
    type Err = UnknownPattern;
    fn from_str(s: &str) -> Result<Self, UnknownPattern> {
        match s {
            "echo" => Ok(InputPattern::Echo),
            "counter" => Ok(InputPattern::Counter),
            _ => Err(UnknownPattern(s.to_string())),
        }
    }
}

/// A check of the User_Prm_Data beyond its length: `Err` names the
/// parameter and what is wrong.
pub type PrmCheck = Box<dyn Fn(&[u8]) -> Result<(), Reason> + Send>;

/// Why a GSD file and module list do not make a device.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GenericError {
    /// A module name matches no module, or several.
    #[error(transparent)]
    Module(#[from] LookupError),
    /// The selection's configuration or parameters cannot be built.
    #[error(transparent)]
    Selection(#[from] SelectionError),
    /// The selection breaks the file's limits.
    #[error("the module list does not fit the GSD file: {0}")]
    Limits(String),
}

/// The value of a parameter of type `t` at `at` (big-endian; signed
/// types sign-extended; `Bit`/`BitArea` only their bits). `None` when the
/// data end before the parameter.
pub fn prm_value(data: &[u8], at: usize, t: PrmDataType) -> Option<i64> {
    let b = data.get(at..at + t.size())?;
    Some(match t {
        PrmDataType::Unsigned8 => b[0] as i64,
        PrmDataType::Signed8 => b[0] as i8 as i64,
        PrmDataType::Unsigned16 => u16::from_be_bytes([b[0], b[1]]) as i64,
        PrmDataType::Signed16 => i16::from_be_bytes([b[0], b[1]]) as i64,
        PrmDataType::Unsigned32 => u32::from_be_bytes([b[0], b[1], b[2], b[3]]) as i64,
        PrmDataType::Signed32 => i32::from_be_bytes([b[0], b[1], b[2], b[3]]) as i64,
        PrmDataType::Bit(n) => ((b[0] >> (n & 7)) & 1) as i64,
        PrmDataType::BitArea(first, last) => {
            let width = (last.saturating_sub(first) + 1).min(8);
            ((b[0] as u16 >> (first & 7)) & ((1u16 << width) - 1)) as i64
        }
    })
}

/// The generic device; see the module docs.
pub struct GenericDevice {
    name: String,
    ident: u16,
    cfg: Vec<u8>,
    features: Features,
    user_prm_len: Option<usize>,
    prm_checks: Vec<PrmCheck>,
    pattern: InputPattern,
    layout: IoLayout,
    outputs: [u8; 244],
    counter: u32,
    records: BTreeMap<(u8, u8), Vec<u8>>,
    /// The highest DP-V1 slot (slot 0 is the device itself, slots 1.. its
    /// modules); `None`: every slot.
    max_slot: Option<u8>,
    no_add_chg: bool,
    ext_diag: Vec<u8>,
    ext_diag_fault: bool,
    static_diag: bool,
    new_diag: bool,
    /// I&M records (DP-V1 devices).
    im: Option<ImStore>,
    /// Report I&M changes as state events (a state file keeps them).
    im_state_events: bool,
    events: EventQueue,
    inbox: InboxSchedule,
    /// Alarms raised, for the slave core to take.
    alarms: VecDeque<Alarm>,
}

impl std::fmt::Debug for GenericDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GenericDevice")
            .field("name", &self.name)
            .field("ident", &format_args!("0x{:04X}", self.ident))
            .field("cfg", &self.cfg)
            .field("features", &self.features)
            .field("user_prm_len", &self.user_prm_len)
            .field("prm_checks", &self.prm_checks.len())
            .field("pattern", &self.pattern)
            .finish_non_exhaustive()
    }
}

impl GenericDevice {
    /// A device named `name` with ident number `ident`, expecting the
    /// configuration `cfg`, with `features`. Any User_Prm_Data is accepted
    /// until [`GenericDevice::with_user_prm`] says otherwise.
    pub fn new(name: impl Into<String>, ident: u16, cfg: Vec<u8>, features: Features) -> Self {
        GenericDevice {
            name: name.into(),
            ident,
            cfg,
            features,
            user_prm_len: None,
            prm_checks: vec![],
            pattern: InputPattern::Echo,
            layout: IoLayout::default(),
            outputs: [0; 244],
            counter: 0,
            records: BTreeMap::new(),
            max_slot: None,
            no_add_chg: false,
            ext_diag: vec![],
            ext_diag_fault: false,
            static_diag: false,
            new_diag: false,
            im: None,
            im_state_events: false,
            events: EventQueue::default(),
            inbox: InboxSchedule::default(),
            alarms: VecDeque::new(),
        }
    }

    /// The device a GSD file describes with the modules `modules` (exact
    /// names; empty for the file's default selection): its ident number and features, the modules'
    /// configuration, and the User_Prm_Data length and parameter ranges
    /// of that selection.
    pub fn from_gsd<S: AsRef<str>>(gsd: &Gsd, modules: &[S]) -> Result<Self, GenericError> {
        let selection = if modules.is_empty() {
            gsd.default_selection()
        } else {
            gsd.select(modules)?
        };
        let problems = gsd.check_selection(&selection);
        if !problems.is_empty() {
            let words: Vec<String> = problems.iter().map(ToString::to_string).collect();
            return Err(GenericError::Limits(words.join("; ")));
        }
        let cfg = gsd.chk_cfg(&selection)?;
        let user_prm_len = gsd.user_prm_data(&selection, &[])?.len();
        let mut checks: Vec<PrmCheck> = vec![];
        for p in gsd.parameters(&selection)? {
            let def = p.definition;
            let (name, at, t, allowed) = (
                def.name.clone(),
                p.offset,
                def.data_type,
                def.allowed.clone(),
            );
            let (lo, hi) = t.limits();
            checks.push(Box::new(move |data: &[u8]| match prm_value(data, at, t) {
                Some(v) if v >= lo && v <= hi && allowed.contains(v) => Ok(()),
                Some(v) => Err(format!(
                    "parameter `{name}` (User_Prm_Data byte {at}) = {v}, allowed {allowed}"
                )
                .into()),
                None => Err(format!("parameter `{name}` at byte {at} is missing").into()),
            }));
        }
        let features = Features {
            sync: gsd.sync_mode_supp,
            freeze: gsd.freeze_mode_supp,
            set_slave_add: gsd.set_slave_add_supp,
            dpv1: gsd.dpv1_slave,
            c1_read_write: gsd.dpv1_slave && gsd.c1_read_write_supp,
            alarms: !gsd.declared_alarms().is_empty(),
            fail_safe: gsd.fail_safe,
            max_diag_len: gsd.max_diag_data_len.unwrap_or(244).clamp(6, 244),
            c1_max_data_len: gsd.c1_max_data_len.unwrap_or(240).clamp(1, 240),
            c2_read_write: gsd.dpv1_slave && gsd.c2_read_write_supp,
            c2_max_data_len: gsd.c2_max_data_len.unwrap_or(240).clamp(1, 240),
            c2_max_count_channels: gsd.c2_max_count_channels.unwrap_or(1).clamp(1, 49),
            max_initiate_pdu_length: gsd.max_initiate_pdu_length.unwrap_or(0),
            im: gsd.dpv1_slave,
        };
        let name = gsd
            .model_name
            .clone()
            .unwrap_or_else(|| format!("ident 0x{:04X}", gsd.ident_number));
        // DP-V1 slots: 0 is the device, 1..=n its modules (Max_Module on a
        // modular station, the selected modules otherwise).
        let modules = if gsd.modular_station {
            gsd.max_module.map_or(selection.len(), usize::from)
        } else {
            selection.len()
        };
        let mut dev = GenericDevice::new(name, gsd.ident_number, cfg, features)
            .with_user_prm(user_prm_len, checks);
        dev.max_slot = Some(modules.min(254) as u8);
        if gsd.dpv1_slave {
            let im0 = ImIdentity::default()
                .im0_from_gsd(gsd)
                .expect("GSD texts are cut to fit");
            dev.im = Some(ImStore::new(&im0));
        }
        Ok(dev)
    }

    /// Use `store` for I&M (a DP-V1 device only; others answer no I&M);
    /// with `state_events`, each write of I&M1..I&M4 is reported as a
    /// [`crate::STATE_EVENT`] with the new state file.
    pub fn with_im(mut self, store: ImStore, state_events: bool) -> Self {
        if self.features.dpv1 {
            self.im = Some(store);
            self.im_state_events = state_events;
        }
        self
    }

    /// The I&M records, for a DP-V1 device.
    pub fn im(&self) -> Option<&ImStore> {
        self.im.as_ref()
    }

    /// Require User_Prm_Data of exactly `len` bytes (for DP-V1 slaves
    /// including the 3 DPV1_Status bytes) that pass `checks`.
    pub fn with_user_prm(mut self, len: usize, checks: Vec<PrmCheck>) -> Self {
        self.user_prm_len = Some(len);
        self.prm_checks = checks;
        self
    }

    /// Choose the input pattern.
    pub fn with_inputs(mut self, pattern: InputPattern) -> Self {
        self.pattern = pattern;
        self
    }

    /// Start with the address the program running the slave kept from
    /// an earlier Set_Slave_Add: with No_Add_Chg, further changes are
    /// refused.
    pub fn with_stored_address(mut self, stored: Option<StoredAddress>) -> Self {
        self.no_add_chg = stored.is_some_and(|s| s.no_add_chg);
        self
    }

    /// The device's name (model name of the GSD).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The expected configuration.
    pub fn cfg(&self) -> &[u8] {
        &self.cfg
    }

    /// The outputs last received.
    pub fn outputs(&self) -> &[u8] {
        &self.outputs[..self.layout.outputs]
    }

    /// The DP-V1 record at `slot`/`index`.
    pub fn record(&self, slot: u8, index: u8) -> Option<&[u8]> {
        self.records.get(&(slot, index)).map(Vec::as_slice)
    }

    /// Read control commands from `inbox` ([`GenericDevice::control`]).
    pub fn with_inbox(mut self, inbox: ControlInbox) -> Self {
        self.inbox.set(inbox);
        self
    }

    /// Apply one control command: `alarm TYPE SLOT CHANGE [HEX]` raises a
    /// DP-V1 alarm. TYPE is `diagnostic`, `process`, `pull`, `plug`,
    /// `status`, `update`, `manufacturer` or a type number (32..=126
    /// manufacturer-specific); SLOT 0..=254; CHANGE `appears`,
    /// `disappears` or `disappears-still-faulty`; HEX the
    /// Diagnostic_User_Data (at most 59 bytes). Returns the answer in
    /// words; the slave core reports what becomes of the alarm.
    pub fn control(&mut self, line: &str) -> Result<String, ControlError> {
        let mut w = line.split_whitespace();
        let arg = |m: String| ControlError::Argument(m);
        const USAGE: &str = "`alarm TYPE SLOT appears|disappears [HEX]`";
        match w.next().unwrap_or("") {
            "alarm" => {
                if !self.features.alarms {
                    return Err(ControlError::Refused(format!(
                        "{}: the GSD declares no DP-V1 alarms (Diagnostic_Alarm_supp, …)",
                        self.name
                    )));
                }
                let t = w
                    .next()
                    .ok_or_else(|| arg(format!("{USAGE}: TYPE missing")))?;
                let alarm_type = AlarmType::from_word(t).ok_or_else(|| {
                    arg(format!(
                        "unknown alarm type `{t}` (diagnostic, process, pull, plug, status, \
                         update, manufacturer, or a number 1..=126)"
                    ))
                })?;
                let slot = w
                    .next()
                    .ok_or_else(|| arg(format!("{USAGE}: SLOT missing")))?;
                let slot: u8 = slot
                    .parse()
                    .ok()
                    .filter(|s| *s <= 254)
                    .ok_or_else(|| arg(format!("slot `{slot}` is not 0..=254")))?;
                let c = w
                    .next()
                    .ok_or_else(|| arg(format!("{USAGE}: appears|disappears missing")))?;
                let change = AlarmChange::from_word(c)
                    .filter(|c| *c != AlarmChange::None)
                    .ok_or_else(|| {
                        arg(format!(
                            "`{c}`: give appears, disappears or disappears-still-faulty"
                        ))
                    })?;
                let hex: Vec<&str> = w.collect();
                let data = profibus_fdl::wire::parse_hex(&hex.join(" "))
                    .map_err(|e| arg(format!("alarm data: {e}")))?;
                if data.len() > profibus_dp::pdu::alarm::MAX_ALARM_DATA_LEN {
                    return Err(arg(format!(
                        "{} bytes of alarm data, at most 59 fit into an alarm block",
                        data.len()
                    )));
                }
                let text = format!(
                    "{} alarm slot {slot} {} raised",
                    alarm_type.word(),
                    change.word()
                );
                self.alarms.push_back(Alarm {
                    alarm_type,
                    slot,
                    change,
                    add_ack: false,
                    data,
                });
                Ok(text)
            }
            "" => Err(arg("empty command".into())),
            other => Err(ControlError::Unknown {
                command: other.to_string(),
                known: "alarm TYPE SLOT appears|disappears [HEX]",
            }),
        }
    }

    /// Set the extended diagnosis: a device-related block with `data`
    /// (empty: none), `fault` sets Ext_Diag, `static_diag` Stat_Diag. The
    /// slave announces the change with "data high".
    pub fn set_diagnosis(&mut self, data: &[u8], fault: bool, static_diag: bool) {
        self.ext_diag = data.to_vec();
        self.ext_diag_fault = fault;
        self.static_diag = static_diag;
        self.new_diag = true;
    }
}

impl Device for GenericDevice {
    fn ident_number(&self) -> u16 {
        self.ident
    }

    fn real_cfg(&self) -> &[u8] {
        &self.cfg
    }

    fn features(&self) -> Features {
        self.features
    }

    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        if let Some(len) = self.user_prm_len {
            expect_user_prm_len(prm, len)?;
        }
        let data = prm.user_prm_data;
        for check in &self.prm_checks {
            check(data)?;
        }
        Ok(())
    }

    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        let layout = expect_cfg(&self.cfg, cfg)?;
        self.layout = layout;
        Ok(layout)
    }

    fn write_outputs(&mut self, _now: Instant, outputs: &[u8]) {
        let n = outputs.len().min(self.outputs.len());
        self.outputs[..n].copy_from_slice(&outputs[..n]);
    }

    fn read_inputs(&mut self, _now: Instant, inputs: &mut [u8]) {
        match self.pattern {
            InputPattern::Echo => {
                let n = inputs.len().min(self.layout.outputs);
                inputs[..n].copy_from_slice(&self.outputs[..n]);
                inputs[n..].fill(0);
            }
            InputPattern::Counter => {
                self.counter = self.counter.wrapping_add(1);
                let c = self.counter.to_be_bytes();
                for (i, b) in inputs.iter_mut().enumerate() {
                    *b = c[i % 4];
                }
            }
        }
    }

    fn clear_outputs(&mut self, _now: Instant, _why: ClearReason) {
        self.outputs.fill(0);
    }

    fn diagnosis(&mut self, _now: Instant, diag: &mut DiagWriter<'_>) {
        if !self.ext_diag.is_empty() {
            diag.device(&self.ext_diag);
        }
        if self.ext_diag_fault {
            diag.set_ext_diag();
        }
        if self.static_diag {
            diag.set_stat_diag();
        }
    }

    fn take_new_diag(&mut self) -> bool {
        std::mem::take(&mut self.new_diag)
    }

    fn dpv1_read(&mut self, _now: Instant, slot: u8, index: u8, out: &mut [u8]) -> Dpv1Outcome {
        if self.max_slot.is_some_and(|m| slot > m) {
            return Dpv1Outcome::read_error(ERR_CLASS_ACCESS, ERR_INVALID_SLOT);
        }
        match self.records.get(&(slot, index)) {
            Some(r) => {
                let n = r.len().min(out.len());
                out[..n].copy_from_slice(&r[..n]);
                Dpv1Outcome::Done(n)
            }
            None => Dpv1Outcome::read_error(ERR_CLASS_ACCESS, ERR_INVALID_INDEX),
        }
    }

    fn dpv1_write(&mut self, _now: Instant, slot: u8, index: u8, data: &[u8]) -> Dpv1Outcome {
        if self.max_slot.is_some_and(|m| slot > m) {
            return Dpv1Outcome::write_error(ERR_CLASS_ACCESS, ERR_INVALID_SLOT);
        }
        if !self.records.contains_key(&(slot, index)) && self.records.len() >= MAX_RECORDS {
            // Resource class: "write constraint conflict".
            return Dpv1Outcome::write_error(ERR_CLASS_RESOURCE, 1);
        }
        self.records.insert((slot, index), data.to_vec());
        self.events.note(
            "record",
            format!(
                "DP-V1 write slot {slot} index {index}: {} bytes",
                data.len()
            ),
        );
        Dpv1Outcome::Done(data.len())
    }

    fn dpv1_data_transport(
        &mut self,
        now: Instant,
        slot: u8,
        index: u8,
        data: &[u8],
        out: &mut [u8],
    ) -> Dpv1Outcome {
        match self.dpv1_write(now, slot, index, data) {
            Dpv1Outcome::Done(_) => {
                let n = data.len().min(out.len());
                out[..n].copy_from_slice(&data[..n]);
                Dpv1Outcome::Done(n)
            }
            other => other,
        }
    }

    fn im_read(&mut self, number: u8, out: &mut [u8; 64]) -> bool {
        self.im.as_ref().is_some_and(|im| im.read(number, out))
    }

    fn im_write(&mut self, _now: Instant, number: u8, record: &[u8; 64]) -> Result<(), Dpv1Error> {
        let Some(im) = self.im.as_mut() else {
            return Err(Dpv1Error::dpv1(
                profibus_dp::pdu::dpv1::FN_WRITE,
                ERR_CLASS_ACCESS,
                profibus_dp::slave::ERR_ACCESS_DENIED,
            ));
        };
        im.write(number, record)?;
        let text = im.state_text();
        self.events.note("im", format!("I&M{number} written"));
        if self.im_state_events {
            self.events.note(crate::STATE_EVENT, text);
        }
        Ok(())
    }

    fn set_address(
        &mut self,
        new_address: u8,
        no_add_chg: bool,
        _rem_slave_data: &[u8],
    ) -> Result<(), Reason> {
        if self.no_add_chg {
            return Err(
                "No_Add_Chg was stored: the address cannot be changed through the bus".into(),
            );
        }
        self.no_add_chg = no_add_chg;
        self.events
            .note("address", format!("address {new_address} accepted"));
        Ok(())
    }

    fn poll_event(&mut self) -> Option<DeviceEvent> {
        self.events.pop()
    }

    fn take_alarm(&mut self) -> Option<Alarm> {
        self.alarms.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.inbox.deadline()
    }

    fn handle_timeout(&mut self, now: Instant) {
        for line in self.inbox.due(now) {
            match self.control(&line) {
                Ok(text) => self.events.note("control", text),
                Err(e) => self.events.note("control-error", e.to_string()),
            }
        }
    }
}

/// The options of the `generic` profile.
#[derive(Debug, Default, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GenericOptions {
    /// The GSD file (required).
    pub gsd: Option<PathBuf>,
    /// Module names in slot order (exact names of the GSD's modules);
    /// none: the file's default selection (a compact station's module,
    /// a modular station's `Preset` modules), which a modular station
    /// without `Preset` modules does not have.
    pub modules: Vec<String>,
    /// Accept known vendor quirks in the GSD file (as warnings).
    pub lenient: bool,
    /// Input pattern: `echo` (default) or `counter`.
    pub inputs: Option<String>,
    /// File in which the program running the slave keeps an address set
    /// by Set_Slave_Add; when it exists its address overrides the
    /// caller's.
    pub address_file: Option<PathBuf>,
    /// Directory of the state file (`im.toml`) keeping the I&M1..I&M4
    /// records masters write (DP-V1 devices); without it they are lost
    /// at the end.
    pub state_dir: Option<PathBuf>,
    /// I&M0 ORDER_ID (at most 20 characters); default: the GSD's
    /// `OrderNumber`.
    pub order_id: Option<String>,
    /// I&M0 SERIAL_NUMBER (at most 16 characters); default: blanks.
    pub serial_number: Option<String>,
    /// I&M0 MANUFACTURER_ID (PI manufacturer table); default 0.
    #[serde(deserialize_with = "crate::profile::opt_int")]
    pub manufacturer_id: Option<u16>,
}

/// The generic device a GSD file and module list describe, as a
/// profile.
#[derive(Debug)]
pub struct GenericProfile {
    options: GenericOptions,
    gsd: Gsd,
    pattern: InputPattern,
    stored: Option<StoredAddress>,
    im: Option<ImStore>,
    warnings: Vec<String>,
}

impl Profile for GenericProfile {
    type Options = GenericOptions;
    const NAME: &'static str = "generic";
    const SUMMARY: &'static str = "any device a GSD file describes: --gsd FILE --module NAME ...";
    const OPTIONS_HELP: &'static str =
        "--gsd FILE, --module NAME (repeat), --lenient, --inputs echo|counter, --address-file FILE, \
--state-dir DIR (keeps I&M1..4), --device-opt order_id=TEXT|serial_number=TEXT|manufacturer_id=N (I&M0)";
    const IDENT: Option<u16> = None;
    const PATH_OPTIONS: &'static [&'static str] = &["gsd", "address_file", "state_dir"];

    fn configure(options: GenericOptions, _address: Option<u8>) -> Result<Self, ProfileError> {
        let path = options.gsd.clone().ok_or_else(|| {
            ProfileError::Invalid("give --gsd FILE (with --module NAME …) or --device NAME".into())
        })?;
        let opts = if options.lenient {
            ParseOptions::LENIENT
        } else {
            ParseOptions::STRICT
        };
        let parsed = Gsd::from_file(&path, opts)?;
        let warnings = parsed
            .warnings
            .iter()
            .map(|w| format!("{}: warning: {w}", path.display()))
            .collect();
        let pattern = match &options.inputs {
            Some(p) => p
                .parse()
                .map_err(|e: UnknownPattern| ProfileError::Invalid(e.to_string()))?,
            None => InputPattern::Echo,
        };
        GenericDevice::from_gsd(&parsed.gsd, &options.modules)
            .map_err(|e| ProfileError::Invalid(format!("{}: {e}", path.display())))?;
        let stored = match &options.address_file {
            Some(f) => StoredAddress::load(f)?,
            None => None,
        };
        let im = if parsed.gsd.dpv1_slave {
            let identity = ImIdentity {
                manufacturer_id: options.manufacturer_id,
                order_id: options.order_id.clone(),
                serial_number: options.serial_number.clone(),
            };
            let store = ImStore::new(&identity.im0_from_gsd(&parsed.gsd)?);
            Some(match &options.state_dir {
                Some(dir) => store.load(&dir.join(IM_STATE_FILE))?,
                None => store,
            })
        } else {
            None
        };
        Ok(GenericProfile {
            options,
            gsd: parsed.gsd,
            pattern,
            stored,
            im,
            warnings,
        })
    }

    fn gsd(&self) -> &Gsd {
        &self.gsd
    }

    fn modules(&self) -> Vec<String> {
        if self.options.modules.is_empty() {
            let sel = self.gsd.default_selection();
            sel.iter()
                .map(|&i| self.gsd.modules[i].name.clone())
                .collect()
        } else {
            self.options.modules.clone()
        }
    }

    fn address(&self) -> Option<u8> {
        self.stored.map(|s| s.address)
    }

    fn address_file(&self) -> Option<PathBuf> {
        self.options.address_file.clone()
    }

    /// `state_dir/im.toml` (I&M1..I&M4), for a DP-V1 device.
    fn state_file(&self) -> Option<PathBuf> {
        let dir = self.options.state_dir.as_ref()?;
        self.im.as_ref().map(|_| dir.join(IM_STATE_FILE))
    }

    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError> {
        let mut dev = GenericDevice::from_gsd(&self.gsd, &self.options.modules)
            .map_err(|e| ProfileError::Device(Box::new(e)))?
            .with_inputs(self.pattern)
            .with_stored_address(self.stored);
        if let Some(inbox) = control {
            dev = dev.with_inbox(inbox);
        }
        if let Some(im) = &self.im {
            dev = dev.with_im(im.clone(), self.options.state_dir.is_some());
        }
        Ok(Box::new(dev))
    }

    /// See [`module_channels`].
    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError> {
        module_channels(&self.modules(), cfg)
    }

    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }
}

/// The channels of a slave given by GSD modules: one `U8` channel per
/// process data byte, named after its module, `NAME[i]` (`slotN[i]` for
/// identifiers beyond the module names).
pub fn module_channels(modules: &[String], cfg: &[u8]) -> Result<ChannelMap, ProfileError> {
    let mut m = ChannelMap::new();
    let (mut inp, mut out) = (0, 0);
    for (slot, id) in profibus_dp::pdu::cfg::identifiers(cfg).enumerate() {
        let id = id.map_err(|e| ProfileError::Config(e.to_string()))?;
        let name = modules
            .get(slot)
            .cloned()
            .unwrap_or_else(|| format!("slot{slot}"));
        for (dir, n, at) in [
            (Direction::Input, id.input_bytes(), &mut inp),
            (Direction::Output, id.output_bytes(), &mut out),
        ] {
            for i in 0..n {
                m.push(format!("{name}[{i}]"), dir, *at + i, ChannelType::U8);
            }
            *at += n;
        }
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dev() -> GenericDevice {
        GenericDevice::new("test", 0x0C0B, vec![0x21, 0x13], Features::default())
    }

    fn prm(user: &[u8]) -> Vec<u8> {
        [vec![0x80, 1, 1, 11, 0x0C, 0x0B, 0], user.to_vec()].concat()
    }

    #[test]
    fn echo_and_counter() {
        let mut d = dev();
        assert_eq!(
            d.check_cfg(&[0x21, 0x13]),
            Ok(IoLayout {
                inputs: 4,
                outputs: 2
            })
        );
        d.write_outputs(Instant::ZERO, &[1, 2]);
        let mut i = [9u8; 4];
        d.read_inputs(Instant::ZERO, &mut i);
        assert_eq!(i, [1, 2, 0, 0]);
        let mut d = dev().with_inputs(InputPattern::Counter);
        d.check_cfg(&[0x21, 0x13]).unwrap();
        d.read_inputs(Instant::ZERO, &mut i);
        d.read_inputs(Instant::ZERO, &mut i);
        assert_eq!(i, [0, 0, 0, 2]);
        assert!(d.check_cfg(&[0x21]).is_err());
    }

    #[test]
    fn user_prm_length_and_checks() {
        let check: PrmCheck = Box::new(|d: &[u8]| {
            if d[1] > 5 {
                Err(format!("parameter `Speed` = {}, allowed 0..=5", d[1]).into())
            } else {
                Ok(())
            }
        });
        let mut d = dev().with_user_prm(2, vec![check]);
        let p = prm(&[0, 3]);
        assert!(d.check_prm(&SetPrm::parse(&p).unwrap()).is_ok());
        let p = prm(&[0, 6]);
        let e = d.check_prm(&SetPrm::parse(&p).unwrap()).unwrap_err();
        assert!(e.to_string().contains("Speed"));
        let p = prm(&[0]);
        let e = d.check_prm(&SetPrm::parse(&p).unwrap()).unwrap_err();
        assert!(e.to_string().contains("1 bytes, the GSD gives 2"));
    }

    #[test]
    fn record_store() {
        let mut d = dev();
        assert!(matches!(
            d.dpv1_read(Instant::ZERO, 0, 1, &mut [0; 4]),
            Dpv1Outcome::Error(_)
        ));
        assert_eq!(
            d.dpv1_write(Instant::ZERO, 0, 1, &[5, 6, 7]),
            Dpv1Outcome::Done(3)
        );
        let mut b = [0u8; 2];
        assert_eq!(
            d.dpv1_read(Instant::ZERO, 0, 1, &mut b),
            Dpv1Outcome::Done(2)
        );
        assert_eq!(b, [5, 6]);
        for i in 2..=MAX_RECORDS as u8 {
            assert_eq!(
                d.dpv1_write(Instant::ZERO, 0, i, &[1]),
                Dpv1Outcome::Done(1)
            );
        }
        assert!(matches!(
            d.dpv1_write(Instant::ZERO, 9, 9, &[1]),
            Dpv1Outcome::Error(_)
        ));
        assert_eq!(d.poll_event().unwrap().kind, "record");
    }

    const GSD: &str = r#"#Profibus_DP
GSD_Revision=3
Vendor_Name="t"
Model_Name="gen test"
Revision="1"
Ident_Number=0x0DCE
Protocol_Ident=0
Station_Type=0
Hardware_Release="1"
Software_Release="1"
9.6_supp=1
MaxTsdr_9.6=60
Implementation_Type="sw"
Freeze_Mode_supp=1
Sync_Mode_supp=0
Set_Slave_Add_supp=1
Min_Slave_Intervall=1
Max_Diag_Data_Len=32
Modular_Station=1
Max_Module=4
Max_Input_Len=64
Max_Output_Len=64
Max_Data_Len=128
DPV1_Slave=1
C1_Read_Write_supp=1
PrmText=1
Text(0)="off"
Text(1)="on"
EndPrmText
ExtUserPrmData=1 "Mode"
Unsigned8 1 0-3
Prm_Text_Ref=1
EndExtUserPrmData
ExtUserPrmData=2 "Offset"
Signed16 -100 -1000-1000
EndExtUserPrmData
C1_Max_Data_Len=32
Max_User_Prm_Data_Len=16
Ext_User_Prm_Data_Const(0)=0x80,0x00,0x00,0x01,0xFF,0x9C
Ext_User_Prm_Data_Ref(3)=1
Ext_User_Prm_Data_Ref(4)=2
Module="1 byte in" 0x10
1
EndModule
Module="2 words in/out" 0x71
2
EndModule
"#;

    fn gsd() -> Gsd {
        Gsd::parse(GSD, Default::default()).unwrap().gsd
    }

    /// The device of [`GSD`] with the modules "2 words in/out" and "1 byte in".
    fn two_words_and_a_byte() -> GenericDevice {
        GenericDevice::from_gsd(&gsd(), &["2 words in/out", "1 byte in"]).unwrap()
    }

    #[test]
    fn dpv1_slots_and_lengths_come_from_the_gsd() {
        let mut d = two_words_and_a_byte();
        assert_eq!(d.features().c1_max_data_len, 32);
        // Max_Module = 4: slots 0 (the device) to 4.
        let slot_error = |o: Dpv1Outcome| match o {
            Dpv1Outcome::Error(e) => e.error_code_1 == (ERR_CLASS_ACCESS << 4 | ERR_INVALID_SLOT),
            _ => false,
        };
        assert!(slot_error(d.dpv1_write(Instant::ZERO, 9, 1, &[1])));
        assert!(slot_error(d.dpv1_write(Instant::ZERO, 5, 1, &[1])));
        assert!(slot_error(d.dpv1_read(Instant::ZERO, 200, 1, &mut [0; 4])));
        assert_eq!(
            d.dpv1_write(Instant::ZERO, 4, 1, &[1]),
            Dpv1Outcome::Done(1)
        );
        assert!(d.records.keys().all(|&(slot, _)| slot <= 4));
        // An unknown index of a valid slot: invalid index.
        match d.dpv1_read(Instant::ZERO, 3, 7, &mut [0; 4]) {
            Dpv1Outcome::Error(e) => {
                assert_eq!(e.error_code_1, ERR_CLASS_ACCESS << 4 | ERR_INVALID_INDEX)
            }
            o => panic!("{o:?}"),
        }
    }

    #[test]
    fn from_gsd_checks_what_the_file_says() {
        let mut d = two_words_and_a_byte();
        assert_eq!(d.ident_number(), 0x0DCE);
        assert_eq!(d.real_cfg(), &[0x71, 0x10]);
        let f = d.features();
        assert!(f.freeze && !f.sync && f.set_slave_add && f.dpv1 && f.c1_read_write);
        assert!(!f.alarms && !f.fail_safe);
        assert_eq!(f.max_diag_len, 32);
        let mk = |user: &[u8]| [vec![0x80, 1, 1, 11, 0x0D, 0xCE, 0], user.to_vec()].concat();
        let good = mk(&[0x80, 0, 0, 1, 0xFF, 0x9C]);
        assert_eq!(d.check_prm(&SetPrm::parse(&good).unwrap()), Ok(()));
        let bad = mk(&[0x80, 0, 0, 4, 0xFF, 0x9C]);
        let e = d.check_prm(&SetPrm::parse(&bad).unwrap()).unwrap_err();
        assert!(
            e.to_string()
                .contains("`Mode` (User_Prm_Data byte 3) = 4, allowed 0..=3"),
            "{e}"
        );
        let bad = mk(&[0x80, 0, 0, 1, 0xFC, 0x18]); // -1000 - 1000 = -1000: ok
        assert_eq!(d.check_prm(&SetPrm::parse(&bad).unwrap()), Ok(()));
        let bad = mk(&[0x80, 0, 0, 1, 0xFC, 0x17]); // -1001
        assert!(d.check_prm(&SetPrm::parse(&bad).unwrap()).is_err());
        let short = mk(&[0x80, 0, 0, 1]);
        assert!(d.check_prm(&SetPrm::parse(&short).unwrap()).is_err());
        assert!(matches!(
            GenericDevice::from_gsd(&gsd(), &["no such module at all"]),
            Err(GenericError::Module(_))
        ));
        assert!(matches!(
            GenericDevice::from_gsd(&gsd(), &["1 byte in"; 5]),
            Err(GenericError::Limits(_))
        ));
    }

    #[test]
    fn prm_values() {
        let d = [0x81, 0xFF, 0x9C, 0x12, 0x34, 0x56, 0x78];
        assert_eq!(prm_value(&d, 0, PrmDataType::Unsigned8), Some(0x81));
        assert_eq!(prm_value(&d, 0, PrmDataType::Signed8), Some(-127));
        assert_eq!(prm_value(&d, 1, PrmDataType::Signed16), Some(-100));
        assert_eq!(prm_value(&d, 3, PrmDataType::Unsigned32), Some(0x12345678));
        assert_eq!(prm_value(&d, 0, PrmDataType::Bit(7)), Some(1));
        assert_eq!(prm_value(&d, 0, PrmDataType::BitArea(0, 2)), Some(1));
        assert_eq!(prm_value(&d, 3, PrmDataType::BitArea(4, 7)), Some(1));
        assert_eq!(prm_value(&d, 5, PrmDataType::Unsigned32), None);
    }

    #[test]
    fn stored_no_add_chg_refuses_changes() {
        let mut d = dev().with_stored_address(None);
        d.set_address(17, true, &[]).unwrap();
        assert!(d.set_address(18, false, &[]).is_err());
        let mut d = dev().with_stored_address(Some(StoredAddress {
            address: 17,
            no_add_chg: true,
        }));
        assert!(d.set_address(18, false, &[]).is_err());
        let mut d = dev().with_stored_address(Some(StoredAddress {
            address: 17,
            no_add_chg: false,
        }));
        assert!(d.set_address(18, false, &[]).is_ok());
    }
}

#[cfg(test)]
mod alarm_tests {
    use super::*;
    use profibus_dp::config::gsd::ParseOptions;

    fn alarm_device(alarms: bool) -> GenericDevice {
        let mut text = String::from_utf8_lossy(crate::gsd_files::DPCTL_GEN).into_owned();
        if alarms {
            text.push_str("\nDiagnostic_Alarm_supp=1\nProcess_Alarm_supp=1\n");
        }
        let gsd = Gsd::parse(&text, ParseOptions::LENIENT).unwrap().gsd;
        GenericDevice::from_gsd(&gsd, &["1 byte in"]).unwrap()
    }

    #[test]
    fn the_alarm_command_raises_an_alarm_for_the_core() {
        let mut d = alarm_device(true);
        assert!(d.features().alarms);
        assert_eq!(
            d.control("alarm diagnostic 1 appears 01 02").unwrap(),
            "diagnostic alarm slot 1 appears raised"
        );
        d.control("alarm 40 0 disappears-still-faulty").unwrap();
        let a = d.take_alarm().unwrap();
        assert_eq!(
            (a.alarm_type, a.slot, a.change, &a.data[..]),
            (
                AlarmType::Diagnostic,
                1,
                AlarmChange::Appears,
                &[1u8, 2][..]
            )
        );
        let a = d.take_alarm().unwrap();
        assert!(a.alarm_type.is_manufacturer());
        assert_eq!(d.take_alarm(), None);
        for (line, want) in [
            (
                "alarm diagnostik 1 appears",
                "unknown alarm type `diagnostik`",
            ),
            ("alarm process 255 appears", "slot `255` is not 0..=254"),
            ("alarm process 1 comes", "give appears, disappears"),
            ("alarm process 1 appears zz", "alarm data"),
            ("alarm process", "SLOT missing"),
            ("alarms", "unknown command `alarms`"),
        ] {
            let e = d.control(line).unwrap_err().to_string();
            assert!(e.contains(want), "{line}: {e}");
        }
        let e = alarm_device(false)
            .control("alarm process 1 appears")
            .unwrap_err();
        assert!(e.to_string().contains("declares no DP-V1 alarms"), "{e}");
    }
}
