//! `profibus-devices`: device profiles: slave emulations of specific
//! PROFIBUS-DP products and master-side helpers for them, plus the
//! [`generic`] device any GSD file describes.
//!
//! # The shape of a profile
//!
//! Every product is one module that implements [`Profile`]:
//!
//! - **typed options**: `type Options`, a serde struct (the keys of a bus
//!   file's `[[slave]]` table, or `dpctl slave --device-opt KEY=VALUE`,
//!   both through [`DeviceOptions`]);
//! - **its GSD** ([`Profile::gsd`]) and the GSD **modules** a master
//!   configures it with ([`Profile::modules`]; Chk_Cfg and
//!   User_Prm_Data follow, [`Configured::chk_cfg`]);
//! - **its slave** ([`Profile::device`]: a
//!   [`profibus_dp::slave::Device`] for the DP slave core) and the
//!   **station address** it chooses ([`Profile::address`]; a
//!   Set_Slave_Add address is kept by the program running it in
//!   [`Profile::address_file`], see [`address`]);
//! - **the master side**: the named, typed [`channels`] of the process
//!   images a configuration gives ([`Profile::channels`]) and its PKW
//!   dialect ([`Profile::pkw_dialect`]; the [`pkw`] module itself knows
//!   no device). Acyclic jobs over a running master are
//!   [`profibus_dp::master::SlaveTask`]s with typed results (`Display` and
//!   `Serialize`): [`pkw_task::PkwTask`] (a parameter as people name it,
//!   through the registry), [`rfid::jobs::CommandRun`] and
//!   [`rfid::jobs::MasterJobs`] (reader commands).
//!
//! [`PROFILES`] is the registry: name → [`ProfileEntry`]. `dpctl slave
//! --device NAME` and bus files with `device = "NAME"` go through it
//! ([`bus::ProfiledBus`] resolves such bus files: the profile's GSD and
//! modules become the slave's Chk_Cfg and User_Prm_Data, and the master
//! gets its named channels); [`profile()`] finds an entry, [`pkw_dialect`]
//! the PKW dialect of a slave.
//!
//! Devices never touch files while they answer the bus: an accepted
//! Set_Slave_Add is reported by the DP slave core and kept by the program
//! running the slave ([`Profile::address_file`], [`address`]); other
//! device state is reported as a [`STATE_EVENT`] device event and kept in
//! [`Profile::state_file`].
//!
//! # Running devices
//!
//! This crate does no I/O. A device runs as a DP slave on a port through
//! `profibus_io::emulation` (what `dpctl slave` does: the baud-rate search
//! runner, keeping Set_Slave_Add addresses and device state in files);
//! `profibus_io::control_io` feeds a [`ControlInbox`] from a file, stdin or
//! a Unix socket, and `profibus_io::jx2` runs the JX2's register clients.
//! The demo plant of `dpctl demo` and the fault soak (a master and a
//! slave of every profile on the simulated bus) are in `profibus-plant`.
//!
//! # How to add a profile
//!
//! 1. Create `src/<name>/mod.rs` (the device: `impl Device`, its docs with
//!    the manual's line references) and `src/<name>/profile.rs` with
//!    ```text
//!    #[derive(Debug, Default, serde::Deserialize)]
//!    #[serde(default, deny_unknown_fields)]
//!    pub struct Options { /* one field per option, snake_case */ }
//!
//!    pub struct MyProfile { /* the configured state: GSD, tables … */ }
//!
//!    impl Profile for MyProfile {
//!        type Options = Options;
//!        const NAME: &'static str = "myname";
//!        const SUMMARY: &'static str = "Vendor product (ident 0x….): what it is";
//!        const OPTIONS_HELP: &'static str = "key = …, key = …";
//!        const IDENT: Option<u16> = Some(IDENT);
//!        fn configure(o: Options, address: Option<u8>) -> Result<Self, ProfileError> { … }
//!        fn gsd(&self) -> &Gsd { … }
//!        fn modules(&self) -> Vec<String> { … }     // GSD module names, slot order
//!        fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError> { … }
//!        fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError> { … }
//!    }
//!    ```
//!    Use [`profile::int`] / [`profile::opt_int`] for numbers that may
//!    come as text (`"0x19"`) and [`profile::read_table`] for a table
//!    file named in the options. Optional items: `PKW` (the product's
//!    PKW dialect, which its module owns), `address`, `address_file`,
//!    `state_file`, `pkw_dialect`, `gsd_file`, `warnings`. A device with
//!    text commands takes them from its [`ControlInbox`] and refuses with
//!    [`ControlError`].
//! 2. Add `pub mod <name>;` and one row `ProfileEntry::of::<<name>::profile::MyProfile>()`
//!    to [`PROFILES`] below.
//!
//! Nothing else changes: `dpctl slave --device myname --device-opt
//! key=value`, `dpctl slave --list-devices`, bus files with `device =
//! "myname"` plus the options, and the master's named channels work from
//! the registry. Errors are [`ProfileError`] (no `String` errors); the
//! device does no file I/O while it runs.

