//! Beckhoff BK3000 PROFIBUS-DP bus coupler with its K-bus terminal strip
//! (ident 0xBECF, `crates/devices/gsd/BK30BECF.GSD`), after the manual "PROFIBUS Koppler
//! BK3000 … LC3100", Technische Dokumentation, version 2.3 of 27.11.2006
//! (from its page summaries, cited as "p. N"; facts cut off there come from the
//! English edition of the same manual and Beckhoff's Information System,
//! listed in `docs/devices/bk3000.md` with what is inferred).
//!
//! - [`catalogue`]: the terminals (channels, widths, DP identifiers of the
//!   compact and complete mappings, scaling, simulated signals).
//! - [`image`]: the strip, the process-image layout and the Chk_Cfg
//!   comparison with its CfgData error byte and I/O-ERR blink code.
//! - [`prm`]: User_Prm_Data and the coupler's diagnosis bytes.
//! - [`master`]: the master side: Chk_Cfg and User_Prm_Data of a terminal
//!   list, named channels decoded from and encoded into the image.
//! - [`fms`]: the FMS object dictionary and KBL of the DP/FMS mixed mode.
//! - [`Bk3000`]: the slave device.
//!
//! # Behaviour of the emulated coupler
//!
//! - Sync and freeze are always supported (p. 35), DP-V1 is not (p. 55):
//!   DP-V1 requests find the SAPs deactivated, as on a DP-V0 slave.
//! - Set_Prm: User_Prm_Data checked byte by byte ([`prm::UserPrm`]); a
//!   refusal sets Prm_Fault and the UserPrm error bytes of the diagnosis.
//! - Chk_Cfg: compared terminal by terminal with the real strip
//!   ([`image::check_cfg`]), or byte for byte with the programmed table
//!   (table 70) when User_Prm_Data byte 9 bit 1 asks for programmed
//!   configuration. A refusal sets Cfg_Fault, the CfgData error bytes, and
//!   the I/O-ERR blink code (6 pulses, then n), reported as an `io-err`
//!   device event.
//! - Data_Exchange: outputs go to the terminals (recorded, `outputs`
//!   events name every changed channel); inputs are simulated (walking
//!   bits, sines, counters) unless pinned with `set`.
//! - Start-up mode 1/2 (parameter mode): data exchange runs but the K-bus
//!   is held (outputs not applied, inputs zero) until the control command
//!   `run`; mode 2 reports Stat_Diag meanwhile (inferred behaviour).
//! - Watchdog, clear, leaving Data_Exch: all terminal outputs 0.
//! - `pull N` / `plug N` (control commands): a pulled terminal breaks the
//!   K-bus behind terminal N-1: K-bus error in the diagnosis (with Ext_Diag
//!   and Stat_Diag), I/O-ERR 4 pulses then N-1, inputs 0 and outputs held
//!   until the terminal is plugged again.

pub mod catalogue;
pub mod commission;
pub mod fms;
pub mod image;
pub mod master;
pub mod plc;
pub mod prm;
pub mod profile;
pub mod registers;
pub mod user;

#[cfg(test)]
mod tests;

use crate::kit::{EventQueue, InboxSchedule};
use crate::{ControlError, ControlInbox};
use catalogue::{Class, Role, Sim};
use image::{CfgError, CfgReject, Dir, Image, Options, Owner, Strip};
use prm::{CouplerDiag, StartupMode, UserPrm};
use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{
    ClearReason, Device, DeviceEvent, DiagWriter, Features, IoLayout, Reason,
};
use profibus_fdl::Instant;
use std::collections::BTreeMap;
use std::time::Duration;

/// The ident number (`BK30BECF.GSD`; the manual does not print it, the
/// file name carries it).
pub const IDENT: u16 = 0xBECF;

/// Longest diagnosis (`Max_Diag_Data_Len`): 6 + length byte + reserved +
/// 7 messages of 8 bytes.
pub const MAX_DIAG_LEN: u8 = 64;

/// The emulated coupler; see the module docs.
#[derive(Debug)]
pub struct Bk3000 {
    strip: Strip,
    present: Vec<bool>,
    /// Terminals that do not answer on the K-bus (`mute N`).
    muted: Vec<bool>,
    /// Terminals replaced while running (`swap N TYPE`).
    swapped: Vec<Option<&'static catalogue::TerminalType>>,
    programmed: Option<Vec<u8>>,
    /// Free placement of the programmed configuration (p. 51).
    placement: Vec<image::Placement>,
    prm: UserPrm,
    image: Image,
    diag: CouplerDiag,
    diag_changed: bool,
    held: bool,
    outputs: Vec<u8>,
    inputs: Vec<u8>,
    pinned: BTreeMap<String, i64>,
    counter: u8,
    /// Register sets of the complex terminals' channels (position, channel).
    regs: BTreeMap<(usize, u8), registers::Channel>,
    /// Diagnosis messages of terminal channels in error (English edition
    /// p. 50: terminal, channel, 3 reserved, status byte, 2 reserved).
    term_diag: Vec<[u8; 8]>,
    /// The 2-byte PLC interface's state ([`plc`]).
    plc: plc::PlcInterface,
    /// Coupler table 0 (settings) and table 98 register 3.
    table0: [u16; 256],
    /// The FMS relationships of the KBL that clients have addressed.
    fms_servers: Vec<profibus_dp::fms::lli::LliServer>,
    /// The outputs of the last Data_Exchange, and whether an FMS Write
    /// changed the terminals' outputs since: the same DP outputs again do
    /// not undo the Write, different ones replace it (mixed mode,
    /// docs/fms.md).
    dp_outputs: Vec<u8>,
    fms_written: bool,
    /// K-bus cycle time set for the cycle-time measurement (table 98 R3).
    cycle_set: u16,
    /// In data exchange with the K-bus started (for the LEDs).
    exchanging: bool,
    /// The LEDs last reported.
    leds: Option<Leds>,
    /// Model the K-bus cycle time as a delay of the process data (K51).
    kbus_timing: bool,
    /// Outputs on their way over the K-bus: applied at the instant.
    pending_outputs: Option<(Instant, Vec<u8>)>,
    /// Input pins not yet latched by a K-bus cycle: from the instant on
    /// the new value shows; before it the previous one (`None`: not
    /// pinned).
    pin_log: Vec<(Instant, String, Option<i64>)>,
    /// The latest instant the device was told.
    clock: Instant,
    events: EventQueue,
    inbox: InboxSchedule,
}

