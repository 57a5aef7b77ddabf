//! The reader's command set and its execution against the simulated
//! antenna field ([`Reader`]).
//!
//! The PROFIBUS manual describes only the transport; the reader-specific
//! commands are "described elsewhere" (L25) and the only one it shows is
//! `VER`. The commands here follow the form of the AEG ID instruction
//! set of the manufacturer's serial readers: a command word, parameters
//! after a space, CR at the end; block numbers in hex, 32-bit blocks; a
//! failed read answered with the no-read code `XXXXXXXX`, wrong input with
//! `NAK #nn`. The answers' wording beyond `VER` is modelled, not taken
//! from a manual.
//!
//! | command | answer | time |
//! |---|---|---|
//! | `VER` | `AEG ID - PFB V1.26␍AEG ID - A9 /PFB V1.28␍` (the manual's example, 42 bytes) | at once |
//! | `GT` (get tag) | the UID of the tag in the field in hex, `␍` | TOR search + `uid_ms` |
//! | `RD b` / `RD b e` | blocks b (to e) in hex, 8 digits per block, `␍` | TOR search + `block_ms` per block |
//! | `WD b DATA` | DATA (8 hex digits per block, one or more blocks from b) written; answered with DATA, `␍` | TOR search + `block_ms` per block |
//! | `TOR n` / `TOR` | sets / tells TOR (decimal, 100 ms units), answered with the value | at once |
//! | empty line | `␍` | at once |
//! | unknown command | `NAK #00␍` | at once |
//! | wrong or missing parameter, block beyond the tag's memory | `NAK #02␍` | |
//! | command line longer than 255 bytes | `NAK #05␍` | at once |
//! | no tag found within TOR | `XXXXXXXX␍` (no read) | |
//!
//! Commands are case-insensitive. A tag command looks for a tag for TOR
//! (TOR 0: one attempt). With a tag in the field it needs the air time,
//! during which the tag must stay; if it leaves, the command looks for a
//! tag again while TOR lasts, else answers no read. A transfer once begun
//! completes even when TOR has passed meanwhile. A write changes the
//! tag's memory only when its transfer completes.

use super::tags::{hex, parse_hex, TagField, BLOCK_LEN};
use profibus_fdl::Instant;
use std::collections::VecDeque;
use std::time::Duration;

/// The answer to `VER`: the manual's example (chapter 2.4), byte for byte.
pub const VERSION: &[u8] = b"AEG ID - PFB V1.26\rAEG ID - A9 /PFB V1.28\r";

/// The no-read code: no tag answered within TOR.
pub const NO_READ: &[u8] = b"XXXXXXXX\r";

/// An error answer `NAK #nn`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Nak {
    /// `NAK #00`: unknown command.
    UnknownCommand,
    /// `NAK #02`: wrong parameter.
    WrongParameter,
    /// `NAK #05`: buffer overflow (command line too long).
    BufferOverflow,
}

impl Nak {
    /// The number of the error.
    pub fn code(self) -> u8 {
        match self {
            Nak::UnknownCommand => 0,
            Nak::WrongParameter => 2,
            Nak::BufferOverflow => 5,
        }
    }

    /// The answer bytes, `NAK #nn` and CR.
    pub fn answer(self) -> Vec<u8> {
        format!("NAK #{:02}\r", self.code()).into_bytes()
    }

    /// The error of number `code`, if the reader has one of that number.
    pub fn from_code(code: u8) -> Option<Nak> {
        [
            Nak::UnknownCommand,
            Nak::WrongParameter,
            Nak::BufferOverflow,
        ]
        .into_iter()
        .find(|n| n.code() == code)
    }

    /// What the error means, in words. The PROFIBUS manual leaves the
    /// reader's commands and their answers to the reader's own
    /// documentation (L25); the numbers and meanings are the ones of this
    /// module's table (see the module docs).
    pub fn meaning(self) -> &'static str {
        match self {
            Nak::UnknownCommand => "unknown command",
            Nak::WrongParameter => {
                "wrong or missing parameter (or a block beyond the tag's memory)"
            }
            Nak::BufferOverflow => "command line too long (more than 255 bytes)",
        }
    }
}

/// The error number of an answer `NAK #nn` (with or without its CR),
/// `None` for any other answer.
pub fn nak_code(answer: &[u8]) -> Option<u8> {
    let text = std::str::from_utf8(answer).ok()?;
    let digits = text.trim_end_matches('\r').strip_prefix("NAK #")?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

/// A `NAK #nn` answer in words, e.g. `NAK #02: wrong or missing
/// parameter (…)`; a number the reader is not known to give is said to
/// be so.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NakText(pub u8);

impl std::fmt::Display for NakText {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.0;
        match Nak::from_code(n) {
            Some(nak) => write!(f, "NAK #{n:02}: {}", nak.meaning()),
            None => write!(
                f,
                "NAK #{n:02}: error {n}, not one this reader is known to give"
            ),
        }
    }
}

