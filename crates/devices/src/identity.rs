//! A product's identity, overridden for any profile: `ident = 0x…` and a
//! vendor's GSD file (`gsd = "…"` next to `device` in a bus file,
//! `--device-opt gsd=FILE` and `--device-opt ident=0x…` for `dpctl slave`).
//!
//! Two of the emulated products have no ident number in their manuals
//! (the JX2-PROFI1, 0x0DC3, and the RFID reader, 0x0DC4, are the
//! project's own numbers); a master set up from the vendor's GSD file
//! sends the vendor's ident number and that file's modules and
//! parameters. With these options the profile takes them:
//!
//! - `ident`: the slave reports this ident number (Slave_Diag) and accepts
//!   only Set_Prm with it; the master side sends it. The device behind
//!   sees its own ident number, so its checks are unchanged.
//! - `gsd`: the vendor's GSD file. Its ident number is the slave's (unless
//!   `ident` is given too), the master side configures from it: each module
//!   of the profile's configuration is the vendor's module with the same
//!   identifier bytes, and the User_Prm_Data are the vendor file's defaults.
//!   The slave accepts User_Prm_Data up to the vendor file's
//!   `User_Prm_Data_Len` (or `Max_User_Prm_Data_Len`); bytes the device
//!   itself would refuse (another length or meaning than its own GSD's)
//!   are accepted, and the device is parameterised with its own defaults
//!   instead: the manuals say nothing about the vendors' parameter bytes.
//!
//! Profiles with an option of their own named `ident` or `gsd` (the
//! generic GSD device's `gsd`) keep it: there it is the device's GSD.

use crate::channels::ChannelMap;
use crate::profile::{Configured, ControlInbox, DeviceOptions, ProfileError};
use crate::BoxedDevice;
use profibus_dp::config::gsd::{Gsd, ParseOptions};
use profibus_dp::pdu::dpv1::Dpv1Error;
use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{
    ClearReason, Device, DeviceEvent, DiagWriter, Dpv1Outcome, Features, IoLayout, OwnAddress,
    Reason, SlaveState,
};
use profibus_fdl::Instant;
use std::path::PathBuf;

/// The option keys this module takes from every profile.
pub const KEYS: [&str; 2] = ["ident", "gsd"];

/// `ident` and `gsd` taken out of `options` (those the profile has no
/// field of its own for, `own`): the rest, the ident number, the GSD path.
pub(crate) fn take(
    options: &DeviceOptions,
    own: &[&str],
) -> Result<(DeviceOptions, Option<u16>, Option<PathBuf>), ProfileError> {
    let mut rest = toml::Table::new();
    let (mut ident, mut gsd) = (None, None);
    for (k, v) in options.table() {
        match k.as_str() {
            "ident" if !own.contains(&"ident") => ident = Some(parse_ident(v)?),
            "gsd" if !own.contains(&"gsd") => {
                let p = v.as_str().ok_or_else(|| ProfileError::BadOption {
                    key: "gsd".into(),
                    message: "give the GSD file's path as text".into(),
                })?;
                gsd = Some(PathBuf::from(p));
            }
            _ => {
                rest.insert(k.clone(), v.clone());
            }
        }
    }
    Ok((DeviceOptions::from_table(rest), ident, gsd))
}

fn parse_ident(v: &toml::Value) -> Result<u16, ProfileError> {
    let bad = |message: String| ProfileError::BadOption {
        key: "ident".into(),
        message,
    };
    let n = match v {
        toml::Value::Integer(i) => *i,
        toml::Value::String(s) => {
            let t = s.trim().replace('_', "");
            match t
                .strip_prefix("0x")
                .or_else(|| t.strip_prefix("0X"))
                .or_else(|| t.strip_prefix("16#"))
            {
                Some(h) => i64::from_str_radix(h, 16),
                None => t.parse(),
            }
            .map_err(|_| bad(format!("`{s}` is not a number")))?
        }
        other => return Err(bad(format!("{other} is not a number"))),
    };
    u16::try_from(n).map_err(|_| bad(format!("{n} is outside 0..=0xFFFF")))
}

/// A configured profile with another identity; see the module docs.
#[derive(Debug)]
pub struct Identified {
    inner: Box<dyn Configured>,
    gsd: Gsd,
    file: Vec<u8>,
    modules: Vec<String>,
    /// The device's own User_Prm_Data, for vendor bytes it refuses.
    own_prm: Option<Vec<u8>>,
    max_prm: Option<usize>,
    warnings: Vec<String>,
}