/// The coupler's LEDs (p. 18-21): I/O RUN, I/O ERR (with its blink code)
/// and BF (bus fault). Our reading of the cut-off table of p. 21: I/O
/// RUN lights while the K-bus runs in data exchange and blinks while
/// PROFIBUS is not yet configured; BF lights without data exchange;
/// I/O ERR is off when the start-up found no error (p. 18).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Leds {
    /// I/O RUN: 0 off, 1 on, 2 blinking.
    pub io_run: u8,
    /// I/O ERR: the blink code (pulses, argument), `None` when off.
    pub io_err: Option<(u8, u8)>,
    /// BF: bus fault.
    pub bf: bool,
}

impl std::fmt::Display for Leds {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let run = ["off", "on", "blinking"][self.io_run.min(2) as usize];
        write!(f, "I/O RUN {run}, ")?;
        match self.io_err {
            None => write!(f, "I/O ERR off, ")?,
            Some((p, n)) => write!(f, "I/O ERR {p} pulses then {n}, ")?,
        }
        write!(f, "BF {}", if self.bf { "on" } else { "off" })
    }
}

impl Bk3000 {
    /// A coupler with `strip`, automatic configuration, default settings.
    pub fn new(strip: Strip) -> Bk3000 {
        let image = strip.default_image(Options::default());
        let mut regs = BTreeMap::new();
        for (k, slot) in strip.slots().iter().enumerate() {
            if slot.ty.class == Class::Complex {
                for ch in 1..=slot.ty.channels {
                    regs.insert((k + 1, ch), registers::Channel::new(slot.ty));
                }
            }
        }
        Bk3000 {
            present: vec![true; strip.len()],
            muted: vec![false; strip.len()],
            swapped: vec![None; strip.len()],
            strip,
            programmed: None,
            placement: vec![],
            prm: UserPrm::default(),
            image,
            diag: CouplerDiag::default(),
            diag_changed: false,
            held: false,
            outputs: vec![],
            inputs: vec![],
            pinned: BTreeMap::new(),
            counter: 0,
            regs,
            term_diag: vec![],
            plc: plc::PlcInterface::default(),
            table0: [0; 256],
            fms_servers: vec![],
            dp_outputs: vec![],
            fms_written: false,
            cycle_set: 0,
            exchanging: false,
            leds: None,
            kbus_timing: false,
            pending_outputs: None,
            pin_log: vec![],
            clock: Instant::ZERO,
            events: EventQueue::with_limit(256),
            inbox: InboxSchedule::default(),
        }
    }

    /// The LEDs now.
    pub fn leds(&self) -> Leds {
        let io_err = if self.diag.kbus != 0 || self.diag.init != 0 {
            Some(self.diag.kbus_code)
        } else if self.diag.cfg.0 != 0 {
            let e = if self.diag.cfg.0 == 1 {
                CfgError::TooFew
            } else {
                CfgError::FaultyByte(self.diag.cfg.1 as usize)
            };
            Some(e.blink())
        } else {
            None
        };
        Leds {
            io_run: if self.exchanging && !self.held && self.kbus_ok() {
                1
            } else if self.exchanging {
                0
            } else {
                2
            },
            io_err,
            bf: !self.exchanging,
        }
    }

    /// Report the LEDs as a `led` event when they changed.
    fn note_leds(&mut self) {
        let now = self.leds();
        if self.leds != Some(now) {
            self.leds = Some(now);
            self.events.note("led", now.to_string());
        }
    }

    /// Store a programmed configuration (table 70): the Chk_Cfg bytes
    /// expected when User_Prm_Data selects programmed configuration. The
    /// table must be a valid configuration of the strip (the emulation
    /// maps the data as in automatic configuration).
    pub fn with_programmed_cfg(mut self, cfg: Vec<u8>) -> Result<Bk3000, NotTheStrip> {
        for opts in [
            Options::default(),
            Options {
                plc_interface: true,
                cycle_counter: false,
            },
            Options {
                plc_interface: false,
                cycle_counter: true,
            },
            Options {
                plc_interface: true,
                cycle_counter: true,
            },
        ] {
            if image::check_cfg(&self.strip, opts, &cfg).is_ok() {
                self.programmed = Some(cfg);
                return Ok(self);
            }
        }
        Err(NotTheStrip {
            cfg,
            strip: self.strip.names().join(","),
        })
    }

    /// Store a programmed configuration (table 70) with terminals placed
    /// freely in the process image (p. 51): `cfg` need only give the
    /// lengths; `places` move terminals from their automatic addresses
    /// ([`Image::placed`]).
    pub fn with_placement(
        mut self,
        cfg: Vec<u8>,
        places: Vec<image::Placement>,
    ) -> Result<Bk3000, String> {
        for plc_interface in [false, true] {
            let opts = Options {
                plc_interface,
                cycle_counter: false,
            };
            if Image::placed(&self.strip, opts, &places, &cfg).is_ok() {
                self.programmed = Some(cfg);
                self.placement = places;
                return Ok(self);
            }
        }
        Image::placed(&self.strip, Options::default(), &places, &cfg).map(|_| self)
    }

    /// Model the K-bus cycle time ([`Bk3000::kbus_cycle_us`]) as a delay
    /// of the process data (manual p. 23, "K-Bus Reaktionszeit"): the
    /// outputs of a Data_Exchange reach the terminals one K-bus cycle
    /// later, and a Data_Exchange response carries the inputs the K-bus
    /// latched one cycle before (a simulated signal's value at `now − T`,
    /// a pinned value from one cycle after the `set`). Off by default:
    /// then the K-bus takes no time.
    pub fn with_kbus_timing(mut self, on: bool) -> Bk3000 {
        self.kbus_timing = on;
        self
    }

    /// The coupler with FMS mode `mode` in table 0 register 16 (p.66):
    /// in [`fms::FmsMode::Mixed`] and [`fms::FmsMode::FmsOnly`] it serves
    /// its object dictionary on the LSAPs of its KBL beside DP.
    pub fn with_fms_mode(mut self, mode: fms::FmsMode) -> Bk3000 {
        self.table0[16] = match mode {
            fms::FmsMode::DpOnly => 0,
            fms::FmsMode::Mixed => 1,
            fms::FmsMode::FmsOnly => 2,
        };
        self
    }

    /// The FMS mode of table 0 register 16.
    pub fn fms_mode(&self) -> fms::FmsMode {
        fms::FmsMode::from_register16(self.table0[16])
    }

    /// The object dictionary of the present configuration (automatic:
    /// channel objects of the current process image).
    pub fn object_dictionary(&self) -> fms::ObjectDictionary {
        fms::ObjectDictionary::new(&self.strip, &self.image, None)
    }

    /// Read control commands from `inbox` ([`Bk3000::control`]).
    pub fn with_inbox(mut self, inbox: ControlInbox) -> Bk3000 {
        self.inbox.set(inbox);
        self
    }

    /// The strip.
    pub fn strip(&self) -> &Strip {
        &self.strip
    }