/// A parsed command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// An empty line.
    Blank,
    /// `VER`.
    Version,
    /// `GT`: the UID of the tag in the field.
    GetTag,
    /// `RD first [last]`.
    Read {
        /// First block.
        first: u8,
        /// Last block (inclusive).
        last: u8,
    },
    /// `WD first DATA`.
    Write {
        /// First block.
        first: u8,
        /// The bytes, a whole number of blocks.
        data: Vec<u8>,
    },
    /// `TOR [n]`.
    Tor(Option<u8>),
}

impl Command {
    /// Whether the command needs a tag (and takes air time).
    pub fn needs_tag(&self) -> bool {
        matches!(
            self,
            Command::GetTag | Command::Read { .. } | Command::Write { .. }
        )
    }
}

fn block(text: &str) -> Result<u8, Nak> {
    if text.is_empty() || text.len() > 2 {
        return Err(Nak::WrongParameter);
    }
    u8::from_str_radix(text, 16).map_err(|_| Nak::WrongParameter)
}

/// Parse a command line (the bytes before the CR).
pub fn parse(line: &[u8]) -> Result<Command, Nak> {
    let text = std::str::from_utf8(line).map_err(|_| Nak::UnknownCommand)?;
    let mut words = text.split(' ').filter(|w| !w.is_empty());
    let Some(word) = words.next() else {
        return Ok(Command::Blank);
    };
    let args: Vec<&str> = words.collect();
    let cmd = match (word.to_ascii_uppercase().as_str(), args.as_slice()) {
        ("VER", []) => Command::Version,
        ("GT", []) => Command::GetTag,
        ("RD", [b]) => {
            let b = block(b)?;
            Command::Read { first: b, last: b }
        }
        ("RD", [b, e]) => {
            let (first, last) = (block(b)?, block(e)?);
            if last < first {
                return Err(Nak::WrongParameter);
            }
            Command::Read { first, last }
        }
        ("WD", [b, d]) => {
            let data = parse_hex(d).ok_or(Nak::WrongParameter)?;
            if data.is_empty() || !data.len().is_multiple_of(BLOCK_LEN) {
                return Err(Nak::WrongParameter);
            }
            Command::Write {
                first: block(b)?,
                data,
            }
        }
        ("TOR", []) => Command::Tor(None),
        ("TOR", [n]) => Command::Tor(Some(n.parse().map_err(|_| Nak::WrongParameter)?)),
        ("VER" | "GT" | "RD" | "WD" | "TOR", _) => return Err(Nak::WrongParameter),
        _ => return Err(Nak::UnknownCommand),
    };
    Ok(cmd)
}

/// A tag command being executed.
#[derive(Debug, Clone)]
struct Operation {
    cmd: Command,
    /// Until when a tag is looked for.
    deadline: Instant,
    /// The air transfer with a tag: its UID and when it completes.
    transfer: Option<(Vec<u8>, Instant)>,
}

/// The reader: executes commands against its [`TagField`], one at a time.
#[derive(Debug, Clone)]
pub struct Reader {
    field: TagField,
    op: Option<Operation>,
    events: VecDeque<String>,
    changed: bool,
    custom: Option<super::custom::CommandSet>,
    /// A user command's answer and when it is due.
    custom_answer: Option<(Instant, Vec<u8>)>,
}

impl Reader {
    /// A reader with this antenna field.
    pub fn new(field: TagField) -> Reader {
        Reader {
            field,
            op: None,
            events: VecDeque::new(),
            changed: false,
            custom: None,
            custom_answer: None,
        }
    }

    /// Answer the commands of a user's command set
    /// ([`super::custom`]).
    pub fn set_commands(&mut self, set: super::custom::CommandSet) {
        self.custom = Some(set);
    }

    /// The antenna field.
    pub fn field(&self) -> &TagField {
        &self.field
    }

    /// A command is executing.
    pub fn busy(&self) -> bool {
        self.op.is_some() || self.custom_answer.is_some()
    }

    /// Whether the field changed (a write, a tag entering or leaving)
    /// since the last call: time to save the tags file.
    pub fn take_changed(&mut self) -> bool {
        std::mem::take(&mut self.changed)
    }

    /// Something for people that happened.
    pub fn take_event(&mut self) -> Option<String> {
        self.events.pop_front()
    }

