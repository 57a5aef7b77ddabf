//! The PKW parameter channel ("Parameter-Kennung-Wert"): four words at the
//! front of the cyclic data (PKE, IND, PWE1, PWE2) through which a master
//! reads and writes single parameters of a slave by handshake, next to the
//! process data. Both Baumüller profiles (`crate::bm4`, `crate::omega`)
//! carry one.
//!
//! This module is a leaf: it knows no device. Each device module owns its
//! [`Dialect`] (`bm4::PKW`, `omega::PKW`); the crate's profile registry
//! finds the dialect of a slave from its ident number and configuration
//! (`crate::pkw_dialect`).
//!
//! - [`Pkw`]: the four words and their wire form (big-endian, 8 bytes).
//! - [`Dialect`]: which command code (AK) means what and which error
//!   numbers exist, per device family. The AK field is
//!   bits 15..12 of PKE, bit 11 is the spare bit R, bits 10..0 the
//!   parameter number PNU (BM4 manual L1497-1524, Omega manual L855-895).
//! - [`PkwEngine`]: the slave side. It sees the master's PKW words with
//!   every Data_Exchange, starts a job when PKE changes to a non-zero
//!   value, hands the decoded [`Command`] to the device's [`PkwServer`]
//!   (its parameter table) and puts the response into the input words, after
//!   the device's processing delay.
//! - [`client::PkwClient`]: the master side, driving the handshake over a
//!   slave's process images.
//!
//! Both are plain state machines fed with the cyclic data and `now`.
//!
//! # Handshake (both manuals)
//!
//! The master writes IND and PWE, then PKE (BM4 L1571-1581, Omega L865,
//! L969-986); the slave answers with a response code in the AK field and
//! the same PNU; the master reads the response and resets PKE (and IND,
//! PWE) to 0; the slave then answers PKE = 0 ("no response"). Choices
//! where the manuals leave it open:
//!
//! - A job starts when the request words change and PKE is not 0; the
//!   IND and PWE words of that telegram are the job's (the master wrote
//!   them first). Repeating the same words does not repeat the job: a
//!   write is executed once. Without [`Dialect::reset_required`] (the
//!   BM4, whose manual orders IND, PWE1, PWE2, then PKE, L1571-1581, but
//!   never asks for PKE = 0 between jobs) a change of any word is a new
//!   job: the next array element by a new IND alone, or a new value with
//!   the same PKE. With it (the Omega) only a new PKE is.
//! - The response stays in the input words until the master's PKE goes
//!   back to 0, then the input PKW words become 0.
//! - Dialects with [`Dialect::reset_required`] (the Omega board: "only
//!   ever one command must be active", L978-983; "previous service data
//!   communication was not reset with PKE = 0" is listed as a cause of
//!   error responses, L1024) answer a new PKE that did not pass through 0
//!   with error [`Dialect::not_reset_error`] instead of executing it.
//!   The BM4 manual says nothing about it; there a changed PKE is a new
//!   job.

pub mod client;

use crate::channels::{ChannelMap, ChannelType, Direction};
use profibus_fdl::Instant;
use std::fmt;
use std::time::Duration;

/// Length of the PKW area in bytes (4 words).
pub const PKW_LEN: usize = 8;

/// The identifier of the PKW module in both devices' GSD files: 4 words
/// in and out, word consistency (BM4 L2262, Omega L1462).
pub const PKW_MODULE: u8 = 0x73;

/// The four PKW words as named channels at the front of both process
/// images: `pke`, `ind`, `pwe1`, `pwe2` (for a profile's
/// [`ChannelMap`]).
pub fn channels(m: &mut ChannelMap) {
    for dir in [Direction::Input, Direction::Output] {
        for (i, name) in ["pke", "ind", "pwe1", "pwe2"].into_iter().enumerate() {
            m.push(name, dir, 2 * i, ChannelType::U16);
        }
    }
}

/// A parameter a device names, as `dpctl pkw list` shows it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct PkwParameter {
    /// Parameter number.
    pub pnu: u16,
    /// Its name.
    pub name: String,
    /// Format and access in words (`word, read only, 0..15`).
    pub details: String,
}

/// The four PKW words.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Pkw {
    /// Parameter code: AK (bits 15..12), R (bit 11), PNU (bits 10..0).
    pub pke: u16,
    /// Index (array element or description element; otherwise 0).
    pub ind: u16,
    /// Value, high word.
    pub pwe1: u16,
    /// Value, low word (word values, element values and error numbers).
    pub pwe2: u16,
}

