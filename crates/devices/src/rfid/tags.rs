//! The simulated antenna field: tags (transponders) with a UID and a
//! memory of 32-bit blocks, which enter and leave the field, and the
//! reader's timing. Kept in a TOML file (`dpctl slave --device rfid --tags
//! FILE.toml`), which the reader rewrites when a tag's memory changes or a
//! tag enters or leaves:
//!
//! ```toml
//! [reader]
//! tor = 10        # TOR: how long a tag command looks for a tag, in 100 ms
//! uid_ms = 10     # air time of reading a UID (GT)
//! block_ms = 20   # air time per block of RD and WD
//!
//! [[tag]]
//! uid = "E004015012345678"   # hex, 1..=10 bytes
//! in_field = true            # in the antenna field now (at most one tag)
//! blocks = 16                # memory size in 4-byte blocks (default 16)
//! data = ["00112233", "44556677"]   # the first blocks; the rest are 0
//! ```

use serde::{Deserialize, Serialize};
use std::time::Duration;

/// Bytes per memory block (the readers' 32-bit blocks).
pub const BLOCK_LEN: usize = 4;

/// Blocks of a tag when the file does not say.
pub const DEFAULT_BLOCKS: usize = 16;

/// Most blocks a tag may have (block numbers are one hex byte).
pub const MAX_BLOCKS: usize = 256;

/// Longest UID in bytes.
pub const MAX_UID_LEN: usize = 10;

/// The most tags a tags file may list (a reader's field holds one tag
/// at a time; the file is a test fixture, not a database).
pub const MAX_TAGS: usize = 1024;

/// What is wrong with a tags file or a tag description.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TagsError {
    /// The TOML does not parse or has wrong types.
    #[error("{0}")]
    Toml(String),
    /// A UID is not 1..=10 bytes of hex.
    #[error("tag UID `{0}` is not 1 to 10 bytes of hex")]
    BadUid(String),
    /// Two tags have the same UID.
    #[error("tag UID {0} is listed twice")]
    DuplicateUid(String),
    /// A block count outside 1..=256.
    #[error("tag {uid}: {blocks} blocks, expected 1..=256")]
    BadBlockCount {
        /// The tag.
        uid: String,
        /// The count given.
        blocks: usize,
    },
    /// A data block that is not 8 hex digits, or more data than blocks.
    #[error("tag {uid}: data block {index} `{text}` is not 8 hex digits or beyond the memory")]
    BadData {
        /// The tag.
        uid: String,
        /// Index in `data`.
        index: usize,
        /// The text.
        text: String,
    },
    /// More tags than [`MAX_TAGS`].
    #[error("{0} tags; a tags file may list at most {MAX_TAGS}")]
    TooMany(usize),
    /// More than one tag marked `in_field`.
    #[error("tags {0} and {1} are both in the field; the reader sees one tag at a time")]
    TwoInField(String, String),
}

/// Timing of the reader's air interface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReaderTiming {
    /// TOR: how long a tag command keeps looking for a tag, in units of
    /// 100 ms (0: one attempt).
    pub tor: u8,
    /// Air time of reading a UID, ms.
    pub uid_ms: u64,
    /// Air time per block read or written, ms.
    pub block_ms: u64,
}

impl Default for ReaderTiming {
    fn default() -> ReaderTiming {
        ReaderTiming {
            tor: 10,
            uid_ms: 10,
            block_ms: 20,
        }
    }
}

impl ReaderTiming {
    /// TOR as a duration.
    pub fn tor_duration(&self) -> Duration {
        Duration::from_millis(100 * self.tor as u64)
    }
}

/// A tag: its UID and memory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tag {
    /// The UID, most significant byte first (as `GT` prints it).
    pub uid: Vec<u8>,
    /// The memory, block by block.
    pub blocks: Vec<[u8; BLOCK_LEN]>,
}

impl Tag {
    /// A tag with `blocks` zeroed blocks.
    pub fn blank(uid: Vec<u8>, blocks: usize) -> Tag {
        Tag {
            uid,
            blocks: vec![[0; BLOCK_LEN]; blocks],
        }
    }

    /// The UID in hex (upper case).
    pub fn uid_hex(&self) -> String {
        hex(&self.uid)
    }
}

