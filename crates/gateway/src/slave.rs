//! What the gateway knows of each configured slave, from the bus file.

use profibus_devices::bus::ProfiledBus;
use profibus_devices::channels::ChannelMap;
use profibus_devices::pkw::Dialect;
use profibus_devices::ProfileError;
use profibus_dp::config::layout::{Capabilities, SlaveLayout};

/// What the gateway knows of one configured slave: its layout
/// ([`ProfiledBus::layouts`]), its named channels and its PKW dialect.
#[derive(Debug, Clone)]
pub struct SlaveInfo {
    /// Address, name, ident number (PKW parameters by name:
    /// [`profibus_devices::pkw_parameter`]), GSD (diagnosis texts), DP-V1
    /// (diagnosis decoding, DP-V1 requests) and capabilities (RFID
    /// requests).
    pub layout: SlaveLayout,
    /// Named channels of its images (device profiles), if any.
    pub channels: Option<ChannelMap>,
    /// The dialect of its PKW channel, if it has one (PKW requests).
    pub pkw: Option<&'static Dialect>,
}

impl SlaveInfo {
    /// Whether it is an RFID reader with the 16-byte command handshake
    /// (RFID requests).
    pub fn rfid(&self) -> bool {
        self.layout.capabilities.contains(Capabilities::RFID)
    }
}

/// A slave whose named channels cannot be worked out (its device
/// profile's or its GSD modules').
#[derive(Debug, thiserror::Error)]
#[error("slave {address}: {error}")]
pub struct SlaveInfoError {
    /// Station address.
    pub address: u8,
    /// The cause.
    pub error: ProfileError,
}

/// The gateway's view of a bus file's slaves: their layouts, named
/// channels (device profiles' channels; `MODULE[i]` bytes for slaves given
/// by GSD modules) and PKW dialects.
pub fn slave_infos(profiled: &ProfiledBus) -> Result<Vec<SlaveInfo>, SlaveInfoError> {
    (profiled.file.slaves.iter())
        .zip(profiled.layouts())
        .map(|(s, layout)| {
            let a = layout.address;
            let channels = (profiled.channels(a))
                .unwrap_or_else(|| {
                    profibus_devices::generic::module_channels(&s.modules, &s.params.cfg)
                })
                .map_err(|error| SlaveInfoError { address: a, error })?;
            Ok(SlaveInfo {
                layout,
                channels: Some(channels),
                pkw: profibus_devices::pkw_dialect(s.params.ident_number, &s.params.cfg).ok(),
            })
        })
        .collect()
}