impl Pkw {
    /// The zero words: "no command" / "no response".
    pub const ZERO: Pkw = Pkw {
        pke: 0,
        ind: 0,
        pwe1: 0,
        pwe2: 0,
    };

    /// Words from AK, PNU, IND and a 32-bit value (PWE1 = high word).
    pub fn new(ak: u8, pnu: u16, ind: u16, value: u32) -> Pkw {
        Pkw {
            pke: ((ak as u16 & 0xF) << 12) | (pnu & 0x7FF),
            ind,
            pwe1: (value >> 16) as u16,
            pwe2: value as u16,
        }
    }

    /// Read the words from the first 8 bytes of `b` (big-endian, as both
    /// devices put them on the bus); `None` when `b` is shorter.
    pub fn parse(b: &[u8]) -> Option<Pkw> {
        let b = b.get(..PKW_LEN)?;
        let w = |i: usize| u16::from_be_bytes([b[i], b[i + 1]]);
        Some(Pkw {
            pke: w(0),
            ind: w(2),
            pwe1: w(4),
            pwe2: w(6),
        })
    }

    /// Write the words into the first 8 bytes of `b` (no-op when shorter).
    pub fn emit(&self, b: &mut [u8]) {
        if let Some(b) = b.get_mut(..PKW_LEN) {
            b[0..2].copy_from_slice(&self.pke.to_be_bytes());
            b[2..4].copy_from_slice(&self.ind.to_be_bytes());
            b[4..6].copy_from_slice(&self.pwe1.to_be_bytes());
            b[6..8].copy_from_slice(&self.pwe2.to_be_bytes());
        }
    }

    /// The command or response code (AK, bits 15..12 of PKE).
    pub fn ak(&self) -> u8 {
        (self.pke >> 12) as u8
    }

    /// The parameter number (PNU, bits 10..0 of PKE).
    pub fn pnu(&self) -> u16 {
        self.pke & 0x7FF
    }

    /// PWE1:PWE2 as one 32-bit value.
    pub fn value(&self) -> u32 {
        ((self.pwe1 as u32) << 16) | self.pwe2 as u32
    }
}

impl fmt::Display for Pkw {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:04X} {:04X} {:04X} {:04X}",
            self.pke, self.ind, self.pwe1, self.pwe2
        )
    }
}

/// What a request asks for, independent of the dialect's code numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// Read the parameter's value ("PWE anfordern" / "Request PWE").
    Read,
    /// Write a word value (PWE2).
    WriteWord(u16),
    /// Write a double word value (PWE1 = high word).
    WriteDword(u32),
    /// Read element `IND` of the parameter description (PBE).
    Describe(u16),
    /// Read array element `IND`.
    ReadElement(u16),
    /// Write array element `index` with a word value.
    WriteElementWord {
        /// Array element (IND).
        index: u16,
        /// Value (PWE2).
        value: u16,
    },
    /// Write array element `index` with a double word value.
    WriteElementDword {
        /// Array element (IND).
        index: u16,
        /// Value.
        value: u32,
    },
    /// A code the dialect does not define or does not support.
    Unsupported(u8),
}

/// A successful answer, independent of the dialect's code numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reply {
    /// A word value (PWE2; PWE1 = 0).
    Word(u16),
    /// A double word value (PWE1 = high word).
    Dword(u32),
    /// A description element (PWE2; IND echoed).
    Element(u16),
    /// An array element, word (PWE2; IND echoed).
    ElementWord(u16),
    /// An array element, double word (IND echoed).
    ElementDword(u32),
}

impl Reply {
    /// The value as a 32-bit number (word values zero-extended).
    pub fn value(&self) -> u32 {
        match *self {
            Reply::Word(v) | Reply::Element(v) | Reply::ElementWord(v) => v as u32,
            Reply::Dword(v) | Reply::ElementDword(v) => v,
        }
    }

    /// Whether the value is a double word.
    pub fn is_dword(&self) -> bool {
        matches!(self, Reply::Dword(_) | Reply::ElementDword(_))
    }
}

