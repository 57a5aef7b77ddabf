//! The GSD files of the emulated devices, built into the binary so that
//! `dpctl demo` and the device profiles need no files at run time. The
//! same files are in the repository's `crates/devices/gsd/` folder (see its README for
//! their sources and the ident numbers chosen).

use profibus_dp::config::gsd::{decode_latin1, Gsd, GsdError, ParseOptions};

/// `DPCTL_GEN.GSD`: dpctl's generic test slave.
pub const DPCTL_GEN: &[u8] = include_bytes!("../gsd/DPCTL_GEN.GSD");
/// `BM4OPRO1.GSD`: Baumüller BM4-O-PRO-01 default configuration.
pub const BM4OPRO1: &[u8] = include_bytes!("../gsd/BM4OPRO1.GSD");
/// `MyGSDFile.gsd`: the BM4-O-PRO-01 manual's generated example.
pub const BM4_EXAMPLE: &[u8] = include_bytes!("../gsd/MyGSDFile.gsd");
/// `BNF_00D0.GSD`: Baumüller Omega Drive-Line II option board.
pub const BNF_00D0: &[u8] = include_bytes!("../gsd/BNF_00D0.GSD");
/// `BK30BECF.GSD`: Beckhoff BK3000 bus coupler.
pub const BK30BECF: &[u8] = include_bytes!("../gsd/BK30BECF.GSD");
/// `AEGI0DC4.GSD`: AEG ID ARE I2/K1 PFB RFID reader.
pub const AEGI0DC4: &[u8] = include_bytes!("../gsd/AEGI0DC4.GSD");

/// `JX2P0DC3.GSD`: Jetter JX2-PROFI1.
pub const JX2P0DC3: &[u8] = crate::jx2::GSD;

/// Every built-in file by its file name, for a GSD library
/// (`profibus_dp::config::library::GsdLibrary::add_built_in`). The
/// manual's example `MyGSDFile.gsd` is left out: it has the ident of
/// `BM4OPRO1.GSD` with other modules.
pub const BUILT_IN: &[(&str, &[u8])] = &[
    ("DPCTL_GEN.GSD", DPCTL_GEN),
    ("BM4OPRO1.GSD", BM4OPRO1),
    ("BNF_00D0.GSD", BNF_00D0),
    ("BK30BECF.GSD", BK30BECF),
    ("AEGI0DC4.GSD", AEGI0DC4),
    ("JX2P0DC3.GSD", JX2P0DC3),
];

/// Parse one of the built-in files (leniently: some keep their vendor
/// quirks).
pub fn parse(bytes: &[u8]) -> Result<Gsd, GsdError> {
    Gsd::parse(&decode_latin1(bytes), ParseOptions { lenient: true }).map(|p| p.gsd)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_file_parses() {
        for (bytes, ident) in [
            (DPCTL_GEN, 0x0DCE),
            (BM4OPRO1, 0x0008),
            (BM4_EXAMPLE, 0x0008),
            (BNF_00D0, 0x00D0),
            (AEGI0DC4, 0x0DC4),
        ] {
            assert_eq!(parse(bytes).unwrap().ident_number, ident);
        }
        assert!(parse(BK30BECF).is_ok());
    }
}
