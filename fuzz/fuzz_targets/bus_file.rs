//! The bus-file loader with the device-profile resolver
//! (`ProfiledBus::parse`: TOML, slaves from GSD modules or `device =
//! "NAME"` with options, bus parameters) on arbitrary text, plus the
//! gateway's `[mqtt]` settings and the named channels of what loads.
//! GSD and data paths resolve against the repository's `crates/devices/gsd/` directory,
//! so the fuzzer can name the real GSD files. Checks: no panic; an error
//! names the file and a line inside the text; what loads gives a master
//! configuration `DpMaster::new` accepts.
//!
//! Run: `cd fuzz && cargo +nightly fuzz run bus_file fuzz/corpus/bus_file fuzz/seeds/bus_file`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_devices::bus::ProfiledBus;
use profibus_dp::master::DpMaster;
use profibus_gateway::settings::MqttSettings;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = profibus_fuzz::gsd_dir().join("fuzz-bus.toml");
    match ProfiledBus::parse(&path, text) {
        Err(e) => {
            assert_eq!(e.path, path);
            let lines = text.lines().count().max(1);
            assert!(e.line <= lines + 1, "line {} of {lines}: {e}", e.line);
        }
        Ok(bus) => {
            DpMaster::new(&bus.file.master).expect("a loaded bus file gives a valid master");
            let _ = MqttSettings::from_table(bus.file.mqtt.as_ref(), "fuzz");
            for s in &bus.file.slaves {
                if let Some(Ok(map)) = bus.channels(s.params.address) {
                    let img = [0xA5u8; 64];
                    for d in [
                        profibus_devices::channels::Direction::Input,
                        profibus_devices::channels::Direction::Output,
                    ] {
                        for (_, v) in map.decode(d, &img) {
                            std::hint::black_box(v);
                        }
                    }
                }
            }
        }
    }
});