/// Upper-case hex of `bytes`, no separators.
pub fn hex(bytes: &[u8]) -> String {
    format!("{:#}", profibus_fdl::wire::Hex(bytes))
}

/// Bytes from hex digits (an even number of them, no separators).
pub fn parse_hex(text: &str) -> Option<Vec<u8>> {
    let t = text.as_bytes();
    if !t.len().is_multiple_of(2) {
        return None;
    }
    t.chunks(2)
        .map(|p| {
            let s = std::str::from_utf8(p).ok()?;
            u8::from_str_radix(s, 16).ok()
        })
        .collect()
}

/// A UID from text: hex, 1..=10 bytes.
pub fn parse_uid(text: &str) -> Result<Vec<u8>, TagsError> {
    match parse_hex(text.trim()) {
        Some(u) if !u.is_empty() && u.len() <= MAX_UID_LEN => Ok(u),
        _ => Err(TagsError::BadUid(text.to_string())),
    }
}

/// The antenna field: the known tags, which one is in the field, and the
/// reader's timing.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct TagField {
    /// Every tag the simulation knows.
    pub tags: Vec<Tag>,
    /// Index in `tags` of the tag in the field.
    in_field: Option<usize>,
    /// Timing of the air interface.
    pub timing: ReaderTiming,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default)]
    reader: ReaderTiming,
    #[serde(default, rename = "tag")]
    tags: Vec<RawTag>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTag {
    uid: String,
    #[serde(default)]
    in_field: bool,
    #[serde(default = "default_blocks")]
    blocks: usize,
    #[serde(default)]
    data: Vec<String>,
}

fn default_blocks() -> usize {
    DEFAULT_BLOCKS
}

impl TagField {
    /// An empty field with the default timing.
    pub fn new() -> TagField {
        TagField::default()
    }

    /// Parse a tags file.
    pub fn parse(text: &str) -> Result<TagField, TagsError> {
        let raw: RawFile = toml::from_str(text).map_err(|e| TagsError::Toml(e.to_string()))?;
        let mut field = TagField {
            tags: vec![],
            in_field: None,
            timing: raw.reader,
        };
        if raw.tags.len() > MAX_TAGS {
            return Err(TagsError::TooMany(raw.tags.len()));
        }
        for t in raw.tags {
            let uid = parse_uid(&t.uid)?;
            let name = hex(&uid);
            if field.find(&uid).is_some() {
                return Err(TagsError::DuplicateUid(name));
            }
            if !(1..=MAX_BLOCKS).contains(&t.blocks) {
                return Err(TagsError::BadBlockCount {
                    uid: name,
                    blocks: t.blocks,
                });
            }
            let mut tag = Tag::blank(uid, t.blocks);
            for (index, text) in t.data.iter().enumerate() {
                match (parse_hex(text.trim()), tag.blocks.get_mut(index)) {
                    (Some(b), Some(block)) if b.len() == BLOCK_LEN => block.copy_from_slice(&b),
                    _ => {
                        return Err(TagsError::BadData {
                            uid: name,
                            index,
                            text: text.clone(),
                        })
                    }
                }
            }
            if t.in_field {
                if let Some(i) = field.in_field {
                    return Err(TagsError::TwoInField(field.tags[i].uid_hex(), name));
                }
                field.in_field = Some(field.tags.len());
            }
            field.tags.push(tag);
        }
        Ok(field)
    }

