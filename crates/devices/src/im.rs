//! I&M records of an emulated device: I&M0 (the identity, read-only)
//! from the profile, I&M1..I&M4 written by masters and kept across
//! restarts in the device's state file ([`crate::STATE_EVENT`]).
//!
//! The slave core answers the I&M call on slot 0, index 255
//! ([`profibus_dp::slave::Device::im_read`] / `im_write`); a device keeps
//! an [`ImStore`] and forwards those two hooks to it.
//!
//! The state file is TOML, one hex string of 64 bytes per record written:
//!
//! ```toml
//! # I&M records written by masters
//! im1 = "20 20 20 20 20 20 20 20 20 20 50 55 4D 50 …"
//! ```

use crate::profile::ProfileError;
use profibus_dp::config::gsd::Gsd;
use profibus_dp::pdu::dpv1::{AccessError, Dpv1Error, ErrorClass, FN_WRITE};
use profibus_dp::pdu::im::{padded, Im0, ImRecord, SoftwareRevision, HEADER_LEN, RECORD_LEN};
use profibus_fdl::wire::{parse_hex, Hex};
use std::path::Path;

/// Name of the I&M state file in a profile's state directory.
pub const IM_STATE_FILE: &str = "im.toml";

/// I&M0 and I&M1..I&M4 of a device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImStore {
    im0: [u8; RECORD_LEN],
    records: [ImRecord; 4],
}

/// What a device's I&M0 says beyond its defaults (profile options).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ImIdentity {
    /// MANUFACTURER_ID (PI manufacturer table); default 0.
    pub manufacturer_id: Option<u16>,
    /// ORDER_ID (at most 20 characters).
    pub order_id: Option<String>,
    /// SERIAL_NUMBER (at most 16 characters).
    pub serial_number: Option<String>,
}

/// HARDWARE_REVISION from a GSD `Hardware_Release` text: its first
/// number ("1.0" → 1, "HW 3" → 3); 0 without one.
fn hardware_revision(text: &str) -> u16 {
    let digits: String = text
        .chars()
        .skip_while(|c| !c.is_ascii_digit())
        .take_while(|c| c.is_ascii_digit())
        .collect();
    digits.parse().unwrap_or(0)
}

/// `s` as printable ASCII of at most `N` bytes (others become `?`, the
/// rest is cut), blank-padded.
fn lossy<const N: usize>(s: &str) -> [u8; N] {
    let mut out = [b' '; N];
    for (o, b) in out.iter_mut().zip(s.bytes()) {
        *o = if (0x20..0x7F).contains(&b) { b } else { b'?' };
    }
    out
}

impl ImIdentity {
    /// I&M0 of a device a GSD file describes: ORDER_ID from
    /// `OrderNumber`, HARDWARE_REVISION from `Hardware_Release` (its
    /// first number), SOFTWARE_REVISION from `Software_Release` ("V1.2.3",
    /// "1.03"; V0.0.0 when it is not of that form), the 10-byte
    /// manufacturer-specific header from `Vendor_Name` (the MANUFACTURER_ID
    /// needs the PI table, which we do not ship: 0 unless given), profile
    /// 0xF600 (generic device), IM_SUPPORTED I&M1..I&M4. The options
    /// override order, serial number and manufacturer; too long or not
    /// ASCII is an error naming the field.
    pub fn im0_from_gsd(&self, gsd: &Gsd) -> Result<Im0, ProfileError> {
        let bad = |e: profibus_dp::pdu::im::ImError| ProfileError::Invalid(e.to_string());
        let mut im0 = Im0::default();
        if let Some(v) = &gsd.vendor_name {
            im0.header = lossy::<HEADER_LEN>(v);
        }
        if let Some(o) = &gsd.order_number {
            im0.order_id = lossy::<20>(o);
        }
        if let Some(h) = &gsd.hardware_release {
            im0.hardware_revision = hardware_revision(h);
        }
        if let Some(s) = gsd
            .software_release
            .as_deref()
            .and_then(SoftwareRevision::parse)
        {
            im0.software_revision = s;
        }
        if let Some(m) = self.manufacturer_id {
            im0.manufacturer_id = m;
        }
        if let Some(o) = &self.order_id {
            im0.order_id = padded::<20>("order_id", o).map_err(bad)?;
        }
        if let Some(s) = &self.serial_number {
            im0.serial_number = padded::<16>("serial_number", s).map_err(bad)?;
        }
        Ok(im0)
    }
}