    /// The current process image (the accepted configuration's, or the
    /// default one before a Chk_Cfg).
    pub fn image(&self) -> &Image {
        &self.image
    }

    /// The accepted User_Prm_Data settings.
    pub fn user_prm(&self) -> UserPrm {
        self.prm
    }

    /// The coupler's diagnosis state.
    pub fn coupler_diag(&self) -> CouplerDiag {
        self.diag
    }

    /// The outputs as the terminals got them last.
    pub fn terminal_outputs(&self) -> &[u8] {
        &self.outputs
    }

    /// The value of the output channel `name` as the terminal has it.
    pub fn output_value(&self, name: &str) -> Option<i64> {
        let e = self.image.find(name, Some(Dir::Out))?;
        Some(Image::get(e, &self.outputs))
    }

    /// Whether terminal `pos` (1-based) is plugged.
    pub fn is_present(&self, pos: usize) -> bool {
        self.present
            .get(pos.wrapping_sub(1))
            .copied()
            .unwrap_or(false)
    }

    fn kbus_ok(&self) -> bool {
        self.diag.kbus == 0 && self.diag.init == 0
    }

    /// Pin the input channel `name` to the engineering value `v` (digital
    /// 0/1, volts, °C, counts; status bytes raw).
    pub fn set_input(&mut self, name: &str, v: f64) -> Result<String, ControlError> {
        let e = self
            .image
            .find(name, Some(Dir::In))
            .ok_or_else(|| {
                ControlError::Argument(format!("no input channel `{name}` (see `status`)"))
            })?
            .clone();
        let raw = match (e.owner, e.role) {
            // Out-of-range values stay out of range: the terminal reports
            // over- or underrange in its status byte.
            (Owner::Terminal(p), Role::Value) if self.regs.contains_key(&(p, e.channel)) => {
                self.strip.slots()[p - 1]
                    .ty
                    .scale
                    .from_engineering_unclamped(v)
            }
            (Owner::Terminal(p), Role::Value) => {
                self.strip.slots()[p - 1].ty.scale.from_engineering(v)
            }
            _ => v.round() as i64,
        };
        let prev = self.pinned.insert(e.name.clone(), raw);
        if self.kbus_timing {
            let due = self.clock + self.kbus_delay();
            self.pin_log.push((due, e.name.clone(), prev));
        }
        Ok(format!("input {} pinned to {}", e.name, self.show(&e, raw)))
    }

    fn show(&self, e: &image::Entry, raw: i64) -> String {
        match (e.owner, e.role) {
            (Owner::Terminal(p), Role::Value) => {
                let sc = self.strip.slots()[p - 1].ty.scale;
                match sc.unit() {
                    Some(u) => format!("{:.3} {u} (raw {raw})", sc.to_engineering(raw)),
                    None => raw.to_string(),
                }
            }
            _ => format!("0x{:02X}", raw as u8),
        }
    }

    /// Pull terminal `pos` (1-based) from the strip: K-bus error.
    pub fn pull(&mut self, pos: usize) -> Result<String, ControlError> {
        self.check_pos(pos)?;
        if !self.present[pos - 1] {
            return Err(ControlError::Refused(format!(
                "terminal {pos} is already pulled"
            )));
        }
        self.present[pos - 1] = false;
        self.update_kbus();
        let (c, a) = self.diag.kbus_code;
        Ok(format!(
            "terminal {pos} ({}) pulled: K-bus error, break behind {}; {}",
            self.strip.slots()[pos - 1].ty.name,
            if a == 0 {
                "the coupler".to_string()
            } else {
                format!("terminal {a}")
            },
            prm::blink_text(c, a)
        ))
    }

    /// Plug terminal `pos` back.
    pub fn plug(&mut self, pos: usize) -> Result<String, ControlError> {
        self.check_pos(pos)?;
        if self.present[pos - 1] {
            return Err(ControlError::Refused(format!(
                "terminal {pos} is plugged already"
            )));
        }
        self.present[pos - 1] = true;
        self.update_kbus();
        Ok(format!(
            "terminal {pos} ({}) plugged{}",
            self.strip.slots()[pos - 1].ty.name,
            if self.kbus_ok() {
                ": K-bus running again".to_string()
            } else {
                format!(
                    ", K-bus still broken behind terminal {}",
                    self.diag.kbus_code.1
                )
            }
        ))
    }

    fn check_pos(&self, pos: usize) -> Result<(), ControlError> {
        if pos == 0 || pos > self.strip.len() {
            return Err(ControlError::Argument(format!(
                "terminal {pos}: the strip has terminals 1..={}",
                self.strip.len()
            )));
        }
        Ok(())
    }

    fn update_kbus(&mut self) {
        let before = self.diag;
        self.diag.init &= !prm::init_err::TERMINAL_TYPES;
        // p. 19-20: the first fault along the K-bus decides the code.
        if let Some(i) = self.present.iter().position(|p| !p) {
            self.diag.kbus = prm::kbus_err::KBUS | prm::kbus_err::RECEIVE;
            self.diag.kbus_code = (prm::KBUS_CODE_BREAK, i as u8);
        } else if self.muted.iter().any(|m| *m) {
            self.diag.kbus = prm::kbus_err::KBUS | prm::kbus_err::TIMEOUT;
            self.diag.kbus_code = (prm::KBUS_CODE_COMMAND, 0);
        } else if let Some(i) = self.swapped.iter().position(|s| s.is_some()) {
            self.diag.init |= prm::init_err::TERMINAL_TYPES;
            self.diag.kbus = prm::kbus_err::KBUS;
            self.diag.kbus_code = (prm::KBUS_CODE_FORMAT, i as u8 + 1);
        } else {
            self.diag.kbus = 0;
            self.diag.kbus_code = (0, 0);
        }
        if self.diag != before {
            self.diag_changed = true;
        }
    }

    /// Terminal `pos` stops answering on the K-bus (`mute N`), or answers
    /// again (`unmute N`): K-bus command error, 3 pulses then 0.
    pub fn mute(&mut self, pos: usize, mute: bool) -> Result<String, ControlError> {
        self.check_pos(pos)?;
        self.muted[pos - 1] = mute;
        self.update_kbus();
        let name = self.strip.slots()[pos - 1].ty.name;
        Ok(if mute {
            let (c, a) = self.diag.kbus_code;
            format!(
                "terminal {pos} ({name}) does not answer: K-bus command error; {}",
                prm::blink_text(c, a)
            )
        } else if self.kbus_ok() {
            format!("terminal {pos} ({name}) answers again: K-bus running")
        } else {
            format!("terminal {pos} ({name}) answers again")
        })
    }

