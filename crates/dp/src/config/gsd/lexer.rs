//! Splitting GSD text into logical lines and scanning tokens in them.
//!
//! A physical line loses its comment (`;` outside a quoted string) and
//! trailing blanks; a line that then ends in `\` continues on the next
//! physical line. [`LogicalLine`] keeps enough to map a byte offset in
//! the joined text back to the line and column of the file. [`Cursor`]
//! scans the tokens the GSD grammar uses: words, numbers in decimal or
//! `0x` hex (optionally signed), quoted strings, punctuation.

use super::{Pos, MAX_LINE_LEN};
use std::borrow::Cow;
use std::fmt::Display;

/// The physical lines of a text, with their 1-based numbers; a line
/// longer than [`MAX_LINE_LEN`] yields `Err(line number)` after scanning at
/// most `MAX_LINE_LEN + 1` bytes of it, and ends the iteration.
pub(crate) struct PhysicalLines<'a> {
    text: &'a str,
    pos: usize,
    line: u32,
    done: bool,
}

impl<'a> PhysicalLines<'a> {
    pub(crate) fn new(text: &'a str) -> Self {
        PhysicalLines {
            text,
            pos: 0,
            line: 0,
            done: false,
        }
    }
}

impl<'a> Iterator for PhysicalLines<'a> {
    type Item = Result<(u32, &'a str), u32>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done || self.pos >= self.text.len() {
            return None;
        }
        self.line += 1;
        let rest = &self.text.as_bytes()[self.pos..];
        let window = &rest[..rest.len().min(MAX_LINE_LEN + 1)];
        // A line ends at LF, CR LF, or a lone CR (old Mac files).
        let (len, next) = match window.iter().position(|&b| b == b'\n' || b == b'\r') {
            Some(n) if window[n] == b'\r' && rest.get(n + 1) == Some(&b'\n') => {
                (n, self.pos + n + 2)
            }
            Some(n) => (n, self.pos + n + 1),
            None if rest.len() <= MAX_LINE_LEN => (rest.len(), self.text.len()),
            None => {
                self.done = true;
                return Some(Err(self.line));
            }
        };
        let line = &self.text[self.pos..self.pos + len];
        self.pos = next;
        Some(Ok((self.line, line)))
    }
}

/// `line` without its comment: everything from the first `;` that is not
/// inside a `"…"` string, or inside a `'…'` string that starts a value
/// (right after `=`, as in the Omega board's `Modules='…'`; an apostrophe
/// elsewhere is an ordinary character).
pub(crate) fn strip_comment(line: &str) -> &str {
    strip_comment_from(line, None).0
}

/// [`strip_comment`] for a physical line that starts inside a string
/// opened by the quote `open` (a string continued with `\` from the line
/// before), also returning the quote of a string still open at the end of
/// the line. A `"` on a continuation line thus closes the string the
/// first piece opened, and a `;` after it starts a comment.
pub(crate) fn strip_comment_from(line: &str, open: Option<u8>) -> (&str, Option<u8>) {
    let mut quote = open;
    let mut prev: u8 = 0;
    for (i, &b) in line.as_bytes().iter().enumerate() {
        match quote {
            Some(q) if b == q => quote = None,
            Some(_) => {}
            None => match b {
                b';' => return (&line[..i], None),
                b'"' => quote = Some(b),
                b'\'' if prev == b'=' => quote = Some(b),
                _ => {}
            },
        }
        if b != b' ' && b != b'\t' {
            prev = b;
        }
    }
    (line, quote)
}

/// Where a piece of a logical line came from.
#[derive(Debug, Clone, Copy)]
struct Segment {
    /// Byte offset in the logical text.
    offset: usize,
    /// Physical line.
    line: u32,
    /// Column of the byte at `offset`.
    col: u32,
}

/// One statement line: comments removed, continuations joined, blanks
/// trimmed at both ends.
#[derive(Debug, Clone)]
pub(crate) struct LogicalLine<'a> {
    /// The text.
    pub text: Cow<'a, str>,
    first: Segment,
    more: Vec<Segment>,
}

impl<'a> LogicalLine<'a> {
    /// Start a logical line from a physical line's content (comment
    /// already stripped, trailing blanks removed).
    pub(crate) fn new(line: u32, content: &'a str) -> Self {
        let trimmed = content.trim_start();
        let lead = content[..content.len() - trimmed.len()].chars().count() as u32;
        LogicalLine {
            text: Cow::Borrowed(trimmed),
            first: Segment {
                offset: 0,
                line,
                col: 1 + lead,
            },
            more: Vec::new(),
        }
    }