    /// Drop the running command (a new start-up of the interface).
    pub fn abort(&mut self) {
        self.op = None;
        self.custom_answer = None;
    }

    /// Start a command line (must not be [`Reader::busy`]). Returns the
    /// answer at once, or `None` when the command runs; then
    /// [`Reader::step`] returns it later.
    pub fn start(&mut self, now: Instant, line: &[u8]) -> Option<Vec<u8>> {
        let text = String::from_utf8_lossy(line);
        if let Some(set) = &self.custom {
            if let Some(c) = set.find(line) {
                self.events
                    .push_back(format!("command `{text}` (user command set)"));
                if c.delay.is_zero() {
                    return Some(c.answer.clone());
                }
                self.custom_answer = Some((now + c.delay, c.answer.clone()));
                return None;
            }
            let known = match parse(line) {
                Ok(Command::Version | Command::Blank) => true,
                Err(Nak::UnknownCommand) => false,
                Ok(_) | Err(_) => set.builtin,
            };
            if !known {
                self.events
                    .push_back(format!("command `{text}`: not in the user command set"));
                return Some(
                    set.unknown
                        .clone()
                        .unwrap_or_else(|| Nak::UnknownCommand.answer()),
                );
            }
        }
        let cmd = match parse(line) {
            Ok(c) => c,
            Err(nak) => {
                self.events
                    .push_back(format!("command `{text}`: NAK #{:02}", nak.code()));
                return Some(nak.answer());
            }
        };
        let answer = match &cmd {
            Command::Blank => b"\r".to_vec(),
            Command::Version => VERSION.to_vec(),
            Command::Tor(Some(n)) => {
                self.field.timing.tor = *n;
                self.changed = true;
                format!("{n}\r").into_bytes()
            }
            Command::Tor(None) => format!("{}\r", self.field.timing.tor).into_bytes(),
            Command::GetTag | Command::Read { .. } | Command::Write { .. } => {
                self.events.push_back(format!("command `{text}` started"));
                self.op = Some(Operation {
                    cmd,
                    deadline: now + self.field.timing.tor_duration(),
                    transfer: None,
                });
                return self.step(now);
            }
        };
        self.events.push_back(format!("command `{text}` answered"));
        Some(answer)
    }

    /// The air time of a command with the current timing.
    fn air_time(&self, cmd: &Command) -> Duration {
        let t = self.field.timing;
        let blocks = match cmd {
            Command::Read { first, last } => (*last - *first) as u64 + 1,
            Command::Write { data, .. } => (data.len() / BLOCK_LEN) as u64,
            _ => return Duration::from_millis(t.uid_ms),
        };
        Duration::from_millis(t.block_ms * blocks)
    }

    /// Advance the running command to `now`; returns its answer when it
    /// is done.
    pub fn step(&mut self, now: Instant) -> Option<Vec<u8>> {
        if let Some((at, _)) = &self.custom_answer {
            if now >= *at {
                return self.custom_answer.take().map(|(_, a)| a);
            }
            return None;
        }
        loop {
            let op = self.op.as_ref()?;
            let present = self.field.in_field().map(|t| t.uid.clone());
            match &op.transfer {
                Some((uid, until)) => {
                    if present.as_ref() != Some(uid) {
                        let uid = hex(uid);
                        self.events
                            .push_back(format!("tag {uid} left the field during the transfer"));
                        if let Some(op) = self.op.as_mut() {
                            op.transfer = None;
                        }
                        continue;
                    }
                    if now < *until {
                        return None;
                    }
                    let op = self.op.take()?;
                    return Some(self.complete(op.cmd));
                }
                None => {
                    if let Some(uid) = present {
                        if let Some(nak) = self.check_range(&op.cmd) {
                            self.op = None;
                            self.events
                                .push_back("block beyond the tag's memory: NAK #02".into());
                            return Some(nak.answer());
                        }
                        let until = now + self.air_time(&op.cmd);
                        self.events.push_back(format!(
                            "transfer with tag {} until {:.3} s",
                            hex(&uid),
                            until.as_nanos() as f64 / 1e9
                        ));
                        if let Some(op) = self.op.as_mut() {
                            op.transfer = Some((uid, until));
                        }
                        continue;
                    }
                    if now >= op.deadline {
                        self.op = None;
                        self.events.push_back("no tag within TOR: no read".into());
                        return Some(NO_READ.to_vec());
                    }
                    return None;
                }
            }
        }
    }

    fn check_range(&self, cmd: &Command) -> Option<Nak> {
        let n = self.field.in_field()?.blocks.len();
        let end = match cmd {
            Command::Read { last, .. } => *last as usize + 1,
            Command::Write { first, data } => *first as usize + data.len() / BLOCK_LEN,
            _ => 0,
        };
        (end > n).then_some(Nak::WrongParameter)
    }

