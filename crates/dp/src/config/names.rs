//! Names people type: the closest valid ones to a misspelt name, for the
//! "did you mean …?" of every error about an unknown name (GSD modules
//! and parameters, bus-file keys, device profiles and their options,
//! terminal names), and the field names of a serde struct (the keys a
//! table may have).
//!
//! Names are matched exactly or not at all; these functions only find
//! what to suggest.

use serde::de::{self, Deserialize, Visitor};
use std::fmt;

/// The most names a suggestion lists.
const MAX_SUGGESTIONS: usize = 3;

/// Lower case, `-` read as `_`, runs of blanks folded to one space.
fn normalize(s: &str) -> String {
    s.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .to_lowercase()
        .replace('-', "_")
}

/// Edit distance between two strings in characters, counting a swap of
/// two neighbours as one edit (optimal string alignment).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let w = b.len() + 1;
    let mut d = vec![0usize; (a.len() + 1) * w];
    for i in 0..=a.len() {
        d[i * w] = i;
    }
    for (j, v) in d.iter_mut().enumerate().take(w) {
        *v = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut v = (d[(i - 1) * w + j] + 1)
                .min(d[i * w + j - 1] + 1)
                .min(d[(i - 1) * w + j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                v = v.min(d[(i - 2) * w + j - 2] + 1);
            }
            d[i * w + j] = v;
        }
    }
    d[a.len() * w + b.len()]
}

/// The valid names closest to `name`, best first, at most three: those
/// equal to it but for case, blanks and `-`/`_`; else those within a few
/// typing errors (about one per four characters) at the smallest
/// distance; else those that contain it (for a name of three characters
/// or more). Empty when none is close.
pub fn closest<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> Vec<&'a str> {
    let want = normalize(name);
    let want_len = want.chars().count();
    let limit = (want_len + 2) / 4;
    let mut scored: Vec<(usize, &'a str)> = vec![];
    let mut containing = vec![];
    for c in candidates {
        if scored.iter().any(|(_, s)| *s == c) || containing.contains(&c) {
            continue;
        }
        let n = normalize(c);
        // The distance is at least the difference in length: skip the
        // quadratic edit distance when that alone is beyond the limit
        // (a long misspelling against short names costs nothing then).
        let close = (want_len.abs_diff(n.chars().count()) <= limit)
            .then(|| edit_distance(&want, &n))
            .filter(|&d| d <= limit);
        if let Some(d) = close {
            scored.push((d, c));
        } else if want_len >= 3 && n.contains(&want) {
            containing.push(c);
        }
    }
    let best = scored.iter().map(|(d, _)| *d).min();
    let mut out: Vec<&str> = match best {
        Some(best) => scored
            .into_iter()
            .filter(|(d, _)| *d == best)
            .map(|(_, c)| c)
            .collect(),
        None => containing,
    };
    out.truncate(MAX_SUGGESTIONS);
    out
}

/// The closest names to a misspelt one ([`closest`]), as the end of an
/// error message: `; did you mean `a`?`, `; did you mean `a` or `b`?`,
/// nothing when none is close.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DidYouMean(pub Vec<String>);

impl DidYouMean {
    /// The names closest to `name` among `candidates`.
    pub fn new<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> DidYouMean {
        DidYouMean(
            closest(name, candidates)
                .into_iter()
                .map(String::from)
                .collect(),
        )
    }

    /// No name is close.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The closest name, if any.
    pub fn first(&self) -> Option<&str> {
        self.0.first().map(String::as_str)
    }
}

impl fmt::Display for DidYouMean {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Some((last, rest)) = self.0.split_last() else {
            return Ok(());
        };
        f.write_str("; did you mean ")?;
        for (i, n) in rest.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "`{n}`")?;
        }
        if !rest.is_empty() {
            f.write_str(" or ")?;
        }
        write!(f, "`{last}`?")
    }
}

/// The field names of a struct deriving `Deserialize` (the keys a table
/// of it may have), as serde sees them (after `rename`); empty for a
/// type that is not a struct.
pub fn field_names<'de, T: Deserialize<'de>>() -> &'static [&'static str] {
    struct_shape::<T>().map_or(&[], |(_, fields)| fields)
}

/// The name and field names a type deriving `Deserialize` asks a
/// deserializer for (`deserialize_struct`), if it is a struct.
pub fn struct_shape<'de, T: Deserialize<'de>>() -> Option<(&'static str, &'static [&'static str])> {
    let mut shape = None;
    let _ = T::deserialize(FieldNames(&mut shape));
    shape
}

/// A deserializer that only records the field list a struct asks for.
struct FieldNames<'a>(&'a mut Option<(&'static str, &'static [&'static str])>);

#[derive(Debug)]
struct Stop;

impl fmt::Display for Stop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("field names recorded")
    }
}

impl std::error::Error for Stop {}

impl de::Error for Stop {
    fn custom<T: fmt::Display>(_: T) -> Stop {
        Stop
    }
}

impl<'de> de::Deserializer<'de> for FieldNames<'_> {
    type Error = Stop;

    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Stop> {
        Err(Stop)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        fields: &'static [&'static str],
        _: V,
    ) -> Result<V::Value, Stop> {
        *self.0 = Some((name, fields));
        Err(Stop)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
        bytes byte_buf option unit unit_struct newtype_struct seq tuple
        tuple_struct map enum identifier ignored_any
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edit_distances() {
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("abc", "abc"), 0);
        assert_eq!(edit_distance("bytse", "bytes"), 1);
    }

    #[test]
    fn closest_names() {
        let modules = [
            "1 word in/out",
            "2 words in/out",
            "4 words in/out",
            "8 bytes in",
        ];
        assert_eq!(
            closest("3 words in/out", modules),
            ["2 words in/out", "4 words in/out"]
        );
        assert_eq!(closest("2 WORDS  in/out", modules), ["2 words in/out"]);
        assert_eq!(closest("8 bytes", modules), ["8 bytes in"]);
        assert!(closest("temperature", modules).is_empty());
        assert_eq!(closest("adress", ["address", "baud"]), ["address"]);
        assert_eq!(closest("omgea", ["generic", "bm4", "omega"]), ["omega"]);
        assert_eq!(closest("us-devise", ["us_device", "switch"]), ["us_device"]);
        assert!(closest("foo", ["address", "baud", "hsa"]).is_empty());
    }

    #[test]
    fn did_you_mean_ends_a_message() {
        let d = |n: &str| DidYouMean::new(n, ["address", "addresses", "baud"]).to_string();
        assert_eq!(d("adress"), "; did you mean `address`?");
        assert_eq!(d("nothing like it"), "");
        let d = DidYouMean(vec!["a".into(), "b".into(), "c".into()]);
        assert_eq!(d.to_string(), "; did you mean `a`, `b` or `c`?");
    }

    #[test]
    fn field_names_of_a_struct() {
        #[derive(serde::Deserialize)]
        #[allow(dead_code)]
        struct S {
            address: u8,
            #[serde(rename = "baud_rate")]
            baud: u32,
        }
        assert_eq!(field_names::<S>(), ["address", "baud_rate"]);
        assert!(field_names::<u8>().is_empty());
    }
}