    /// Append the content of a continuation line.
    pub(crate) fn push(&mut self, line: u32, content: &str) {
        let text = self.text.to_mut();
        self.more.push(Segment {
            offset: text.len(),
            line,
            col: 1,
        });
        text.push_str(content);
    }

    /// Finish the line after its last continuation: remove blanks at
    /// both ends (a continuation may leave leading blanks when the first
    /// piece was empty) and stray trailing `\\` (a statement cannot end in
    /// a backslash), keeping positions right.
    pub(crate) fn trim(&mut self) {
        // Most lines have nothing to trim (the first piece is trimmed when
        // the line starts, and the last piece's trailing blanks are gone).
        let (first, last) = (self.text.chars().next(), self.text.chars().next_back());
        if !first.is_some_and(char::is_whitespace)
            && !last.is_some_and(|c| c.is_whitespace() || c == '\\')
        {
            return;
        }
        let end = self
            .text
            .trim_end_matches(|c: char| c.is_whitespace() || c == '\\')
            .len();
        let lead = self.text[..end].len() - self.text[..end].trim_start().len();
        if lead > 0 {
            // The segment holding the first kept byte becomes the first.
            let mut segs = vec![self.first];
            segs.append(&mut self.more);
            let k = segs.iter().rposition(|g| g.offset <= lead).unwrap_or(0);
            let skipped = self.text[segs[k].offset..lead].chars().count() as u32;
            self.first = Segment {
                offset: 0,
                line: segs[k].line,
                col: segs[k].col + skipped,
            };
            self.more = segs[k + 1..]
                .iter()
                .map(|g| Segment {
                    offset: g.offset - lead,
                    ..*g
                })
                .collect();
        }
        match &mut self.text {
            Cow::Borrowed(s) => *s = &s[lead..end],
            Cow::Owned(s) => {
                s.truncate(end);
                s.drain(..lead);
            }
        }
    }

    /// The first physical line.
    pub(crate) fn line(&self) -> u32 {
        self.first.line
    }

    /// Line and column of the byte at `offset` of the text.
    pub(crate) fn pos(&self, offset: usize) -> Pos {
        let offset = offset.min(self.text.len());
        let seg = self
            .more
            .iter()
            .rev()
            .find(|s| s.offset <= offset)
            .unwrap_or(&self.first);
        let start = seg.offset.min(offset);
        let chars = self
            .text
            .get(start..offset)
            .map_or(0, |s| s.chars().count()) as u32;
        Pos {
            line: seg.line,
            col: seg.col + chars,
        }
    }
}

/// A scanning error: byte offset in the logical text and message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ScanError {
    pub at: usize,
    pub msg: String,
}

pub(crate) type Scan<T> = Result<T, ScanError>;

/// A quoted string and the quote character used.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Quoted<'t> {
    pub text: &'t str,
    pub quote: char,
    pub at: usize,
}

/// A scanner over one logical line.
#[derive(Debug, Clone)]
pub(crate) struct Cursor<'t> {
    s: &'t str,
    i: usize,
}

impl<'t> Cursor<'t> {
    pub(crate) fn new(s: &'t str) -> Self {
        Cursor { s, i: 0 }
    }

    /// Current byte offset.
    pub(crate) fn at(&self) -> usize {
        self.i
    }