    fn complete(&mut self, cmd: Command) -> Vec<u8> {
        let Some(tag) = self.field.in_field_mut() else {
            return NO_READ.to_vec();
        };
        let mut answer = match cmd {
            Command::Read { first, last } => {
                let mut s = String::new();
                for b in &tag.blocks[first as usize..=last as usize] {
                    s.push_str(&hex(b));
                }
                s
            }
            Command::Write { first, data } => {
                for (i, chunk) in data.chunks(BLOCK_LEN).enumerate() {
                    tag.blocks[first as usize + i].copy_from_slice(chunk);
                }
                self.changed = true;
                hex(&data)
            }
            _ => tag.uid_hex(),
        };
        let uid = tag.uid_hex();
        self.events.push_back(format!(
            "transfer with tag {uid} done ({} bytes)",
            answer.len()
        ));
        answer.push('\r');
        answer.into_bytes()
    }

    /// When [`Reader::step`] next has something to do.
    pub fn next_wake(&self) -> Option<Instant> {
        if let Some((at, _)) = &self.custom_answer {
            return Some(*at);
        }
        let op = self.op.as_ref()?;
        Some(match &op.transfer {
            Some((_, until)) => *until,
            None => op.deadline,
        })
    }

    /// Tag `uid` enters the field (a tag in it leaves).
    pub fn enter(&mut self, uid: &[u8]) {
        if self.field.in_field().is_some_and(|t| t.uid == uid) {
            return;
        }
        if let Some(old) = self.field.enter(uid) {
            self.events
                .push_back(format!("tag {} left the field", hex(&old)));
        }
        self.events
            .push_back(format!("tag {} entered the field", hex(uid)));
        self.changed = true;
    }