    /// Replace terminal `pos` by `ty` while the coupler runs (`swap N
    /// TYPE`): the strip no longer is the one found at start-up:
    /// initialisation error "terminal types", K-bus halted, blink code 14
    /// then N, until the original type is plugged back.
    pub fn swap(&mut self, pos: usize, ty: &str) -> Result<String, ControlError> {
        self.check_pos(pos)?;
        let orig = self.strip.slots()[pos - 1].ty;
        let new = catalogue::lookup(ty)
            .ok_or_else(|| ControlError::Argument(format!("`{ty}` is not in the catalogue")))?;
        self.swapped[pos - 1] = (new.name != orig.name).then_some(new);
        self.update_kbus();
        Ok(if new.name == orig.name {
            format!(
                "terminal {pos} is a {} again{}",
                orig.name,
                if self.kbus_ok() {
                    ": K-bus running"
                } else {
                    ""
                }
            )
        } else {
            let (c, a) = self.diag.kbus_code;
            format!(
                "terminal {pos}: {} replaced by {}: the strip changed; {}",
                orig.name,
                new.name,
                prm::blink_text(c, a)
            )
        })
    }

    /// Apply one control command: `status`, `set NAME VALUE`, `release
    /// NAME|all`, `pull N`, `plug N`, `run` (leave parameter mode),
    /// `outputs` (the terminals' outputs). Returns the answer in words.
    pub fn control(&mut self, line: &str) -> Result<String, ControlError> {
        let mut w = line.split_whitespace();
        let cmd = w.next().unwrap_or("");
        let arg = |m: &str| ControlError::Argument(m.to_string());
        let num = |s: Option<&str>| -> Result<usize, ControlError> {
            s.and_then(|s| s.parse().ok())
                .ok_or_else(|| arg(&format!("`{cmd}` needs a terminal position")))
        };
        match cmd {
            "status" => Ok(self.status_text()),
            "outputs" => Ok(self.channel_text(Dir::Out)),
            "set" => {
                let name = w.next().ok_or_else(|| arg("`set NAME VALUE`"))?;
                let v: f64 = w
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(|| arg("`set NAME VALUE` needs a number"))?;
                self.set_input(name, v)
            }
            "release" => match w.next() {
                Some("all") | None => {
                    self.pinned.clear();
                    Ok("all inputs simulated again".into())
                }
                Some(n) => {
                    let e = self
                        .image
                        .find(n, Some(Dir::In))
                        .ok_or_else(|| arg(&format!("no input channel `{n}`")))?;
                    let name = e.name.clone();
                    self.pinned.remove(&name);
                    Ok(format!("input {name} simulated again"))
                }
            },
            "pull" => self.pull(num(w.next())?),
            "mute" => self.mute(num(w.next())?, true),
            "unmute" => self.mute(num(w.next())?, false),
            "swap" => {
                let pos = num(w.next())?;
                let ty = w.next().ok_or_else(|| arg("`swap N TYPE`"))?;
                self.swap(pos, ty)
            }
            "plug" => self.plug(num(w.next())?),
            "run" => {
                if self.held {
                    self.held = false;
                    self.diag_changed = true;
                    Ok("parameter mode left: K-bus running".into())
                } else {
                    Ok("K-bus already running".into())
                }
            }
            "" => Err(arg("empty command")),
            other => Err(ControlError::Unknown {
                command: other.to_string(),
                known: "status, outputs, set NAME VALUE, release NAME|all, pull N, plug N, mute N, unmute N, swap N TYPE, run",
            }),
        }
    }

    fn channel_text(&self, dir: Dir) -> String {
        let data = match dir {
            Dir::In => &self.inputs,
            Dir::Out => &self.outputs,
        };
        let parts: Vec<String> = self
            .image
            .entries
            .iter()
            .filter(|e| e.dir == dir && e.role != Role::Reserved)
            .map(|e| format!("{}={}", e.name, self.show(e, Image::get(e, data))))
            .collect();
        if parts.is_empty() {
            "(none)".into()
        } else {
            parts.join(", ")
        }
    }

    fn status_text(&self) -> String {
        let pulled: Vec<String> = self
            .present
            .iter()
            .enumerate()
            .filter(|(_, p)| !**p)
            .map(|(i, _)| (i + 1).to_string())
            .collect();
        let mut s = format!(
            "strip {}; cfg {}; {} in / {} out bytes; K-bus {}{}",
            self.strip.names().join(","),
            hex(&self.image.cfg),
            self.image.in_len,
            self.image.out_len,
            if self.kbus_ok() { "running" } else { "ERROR" },
            if self.held {
                " (held: parameter mode)"
            } else {
                ""
            }
        );
        if !pulled.is_empty() {
            s += &format!("; pulled: {}", pulled.join(","));
        }
        s += &format!("; LEDs: {}", self.leds());
        for l in self.diag.describe() {
            s += "; ";
            s += &l;
        }
        s += &format!("; inputs: {}", self.channel_text(Dir::In));
        s += &format!("; outputs: {}", self.channel_text(Dir::Out));
        s
    }

    fn simulate(&self, e: &image::Entry, now: Instant) -> i64 {
        let Owner::Terminal(pos) = e.owner else {
            return 0;
        };
        let ty = self.strip.slots()[pos - 1].ty;
        let t = now.as_nanos() as f64 / 1e9;
        let ch = e.channel as f64;
        match e.role {
            Role::Status | Role::Control | Role::Reserved => 0,
            Role::Value => match ty.sim {
                Sim::Walk => {
                    let step = (t / 0.5) as u64 % ty.channels as u64;
                    (step + 1 == e.channel as u64) as i64
                }
                Sim::Sine => ty
                    .scale
                    .from_engineering(5.0 * (std::f64::consts::TAU * t / 20.0 + ch).sin()),
                Sim::Temperature => ty
                    .scale
                    .from_engineering(22.5 + 2.5 * (std::f64::consts::TAU * t / 60.0 + ch).sin()),
                Sim::Counter => (t * 10.0) as i64 & 0xFFFF_FFFF,
                Sim::Encoder => (t * 100.0) as i64 & 0x00FF_FFFF,
                Sim::Echo => self
                    .image
                    .entries
                    .iter()
                    .find(|o| {
                        o.dir == Dir::Out
                            && o.owner == e.owner
                            && o.channel == e.channel
                            && o.role == Role::Value
                    })
                    .map_or(0, |o| Image::get(o, &self.outputs)),
                Sim::None => 0,
            },
        }
    }

