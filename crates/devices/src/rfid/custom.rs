//! A reader's own command set, loaded by the user: the PROFIBUS manual
//! gives only `VER` (L97); the other commands of [`super::commands`] are
//! modelled. A user whose reader speaks other commands describes them in
//! a TOML file (profile option `commands = "FILE.toml"`):
//!
//! ```toml
//! builtin = false            # drop the modelled GT, RD, WD, TOR (default: keep)
//! unknown = "NAK #00\r"      # the answer to any other command (default NAK #00)
//!
//! [[command]]
//! command = "SN"             # the command word, case-insensitive
//! answer = "A9-0042\r"       # the answer (TOML escapes: \r is CR)
//! delay_ms = 40              # the reader's time to answer (default 0)
//!
//! [[command]]
//! command = "BEEP"
//! answer_hex = "4F4B0D"      # or the answer as hex bytes
//! ```
//!
//! An entry matches a command line whose first word is its `command`
//! (parameters after a space are ignored); entries are looked at before
//! the built-in commands, so an entry may also replace one of them.
//! `VER` keeps the manual's answer unless an entry names it.

use super::tags::parse_hex;
use serde::Deserialize;
use std::time::Duration;

/// One command of a user's command set.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CustomCommand {
    /// The command word, upper case.
    pub command: String,
    /// The answer bytes.
    pub answer: Vec<u8>,
    /// The time the reader takes to answer.
    pub delay: Duration,
}

/// A user's command set; see the module docs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CommandSet {
    /// Keep the modelled commands (GT, RD, WD, TOR).
    pub builtin: bool,
    /// The answer to a command that no entry (and, with `builtin`, no
    /// modelled command) names; `None`: `NAK #00`.
    pub unknown: Option<Vec<u8>>,
    /// The entries.
    pub commands: Vec<CustomCommand>,
}

/// Why a command set file is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandSetError {
    /// Not TOML of the expected shape.
    #[error("{0}")]
    Toml(String),
    /// An entry with both or neither of `answer` and `answer_hex`, or bad hex.
    #[error("command `{command}`: {message}")]
    Entry {
        /// The command word.
        command: String,
        /// What is wrong.
        message: String,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSet {
    #[serde(default = "yes")]
    builtin: bool,
    unknown: Option<String>,
    #[serde(default)]
    command: Vec<RawCommand>,
}

fn yes() -> bool {
    true
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCommand {
    command: String,
    answer: Option<String>,
    answer_hex: Option<String>,
    #[serde(default)]
    delay_ms: u64,
}

impl CommandSet {
    /// Parse a command set file's text.
    pub fn parse(text: &str) -> Result<CommandSet, CommandSetError> {
        let raw: RawSet = toml::from_str(text).map_err(|e| CommandSetError::Toml(e.to_string()))?;
        let mut commands = vec![];
        for c in raw.command {
            let entry = |message: &str| CommandSetError::Entry {
                command: c.command.clone(),
                message: message.into(),
            };
            let word = c.command.trim().to_uppercase();
            if word.is_empty() || word.contains(char::is_whitespace) {
                return Err(entry("the command is one word"));
            }
            let answer = match (&c.answer, &c.answer_hex) {
                (Some(a), None) => a.as_bytes().to_vec(),
                (None, Some(h)) => {
                    parse_hex(h).ok_or_else(|| entry("answer_hex is not hex bytes"))?
                }
                _ => return Err(entry("give one of answer and answer_hex")),
            };
            commands.push(CustomCommand {
                command: word,
                answer,
                delay: Duration::from_millis(c.delay_ms),
            });
        }
        Ok(CommandSet {
            builtin: raw.builtin,
            unknown: raw.unknown.map(String::into_bytes),
            commands,
        })
    }

    /// The entry for a command line, if one names its first word.
    pub fn find(&self, line: &[u8]) -> Option<&CustomCommand> {
        let text = String::from_utf8_lossy(line);
        let word = text.split_whitespace().next()?.to_uppercase();
        self.commands.iter().find(|c| c.command == word)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_command_set_file() {
        let s = CommandSet::parse(
            "builtin = false\nunknown = \"?\\r\"\n[[command]]\ncommand = \"sn\"\nanswer = \"A9-0042\\r\"\ndelay_ms = 40\n[[command]]\ncommand = \"BEEP\"\nanswer_hex = \"4F4B0D\"\n",
        )
        .unwrap();
        assert!(!s.builtin);
        assert_eq!(s.unknown.as_deref(), Some(&b"?\r"[..]));
        let c = s.find(b"SN 1").unwrap();
        assert_eq!(
            (c.answer.as_slice(), c.delay),
            (&b"A9-0042\r"[..], Duration::from_millis(40))
        );
        assert_eq!(s.find(b"beep").unwrap().answer, b"OK\r");
        assert!(s.find(b"GT").is_none());
        for (bad, says) in [
            ("[[command]]\ncommand = \"X\"\n", "one of answer"),
            (
                "[[command]]\ncommand = \"A B\"\nanswer = \"x\"\n",
                "one word",
            ),
            (
                "[[command]]\ncommand = \"X\"\nanswer_hex = \"zz\"\n",
                "not hex",
            ),
            ("nope = 1\n", "unknown field"),
        ] {
            let e = CommandSet::parse(bad).unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