#![forbid(unsafe_code)]

pub mod address;
pub mod bk3000;
pub mod bm4;
pub mod bus;
pub mod channels;
pub mod commission;
pub mod generic;
pub mod gsd_files;
pub mod identity;
pub mod im;
pub mod jx2;
mod kit;
pub mod omega;
pub mod pkw;
pub mod pkw_task;
pub mod profile;
pub mod rfid;

pub use profile::{
    Configured, ControlError, ControlInbox, DeviceOptions, Profile, ProfileEntry, ProfileError,
    STATE_EVENT,
};

use profibus_dp::slave::Device;

/// A device as `dpctl slave` runs it.
pub type BoxedDevice = Box<dyn Device + Send>;

/// Every device profile (a new profile adds its row here).
pub const PROFILES: &[ProfileEntry] = &[
    ProfileEntry::of::<generic::GenericProfile>(),
    ProfileEntry::of::<bm4::profile::Bm4Profile>(),
    ProfileEntry::of::<omega::profile::OmegaProfile>(),
    ProfileEntry::of::<jx2::profile::Jx2Profile>(),
    ProfileEntry::of::<rfid::profile::RfidProfile>(),
    ProfileEntry::of::<bk3000::profile::Bk3000Profile>(),
];

/// The profile named `name` (case-insensitive).
pub fn profile(name: &str) -> Result<&'static ProfileEntry, ProfileError> {
    PROFILES
        .iter()
        .find(|p| p.name.eq_ignore_ascii_case(name))
        .ok_or_else(|| ProfileError::Unknown {
            name: name.to_string(),
            suggestions: profibus_dp::config::names::DidYouMean::new(
                name,
                PROFILES.iter().map(|p| p.name),
            ),
            available: PROFILES
                .iter()
                .map(|p| p.name)
                .collect::<Vec<_>>()
                .join(", "),
        })
}

/// Why a slave has no PKW dialect.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PkwLookupError {
    /// The product has a PKW channel, but the configuration lacks the
    /// module.
    #[error("the configuration of ident 0x{0:04X} has no PKW module (configure the service data module first)")]
    NotConfigured(u16),
    /// No profile with a PKW channel has that ident number.
    #[error("ident 0x{ident:04X} has no known PKW channel (known: {known})")]
    Unknown {
        /// The slave's ident number.
        ident: u16,
        /// The products with one.
        known: String,
    },
}

/// The PKW dialect of a slave with ident number `ident` configured with
/// `cfg` (Chk_Cfg bytes), from the profile with that ident number.
pub fn pkw_dialect(ident: u16, cfg: &[u8]) -> Result<&'static pkw::Dialect, PkwLookupError> {
    if let Some(p) = PROFILES
        .iter()
        .find(|p| p.ident == Some(ident) && p.pkw.is_some())
    {
        return p
            .pkw_dialect(cfg)
            .ok_or(PkwLookupError::NotConfigured(ident));
    }
    let known: Vec<String> = PROFILES
        .iter()
        .filter_map(|p| Some(format!("0x{:04X} {}", p.ident?, p.pkw?.name)))
        .collect();
    Err(PkwLookupError::Unknown {
        ident,
        known: known.join(", "),
    })
}