/// The code numbers and error numbers of one device family's PKW channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dialect {
    /// Name for people.
    pub name: &'static str,
    /// Request AK for array element read, if the family has it.
    pub read_element: Option<u8>,
    /// Request AK for array element write (word).
    pub write_element_word: Option<u8>,
    /// Request AK for array element write (double word).
    pub write_element_dword: Option<u8>,
    /// Request AK for "request parameter description element" (PBE).
    pub describe: Option<u8>,
    /// Response AK of a description element.
    pub resp_element: Option<u8>,
    /// Response AK of an array element, word.
    pub resp_element_word: Option<u8>,
    /// Response AK of an array element, double word.
    pub resp_element_dword: Option<u8>,
    /// A new job must follow PKE = 0 (see the module docs).
    pub reset_required: bool,
    /// Error number answered to a job that did not follow PKE = 0.
    pub not_reset_error: u16,
    /// The error numbers with their meaning.
    pub errors: &'static [(u16, &'static str)],
}

/// Request AK "read" in both dialects.
pub const AK_READ: u8 = 1;
/// Request AK "write word" in both dialects.
pub const AK_WRITE_WORD: u8 = 2;
/// Request AK "write double word" in both dialects.
pub const AK_WRITE_DWORD: u8 = 3;
/// Response AK "word value" in both dialects.
pub const AK_RESP_WORD: u8 = 1;
/// Response AK "double word value" in both dialects.
pub const AK_RESP_DWORD: u8 = 2;
/// Response AK "cannot execute", error number in PWE2, in both dialects.
pub const AK_RESP_ERROR: u8 = 7;

impl Dialect {
    /// The codes every dialect shares (read, write word, write double
    /// word; responses word, double word, error) and nothing else: the
    /// base a device's dialect extends with struct update syntax.
    pub const BASE: Dialect = Dialect {
        name: "PKW",
        read_element: None,
        write_element_word: None,
        write_element_dword: None,
        describe: None,
        resp_element: None,
        resp_element_word: None,
        resp_element_dword: None,
        reset_required: false,
        not_reset_error: 0,
        errors: &[],
    };

    /// Decode a request's command (AK, IND, PWE).
    pub fn command(&self, req: &Pkw) -> Command {
        let ak = req.ak();
        match ak {
            AK_READ => Command::Read,
            AK_WRITE_WORD => Command::WriteWord(req.pwe2),
            AK_WRITE_DWORD => Command::WriteDword(req.value()),
            _ if Some(ak) == self.describe => Command::Describe(req.ind),
            _ if Some(ak) == self.read_element => Command::ReadElement(req.ind),
            _ if Some(ak) == self.write_element_word => Command::WriteElementWord {
                index: req.ind,
                value: req.pwe2,
            },
            _ if Some(ak) == self.write_element_dword => Command::WriteElementDword {
                index: req.ind,
                value: req.value(),
            },
            _ => Command::Unsupported(ak),
        }
    }

    /// The request words of `cmd` for parameter `pnu`; `None` when the
    /// dialect has no code for it.
    pub fn request(&self, pnu: u16, cmd: Command) -> Option<Pkw> {
        Some(match cmd {
            Command::Read => Pkw::new(AK_READ, pnu, 0, 0),
            Command::WriteWord(v) => Pkw::new(AK_WRITE_WORD, pnu, 0, v as u32),
            Command::WriteDword(v) => Pkw::new(AK_WRITE_DWORD, pnu, 0, v),
            Command::Describe(ind) => Pkw::new(self.describe?, pnu, ind, 0),
            Command::ReadElement(i) => Pkw::new(self.read_element?, pnu, i, 0),
            Command::WriteElementWord { index, value } => {
                Pkw::new(self.write_element_word?, pnu, index, value as u32)
            }
            Command::WriteElementDword { index, value } => {
                Pkw::new(self.write_element_dword?, pnu, index, value)
            }
            Command::Unsupported(ak) => Pkw::new(ak, pnu, 0, 0),
        })
    }

    /// The response words of a successful job.
    pub fn response(&self, pnu: u16, ind: u16, reply: Reply) -> Pkw {
        let (ak, ind) = match reply {
            Reply::Word(_) => (AK_RESP_WORD, 0),
            Reply::Dword(_) => (AK_RESP_DWORD, 0),
            Reply::Element(_) => (self.resp_element.unwrap_or(AK_RESP_WORD), ind),
            Reply::ElementWord(_) => (self.resp_element_word.unwrap_or(AK_RESP_WORD), ind),
            Reply::ElementDword(_) => (self.resp_element_dword.unwrap_or(AK_RESP_DWORD), ind),
        };
        Pkw::new(ak, pnu, ind, reply.value())
    }

