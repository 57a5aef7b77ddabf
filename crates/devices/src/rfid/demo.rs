//! The demo plant's RFID reader (`dpctl demo`): a tag that comes and
//! goes, and the PLC's commands over the handshake in turn.

use super::client::RfidClient;
use super::jobs::RfidDone;
use super::tags::TagField;
use super::Rfid;
use crate::channels::ChannelMap;
use crate::{ControlInbox, DeviceOptions, ProfileError};
use profibus_dp::config::gsd::Gsd;
use profibus_dp::master::{DpMaster, SlaveState};
use profibus_dp::slave::Device;
use profibus_fdl::Instant;
use serde::Serialize;
use std::fmt;
use std::time::Duration;

/// The tag of the demo.
const TAGS: &str = "[reader]\ntor = 3\nuid_ms = 10\nblock_ms = 20\n\n\
    [[tag]]\nuid = \"E004015012345678\"\ndata = [\"00C0FFEE\"]\n";

/// How long the tag stays in the antenna field, and away.
const IN_FIELD: Duration = Duration::from_millis(1500);
const AWAY: Duration = Duration::from_millis(1000);

/// Pause between two commands.
const PAUSE: Duration = Duration::from_millis(150);

/// The slave side of the demo reader: its GSD, modules, device and
/// channels.
pub struct Parts {
    /// The GSD.
    pub gsd: Gsd,
    /// Its module.
    pub modules: Vec<String>,
    /// The emulated reader.
    pub device: Box<dyn Device + Send>,
    /// Named channels.
    pub channels: ChannelMap,
}

/// The PLC side: runs the commands and moves the tag.
pub struct DemoReader {
    address: u8,
    client: RfidClient,
    inbox: ControlInbox,
    tag_in: bool,
    tag_due: Instant,
    next: usize,
    due: Instant,
    running: Option<String>,
}

impl DemoReader {
    /// The reader at `address`.
    pub fn new(address: u8) -> Result<(DemoReader, Parts), ProfileError> {
        let p = crate::profile("rfid")?.configure(&DeviceOptions::new(), Some(address))?;
        let inbox = ControlInbox::new();
        let field = TagField::parse(TAGS).map_err(|e| ProfileError::Device(Box::new(e)))?;
        let device = Box::new(Rfid::new(field).with_inbox(inbox.clone()));
        let parts = Parts {
            gsd: p.gsd().clone(),
            modules: p.modules(),
            device,
            channels: p.channels(&p.chk_cfg()?)?,
        };
        Ok((
            DemoReader {
                address,
                client: RfidClient::new(Duration::from_millis(2000)),
                inbox,
                tag_in: false,
                tag_due: Instant::ZERO + Duration::from_millis(300),
                next: 0,
                due: Instant::ZERO,
                running: None,
            },
            parts,
        ))
    }

    fn command(&self, ramp: u16) -> String {
        match self.next {
            0 => "VER".into(),
            1 => "GT".into(),
            2 => format!("WD 1 {:08X}", ramp as u32),
            _ => "RD 0 1".into(),
        }
    }

    /// One step of the PLC program; returns what happened, for the
    /// view.
    pub fn step(&mut self, m: &mut DpMaster, now: Instant, ramp: u16) -> Vec<Event> {
        let mut out = vec![];
        if now >= self.tag_due {
            self.tag_in = !self.tag_in;
            self.tag_due = now + if self.tag_in { IN_FIELD } else { AWAY };
            self.inbox.push(if self.tag_in {
                "enter E004015012345678"
            } else {
                "leave"
            });
            out.push(Event::Tag(TagMoved {
                slave: self.address,
                tag: "E004015012345678",
                in_field: self.tag_in,
            }));
        }
        let Some(h) = m.handle(self.address) else {
            return out;
        };
        if m.slave(h).state != SlaveState::DataExchange && self.client.is_idle() {
            return out;
        }
        if let Some(r) = self.client.poll_master(now, m, h) {
            let cmd = self.running.take().unwrap_or_default();
            out.push(Event::Done(RfidDone::new(self.address, cmd, r)));
            self.due = now + PAUSE;
        }
        if self.client.is_idle() && now >= self.due {
            let cmd = self.command(ramp);
            self.next = if self.next == 3 { 1 } else { self.next + 1 };
            if self.client.start(now, cmd.as_bytes()).is_ok() {
                self.running = Some(cmd);
            }
        }
        out
    }
}

/// The demo reader's events: `Display` for the log, `Serialize` for
/// JSON lines.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Event {
    /// A tag entered or left the field.
    Tag(TagMoved),
    /// A command ended.
    Done(RfidDone),
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Event::Tag(t) => t.fmt(f),
            Event::Done(d) => d.fmt(f),
        }
    }
}

/// A tag entered or left the reader's field (event `rfid_tag`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "event", rename = "rfid_tag")]
pub struct TagMoved {
    /// The reader's station address.
    pub slave: u8,
    /// The tag's UID.
    pub tag: &'static str,
    /// It entered (else it left).
    pub in_field: bool,
}

impl fmt::Display for TagMoved {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = if self.in_field { "enters" } else { "leaves" };
        let (slave, tag) = (self.slave, self.tag);
        write!(f, "rfid slave {slave}: tag {tag} {what} the field")
    }
}