/// What a slave with ident number `ident` configured with `cfg`
/// (Chk_Cfg bytes) can do beyond cyclic data, from the profile with that
/// ident number ([`Profile::capabilities`]); none for an unknown product.
pub fn capabilities(ident: u16, cfg: &[u8]) -> profibus_dp::config::layout::Capabilities {
    PROFILES
        .iter()
        .filter(|p| p.ident == Some(ident))
        .fold(Default::default(), |c, p| c | p.capabilities(cfg))
}

/// The PKW parameter number of the parameter named `name` of a slave with
/// ident number `ident` and GSD `gsd`, from the profile with that ident
/// number (e.g. a BM4-O-PRO-01 variable: its module's parameter number).
pub fn pkw_parameter(ident: u16, gsd: &profibus_dp::config::gsd::Gsd, name: &str) -> Option<u16> {
    PROFILES
        .iter()
        .filter(|p| p.ident == Some(ident))
        .find_map(|p| p.pkw_parameter(gsd, name))
}

/// The PKW parameters a slave with ident number `ident` and GSD `gsd`
/// names (`dpctl pkw list`), from the profile with that ident number.
pub fn pkw_parameters(ident: u16, gsd: &profibus_dp::config::gsd::Gsd) -> Vec<pkw::PkwParameter> {
    PROFILES
        .iter()
        .filter(|p| p.ident == Some(ident))
        .flat_map(|p| p.pkw_parameters(gsd))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_names_are_unique_and_found() {
        for p in PROFILES {
            assert_eq!(profile(&p.name.to_uppercase()).unwrap().name, p.name);
            assert_eq!(PROFILES.iter().filter(|q| q.name == p.name).count(), 1);
        }
        assert!(matches!(profile("nope"), Err(ProfileError::Unknown { .. })));
        let e = profile("omgea").unwrap_err().to_string();
        assert!(
            e.starts_with("no device profile `omgea`; did you mean `omega`? (available: "),
            "{e}"
        );
    }

    #[test]
    fn registry_rows_list_name_summary_and_options() {
        let omega = profile("omega").unwrap().to_string();
        let (first, options) = omega.split_once('\n').unwrap();
        assert!(
            first.starts_with("omega    ") && first.contains("Omega"),
            "{omega}"
        );
        assert!(options.starts_with("         options: "), "{omega}");
    }

    #[test]
    fn capabilities_come_from_the_profile() {
        use profibus_dp::config::layout::Capabilities;
        assert_eq!(capabilities(bm4::IDENT, &[0x73]), Capabilities::PKW);
        assert_eq!(
            capabilities(omega::IDENT, &[0x71, 0x53, 0x63]),
            Capabilities::empty()
        );
        assert_eq!(capabilities(rfid::IDENT, &rfid::CFG), Capabilities::RFID);
        assert_eq!(capabilities(0x1234, &[0x73]), Capabilities::empty());
    }

    #[test]
    fn pkw_dialect_by_ident_and_configuration() {
        assert_eq!(
            pkw_dialect(bm4::IDENT, &[0x73]).unwrap().name,
            bm4::PKW.name
        );
        assert_eq!(
            pkw_dialect(omega::IDENT, &[0x73, 0x71, 0x53, 0x63])
                .unwrap()
                .name,
            omega::PKW.name
        );
        assert_eq!(
            pkw_dialect(omega::IDENT, &[0x71, 0x53, 0x63]),
            Err(PkwLookupError::NotConfigured(omega::IDENT))
        );
        let e = pkw_dialect(0x1234, &[0x73]).unwrap_err().to_string();
        assert!(
            e.contains("0x0008 BM4-O-PRO-01") && e.contains("0x00D0"),
            "{e}"
        );
    }
}