    /// The response words of a refused job: AK 7, error number in PWE2,
    /// PWE1 = 0; IND echoed for indexed jobs (Omega L1017, L1150),
    /// otherwise 0.
    pub fn error(&self, pnu: u16, ind: u16, code: u16) -> Pkw {
        Pkw::new(AK_RESP_ERROR, pnu, ind, code as u32)
    }

    /// Decode a response: the value, or the error number.
    pub fn decode_response(&self, resp: &Pkw) -> Option<Result<Reply, u16>> {
        let ak = resp.ak();
        Some(Ok(match ak {
            AK_RESP_ERROR => return Some(Err(resp.pwe2)),
            AK_RESP_WORD => Reply::Word(resp.pwe2),
            AK_RESP_DWORD => Reply::Dword(resp.value()),
            _ if Some(ak) == self.resp_element => Reply::Element(resp.pwe2),
            _ if Some(ak) == self.resp_element_word => Reply::ElementWord(resp.pwe2),
            _ if Some(ak) == self.resp_element_dword => Reply::ElementDword(resp.value()),
            _ => return None,
        }))
    }

    /// An error number in words.
    pub fn error_text(&self, code: u16) -> &'static str {
        self.errors
            .iter()
            .find(|(c, _)| *c == code)
            .map(|(_, t)| *t)
            .unwrap_or("reserved error number")
    }
}

/// A device's parameter table as the PKW engine uses it.
pub trait PkwServer {
    /// Execute `cmd` on parameter `pnu` with index `ind` (as received).
    /// `Err` is the dialect's error number (PWE2 of the error response).
    fn execute(&mut self, now: Instant, pnu: u16, ind: u16, cmd: Command) -> Result<Reply, u16>;
}

/// A job the engine finished, for the device's event log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PkwJob {
    /// The request words.
    pub request: Pkw,
    /// The response words.
    pub response: Pkw,
}

/// The slave side of the PKW channel; see the module docs.
#[derive(Debug, Clone)]
pub struct PkwEngine {
    dialect: &'static Dialect,
    delay: Duration,
    /// The last request seen.
    last: Pkw,
    /// The response in the input words.
    response: Pkw,
    /// A response to show from the given time on.
    pending: Option<(Instant, Pkw)>,
    jobs: u64,
}

impl PkwEngine {
    /// An idle engine for `dialect` that shows each response `delay`
    /// after the request arrived (the device's processing time; the input
    /// words say "no response" meanwhile).
    pub fn new(dialect: &'static Dialect, delay: Duration) -> PkwEngine {
        PkwEngine {
            dialect,
            delay,
            last: Pkw::ZERO,
            response: Pkw::ZERO,
            pending: None,
            jobs: 0,
        }
    }

