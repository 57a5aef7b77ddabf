//! AEG ID identification system with PROFIBUS-DP (RFID reader "ARE I2 /
//! PFB", "ARE K1 / PFB"), after its manual "Profibus-DP Kommunikation"
//! (AEG ID, German, no document number or edition printed; section 2
//! "Datenaustausch über Profibus-DP"; cited as Lnnn = manual line N, see
//! `docs/sources.md`).
//!
//! The reader carries a byte-stream command protocol inside 16 bytes of
//! cyclic data each way (L42-56):
//!
//! | byte | request (master → reader) | response (reader → master) |
//! |---|---|---|
//! | 1 | R: receive-request number | status: bit 3 = data flag ([`DATA_FLAG`]) |
//! | 2 | S: send-job number | E: receive-acknowledge number |
//! | 3 | L: payload length 0..=13 | L: payload length 0..=13 |
//! | 4-16 | payload | payload |
//!
//! - [`link`]: the reader's side of the handshake (send jobs, fragments,
//!   the one-cycle delay of a fetch), sans I/O.
//! - [`commands`]: the command set (`VER` exactly as the manual's example,
//!   `GT`, `RD`, `WD`, `TOR`, error answers) executed against a simulated
//!   antenna field with the reader's air times.
//! - [`tags`]: the antenna field and its TOML file.
//! - [`client`]: the master side ([`client::RfidClient`]): send a command
//!   line, get the whole answer.
//! - [`Rfid`]: the [`Device`] for the DP slave core, joining the three
//!   slave-side parts; [`profile`]: its registry entry.
//!
//! # Identity
//!
//! Ident number 0x0DC4 and `crates/devices/gsd/AEGI0DC4.GSD` are this project's choice
//! (the manual names neither, see the GSD's header): a compact station
//! with the one module `0x3F` (16 bytes in and out), no User_Prm_Data, no
//! sync, freeze, Set_Slave_Add or DP-V1, 6 bytes of diagnosis (none
//! device-specific: the manual describes no diagnosis).
//!
//! # Choices where the manual is silent
//!
//! - After power-up and after each new start-up of the DP interface (the
//!   slave leaves Data_Exch, the watchdog expires) R, S and E count from 0,
//!   unsent answers and half-received commands are dropped, a running
//!   command is abandoned. The manual's example starts from R = S = E = 0.
//! - Global_Control Clear_Data leaves the handshake alone (the master
//!   sends no outputs then; the numbers keep their values).
//! - The remaining ones are listed in [`link`] and [`commands`].

pub mod client;
pub mod commands;
pub mod custom;
pub mod demo;
pub mod jobs;
pub mod link;
pub mod profile;
pub mod tags;

#[cfg(test)]
mod tests;

use crate::kit::{EventQueue, InboxSchedule};
use crate::{ControlError, ControlInbox};
use commands::{Nak, Reader};
use link::{Line, ReaderLink, Received};
use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{
    expect_cfg, ClearReason, Device, DeviceEvent, Features, IoLayout, Reason,
};
use profibus_fdl::Instant;
use tags::{parse_uid, TagField};

/// The ident number (our choice, `crates/devices/gsd/AEGI0DC4.GSD`).
pub const IDENT: u16 = 0x0DC4;

/// `AEGI0DC4.GSD`.
pub const GSD: &[u8] = crate::gsd_files::AEGI0DC4;

/// The configuration: one module of 16 bytes in and out (`0x3F`).
pub const CFG: [u8; 1] = [0x3F];

/// Bytes of the data telegram each way (L58).
pub const TELEGRAM_LEN: usize = 16;

/// Bytes of the handshake header (L36).
pub const HEADER_LEN: usize = 3;

/// Most payload bytes per telegram (L58).
pub const PAYLOAD_MAX: usize = TELEGRAM_LEN - HEADER_LEN;

/// The data flag in the response's status byte (bit 3, L60-66): the reader
/// has data to send.
pub const DATA_FLAG: u8 = 0x08;

/// The command-line terminator (L97).
pub const CR: u8 = 0x0D;

/// The manual's worked example (chapter 2.4, L97-170): the master's
/// requests for the command `VER`, in order, hex (bytes not shown are 0).
/// Known-answer data for tests of the emulation and of its peers.
pub const MANUAL_REQUESTS: [&str; 5] = ["00 01 04 56 45 52 0D", "01 01", "02 01", "03 01", "04 01"];