    /// Consume and return the rest of the line (blanks skipped).
    pub(crate) fn take_rest(&mut self) -> &'t str {
        self.ws();
        let rest = &self.s[self.i..];
        self.i = self.s.len();
        rest
    }

    /// Skip blanks.
    pub(crate) fn ws(&mut self) {
        let b = self.s.as_bytes();
        while self.i < b.len() && (b[self.i] == b' ' || b[self.i] == b'\t') {
            self.i += 1;
        }
    }

    /// Whether only blanks remain.
    pub(crate) fn at_end(&mut self) -> bool {
        self.ws();
        self.i >= self.s.len()
    }

    /// The next character after blanks, not consumed.
    pub(crate) fn peek(&mut self) -> Option<char> {
        self.ws();
        self.s[self.i..].chars().next()
    }

    /// Consume `c` (after blanks) if it is next.
    pub(crate) fn eat(&mut self, c: char) -> bool {
        if self.peek() == Some(c) {
            self.i += c.len_utf8();
            true
        } else {
            false
        }
    }

    /// Consume `c` or fail saying what was expected.
    pub(crate) fn expect(&mut self, c: char, what: impl Display) -> Scan<()> {
        if self.eat(c) {
            Ok(())
        } else {
            Err(self.error(format!("expected {what}, found {}", self.found())))
        }
    }

    /// Fail unless only blanks remain.
    pub(crate) fn end(&mut self, after: impl Display) -> Scan<()> {
        if self.at_end() {
            Ok(())
        } else {
            Err(self.error(format!("unexpected {} after {after}", self.found())))
        }
    }

    /// Offset of the next non-blank byte.
    fn next_at(&self) -> usize {
        let b = self.s.as_bytes();
        let mut i = self.i;
        while i < b.len() && (b[i] == b' ' || b[i] == b'\t') {
            i += 1;
        }
        i
    }

    /// Describe the next token for a message.
    pub(crate) fn found(&self) -> String {
        let rest = &self.s[self.next_at()..];
        match rest.chars().next() {
            None => "end of line".into(),
            Some(_) => {
                let end = rest
                    .char_indices()
                    .find(|&(i, c)| i > 0 && (c == ' ' || c == '\t' || c == ','))
                    .map_or(rest.len(), |(i, _)| i);
                let tok: String = rest[..end].chars().take(24).collect();
                format!("`{tok}`")
            }
        }
    }

    /// An error at the next token.
    pub(crate) fn error(&self, msg: String) -> ScanError {
        ScanError {
            at: self.next_at(),
            msg,
        }
    }

    /// A keyword-like word: letters, digits, `_`, `.` (so `9.6_supp`
    /// and `MaxTsdr_1.5M` are words).
    pub(crate) fn word(&mut self) -> Option<&'t str> {
        self.ws();
        let b = self.s.as_bytes();
        let start = self.i;
        while self.i < b.len()
            && (b[self.i].is_ascii_alphanumeric() || matches!(b[self.i], b'_' | b'.'))
        {
            self.i += 1;
        }
        (self.i > start).then(|| &self.s[start..self.i])
    }

    /// An integer: optional sign, then decimal digits or `0x` and hex
    /// digits.
    pub(crate) fn int(&mut self, what: impl Display) -> Scan<i64> {
        self.ws();
        let start = self.i;
        let b = self.s.as_bytes();
        let mut i = self.i;
        let neg = match b.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let (radix, digits_at) =
            if b.get(i) == Some(&b'0') && matches!(b.get(i + 1), Some(b'x' | b'X')) {
                (16, i + 2)
            } else {
                (10, i)
            };
        // The value as the digits go by; `None` once it overflows.
        let mut value = Some(0i64);
        let mut j = digits_at;
        while let Some(d) = b.get(j).and_then(|&d| (d as char).to_digit(radix)) {
            value = value
                .and_then(|v| v.checked_mul(i64::from(radix)))
                .and_then(|v| v.checked_add(i64::from(d)));
            j += 1;
        }
        if j == digits_at {
            return Err(self.error(format!("expected {what}, found {}", self.found())));
        }
        // A number glued to letters (`12abc`, `0x1G`) is not a number.
        if j < b.len() && (b[j].is_ascii_alphanumeric() || b[j] == b'_' || b[j] == b'.') {
            let mut c = self.clone();
            c.i = start;
            return Err(c.error(format!("expected {what}, found {}", c.found())));
        }
        let v = value.ok_or_else(|| ScanError {
            at: start,
            msg: format!("number `{}` is too large", &self.s[start..j]),
        })?;
        self.i = j;
        Ok(if neg { -v } else { v })
    }

    /// An integer in `lo..=hi`.
    pub(crate) fn int_in(&mut self, what: impl Display, lo: i64, hi: i64) -> Scan<i64> {
        self.ws();
        let at = self.i;
        let v = self.int(&what)?;
        if v < lo || v > hi {
            return Err(ScanError {
                at,
                msg: format!("{what} {v} is outside {lo}..={hi}"),
            });
        }
        Ok(v)
    }

    /// A string in double quotes, or (when `single` is allowed) in single
    /// quotes.
    pub(crate) fn string(&mut self, what: impl Display, single: bool) -> Scan<Quoted<'t>> {
        self.ws();
        let at = self.i;
        let q = match self.s[self.i..].chars().next() {
            Some('"') => '"',
            Some('\'') if single => '\'',
            _ => {
                return Err(self.error(format!(
                    "expected {what} in double quotes, found {}",
                    self.found()
                )));
            }
        };
        let body = &self.s[self.i + 1..];
        match body.find(q) {
            Some(n) => {
                self.i += 1 + n + 1;
                Ok(Quoted {
                    text: &body[..n],
                    quote: q,
                    at,
                })
            }
            None => Err(ScanError {
                at,
                msg: format!("{what}: the string is not closed with {q}"),
            }),
        }
    }

    /// A comma-separated list of bytes (0..=255), at least one.
    pub(crate) fn bytes(&mut self, what: impl Display) -> Scan<Vec<u8>> {
        let mut v = Vec::new();
        loop {
            v.push(self.int_in(&what, 0, 255)? as u8);
            if !self.eat(',') {
                return Ok(v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comments_respect_quotes() {
        assert_eq!(strip_comment("A=1 ; c"), "A=1 ");
        assert_eq!(strip_comment("A=\"x;y\" ;c"), "A=\"x;y\" ");
        assert_eq!(strip_comment("M='a;b' 0x10;"), "M='a;b' 0x10");
        assert_eq!(strip_comment(";#Profibus_DP"), "");
        assert_eq!(strip_comment("M = 'a;b' 0x10"), "M = 'a;b' 0x10");
        assert_eq!(strip_comment("F=1@it's;c"), "F=1@it's");
    }

    #[test]
    fn comments_after_a_continued_string() {
        assert_eq!(
            strip_comment_from("A=\"x;\\", None),
            ("A=\"x;\\", Some(b'"'))
        );
        assert_eq!(strip_comment_from("y\" ;c \"", Some(b'"')), ("y\" ", None));
        assert_eq!(strip_comment_from("y;z", Some(b'"')), ("y;z", Some(b'"')));
        assert_eq!(strip_comment_from("y ;z", None), ("y ", None));
    }

    #[test]
    fn physical_lines_and_limits() {
        let v: Vec<_> = PhysicalLines::new("a\r\nb\n\nc").collect();
        assert_eq!(
            v,
            vec![Ok((1, "a")), Ok((2, "b")), Ok((3, "")), Ok((4, "c"))]
        );
        let long = "x".repeat(MAX_LINE_LEN + 10);
        let text = format!("a\n{long}\nb");
        let v: Vec<_> = PhysicalLines::new(&text).collect();
        assert_eq!(v, vec![Ok((1, "a")), Err(2)]);
    }

    #[test]
    fn positions_across_continuations() {
        let mut l = LogicalLine::new(3, "  Module=\"a\" 0x10,");
        l.push(4, "   0x20");
        l.trim();
        assert_eq!(l.text, "Module=\"a\" 0x10,   0x20");
        assert_eq!(l.pos(0), Pos { line: 3, col: 3 });
        let at = l.text.find("0x20").unwrap();
        assert_eq!(l.pos(at), Pos { line: 4, col: 4 });
        // An empty first piece: the text starts on the continuation line.
        let mut l = LogicalLine::new(7, "");
        l.push(8, "   Foo=1 \\");
        l.trim();
        assert_eq!(l.text, "Foo=1");
        assert_eq!(l.pos(0), Pos { line: 8, col: 4 });
        assert_eq!(l.pos(4), Pos { line: 8, col: 8 });
    }

    #[test]
    fn numbers() {
        let mut c = Cursor::new("0x1F, 42 -7 0X10 12ab");
        assert_eq!(c.int("n"), Ok(31));
        assert!(c.eat(','));
        assert_eq!(c.int("n"), Ok(42));
        assert_eq!(c.int("n"), Ok(-7));
        assert_eq!(c.int("n"), Ok(16));
        assert!(c.int("n").is_err());
        let mut c = Cursor::new("-100--1");
        assert_eq!(c.int("n"), Ok(-100));
        assert!(c.eat('-'));
        assert_eq!(c.int("n"), Ok(-1));
        assert!(Cursor::new("99999999999999999999").int("n").is_err());
        assert!(Cursor::new("0x").int("n").is_err());
    }

    #[test]
    fn strings() {
        let mut c = Cursor::new(" \"a b\" 'c'");
        assert_eq!(c.string("name", false).unwrap().text, "a b");
        assert!(c.clone().string("name", false).is_err());
        let q = c.string("name", true).unwrap();
        assert_eq!((q.text, q.quote), ("c", '\''));
        assert!(Cursor::new("\"open").string("name", false).is_err());
    }
}