    /// Run every input channel with a register set through its scaling,
    /// filter and range check: (position, channel) → (value, status).
    fn process_channels(&mut self, now: Instant) -> BTreeMap<(usize, u8), (i64, u8)> {
        let mut out = BTreeMap::new();
        let values: Vec<image::Entry> = self
            .image
            .entries
            .iter()
            .filter(|e| e.dir == Dir::In && e.role == Role::Value && e.bytes == 2)
            .filter(|e| matches!(e.owner, Owner::Terminal(p) if self.regs.contains_key(&(p, e.channel))))
            .cloned()
            .collect();
        for e in values {
            let Owner::Terminal(p) = e.owner else {
                continue;
            };
            let raw = match self.pinned.get(&e.name) {
                Some(&v) => v,
                None => self.simulate(&e, now),
            };
            let scale = self.strip.slots()[p - 1].ty.scale;
            if let Some(ch) = self.regs.get_mut(&(p, e.channel)) {
                out.insert((p, e.channel), ch.process(raw, &scale));
            }
        }
        // Channels in error get a diagnosis message (English ed. p. 50).
        let msgs: Vec<[u8; 8]> = out
            .iter()
            .filter(|(_, (_, st))| st & registers::status::ERROR != 0)
            .map(|(&(p, ch), &(_, st))| [p as u8, ch, 0, 0, 0, st, 0, 0])
            .collect();
        if msgs != self.term_diag {
            self.term_diag = msgs;
            self.diag_changed = true;
        }
        out
    }

    /// A terminal's status byte or value: register communication while
    /// the control byte's bit 7 is set (status = control without the
    /// write bit; value = the register read, 0 after a write), else the
    /// processed value and status.
    fn terminal_input(
        &self,
        e: &image::Entry,
        pos: usize,
        processed: &BTreeMap<(usize, u8), (i64, u8)>,
        now: Instant,
    ) -> i64 {
        let c = self.control_byte(pos, e.channel);
        let reg_mode = c & 0x80 != 0 && self.regs.contains_key(&(pos, e.channel));
        match e.role {
            Role::Status if reg_mode => (c & !0x40) as i64,
            Role::Status => match self.pinned.get(&e.name) {
                Some(&v) => v,
                None => processed.get(&(pos, e.channel)).map_or(0, |p| p.1 as i64),
            },
            Role::Value if reg_mode && e.bytes >= 2 => {
                if c & 0x40 != 0 {
                    0
                } else {
                    let r = self.regs[&(pos, e.channel)].read(c & 0x3F);
                    r as i16 as i64
                }
            }
            _ => match processed.get(&(pos, e.channel)) {
                Some(&(v, _)) if e.bytes == 2 => v,
                _ => match self.pinned.get(&e.name) {
                    Some(&v) => v,
                    None => self.simulate(e, now),
                },
            },
        }
    }

    /// Register writes of the control bytes with bits 7 and 6 set: the
    /// channel's output word into register `control & 0x3F`.
    fn register_writes(&mut self) {
        let writes: Vec<(usize, u8, u8, u16)> = self
            .image
            .entries
            .iter()
            .filter(|e| e.dir == Dir::Out && e.role == Role::Control)
            .filter_map(|e| {
                let Owner::Terminal(p) = e.owner else {
                    return None;
                };
                let c = Image::get(e, &self.outputs) as u8;
                if c & 0xC0 != 0xC0 {
                    return None;
                }
                let v = self
                    .image
                    .entries
                    .iter()
                    .find(|o| {
                        o.dir == Dir::Out
                            && o.owner == e.owner
                            && o.channel == e.channel
                            && o.role == Role::Value
                    })
                    .map_or(0, |o| Image::get(o, &self.outputs));
                Some((p, e.channel, c & 0x3F, v as u16))
            })
            .collect();
        for (p, ch, r, v) in writes {
            let Some(set) = self.regs.get_mut(&(p, ch)) else {
                continue;
            };
            let name = self.strip.slots()[p - 1].ty.name;
            match set.write(r, v) {
                Ok(()) => self.events.note(
                    "register",
                    format!("terminal {p} ({name}) channel {ch}: R{r} = 0x{v:04X}"),
                ),
                Err(e) => self.events.note(
                    "register",
                    format!("terminal {p} ({name}) channel {ch}: write refused: {e}"),
                ),
            }
        }
    }

    /// Register `r` of channel `ch` of terminal `pos` (1-based).
    pub fn register(&self, pos: usize, ch: u8, r: u8) -> Option<u16> {
        self.regs.get(&(pos, ch)).map(|c| c.read(r))
    }

    fn control_byte(&self, pos: usize, channel: u8) -> u8 {
        self.image
            .entries
            .iter()
            .find(|o| {
                o.dir == Dir::Out
                    && o.owner == Owner::Terminal(pos)
                    && o.channel == channel
                    && o.role == Role::Control
            })
            .map_or(0, |o| Image::get(o, &self.outputs) as u8)
    }

    fn apply_outputs(&mut self, outputs: &[u8]) {
        if self.outputs.as_slice() == outputs {
            return;
        }
        let old = std::mem::replace(&mut self.outputs, outputs.to_vec());
        self.register_writes();
        let changed: Vec<String> = self
            .image
            .entries
            .iter()
            .filter(|e| e.dir == Dir::Out && e.role != Role::Reserved)
            .filter(|e| old.len() != outputs.len() || Image::get(e, &old) != Image::get(e, outputs))
            .map(|e| format!("{}={}", e.name, self.show(e, Image::get(e, outputs))))
            .collect();
        if !changed.is_empty() {
            self.events.note(
                "outputs",
                format!("terminal outputs: {}", changed.join(", ")),
            );
        }
    }

    /// RunOnCfgFault (p. 46): the master's configuration describes a
    /// maximal strip; the coupler runs anyway with the master's lengths,
    /// maps its real strip's automatic image where it fits, and reports
    /// the CfgData error in its diagnosis (no Cfg_Fault).
    fn run_on_cfg_fault(&mut self, rej: CfgReject, cfg: &[u8]) -> Result<IoLayout, Reason> {
        let totals = match profibus_dp::pdu::cfg::totals(cfg) {
            Ok(t) if t.input_bytes <= image::MAX_IO && t.output_bytes <= image::MAX_IO => t,
            _ => return Err(self.cfg_fault(rej)),
        };
        let (p, n) = rej.error.blink();
        self.diag.cfg = (rej.error.code(), rej.error.byte());
        self.diag_changed = true;
        self.events.note(
            "io-err",
            format!("RunOnCfgFault: running with the master's configuration; I/O-ERR {p} pulses, then {n}: {}", rej.error),
        );
        let mut img = self.strip.default_image(self.options());
        img.entries.retain(|e| {
            let len = match e.dir {
                Dir::In => totals.input_bytes,
                Dir::Out => totals.output_bytes,
            };
            e.byte + (e.bytes.max(1) as usize) <= len
        });
        img.in_len = totals.input_bytes;
        img.out_len = totals.output_bytes;
        img.cfg = cfg.to_vec();
        let layout = IoLayout {
            inputs: img.in_len,
            outputs: img.out_len,
        };
        self.image = img;
        self.outputs = vec![0; layout.outputs];
        self.inputs = vec![0; layout.inputs];
        self.exchanging = true;
        Ok(layout)
    }

