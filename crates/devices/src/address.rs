//! A station address set by Set_Slave_Add, as the shell keeps it across
//! restarts: a small TOML file (`address = 21`, `no_add_chg = true`).
//!
//! The devices never touch the file while they run: the DP slave core
//! reports an accepted Set_Slave_Add as `SlaveEvent::AddressChanged`, and
//! the program running the slave (e.g. `dpctl slave`) saves it with
//! [`StoredAddress::save`]. Profiles read it once when they are configured
//! ([`StoredAddress::load`]).

use serde::{Deserialize, Deserializer, Serialize};
use std::path::{Path, PathBuf};

/// What an address file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StoredAddress {
    /// The address the master set (0..=125).
    pub address: u8,
    /// No_Add_Chg: no further changes through the bus.
    #[serde(default, deserialize_with = "flag")]
    pub no_add_chg: bool,
}

/// `true`/`false`, or `1`/`0` as files of earlier versions wrote it.
fn flag<'de, D: Deserializer<'de>>(d: D) -> Result<bool, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Flag {
        Bool(bool),
        Int(i64),
    }
    Ok(match Flag::deserialize(d)? {
        Flag::Bool(b) => b,
        Flag::Int(i) => i != 0,
    })
}

/// Why an address file cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum AddressFileError {
    /// Reading or writing failed.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause (in the message; not also `source()`, so that a
        /// printed error chain names it once).
        error: std::io::Error,
    },
    /// The file is not an address file.
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl StoredAddress {
    /// The address stored in `path`; `Ok(None)` when the file does not
    /// exist.
    pub fn load(path: &Path) -> Result<Option<StoredAddress>, AddressFileError> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(error) => {
                return Err(AddressFileError::Io {
                    path: path.into(),
                    error,
                })
            }
        };
        let invalid = |message: String| AddressFileError::Invalid {
            path: path.into(),
            message,
        };
        let s: StoredAddress =
            toml::from_str(&text).map_err(|e| invalid(e.message().to_string()))?;
        if s.address > 125 {
            return Err(invalid(format!("address {} is outside 0..=125", s.address)));
        }
        Ok(Some(s))
    }

    /// Write to `path` (a temporary file first, then renamed over it).
    pub fn save(&self, path: &Path) -> Result<(), AddressFileError> {
        let io = |error| AddressFileError::Io {
            path: path.into(),
            error,
        };
        let text = toml::to_string(self).expect("two plain fields serialise");
        let tmp = path.with_extension("tmp");
        std::fs::write(&tmp, text).map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_old_format() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().to_path_buf();
        let path = dir.join("addr.toml");
        assert!(StoredAddress::load(&path).unwrap().is_none());
        let s = StoredAddress {
            address: 21,
            no_add_chg: true,
        };
        s.save(&path).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "address = 21\nno_add_chg = true\n"
        );
        assert_eq!(StoredAddress::load(&path).unwrap(), Some(s));
        std::fs::write(&path, "address=9\nno_add_chg=0\n").unwrap();
        assert_eq!(
            StoredAddress::load(&path).unwrap(),
            Some(StoredAddress {
                address: 9,
                no_add_chg: false
            })
        );
        std::fs::write(&path, "address=300\n").unwrap();
        assert!(StoredAddress::load(&path).is_err());
        std::fs::write(&path, "address=126\n").unwrap();
        assert!(StoredAddress::load(&path).is_err());
    }
}
