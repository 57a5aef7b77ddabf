//! What the gateway knows of each configured slave, from the bus file.

use profibus_devices::bus::ProfiledBus;
use profibus_devices::channels::ChannelMap;
use profibus_devices::pkw::Dialect;
use profibus_devices::ProfileError;
use profibus_dp::config::gsd::Gsd;
use profibus_dp::config::layout::Capabilities;

/// What the gateway knows of one configured slave.
#[derive(Debug, Clone)]
pub struct SlaveInfo {
    /// Station address.
    pub address: u8,
    /// Name from the bus file.
    pub name: String,
    /// Ident number (PKW parameters by name: [`profibus_devices::pkw_parameter`]).
    pub ident_number: u16,
    /// Named channels of its images (device profiles), if any.
    pub channels: Option<ChannelMap>,
    /// Its GSD, for diagnosis texts.
    pub gsd: Option<Gsd>,
    /// Whether it is a DP-V1 slave (diagnosis decoding, DP-V1 requests).
    pub dpv1: bool,
    /// The dialect of its PKW channel, if it has one (PKW requests).
    pub pkw: Option<&'static Dialect>,
    /// Whether it is an RFID reader with the 16-byte command handshake
    /// (RFID requests).
    pub rfid: bool,
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

/// The gateway's view of a bus file's slaves: names, named channels
/// (device profiles' channels; `MODULE[i]` bytes for slaves given by GSD
/// modules), GSDs, PKW dialects, RFID readers.
pub fn slave_infos(profiled: &ProfiledBus) -> Result<Vec<SlaveInfo>, SlaveInfoError> {
    profiled
        .file
        .slaves
        .iter()
        .map(|s| {
            let a = s.params.address;
            Ok(SlaveInfo {
                address: a,
                name: s.params.name.clone(),
                ident_number: s.params.ident_number,
                channels: Some(
                    profiled
                        .channels(a)
                        .unwrap_or_else(|| {
                            profibus_devices::generic::module_channels(&s.modules, &s.params.cfg)
                        })
                        .map_err(|error| SlaveInfoError { address: a, error })?,
                ),
                gsd: Some(s.gsd.clone()),
                dpv1: s.params.dpv1,
                pkw: profibus_devices::pkw_dialect(s.params.ident_number, &s.params.cfg).ok(),
                rfid: profibus_devices::capabilities(s.params.ident_number, &s.params.cfg)
                    .contains(Capabilities::RFID),
            })
        })
        .collect()
}