impl Identified {
    /// `inner` with the ident number `ident` and/or the vendor GSD file
    /// at `gsd`.
    pub fn new(
        inner: Box<dyn Configured>,
        ident: Option<u16>,
        gsd: Option<PathBuf>,
    ) -> Result<Identified, ProfileError> {
        let mut warnings = inner.warnings();
        let Some(path) = gsd else {
            let mut g = inner.gsd().clone();
            g.ident_number = ident.unwrap_or(g.ident_number);
            return Ok(Identified {
                file: g.write_latin1(),
                gsd: g,
                modules: inner.modules(),
                own_prm: None,
                max_prm: None,
                warnings,
                inner,
            });
        };
        let file_error = |error| ProfileError::File {
            path: path.clone(),
            error,
        };
        let size = std::fs::metadata(&path).map_err(file_error)?.len();
        if size > crate::profile::MAX_OPTION_FILE {
            return Err(ProfileError::Table {
                path,
                message: format!("{size} bytes: a GSD file has at most 1 MiB"),
            });
        }
        let bytes = std::fs::read(&path).map_err(file_error)?;
        let text: String = bytes.iter().map(|&b| b as char).collect();
        let parsed =
            Gsd::parse(&text, ParseOptions { lenient: true }).map_err(|e| ProfileError::Table {
                path: path.clone(),
                message: e.to_string(),
            })?;
        for w in &parsed.warnings {
            warnings.push(format!("{}:{w}", path.display()));
        }
        let mut vendor = parsed.gsd;
        vendor.ident_number = ident.unwrap_or(vendor.ident_number);
        // The profile's modules by identifier bytes in the vendor's file.
        let own = inner.gsd();
        let mut modules = vec![];
        for name in inner.modules() {
            let i = own.select(&[name.as_str()])?[0];
            let cfg = &own.modules[i].cfg;
            let m = vendor.modules.iter().find(|m| &m.cfg == cfg).ok_or_else(|| {
                ProfileError::Invalid(format!(
                    "{}: no module with the identifier bytes {} of the `{}` profile's module `{name}`",
                    path.display(),
                    cfg.iter()
                        .map(|b| format!("0x{b:02X}"))
                        .collect::<Vec<_>>()
                        .join(","),
                    inner.name(),
                ))
            })?;
            modules.push(m.name.clone());
        }
        let own_prm = inner.user_prm_data()?;
        let max_prm = vendor
            .max_user_prm_data_len
            .or(vendor.user_prm_data_len)
            .map(usize::from);
        Ok(Identified {
            inner,
            gsd: vendor,
            file: bytes,
            modules,
            own_prm: Some(own_prm),
            max_prm,
            warnings,
        })
    }
}

impl Configured for Identified {
    fn name(&self) -> &'static str {
        self.inner.name()
    }
    fn gsd(&self) -> &Gsd {
        &self.gsd
    }
    fn gsd_file(&self) -> Vec<u8> {
        self.file.clone()
    }
    fn modules(&self) -> Vec<String> {
        self.modules.clone()
    }
    fn address(&self) -> Option<u8> {
        self.inner.address()
    }
    fn address_file(&self) -> Option<PathBuf> {
        self.inner.address_file()
    }
    fn state_file(&self) -> Option<PathBuf> {
        self.inner.state_file()
    }
    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError> {
        let inner = self.inner.device(control)?;
        Ok(Box::new(IdentityDevice::new(
            inner,
            self.gsd.ident_number,
            self.own_prm.clone(),
            self.max_prm,
        )))
    }
    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError> {
        self.inner.channels(cfg)
    }
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }
}

/// A slave device reporting another ident number (and, with a vendor
/// GSD, taking the vendor's User_Prm_Data); see the module docs. Every
/// [`Device`] method is passed to the device behind: a method added to
/// the trait must be added here too (as in `impl Device for Box<D>`).
pub struct IdentityDevice {
    inner: BoxedDevice,
    ident: u16,
    own_prm: Option<Vec<u8>>,
    max_prm: Option<usize>,
}

impl std::fmt::Debug for IdentityDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("IdentityDevice")
            .field("ident", &self.ident)
            .field("own_ident", &self.inner.ident_number())
            .finish_non_exhaustive()
    }
}

impl IdentityDevice {
    /// `inner` reporting `ident`; with `own_prm`, Set_Prm User_Prm_Data
    /// that `inner` refuses (and at most `max_prm` bytes long) are passed
    /// as `own_prm` instead.
    pub fn new(
        inner: BoxedDevice,
        ident: u16,
        own_prm: Option<Vec<u8>>,
        max_prm: Option<usize>,
    ) -> IdentityDevice {
        IdentityDevice {
            inner,
            ident,
            own_prm,
            max_prm,
        }
    }
}