    /// The tag in the field leaves it; returns its UID.
    pub fn leave(&mut self) -> Option<Vec<u8>> {
        let uid = self.field.leave()?;
        self.events
            .push_back(format!("tag {} left the field", hex(&uid)));
        self.changed = true;
        Some(uid)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rfid::tags::ReaderTiming;

    fn ms(n: u64) -> Instant {
        Instant::ZERO + Duration::from_millis(n)
    }

    fn reader() -> Reader {
        let mut f = TagField::parse(
            "[[tag]]\nuid = \"E004015012345678\"\nblocks = 4\ndata = [\"00112233\", \"44556677\"]",
        )
        .unwrap();
        f.timing = ReaderTiming {
            tor: 5,
            uid_ms: 10,
            block_ms: 20,
        };
        Reader::new(f)
    }

    #[test]
    fn parsing() {
        assert_eq!(parse(b"VER"), Ok(Command::Version));
        assert_eq!(parse(b"ver"), Ok(Command::Version));
        assert_eq!(parse(b""), Ok(Command::Blank));
        assert_eq!(
            parse(b"RD 1F"),
            Ok(Command::Read {
                first: 31,
                last: 31
            })
        );
        assert_eq!(parse(b"RD 0 3"), Ok(Command::Read { first: 0, last: 3 }));
        assert_eq!(parse(b"RD 3 0"), Err(Nak::WrongParameter));
        assert_eq!(parse(b"RD"), Err(Nak::WrongParameter));
        assert_eq!(parse(b"RD 100"), Err(Nak::WrongParameter));
        assert_eq!(
            parse(b"WD 2 0011223344556677"),
            Ok(Command::Write {
                first: 2,
                data: vec![0, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77]
            })
        );
        assert_eq!(parse(b"WD 2 001122"), Err(Nak::WrongParameter));
        assert_eq!(parse(b"TOR 50"), Ok(Command::Tor(Some(50))));
        assert_eq!(parse(b"TOR 256"), Err(Nak::WrongParameter));
        assert_eq!(parse(b"XYZ"), Err(Nak::UnknownCommand));
        assert_eq!(parse(&[0xFF, 0xFE]), Err(Nak::UnknownCommand));
        assert_eq!(Nak::UnknownCommand.answer(), b"NAK #00\r");
        // Every error answer is known again, and told in words.
        for nak in [
            Nak::UnknownCommand,
            Nak::WrongParameter,
            Nak::BufferOverflow,
        ] {
            assert_eq!(nak_code(&nak.answer()), Some(nak.code()));
            assert_eq!(Nak::from_code(nak.code()), Some(nak));
        }
        assert_eq!(nak_code(b"NAK #02"), Some(2));
        assert_eq!(nak_code(b"NAK #\r"), None);
        assert_eq!(nak_code(b"E004015012345678\r"), None);
        assert_eq!(
            NakText(2).to_string(),
            "NAK #02: wrong or missing parameter (or a block beyond the tag's memory)"
        );
        assert_eq!(
            NakText(7).to_string(),
            "NAK #07: error 7, not one this reader is known to give"
        );
    }

    #[test]
    fn immediate_commands() {
        let mut r = reader();
        assert_eq!(r.start(ms(0), b"VER").unwrap(), VERSION);
        assert_eq!(VERSION.len(), 42);
        assert_eq!(r.start(ms(0), b"TOR 7").unwrap(), b"7\r");
        assert_eq!(r.start(ms(0), b"TOR").unwrap(), b"7\r");
        assert_eq!(r.start(ms(0), b"FOO").unwrap(), b"NAK #00\r");
        assert_eq!(r.start(ms(0), b"").unwrap(), b"\r");
        assert!(!r.busy());
    }

    #[test]
    fn a_read_takes_its_air_time() {
        let mut r = reader();
        r.enter(&r.field().tags[0].uid.clone());
        assert_eq!(r.start(ms(0), b"RD 0 1"), None);
        assert!(r.busy());
        assert_eq!(r.next_wake(), Some(ms(40)));
        assert_eq!(r.step(ms(39)), None);
        assert_eq!(r.step(ms(40)).unwrap(), b"0011223344556677\r");
        assert_eq!(r.start(ms(50), b"GT"), None);
        assert_eq!(r.step(ms(60)).unwrap(), b"E004015012345678\r");
        assert_eq!(r.start(ms(60), b"RD 0 4"), Some(b"NAK #02\r".to_vec()));
    }

    #[test]
    fn a_write_lands_when_its_transfer_completes() {
        let mut r = reader();
        r.enter(&r.field().tags[0].uid.clone());
        r.take_changed();
        assert_eq!(r.start(ms(0), b"WD 2 AABBCCDDEEFF0011"), None);
        assert_eq!(r.step(ms(20)), None);
        assert_eq!(r.field().tags[0].blocks[2], [0; 4], "not yet");
        assert_eq!(r.step(ms(40)).unwrap(), b"AABBCCDDEEFF0011\r");
        assert_eq!(r.field().tags[0].blocks[3], [0xEE, 0xFF, 0x00, 0x11]);
        assert!(r.take_changed());
        assert_eq!(
            r.start(ms(50), b"WD 3 0000000000000000"),
            Some(b"NAK #02\r".to_vec())
        );
    }

    #[test]
    fn no_tag_within_tor_is_a_no_read() {
        let mut r = reader();
        assert_eq!(r.start(ms(0), b"GT"), None);
        assert_eq!(r.next_wake(), Some(ms(500)));
        assert_eq!(r.step(ms(499)), None);
        assert_eq!(r.step(ms(500)).unwrap(), NO_READ);
        // TOR 0: one attempt.
        r.start(ms(600), b"TOR 0");
        assert_eq!(r.start(ms(600), b"RD 0").unwrap(), NO_READ);
    }

    #[test]
    fn a_tag_arriving_and_leaving_while_a_read_runs() {
        let mut r = reader();
        let uid = r.field().tags[0].uid.clone();
        assert_eq!(r.start(ms(0), b"RD 0 3"), None);
        assert_eq!(r.step(ms(100)), None);
        // The tag arrives: the transfer (80 ms) begins at the next step.
        r.enter(&uid);
        assert_eq!(r.step(ms(110)), None);
        assert_eq!(r.next_wake(), Some(ms(190)));
        // It leaves halfway: the reader looks again while TOR lasts.
        r.leave();
        assert_eq!(r.step(ms(150)), None);
        assert_eq!(r.next_wake(), Some(ms(500)));
        r.enter(&uid);
        assert_eq!(r.step(ms(300)), None);
        assert_eq!(
            r.step(ms(380)).unwrap(),
            b"00112233445566770000000000000000\r"
        );
        // It leaves for good: no read once TOR (500 ms) has passed.
        assert_eq!(r.start(ms(400), b"RD 0 3"), None);
        assert_eq!(r.step(ms(450)), None);
        r.leave();
        assert_eq!(r.step(ms(451)), None);
        assert_eq!(r.step(ms(900)).unwrap(), NO_READ);
        // TOR 0: a transfer once begun completes.
        r.start(ms(900), b"TOR 0");
        r.enter(&uid);
        assert_eq!(r.start(ms(1000), b"GT"), None);
        assert_eq!(r.step(ms(1010)).unwrap(), b"E004015012345678\r");
    }
}