    fn cfg_fault(&mut self, rej: CfgReject) -> Reason {
        let (p, n) = rej.error.blink();
        self.diag.cfg = (rej.error.code(), rej.error.byte());
        self.diag_changed = true;
        let text = format!("{}: {}; {}", rej.error, rej.reason, prm::blink_text(p, n));
        self.events.note(
            "io-err",
            format!("I/O-ERR {p} pulses, then {n}: {}", rej.error),
        );
        text.into()
    }
}

impl Bk3000 {
    /// One step of the 2-byte PLC interface: a new toggle bit executes
    /// the function of the control byte ([`plc`]).
    fn plc_step(&mut self, control: u8, data: u8) {
        let Some(req) = self.plc.step(control, data) else {
            return;
        };
        let result = match req {
            plc::Request::Read {
                terminal,
                table,
                register,
            } => self.plc_read(terminal, table, register),
            plc::Request::Write {
                terminal,
                table,
                register,
                value,
            } => self
                .plc_write(terminal, table, register, value)
                .map(|()| value),
            plc::Request::StartKbus => {
                if self.held {
                    self.held = false;
                    self.diag_changed = true;
                    self.events.note(
                        "control",
                        "parameter mode left through the PLC interface: K-bus running".into(),
                    );
                }
                Ok(0)
            }
        };
        match result {
            Ok(v) => self.plc.done(v),
            Err(why) => {
                self.events.note("plc", format!("PLC interface: {why}"));
                self.plc.failed();
            }
        }
    }

    /// The terminals that count for the PLC interface and table 9: every
    /// terminal with process data (1-based positions in the strip).
    fn active_terminals(&self) -> Vec<usize> {
        self.strip
            .slots()
            .iter()
            .enumerate()
            .filter(|(_, s)| s.ty.class != Class::Passive)
            .map(|(k, _)| k + 1)
            .collect()
    }

    /// Table 9: 3000 in register 0, then one word per terminal: the type
    /// number of a complex terminal, `0x8000 | bits << 8 | out << 1 | in`
    /// of a digital one (Beckhoff's terminal composition, not from the
    /// manual).
    pub fn table9(&self) -> Vec<u16> {
        let mut t = vec![3000];
        for p in self.active_terminals() {
            let ty = self.strip.slots()[p - 1].ty;
            t.push(if ty.is_digital() {
                let (i, o) = ty.digital_bits();
                0x8000 | (u16::from(i.max(o)) << 8) | (u16::from(o > 0) << 1) | u16::from(i > 0)
            } else {
                ty.type_number()
            });
        }
        t
    }

    /// The modelled K-bus cycle time in µs (table 98, and the delay of
    /// [`Bk3000::with_kbus_timing`]): 140 µs plus 3.3 µs per digital bit
    /// (inputs and outputs), and with byte-oriented terminals 394 µs plus
    /// 70 µs per such terminal. A straight-line fit of the K-bus
    /// reaction-time table (manual p. 23; the seed's summary is cut off,
    /// the table's values are Beckhoff's measured ones as its BK7000 and
    /// Fieldbus Box manuals print them): every row of the table within
    /// 15 µs (4 DO 150, 32 DO 245, 32 DI 250, 32/32 350, 4/4 + 1 KL3202
    /// 630, + 2 KL3202 700 µs). The manual allows extrapolating to larger
    /// strips, as the line does.
    pub fn kbus_cycle_us(&self) -> u16 {
        let (mut bits, mut byte_terminals) = (0usize, 0usize);
        for s in self.strip.slots() {
            let (i, o) = s.ty.digital_bits();
            bits += usize::from(i + o);
            let img =
                s.ty.default_variant()
                    .map_or(0, |v| usize::from(v.in_len) + usize::from(v.out_len));
            if !s.ty.is_digital() && img > 0 {
                byte_terminals += 1;
            }
        }
        let mut us = 140 + bits * 33 / 10;
        if byte_terminals > 0 {
            us += 394 + 70 * byte_terminals;
        }
        us.min(u16::MAX as usize) as u16
    }

    fn kbus_delay(&self) -> Duration {
        if self.kbus_timing {
            Duration::from_micros(self.kbus_cycle_us().into())
        } else {
            Duration::ZERO
        }
    }

    /// Apply outputs whose K-bus cycle ended by `now`.
    fn deliver_outputs(&mut self, now: Instant) {
        if self
            .pending_outputs
            .as_ref()
            .is_some_and(|(t, _)| *t <= now)
        {
            let (_, out) = self.pending_outputs.take().expect("checked");
            if !self.held && self.kbus_ok() {
                self.apply_outputs(&out);
            }
        }
    }

    fn plc_read(&self, terminal: u8, table: u8, register: u8) -> Result<u16, String> {
        if terminal == 0 {
            return match table {
                0 => Ok(self.table0[register as usize]),
                9 => Ok(self.table9().get(register as usize).copied().unwrap_or(0)),
                70 => {
                    let cfg = self.programmed.clone().unwrap_or_default();
                    Ok(match register {
                        0 => cfg.len() as u16,
                        r => cfg.get(r as usize - 1).copied().unwrap_or(0).into(),
                    })
                }
                98 => {
                    let t = self.kbus_cycle_us();
                    Ok(match register {
                        0..=2 => t,
                        3 => self.cycle_set,
                        _ => 0,
                    })
                }
                t => Err(format!("the coupler has no table {t} (0, 9, 70, 98)")),
            };
        }
        let (pos, ch) = self.plc_channel(terminal, table)?;
        Ok(self.regs[&(pos, ch)].read(register))
    }

    fn plc_write(
        &mut self,
        terminal: u8,
        table: u8,
        register: u8,
        value: u16,
    ) -> Result<(), String> {
        if terminal == 0 {
            return match table {
                0 => {
                    self.table0[register as usize] = value;
                    Ok(())
                }
                9 => Err("table 9 (the terminal list) is read-only".into()),
                70 => {
                    let mut cfg = self.programmed.clone().unwrap_or_default();
                    match register {
                        0 => cfg.resize(value.min(244) as usize, 0),
                        r => {
                            let i = r as usize - 1;
                            if cfg.len() <= i {
                                cfg.resize(i + 1, 0);
                            }
                            cfg[i] = value as u8;
                        }
                    }
                    self.events.note(
                        "plc",
                        format!("table 70 (programmed configuration): {}", hex(&cfg)),
                    );
                    self.programmed = Some(cfg);
                    Ok(())
                }
                98 if register == 3 => {
                    self.cycle_set = value;
                    Ok(())
                }
                98 => Err("table 98 registers 0-2 are measured values".into()),
                t => Err(format!("the coupler has no table {t} (0, 9, 70, 98)")),
            };
        }
        let (pos, ch) = self.plc_channel(terminal, table)?;
        let set = self.regs.get_mut(&(pos, ch)).expect("checked");
        set.write(register, value)
            .map_err(|e| format!("terminal {terminal}: {e}"))
    }