    /// The dialect.
    pub fn dialect(&self) -> &'static Dialect {
        self.dialect
    }

    /// Change the processing delay for the jobs that start from now on.
    pub fn set_delay(&mut self, delay: Duration) {
        self.delay = delay;
    }

    /// Jobs executed so far.
    pub fn jobs(&self) -> u64 {
        self.jobs
    }

    /// The master's PKW words of one Data_Exchange. Returns the job when
    /// one was executed.
    pub fn on_request<S: PkwServer + ?Sized>(
        &mut self,
        now: Instant,
        req: Pkw,
        server: &mut S,
    ) -> Option<PkwJob> {
        let previous = std::mem::replace(&mut self.last, req);
        if req.pke == 0 {
            self.response = Pkw::ZERO;
            self.pending = None;
            return None;
        }
        let new_job = if self.dialect.reset_required {
            req.pke != previous.pke
        } else {
            req != previous
        };
        if !new_job {
            return None;
        }
        self.jobs += 1;
        let (pnu, ind) = (req.pnu(), req.ind);
        let response = if previous.pke != 0 && self.dialect.reset_required {
            self.dialect.error(pnu, 0, self.dialect.not_reset_error)
        } else {
            let cmd = self.dialect.command(&req);
            let indexed = matches!(
                cmd,
                Command::Describe(_)
                    | Command::ReadElement(_)
                    | Command::WriteElementWord { .. }
                    | Command::WriteElementDword { .. }
            );
            match server.execute(now, pnu, ind, cmd) {
                Ok(reply) => self.dialect.response(pnu, ind, reply),
                Err(code) => self.dialect.error(pnu, if indexed { ind } else { 0 }, code),
            }
        };
        self.response = Pkw::ZERO;
        if self.delay.is_zero() {
            self.response = response;
            self.pending = None;
        } else {
            self.pending = Some((now + self.delay, response));
        }
        Some(PkwJob {
            request: req,
            response,
        })
    }

    /// The PKW words for the inputs at `now`.
    pub fn response(&mut self, now: Instant) -> Pkw {
        if let Some((at, r)) = self.pending {
            if now >= at {
                self.response = r;
                self.pending = None;
            }
        }
        self.response
    }

    /// When a held response becomes visible.
    pub fn poll_timeout(&self) -> Option<Instant> {
        self.pending.map(|(t, _)| t)
    }

    /// Forget the channel's state (the slave left Data_Exchange).
    pub fn reset(&mut self) {
        self.last = Pkw::ZERO;
        self.response = Pkw::ZERO;
        self.pending = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dialect with array element codes (as the BM4-O-PRO-01's).
    pub(crate) const ELEMENTS: Dialect = Dialect {
        read_element: Some(6),
        write_element_word: Some(7),
        write_element_dword: Some(8),
        resp_element_word: Some(4),
        resp_element_dword: Some(5),
        errors: &[(0x0B, "does not exist")],
        ..Dialect::BASE
    };

    /// A dialect with description elements and the PKE = 0 rule (as the
    /// Omega board's).
    pub(crate) const DESCRIBE: Dialect = Dialect {
        describe: Some(4),
        resp_element: Some(3),
        reset_required: true,
        not_reset_error: 0x0101,
        errors: &[(0x82, "error reading actual value")],
        ..Dialect::BASE
    };

    /// Word parameter 1 = 0x1234, read-only word 2; everything else
    /// "does not exist" (BM4 numbers).
    struct Table(u16);
    impl PkwServer for Table {
        fn execute(&mut self, _: Instant, pnu: u16, _: u16, cmd: Command) -> Result<Reply, u16> {
            match (pnu, cmd) {
                (1, Command::Read) => Ok(Reply::Word(self.0)),
                (1, Command::WriteWord(v)) => {
                    self.0 = v;
                    Ok(Reply::Word(v))
                }
                (2, Command::WriteWord(_)) => Err(1),
                (_, Command::Unsupported(_)) => Err(0x16),
                _ => Err(0x0B),
            }
        }
    }

    #[test]
    fn words_round_trip() {
        let p = Pkw::new(3, 2, 0, 0x1234_5678);
        let mut b = [0u8; 8];
        p.emit(&mut b);
        assert_eq!(b, [0x30, 0x02, 0, 0, 0x12, 0x34, 0x56, 0x78]);
        assert_eq!(Pkw::parse(&b), Some(p));
        assert_eq!((p.ak(), p.pnu(), p.value()), (3, 2, 0x1234_5678));
        assert_eq!(Pkw::parse(&b[..7]), None);
        assert_eq!(p.to_string(), "3002 0000 1234 5678");
    }

    #[test]
    fn dialect_codes() {
        let r = Pkw::new(6, 9, 3, 0);
        assert_eq!(ELEMENTS.command(&r), Command::ReadElement(3));
        assert_eq!(DESCRIBE.command(&r), Command::Unsupported(6));
        assert_eq!(
            DESCRIBE.command(&Pkw::new(4, 9, 6, 0)),
            Command::Describe(6)
        );
        assert_eq!(
            ELEMENTS.command(&Pkw::new(4, 9, 6, 0)),
            Command::Unsupported(4)
        );
        assert_eq!(
            DESCRIBE.response(0x7E, 6, Reply::Element(0xF)),
            Pkw {
                pke: 0x307E,
                ind: 6,
                pwe1: 0,
                pwe2: 0xF
            }
        );
        assert_eq!(ELEMENTS.response(5, 2, Reply::ElementDword(7)).pke, 0x5005);
        assert_eq!(
            ELEMENTS.decode_response(&Pkw::new(5, 5, 2, 7)),
            Some(Ok(Reply::ElementDword(7)))
        );
        assert_eq!(DESCRIBE.decode_response(&Pkw::new(5, 5, 2, 7)), None);
        assert_eq!(
            DESCRIBE.decode_response(&Pkw::new(7, 5, 0, 0x82)),
            Some(Err(0x82))
        );
        assert_eq!(DESCRIBE.error_text(0x82), "error reading actual value");
        assert!(ELEMENTS.error_text(0x0B).starts_with("does not exist"));
        assert_eq!(ELEMENTS.request(1, Command::Describe(1)), None);
    }

    #[test]
    fn handshake_executes_once_and_resets() {
        let mut t = Table(0x1234);
        let mut e = PkwEngine::new(&ELEMENTS, Duration::ZERO);
        let now = Instant::ZERO;
        assert_eq!(e.on_request(now, Pkw::ZERO, &mut t), None);
        let job = e.on_request(now, Pkw::new(2, 1, 0, 0x55), &mut t).unwrap();
        assert_eq!(job.response, Pkw::new(1, 1, 0, 0x55));
        assert_eq!(e.response(now), Pkw::new(1, 1, 0, 0x55));
        // Repeated: not executed again.
        t.0 = 9;
        assert_eq!(e.on_request(now, Pkw::new(2, 1, 0, 0x55), &mut t), None);
        assert_eq!(t.0, 9);
        assert_eq!(e.response(now), Pkw::new(1, 1, 0, 0x55));
        // Reset.
        assert_eq!(e.on_request(now, Pkw::ZERO, &mut t), None);
        assert_eq!(e.response(now), Pkw::ZERO);
        // Errors: PWE2 = number, PWE1 = 0.
        let j = e.on_request(now, Pkw::new(1, 7, 0, 0), &mut t).unwrap();
        assert_eq!(j.response, Pkw::new(7, 7, 0, 0x0B));
        // Without the PKE = 0 rule a changed PKE without reset is a new job.
        let j = e.on_request(now, Pkw::new(1, 1, 0, 0), &mut t).unwrap();
        assert_eq!(j.response, Pkw::new(1, 1, 0, 9));
        assert_eq!(e.jobs(), 3);
    }

    #[test]
    fn any_changed_word_is_a_new_job_without_the_reset_rule() {
        // BM4 L1571-1581: IND, PWE1, PWE2, then PKE; no PKE = 0 between
        // jobs. A second write with a new value and the same PKE runs.
        let mut t = Table(0);
        let mut e = PkwEngine::new(&ELEMENTS, Duration::ZERO);
        let now = Instant::ZERO;
        e.on_request(now, Pkw::new(2, 1, 0, 0x11), &mut t).unwrap();
        let j = e.on_request(now, Pkw::new(2, 1, 0, 0x22), &mut t).unwrap();
        assert_eq!(j.response, Pkw::new(1, 1, 0, 0x22));
        assert_eq!(t.0, 0x22);
        assert_eq!(e.on_request(now, Pkw::new(2, 1, 0, 0x22), &mut t), None);
        // With the reset rule (Omega) a new value alone is no new job.
        let mut e = PkwEngine::new(&DESCRIBE, Duration::ZERO);
        e.on_request(now, Pkw::new(2, 1, 0, 0x33), &mut t).unwrap();
        assert_eq!(e.on_request(now, Pkw::new(2, 1, 0, 0x44), &mut t), None);
        assert_eq!(t.0, 0x33);
    }

    #[test]
    fn reset_rule_and_delay_and_delays() {
        let mut t = Table(0x1234);
        let mut e = PkwEngine::new(&DESCRIBE, Duration::from_millis(5));
        let t0 = Instant::ZERO;
        e.on_request(t0, Pkw::new(1, 1, 0, 0), &mut t).unwrap();
        assert_eq!(e.response(t0), Pkw::ZERO, "not yet");
        assert_eq!(e.poll_timeout(), Some(t0 + Duration::from_millis(5)));
        let t1 = t0 + Duration::from_millis(5);
        assert_eq!(e.response(t1), Pkw::new(1, 1, 0, 0x1234));
        let j = e.on_request(t1, Pkw::new(2, 1, 0, 7), &mut t).unwrap();
        assert_eq!(j.response, Pkw::new(7, 1, 0, 0x0101));
        assert_eq!(t.0, 0x1234, "not executed");
        e.on_request(t1, Pkw::ZERO, &mut t);
        assert_eq!(e.response(t1 + Duration::from_millis(9)), Pkw::ZERO);
    }
}