/// The reader's responses to [`MANUAL_REQUESTS`], hex (bytes not shown
/// are 0).
pub const MANUAL_RESPONSES: [&str; 5] = [
    "08 00 00",
    "08 01 0D 41 45 47 20 49 44 20 2D 20 50 46 42 20",
    "08 02 06 56 31 2E 32 36 0D",
    "08 03 0D 41 45 47 20 49 44 20 2D 20 41 39 20 2F",
    "00 04 0A 50 46 42 20 56 31 2E 32 38 0D",
];

/// The emulated reader: a [`Device`] for the DP slave core.
#[derive(Debug)]
pub struct Rfid {
    link: ReaderLink,
    reader: Reader,
    events: EventQueue,
    inbox: InboxSchedule,
    state_events: bool,
}

impl Rfid {
    /// A reader with this antenna field (kept in memory only).
    pub fn new(field: TagField) -> Rfid {
        Rfid {
            link: ReaderLink::new(),
            reader: Reader::new(field),
            events: EventQueue::with_limit(256),
            inbox: InboxSchedule::default(),
            state_events: false,
        }
    }

    /// Report every change of the antenna field (a write, a tag entering
    /// or leaving, TOR) as a [`DeviceEvent`] of kind
    /// [`STATE_EVENT`](crate::STATE_EVENT) with the new tags file as its
    /// text, for the program that keeps the file.
    pub fn with_state_events(mut self, on: bool) -> Rfid {
        self.state_events = on;
        self
    }

    /// Answer a user's command set besides (or instead of) the modelled
    /// commands ([`custom`]).
    pub fn with_commands(mut self, set: custom::CommandSet) -> Rfid {
        self.reader.set_commands(set);
        self
    }

    /// Read control commands from `inbox` (see [`Rfid::control`]).
    pub fn with_inbox(mut self, inbox: ControlInbox) -> Rfid {
        self.inbox.set(inbox);
        self
    }

    /// The handshake.
    pub fn link(&self) -> &ReaderLink {
        &self.link
    }

    /// The command executor and its antenna field.
    pub fn reader(&self) -> &Reader {
        &self.reader
    }

    /// Tag `uid` (hex) enters the antenna field.
    pub fn tag_enters(&mut self, now: Instant, uid: &[u8]) {
        self.reader.enter(uid);
        self.run(now);
    }

    /// The tag in the antenna field leaves it.
    pub fn tag_leaves(&mut self, now: Instant) {
        self.reader.leave();
        self.run(now);
    }

    /// A control command: `enter UID` (a tag enters the field; an unknown
    /// UID is a new blank tag), `leave` (the tag in the field leaves),
    /// `tags` (list the tags), `status`. Returns what it did in words.
    pub fn control(&mut self, now: Instant, line: &str) -> Result<String, ControlError> {
        let mut words = line.split_whitespace();
        let reply = match (words.next(), words.next(), words.next()) {
            (Some("enter"), Some(uid), None) => {
                let uid = parse_uid(uid).map_err(|e| ControlError::Argument(e.to_string()))?;
                self.tag_enters(now, &uid);
                format!("tag {} in the field", tags::hex(&uid))
            }
            (Some("leave"), None, None) => {
                let was = self.reader.field().in_field().map(|t| t.uid_hex());
                self.tag_leaves(now);
                match was {
                    Some(u) => format!("tag {u} left the field"),
                    None => "no tag in the field".into(),
                }
            }
            (Some("tags"), None, None) => {
                let f = self.reader.field();
                let list: Vec<String> = f
                    .tags
                    .iter()
                    .map(|t| {
                        let here = f.in_field().is_some_and(|i| i.uid == t.uid);
                        format!(
                            "{} ({} blocks{})",
                            t.uid_hex(),
                            t.blocks.len(),
                            if here { ", in the field" } else { "" }
                        )
                    })
                    .collect();
                if list.is_empty() {
                    "no tags".into()
                } else {
                    list.join(", ")
                }
            }
            (Some("status"), None, None) => {
                let s = self.link.stats();
                format!(
                    "tag in the field: {}; command running: {}; answer bytes waiting: {}; jobs {}, ignored {}, fragments {}",
                    self.reader
                        .field()
                        .in_field()
                        .map_or("none".into(), |t| t.uid_hex()),
                    self.reader.busy(),
                    self.link.pending_answer().len(),
                    s.jobs,
                    s.ignored_jobs,
                    s.fragments
                )
            }
            _ => {
                return Err(ControlError::Unknown {
                    command: line.to_string(),
                    known: "enter UID, leave, tags, status",
                })
            }
        };
        Ok(reply)
    }