    /// Terminal `terminal` (counted without passive terminals) and its
    /// table (channel - 1) as a register set.
    fn plc_channel(&self, terminal: u8, table: u8) -> Result<(usize, u8), String> {
        let pos = *self
            .active_terminals()
            .get(terminal as usize - 1)
            .ok_or_else(|| format!("no terminal {terminal}"))?;
        let ch = table + 1;
        if !self.regs.contains_key(&(pos, ch)) {
            return Err(format!("terminal {terminal} has no register table {table}"));
        }
        Ok((pos, ch))
    }
}

impl Device for Bk3000 {
    fn ident_number(&self) -> u16 {
        IDENT
    }

    fn real_cfg(&self) -> &[u8] {
        &self.image.cfg
    }

    fn features(&self) -> Features {
        Features {
            sync: true,
            freeze: true,
            max_diag_len: MAX_DIAG_LEN,
            ..Features::default()
        }
    }

    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        self.exchanging = false;
        match UserPrm::parse(prm.user_prm_data, self.programmed.is_some()) {
            Ok(p) => {
                if self.diag.prm != (0, 0) {
                    self.diag_changed = true;
                }
                self.diag.prm = (0, 0);
                self.prm = p;
                self.held = p.startup != StartupMode::DataExchange;
                if self.programmed.is_none() || !p.programmed {
                    let opts = self.options();
                    if self.image.cfg != self.strip.default_image(opts).cfg {
                        self.image = self.strip.default_image(opts);
                    }
                }
                Ok(())
            }
            Err(e) => {
                self.diag.prm = (e.code(), e.byte());
                self.diag_changed = true;
                Err(format!("{e} (UserPrmData error {}, byte {})", e.code(), e.byte()).into())
            }
        }
    }

    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        let opts = self.options();
        let result = if self.prm.programmed {
            let table = self.programmed.clone().unwrap_or_default();
            match table.iter().zip(cfg).position(|(a, b)| a != b) {
                Some(i) => Err(CfgReject {
                    error: CfgError::FaultyByte(i),
                    reason: format!("programmed configuration is {}", hex(&table)),
                }),
                None if cfg.len() < table.len() => Err(CfgReject {
                    error: CfgError::TooFew,
                    reason: format!("programmed configuration is {}", hex(&table)),
                }),
                None if cfg.len() > table.len() => Err(CfgReject {
                    error: CfgError::FaultyByte(table.len()),
                    reason: format!("programmed configuration is {}", hex(&table)),
                }),
                None if !self.placement.is_empty() => {
                    Image::placed(&self.strip, opts, &self.placement, cfg).map_err(|reason| {
                        CfgReject {
                            error: CfgError::FaultyByte(0),
                            reason,
                        }
                    })
                }
                None => image::check_cfg(&self.strip, opts, cfg),
            }
        } else {
            image::check_cfg(&self.strip, opts, cfg)
        };
        match result {
            Ok(img) => {
                if self.diag.cfg != (0, 0) {
                    self.diag_changed = true;
                }
                self.diag.cfg = (0, 0);
                let layout = IoLayout {
                    inputs: img.in_len,
                    outputs: img.out_len,
                };
                if img.in_len > image::MAX_IO || img.out_len > image::MAX_IO {
                    return Err(self.cfg_fault(CfgReject {
                        error: CfgError::FaultyByte(0),
                        reason: format!(
                            "{} input and {} output bytes, at most 244 each way",
                            img.in_len, img.out_len
                        ),
                    }));
                }
                self.image = img;
                self.outputs = vec![0; layout.outputs];
                self.inputs = vec![0; layout.inputs];
                self.exchanging = true;
                Ok(layout)
            }
            Err(rej) if self.prm.run_on_cfg_fault && !self.prm.programmed => {
                self.run_on_cfg_fault(rej, cfg)
            }
            Err(rej) => Err(self.cfg_fault(rej)),
        }
    }

    fn write_outputs(&mut self, now: Instant, outputs: &[u8]) {
        self.clock = self.clock.max(now);
        self.deliver_outputs(now);
        if self.prm.plc_interface && outputs.len() >= 2 {
            // The PLC interface is the coupler's own: it works in
            // parameter mode and with the K-bus stopped (p. 45).
            self.plc_step(outputs[0], outputs[1]);
        }
        if self.fms_written && self.dp_outputs == outputs {
            return;
        }
        self.fms_written = false;
        self.dp_outputs.clear();
        self.dp_outputs.extend_from_slice(outputs);
        if self.held || !self.kbus_ok() {
            return;
        }
        if self.kbus_timing {
            let due = now + self.kbus_delay();
            self.pending_outputs = Some((due, outputs.to_vec()));
        } else {
            self.apply_outputs(outputs);
        }
    }

    fn read_inputs(&mut self, now: Instant, inputs: &mut [u8]) {
        self.clock = self.clock.max(now);
        self.deliver_outputs(now);
        // The inputs the K-bus latched one cycle ago: simulated signals
        // at `now − T`, pins not older than T with their previous value.
        let caller_now = now;
        let now = Instant::from_nanos(
            now.as_nanos()
                .saturating_sub(self.kbus_delay().as_nanos() as u64),
        );
        let saved_pins = (!self.pin_log.is_empty()).then(|| {
            let saved = self.pinned.clone();
            for (due, name, prev) in self.pin_log.iter().rev() {
                if *due > caller_now {
                    match prev {
                        Some(v) => self.pinned.insert(name.clone(), *v),
                        None => self.pinned.remove(name),
                    };
                }
            }
            saved
        });
        if !self.held && self.kbus_ok() {
            self.counter = self.counter.wrapping_add(1).max(1);
            let processed = self.process_channels(now);
            for e in self.image.entries.iter().filter(|e| e.dir == Dir::In) {
                let v = match (e.owner, self.pinned.get(&e.name)) {
                    (Owner::Terminal(p), _) if e.role == Role::Status || e.role == Role::Value => {
                        self.terminal_input(e, p, &processed, now)
                    }
                    (_, Some(&v)) => v,
                    (Owner::CycleCounter, None) => self.counter as i64,
                    // Filled in below, also while the K-bus is held.
                    (Owner::PlcInterface, None) => 0,
                    (Owner::Terminal(_), None) => self.simulate(e, now),
                };
                Image::put(e, inputs, v);
            }
        }
        if self.prm.plc_interface && inputs.len() >= 2 {
            let (st, data) = self.plc.answer();
            inputs[0] = st;
            inputs[1] = data;
        }
        if self.inputs.len() == inputs.len() {
            self.inputs.copy_from_slice(inputs);
        } else {
            self.inputs = inputs.to_vec();
        }
        if let Some(saved) = saved_pins {
            self.pinned = saved;
            self.pin_log.retain(|(due, _, _)| *due > caller_now);
        }
    }

    fn clear_outputs(&mut self, _now: Instant, why: ClearReason) {
        // Outputs still on the K-bus do not arrive after the safe state.
        self.pending_outputs = None;
        self.fms_written = false;
        if matches!(why, ClearReason::Watchdog | ClearReason::LeftDataExchange) {
            self.exchanging = false;
        }
        let zero = vec![0; self.outputs.len()];
        if self.outputs != zero {
            self.outputs = zero;
            self.events.note(
                "outputs",
                format!("terminal outputs cleared ({})", why.as_str()),
            );
        }
    }

    fn diagnosis(&mut self, _now: Instant, diag: &mut DiagWriter<'_>) {
        let mut payload = self.diag.payload();
        if !self.term_diag.is_empty() {
            if payload.is_empty() {
                payload.push(0);
            }
            // Room for 7 messages after the length and reserved bytes.
            let room = (MAX_DIAG_LEN as usize - 8 - (payload.len() - 1)) / 8;
            for m in self.term_diag.iter().take(room) {
                payload.extend_from_slice(m);
            }
        }
        if !payload.is_empty() {
            diag.device(&payload);
            diag.set_ext_diag();
        }
        if self.diag.kbus != 0
            || self.diag.init != 0
            || (self.held && self.prm.startup == StartupMode::ParameterStatDiag)
        {
            diag.set_stat_diag();
        }
    }

    fn take_new_diag(&mut self) -> bool {
        std::mem::take(&mut self.diag_changed)
    }

    fn poll_event(&mut self) -> Option<DeviceEvent> {
        if self.leds.is_none() {
            // p. 11, 15: self-test, then the terminal test finds the strip.
            self.events.note(
                "self-test",
                format!(
                    "self-test passed; terminal test found {} terminals: {}",
                    self.strip.len(),
                    self.strip.names().join(",")
                ),
            );
        }
        self.note_leds();
        self.events.pop()
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
        let entry = fms::kbl(self.fms_mode())
            .into_iter()
            .find(|e| e.lsap == dsap)?;
        self.clock = self.clock.max(now);
        // The inputs as the last Data_Exchange carried them; without one
        // (FMS only) the terminals' inputs now.
        if self.inputs.len() != self.image.in_len {
            let mut fresh = vec![0; self.image.in_len];
            self.read_inputs(now, &mut fresh);
        }
        if self.outputs.len() != self.image.out_len {
            self.outputs.resize(self.image.out_len, 0);
        }
        let od = self.object_dictionary();
        let pos = match self.fms_servers.iter().position(|s| s.lsap == dsap) {
            Some(i) => i,
            None => {
                self.fms_servers.push(profibus_dp::fms::lli::LliServer::new(
                    dsap, entry.kind, None,
                ));
                self.fms_servers.len() - 1
            }
        };
        let mut outputs = self.outputs.clone();
        let mut app = fms::FmsServer {
            od: &od,
            inputs: &self.inputs,
            outputs: &mut outputs,
            written: false,
        };
        let reply = self.fms_servers[pos].on_srd(now, from, ssap, data, &mut app);
        if app.written {
            // Applied at once; a class-1 master's next outputs replace
            // them (docs/fms.md).
            self.apply_outputs(&outputs);
            self.fms_written = true;
        }
        self.note_fms_events();
        let reply = reply.unwrap_or_default();
        let n = reply.len().min(out.len());
        out[..n].copy_from_slice(&reply[..n]);
        Some(n)
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let out = self.pending_outputs.as_ref().map(|(t, _)| *t);
        let fms = self
            .fms_servers
            .iter()
            .filter_map(|s| s.poll_timeout())
            .min();
        [self.inbox.deadline(), out, fms]
            .into_iter()
            .flatten()
            .min()
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.clock = self.clock.max(now);
        self.deliver_outputs(now);
        for srv in &mut self.fms_servers {
            srv.handle_timeout(now);
        }
        self.note_fms_events();
        for line in self.inbox.due(now) {
            let kbus = ["pull", "plug", "mute", "unmute", "swap"]
                .iter()
                .any(|c| line.starts_with(c));
            match self.control(&line) {
                Ok(text) if kbus => self.events.note("kbus", text),
                Ok(text) => self.events.note("control", text),
                Err(e) => self.events.note("control-error", e.to_string()),
            }
        }
    }
}