    /// The file text of this field (what [`TagField::parse`] reads back).
    pub fn to_toml(&self) -> String {
        let raw = RawFile {
            reader: self.timing,
            tags: self
                .tags
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    // Trailing zero blocks are left out.
                    let used = t
                        .blocks
                        .iter()
                        .rposition(|b| *b != [0; BLOCK_LEN])
                        .map_or(0, |p| p + 1);
                    RawTag {
                        uid: t.uid_hex(),
                        in_field: self.in_field == Some(i),
                        blocks: t.blocks.len(),
                        data: t.blocks[..used].iter().map(|b| hex(b)).collect(),
                    }
                })
                .collect(),
        };
        toml::to_string(&raw).unwrap_or_default()
    }

    /// Index of the tag with `uid`.
    pub fn find(&self, uid: &[u8]) -> Option<usize> {
        self.tags.iter().position(|t| t.uid == uid)
    }

    /// The tag in the field.
    pub fn in_field(&self) -> Option<&Tag> {
        self.in_field.map(|i| &self.tags[i])
    }

    /// The tag in the field, to change its memory.
    pub fn in_field_mut(&mut self) -> Option<&mut Tag> {
        self.in_field.map(|i| &mut self.tags[i])
    }

    /// The tag `uid` enters the field (a blank tag of
    /// [`DEFAULT_BLOCKS`] blocks if it is not known yet); a tag that was
    /// in the field leaves it. Returns the UID of the tag that left.
    pub fn enter(&mut self, uid: &[u8]) -> Option<Vec<u8>> {
        let i = match self.find(uid) {
            Some(i) => i,
            None => {
                self.tags.push(Tag::blank(uid.to_vec(), DEFAULT_BLOCKS));
                self.tags.len() - 1
            }
        };
        let left = self.in_field.filter(|&j| j != i);
        self.in_field = Some(i);
        left.map(|j| self.tags[j].uid.clone())
    }

    /// The tag in the field leaves it; returns its UID.
    pub fn leave(&mut self) -> Option<Vec<u8>> {
        self.in_field.take().map(|i| self.tags[i].uid.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = r#"
[reader]
tor = 3
uid_ms = 5
block_ms = 7

[[tag]]
uid = "e004015012345678"
in_field = true
blocks = 8
data = ["00112233", "DEADBEEF"]

[[tag]]
uid = "0A0B0C0D"
"#;

    #[test]
    fn parse_and_write_back() {
        let f = TagField::parse(FILE).unwrap();
        assert_eq!(
            f.timing,
            ReaderTiming {
                tor: 3,
                uid_ms: 5,
                block_ms: 7
            }
        );
        let t = f.in_field().unwrap();
        assert_eq!(t.uid_hex(), "E004015012345678");
        assert_eq!(t.blocks.len(), 8);
        assert_eq!(t.blocks[1], [0xDE, 0xAD, 0xBE, 0xEF]);
        assert_eq!(t.blocks[2], [0; 4]);
        assert_eq!(f.tags[1].blocks.len(), DEFAULT_BLOCKS);
        let again = TagField::parse(&f.to_toml()).unwrap();
        assert_eq!(again, f);
    }

    #[test]
    fn enter_and_leave() {
        let mut f = TagField::parse(FILE).unwrap();
        let other = parse_uid("0A0B0C0D").unwrap();
        assert_eq!(f.enter(&other), Some(f.tags[0].uid.clone()));
        assert_eq!(f.in_field().unwrap().uid, other);
        assert_eq!(f.leave(), Some(other));
        assert_eq!(f.leave(), None);
        // An unknown tag is created blank.
        f.enter(&[1, 2, 3, 4]);
        assert_eq!(f.tags.len(), 3);
        assert_eq!(f.in_field().unwrap().blocks, vec![[0; 4]; DEFAULT_BLOCKS]);
    }

    #[test]
    fn bad_files() {
        let err = |t: &str| TagField::parse(t).unwrap_err();
        assert!(matches!(
            err("[[tag]]\nuid = \"XYZ\""),
            TagsError::BadUid(_)
        ));
        assert!(matches!(
            err("[[tag]]\nuid = \"01\"\n[[tag]]\nuid = \"01\""),
            TagsError::DuplicateUid(_)
        ));
        assert!(matches!(
            err("[[tag]]\nuid = \"01\"\nblocks = 0"),
            TagsError::BadBlockCount { .. }
        ));
        assert!(matches!(
            err("[[tag]]\nuid = \"01\"\nblocks = 1\ndata = [\"00\"]"),
            TagsError::BadData { .. }
        ));
        assert!(matches!(
            err("[[tag]]\nuid = \"01\"\nblocks = 1\ndata = [\"00000000\", \"00000000\"]"),
            TagsError::BadData { index: 1, .. }
        ));
        assert!(matches!(
            err("[[tag]]\nuid = \"01\"\nin_field = true\n[[tag]]\nuid = \"02\"\nin_field = true"),
            TagsError::TwoInField(..)
        ));
        assert!(matches!(err("[reader]\nspeed = 1"), TagsError::Toml(_)));
    }
}
