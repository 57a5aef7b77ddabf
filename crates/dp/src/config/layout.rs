//! The configured-slave layout: what a bus file says about one slave,
//! worked out once: its address and name, its GSD modules with their
//! byte spans in the process images, and its capabilities (PKW, RFID
//! handshake), which the device profile fills in (`profibus-devices`).
//!
//! The monitor, the terminal views, the gateway and the command line read
//! a slave's modules from here instead of summing module sizes each.

use crate::config::busfile::{BusFile, BusSlave};
use crate::config::gsd::Gsd;

/// A byte range of a process image: `len` bytes from `offset`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Span {
    /// First byte.
    pub offset: usize,
    /// Number of bytes.
    pub len: usize,
}

impl Span {
    /// The span's bytes of `image`, cut short where the image is shorter
    /// (a slave that answered fewer bytes than configured).
    pub fn of<'a>(&self, image: &'a [u8]) -> &'a [u8] {
        let end = (self.offset + self.len).min(image.len());
        image.get(self.offset.min(end)..end).unwrap_or(&[])
    }
}

/// One configured GSD module and its share of the process images.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModuleLayout {
    /// The module's name in the GSD.
    pub name: String,
    /// Its bytes of the input image (what the slave sends).
    pub inputs: Span,
    /// Its bytes of the output image (what the master sends).
    pub outputs: Span,
}

impl ModuleLayout {
    /// The modules `names` of `gsd` in slot order with their spans; the
    /// names the GSD lacks (or whose identifiers do not decode) are left
    /// out, and the spans of the others follow on.
    pub fn of_gsd<S: AsRef<str>>(gsd: &Gsd, names: &[S]) -> Vec<ModuleLayout> {
        let (mut i, mut o) = (0, 0);
        let mut out = Vec::with_capacity(names.len());
        for n in names {
            let Some(io) = gsd.module(n.as_ref()).and_then(|m| m.io().ok()) else {
                continue;
            };
            out.push(ModuleLayout {
                name: n.as_ref().to_string(),
                inputs: Span {
                    offset: i,
                    len: io.input_bytes,
                },
                outputs: Span {
                    offset: o,
                    len: io.output_bytes,
                },
            });
            i += io.input_bytes;
            o += io.output_bytes;
        }
        out
    }

    /// [`ModuleLayout::of_gsd`], but `None` when a name is not a module of
    /// `gsd` (the spans would not fit the images).
    pub fn all_of_gsd<S: AsRef<str>>(gsd: &Gsd, names: &[S]) -> Option<Vec<ModuleLayout>> {
        let out = ModuleLayout::of_gsd(gsd, names);
        (out.len() == names.len()).then_some(out)
    }
}

bitflags::bitflags! {
    /// What a slave can do beyond cyclic data: the services a master side
    /// offers for it. Filled in from the slave's device profile
    /// (`profibus_devices::Profile::capabilities`), never from its ident
    /// number here.
    #[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
    pub struct Capabilities: u8 {
        /// A PKW channel (parameter jobs in the cyclic images).
        const PKW = 1;
        /// The RFID reader's 16-byte command handshake.
        const RFID = 1 << 1;
    }
}

/// A slave as a bus file configures it: see the module docs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SlaveLayout {
    /// Station address.
    pub address: u8,
    /// Name for people.
    pub name: String,
    /// Ident number.
    pub ident_number: u16,
    /// Its GSD, for diagnosis texts.
    pub gsd: Option<Gsd>,
    /// Whether it is a DP-V1 slave.
    pub dpv1: bool,
    /// Its GSD modules in slot order, with their spans.
    pub modules: Vec<ModuleLayout>,
    /// What it can do beyond cyclic data (from its device profile).
    pub capabilities: Capabilities,
}

impl SlaveLayout {
    /// The layout of the bus file's slave `s`, without capabilities
    /// (those come from the profile).
    pub fn of_slave(s: &BusSlave) -> SlaveLayout {
        SlaveLayout {
            address: s.params.address,
            name: s.params.name.clone(),
            ident_number: s.params.ident_number,
            gsd: Some(s.gsd.clone()),
            dpv1: s.params.dpv1,
            modules: ModuleLayout::of_gsd(&s.gsd, &s.modules),
            capabilities: Capabilities::empty(),
        }
    }

    /// The layouts of a bus file's slaves, in bus order.
    pub fn of_bus(bus: &BusFile) -> Vec<SlaveLayout> {
        bus.slaves.iter().map(SlaveLayout::of_slave).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_follow_on_and_clip() {
        let s = Span { offset: 2, len: 3 };
        assert_eq!(s.of(&[0, 1, 2, 3, 4, 5]), &[2, 3, 4]);
        assert_eq!(s.of(&[0, 1, 2, 3]), &[2, 3]);
        assert_eq!(s.of(&[0]), &[] as &[u8]);
    }
}