impl Bk3000 {
    /// The FMS servers' connects and aborts as `fms` events.
    fn note_fms_events(&mut self) {
        use profibus_dp::fms::lli::ServerEvent;
        for i in 0..self.fms_servers.len() {
            let lsap = self.fms_servers[i].lsap;
            for ev in self.fms_servers[i].take_events() {
                let text = match ev {
                    ServerEvent::Connected { client, monitoring } => format!(
                        "LSAP {lsap}: client {client} connected, monitoring {}",
                        monitoring.map_or("off".to_string(), |m| format!("{} ms", m.as_millis()))
                    ),
                    ServerEvent::Aborted { reason, locally } => format!(
                        "LSAP {lsap}: connection aborted by the {}, reason {reason}{}",
                        if locally { "coupler" } else { "client" },
                        if reason == profibus_dp::fms::lli::ABORT_TIMEOUT {
                            " (client silent)"
                        } else {
                            ""
                        }
                    ),
                };
                self.events.note("fms", text);
            }
        }
    }

    fn options(&self) -> Options {
        Options {
            plc_interface: self.prm.plc_interface,
            cycle_counter: self.prm.cycle_counter,
        }
    }
}

fn hex(b: &[u8]) -> String {
    if b.is_empty() {
        return "(none)".into();
    }
    profibus_fdl::wire::Hex(b).to_string()
}

impl Class {
    /// Words for people.
    pub fn as_str(self) -> &'static str {
        match self {
            Class::DigitalIn => "digital inputs",
            Class::DigitalOut => "digital outputs",
            Class::DigitalInOut => "digital inputs and outputs",
            Class::Complex => "byte-oriented",
            Class::Passive => "no process data",
        }
    }
}

/// A programmed configuration (table 70) that is no valid configuration
/// of the strip.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "programmed configuration {} does not describe the strip {strip}",
    hex(cfg)
)]
pub struct NotTheStrip {
    /// The configuration bytes.
    pub cfg: Vec<u8>,
    /// The strip's terminals, comma-separated.
    pub strip: String,
}
