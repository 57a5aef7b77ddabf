//! A field of a document (the `[mqtt]` table, a request payload) parsed
//! with serde derives but checked afterwards, so that each field keeps
//! its own message: [`Field`].

use serde::de::{Deserializer, IgnoredAny};
use serde::Deserialize;

/// A field as written: absent, a value of type `T`, or anything else
/// (`null` included).
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Field<T> {
    /// Not given.
    #[default]
    Absent,
    /// A value of type `T`.
    Valid(T),
    /// A value of another type or out of `T`'s range.
    Invalid,
}

impl<T> Field<T> {
    /// Whether the field was given.
    pub fn is_given(&self) -> bool {
        !matches!(self, Field::Absent)
    }

    /// `None` when absent, else the value or `Err(())` for a wrong one.
    pub fn given(self) -> Option<Result<T, ()>> {
        match self {
            Field::Absent => None,
            Field::Valid(v) => Some(Ok(v)),
            Field::Invalid => Some(Err(())),
        }
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Field<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Any<T> {
            Valid(T),
            Invalid(IgnoredAny),
        }
        Ok(match Any::deserialize(d)? {
            Any::Valid(v) => Field::Valid(v),
            Any::Invalid(_) => Field::Invalid,
        })
    }
}