    /// Advance the running command, start queued ones, save the field.
    fn run(&mut self, now: Instant) {
        loop {
            if self.reader.busy() {
                match self.reader.step(now) {
                    Some(a) => self.answer(&a),
                    None => break,
                }
                continue;
            }
            match self.link.take_command() {
                None => break,
                Some(Line::Overflow) => {
                    self.events
                        .note("rfid", "command line too long: NAK #05".into());
                    self.answer(&Nak::BufferOverflow.answer());
                }
                Some(Line::Text(t)) => {
                    if let Some(a) = self.reader.start(now, &t) {
                        self.answer(&a);
                    }
                }
            }
        }
        while let Some(e) = self.reader.take_event() {
            self.events.note("rfid", e);
        }
        if self.reader.take_changed() && self.state_events {
            let text = self.reader.field().to_toml();
            self.events.note(crate::STATE_EVENT, text);
        }
    }

    fn answer(&mut self, bytes: &[u8]) {
        while let Some(e) = self.reader.take_event() {
            self.events.note("rfid", e);
        }
        self.link.push_answer(bytes);
        let text = format!(
            "answer ready: {} bytes `{}`",
            bytes.len(),
            String::from_utf8_lossy(bytes).replace('\r', "\\r")
        );
        self.events.note("rfid", text);
    }

    fn poll_inbox(&mut self, now: Instant) {
        for line in self.inbox.due(now) {
            match self.control(now, &line) {
                Ok(t) => self.events.note("control", t),
                Err(e) => self.events.note("control_error", e.to_string()),
            }
        }
    }
}

impl Device for Rfid {
    fn ident_number(&self) -> u16 {
        IDENT
    }

    fn real_cfg(&self) -> &[u8] {
        &CFG
    }

    fn features(&self) -> Features {
        Features {
            max_diag_len: 6,
            ..Features::default()
        }
    }

    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        if prm.user_prm_data.is_empty() {
            Ok(())
        } else {
            Err(format!(
                "{} bytes of User_Prm_Data, the reader takes none (User_Prm_Data_Len=0)",
                prm.user_prm_data.len()
            )
            .into())
        }
    }

    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        expect_cfg(&CFG, cfg)
    }

    fn write_outputs(&mut self, now: Instant, outputs: &[u8]) {
        self.poll_inbox(now);
        self.run(now);
        let busy = self.reader.busy();
        match self.link.request(outputs, busy) {
            Received::Ignored => self.events.note(
                "rfid",
                "send job while the data flag is set: ignored (the manual allows sending only with the flag 0)".into(),
            ),
            Received::Job { bytes, lines } if bytes > 0 => {
                let text = format!("send job: {bytes} bytes, {lines} command line(s) complete");
                self.events.note("rfid", text)
            }
            _ => {}
        }
        self.run(now);
    }

    fn read_inputs(&mut self, now: Instant, inputs: &mut [u8]) {
        self.run(now);
        self.link.response(inputs);
    }

    fn clear_outputs(&mut self, now: Instant, why: ClearReason) {
        if matches!(why, ClearReason::LeftDataExchange | ClearReason::Watchdog) {
            let busy = self.reader.busy() || self.link.data_waiting();
            self.link.reset();
            self.reader.abort();
            if busy {
                self.events.note(
                    "rfid",
                    format!("{}: command and answer dropped", why.as_str()),
                );
            }
            self.run(now);
        }
    }

    fn poll_event(&mut self) -> Option<DeviceEvent> {
        self.events.pop()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let inbox = self.inbox.deadline();
        [inbox, self.reader.next_wake()].into_iter().flatten().min()
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.poll_inbox(now);
        self.run(now);
    }
}
