//! Commissioning with the device profiles: which profile a scanned slave
//! is, from its ident number, and which of its options give the
//! configuration it reported (`dpctl scan --write-config`; the bus-file
//! side is [`profibus_dp::config::commission`]).

use crate::PROFILES;
use profibus_dp::config::commission::{DeviceMatch, ProfileMatcher};
use profibus_fdl::wire::Hex;

/// The registry as a [`ProfileMatcher`]: a profile whose
/// [`Profile::IDENT`](crate::Profile::IDENT) is the slave's, with the
/// first of its [`Profile::options_for_cfg`](crate::Profile::options_for_cfg)
/// candidates whose Chk_Cfg is the slave's Get_Cfg.
#[derive(Debug, Clone, Copy, Default)]
pub struct Registry;

impl ProfileMatcher for Registry {
    fn device_for(
        &self,
        address: u8,
        ident: u16,
        cfg: &[u8],
    ) -> Result<Option<DeviceMatch>, String> {
        let mut known = Vec::new();
        for p in PROFILES.iter().filter(|p| p.ident == Some(ident)) {
            known.push(p.name);
            if let Some(o) = p.options_giving(cfg, Some(address)) {
                return Ok(Some(DeviceMatch {
                    name: p.name.to_string(),
                    notes: p.commission_notes(cfg, &o),
                    options: o.table().clone(),
                }));
            }
        }
        if known.is_empty() {
            return Ok(None);
        }
        Err(format!(
            "device profile `{}` knows ident 0x{ident:04X}, but none of the options it derives \
             gives Get_Cfg `{}`: configured from its GSD modules instead",
            known.join("`, `"),
            Hex(cfg)
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DeviceOptions;

    fn cfg_of(name: &str, pairs: &[&str]) -> Vec<u8> {
        let mut o = DeviceOptions::new();
        for p in pairs {
            o.set_pair(p).unwrap();
        }
        crate::profile(name)
            .unwrap()
            .configure(&o, Some(5))
            .unwrap()
            .chk_cfg()
            .unwrap()
    }

    #[test]
    fn profiles_found_by_ident_with_the_options_of_the_configuration() {
        let r = Registry;
        // Default options: every profile with a fixed ident.
        for p in PROFILES {
            let Some(ident) = p.ident else { continue };
            let cfg = cfg_of(p.name, &[]);
            let m = r.device_for(5, ident, &cfg).unwrap().unwrap();
            assert_eq!(m.name, p.name);
        }
        // The JX2's word counts and consistent block from the bytes.
        let pairs = [
            "input_words=16",
            "consistent_inputs=4",
            "consistent_input_offset=8",
            "output_words=12",
            "consistent_outputs=8",
            "consistent_output_offset=4",
        ];
        let cfg = cfg_of("jx2", &pairs);
        let m = r
            .device_for(5, crate::jx2::IDENT, &cfg)
            .unwrap()
            .expect("jx2");
        assert_eq!(m.options["input_words"].as_integer(), Some(16));
        assert_eq!(m.options["consistent_output_offset"].as_integer(), Some(4));
        // Unknown ident: no profile; known ident, foreign bytes: why.
        assert_eq!(r.device_for(5, 0x4711, &[0x10]), Ok(None));
        let e = r.device_for(5, crate::rfid::IDENT, &[0x10]).unwrap_err();
        assert!(
            e.starts_with("device profile `rfid` knows ident 0x0DC4"),
            "{e}"
        );
    }
}