impl ImStore {
    /// A device with `im0` and empty I&M1..I&M4 (blanks, I&M4 zeros).
    pub fn new(im0: &Im0) -> ImStore {
        ImStore {
            im0: im0.bytes(),
            records: [1, 2, 3, 4].map(ImRecord::empty),
        }
    }

    /// The store with the records kept in `text` (the state file).
    pub fn with_state(mut self, text: &str) -> Result<ImStore, String> {
        let table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| e.message().to_string())?;
        for (key, value) in &table {
            let n = match key.as_str() {
                "im1" => 1,
                "im2" => 2,
                "im3" => 3,
                "im4" => 4,
                _ => return Err(format!("unknown key `{key}` (im1, im2, im3, im4)")),
            };
            let hex = value
                .as_str()
                .ok_or_else(|| format!("`{key}` must be a hex string"))?;
            let bytes = parse_hex(hex).map_err(|e| format!("`{key}`: {e}"))?;
            let record = ImRecord::parse(n, &bytes).map_err(|e| format!("`{key}`: {e}"))?;
            self.records[n as usize - 1] = record;
        }
        Ok(self)
    }

    /// The store with the records kept in the state file `path`, if it
    /// exists.
    pub fn load(self, path: &Path) -> Result<ImStore, ProfileError> {
        if !path.exists() {
            return Ok(self);
        }
        crate::profile::read_table(path, |text| self.with_state(text))
    }

    /// I&M`number`: its 64 bytes into `out`, false for numbers above 4.
    pub fn read(&self, number: u8, out: &mut [u8; RECORD_LEN]) -> bool {
        match number {
            0 => *out = self.im0,
            1..=4 => *out = self.records[number as usize - 1].bytes,
            _ => return false,
        }
        true
    }

    /// Write I&M`number` (1..=4); I&M0 is "access denied".
    pub fn write(&mut self, number: u8, record: &[u8; RECORD_LEN]) -> Result<(), Dpv1Error> {
        match number {
            1..=4 => {
                self.records[number as usize - 1].bytes = *record;
                Ok(())
            }
            _ => Err(Dpv1Error::dpv1(
                FN_WRITE,
                ErrorClass::Access.code(),
                AccessError::AccessDenied.code(),
            )),
        }
    }

    /// I&M`number` (1..=4).
    pub fn record(&self, number: u8) -> Option<&ImRecord> {
        self.records.get((number as usize).checked_sub(1)?)
    }

    /// The state file's text: the records that differ from their empty
    /// content.
    pub fn state_text(&self) -> String {
        let mut s = String::from("# I&M records written by masters (64 bytes each)\n");
        for r in &self.records {
            if *r != ImRecord::empty(r.number) {
                s.push_str(&format!("im{} = \"{}\"\n", r.number, Hex(&r.bytes)));
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hardware_revision_is_the_first_number() {
        assert_eq!(hardware_revision("1.0"), 1);
        assert_eq!(hardware_revision("HW 3"), 3);
        assert_eq!(hardware_revision("A"), 0);
    }

    #[test]
    fn state_text_round_trips_and_bad_files_are_named() {
        let mut store = ImStore::new(&Im0::default());
        let im1 = ImRecord::im1("PUMP 3", "HALL B").unwrap();
        store.write(1, &im1.bytes).unwrap();
        assert!(store.write(0, &[0; 64]).is_err(), "I&M0 is read-only");
        let text = store.state_text();
        assert!(text.contains("im1 = \""), "{text}");
        assert!(!text.contains("im2"), "empty records are not kept: {text}");
        let back = ImStore::new(&Im0::default()).with_state(&text).unwrap();
        assert_eq!(back, store);
        let e = ImStore::new(&Im0::default())
            .with_state("im5 = \"00\"")
            .unwrap_err();
        assert!(e.contains("unknown key `im5`"), "{e}");
        let e = ImStore::new(&Im0::default())
            .with_state("im1 = \"00 01\"")
            .unwrap_err();
        assert!(e.contains("needs 64"), "{e}");
    }
}