impl Device for IdentityDevice {
    fn ident_number(&self) -> u16 {
        self.ident
    }
    fn real_cfg(&self) -> &[u8] {
        self.inner.real_cfg()
    }
    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        let mut own = *prm;
        own.ident_number = self.inner.ident_number();
        let Some(defaults) = &self.own_prm else {
            return self.inner.check_prm(&own);
        };
        if let Some(max) = self.max_prm.filter(|m| prm.user_prm_data.len() > *m) {
            return Err(format!(
                "{} bytes of User_Prm_Data, the vendor GSD allows {max}",
                prm.user_prm_data.len()
            )
            .into());
        }
        if self.inner.check_prm(&own).is_ok() {
            return Ok(());
        }
        own.user_prm_data = defaults;
        self.inner.check_prm(&own)
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        self.inner.check_cfg(cfg)
    }
    fn write_outputs(&mut self, now: Instant, outputs: &[u8]) {
        self.inner.write_outputs(now, outputs)
    }
    fn read_inputs(&mut self, now: Instant, inputs: &mut [u8]) {
        self.inner.read_inputs(now, inputs)
    }
    fn features(&self) -> Features {
        self.inner.features()
    }
    fn clear_outputs(&mut self, now: Instant, why: ClearReason) {
        self.inner.clear_outputs(now, why)
    }
    fn diagnosis(&mut self, now: Instant, diag: &mut DiagWriter<'_>) {
        self.inner.diagnosis(now, diag)
    }
    fn take_new_diag(&mut self) -> bool {
        self.inner.take_new_diag()
    }
    fn dpv1_read(&mut self, now: Instant, slot: u8, index: u8, out: &mut [u8]) -> Dpv1Outcome {
        self.inner.dpv1_read(now, slot, index, out)
    }
    fn dpv1_write(&mut self, now: Instant, slot: u8, index: u8, data: &[u8]) -> Dpv1Outcome {
        self.inner.dpv1_write(now, slot, index, data)
    }
    fn dpv1_poll(&mut self, now: Instant, out: &mut [u8]) -> Dpv1Outcome {
        self.inner.dpv1_poll(now, out)
    }
    fn dpv1_data_transport(
        &mut self,
        now: Instant,
        slot: u8,
        index: u8,
        data: &[u8],
        out: &mut [u8],
    ) -> Dpv1Outcome {
        self.inner.dpv1_data_transport(now, slot, index, data, out)
    }
    fn im_read(&mut self, number: u8, out: &mut [u8; 64]) -> bool {
        self.inner.im_read(number, out)
    }
    fn im_write(&mut self, now: Instant, number: u8, record: &[u8; 64]) -> Result<(), Dpv1Error> {
        self.inner.im_write(now, number, record)
    }
    fn alarm_ack(
        &mut self,
        now: Instant,
        slot: u8,
        alarm_type: u8,
        seq: u8,
    ) -> Result<(), Dpv1Error> {
        self.inner.alarm_ack(now, slot, alarm_type, seq)
    }
    fn take_alarm(&mut self) -> Option<profibus_dp::slave::Alarm> {
        self.inner.take_alarm()
    }
    fn set_address(
        &mut self,
        new_address: u8,
        no_add_chg: bool,
        rem_slave_data: &[u8],
    ) -> Result<(), Reason> {
        self.inner
            .set_address(new_address, no_add_chg, rem_slave_data)
    }
    fn own_address(&self) -> OwnAddress {
        self.inner.own_address()
    }
    fn take_restart(&mut self) -> bool {
        self.inner.take_restart()
    }
    fn state_changed(&mut self, now: Instant, state: SlaveState) {
        self.inner.state_changed(now, state)
    }
    fn prm_refused(&mut self, now: Instant, reason: &Reason) {
        self.inner.prm_refused(now, reason)
    }
    fn fdl_request(
        &mut self,
        now: Instant,
        from: u8,
        dsap: u8,
        ssap: u8,
        data: &[u8],
        out: &mut [u8],
    ) -> Option<usize> {
        self.inner.fdl_request(now, from, dsap, ssap, data, out)
    }
    fn poll_event(&mut self) -> Option<DeviceEvent> {
        self.inner.poll_event()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        self.inner.poll_timeout()
    }
    fn handle_timeout(&mut self, now: Instant) {
        self.inner.handle_timeout(now)
    }
}

#[cfg(test)]
mod tests {
    /// The names of the methods of the first `impl … {` block starting
    /// with `head` in `src`.
    fn methods(src: &str, head: &str) -> Vec<String> {
        let start = src.find(head).expect(head);
        let body = &src[start..];
        let end = body.find("\n}\n").unwrap();
        let mut v: Vec<String> = body[..end]
            .split("fn ")
            .skip(1)
            .map(|s| s.split(['(', '<']).next().unwrap().trim().to_string())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn every_device_method_is_passed_on() {
        // A method added to `Device` must be passed to the device behind;
        // `impl Device for Box<D>` in profibus-dp lists them all.
        let dp = include_str!("../../dp/src/slave/device.rs");
        let ours = include_str!("identity.rs");
        assert_eq!(
            methods(ours, "impl Device for IdentityDevice"),
            methods(dp, "impl<D: Device + ?Sized> Device for Box<D>")
        );
    }

    #[test]
    fn ident_option_values() {
        use super::parse_ident;
        assert_eq!(parse_ident(&toml::Value::Integer(0x0DC3)).unwrap(), 0x0DC3);
        assert_eq!(parse_ident(&"0x08AE".into()).unwrap(), 0x08AE);
        assert_eq!(parse_ident(&"16#08AE".into()).unwrap(), 0x08AE);
        let e = parse_ident(&toml::Value::Integer(70000)).unwrap_err();
        assert!(e.to_string().contains("outside 0..=0xFFFF"), "{e}");
    }
}
