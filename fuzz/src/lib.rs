//! Shared harnesses of the fuzz targets: one device-profile harness that
//! the six `device_*` targets run with their profile, so that each
//! profile gets its own corpus and its own executions.

use profibus_devices::bus::ProfiledBus;
use profibus_devices::channels::Direction;
use profibus_devices::{BoxedDevice, Configured, ControlInbox, DeviceOptions};
use profibus_dp::master::SlaveParams;
use profibus_dp::pdu::sap;
use profibus_dp::slave::{DpSlave, SlaveState};
use profibus_fdl::station::passive::{Reply, Responder};
use profibus_fdl::{DataTelegram, FunctionCode, Instant};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

/// The repository's `crates/devices/gsd/` directory (bus files of the targets live
/// there, so relative GSD and data paths resolve).
pub fn gsd_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../crates/devices/gsd")
}

/// A configured profile with the master's Set_Prm and Chk_Cfg for it.
pub struct Fixture {
    /// The configured profile.
    pub profile: Box<dyn Configured>,
    /// What the master sends the slave (from a bus file).
    pub params: SlaveParams,
    /// The slave's station address (the device's own, if it chooses).
    pub address: u8,
}

impl Fixture {
    /// The configured profile.
    pub fn profile(&self) -> &dyn Configured {
        self.profile.as_ref()
    }
}

/// Configure profile `name` with `options` (TOML lines, paths relative
/// to `crates/devices/gsd/`) from the registry, and load the bus file whose slave 8 has
/// the `[[slave]]` keys `slave` for the master's side (for the generic
/// profile: `gsd` and `modules`; otherwise `device` and the options).
pub fn fixture(name: &str, options: &str, slave: &str) -> Fixture {
    let entry = profibus_devices::profile(name).expect("a registered profile");
    let mut opts = DeviceOptions::new();
    for (k, v) in toml::from_str::<toml::Table>(options).expect("TOML options") {
        opts.set(&k, v);
    }
    opts.paths_relative_to(&gsd_dir(), entry.path_options);
    let profile = entry
        .configure(&opts, Some(8))
        .unwrap_or_else(|e| panic!("{name} does not configure: {e}"));
    let text =
        format!("[master]\naddress = 2\nbaud = \"1.5M\"\n\n[[slave]]\naddress = 8\n{slave}\n");
    let bus = ProfiledBus::parse(&gsd_dir().join("fuzz-bus.toml"), &text)
        .unwrap_or_else(|e| panic!("bus file for {name} does not load: {e}"));
    let params = bus.file.slaves[0].params.clone();
    let address = profile.address().unwrap_or(8);
    Fixture {
        profile,
        params,
        address,
    }
}

/// The fixture of a profile configured in a bus file with `options`.
pub fn profile_fixture(name: &str, options: &str) -> Fixture {
    fixture(name, options, &format!("device = \"{name}\"\n{options}"))
}

/// Run the device-profile harness: the slave device of `fx` inside the
/// DP slave core, fed records of requests and control lines.
///
/// Records: `kind, dt, len, body[len]`. `kind % 8`:
/// 0 the master's Set_Prm; 1 a Set_Prm with the right header and `body`
/// as User_Prm_Data; 2 the master's Chk_Cfg; 3 `body` as Chk_Cfg;
/// 4 Data_Exchange with `body` as outputs (cut or padded to the
/// configured length unless `kind & 8`); 5 an MSAC_C1 request (`body`,
/// first byte made a Read 0x5E or Write 0x5F unless `kind & 8`); 6 `body`
/// as a control line; 7 `body` as a raw request: `da sa fc dsap ssap`
/// then the data unit (0xFF = no SAP).
///
/// Checks: no panic; no response of more than 244 data bytes; no answer
/// to a broadcast or SDN; the core's outputs are zero outside Data_Exch;
/// the named channels decode any image of any length.
pub fn run_device(fx: &Fixture, data: &[u8]) {
    let inbox = ControlInbox::new();
    let dev: BoxedDevice = fx.profile().device(Some(inbox.clone())).expect("device");
    let mut slave = DpSlave::new(dev, fx.address);
    let prm = fx.params.set_prm();
    let cfg = &fx.params.cfg;
    let channels = fx.profile().channels(cfg).ok();
    let mut now = Instant::ZERO;
    let mut rest = data;
    let mut buf = [0u8; 246];
    let mut scratch = Vec::new();
    let me = fx.address;
    while let [kind, dt, len, tail @ ..] = rest {
        let n = (*len as usize).min(tail.len());
        let (body, tail) = tail.split_at(n);
        rest = tail;
        now += Duration::from_micros(*dt as u64 * 500);
        while let Some(t) = slave.poll_timeout().filter(|&t| t <= now) {
            slave.handle_timeout(t.max(now));
            if t > now {
                break;
            }
            // A deadline at or before now must move on.
            if slave.poll_timeout().is_some_and(|t2| t2 <= t) {
                break;
            }
        }
        let exact = kind & 8 == 0;
        scratch.clear();
        let (da, sa, fc, dsap, ssap, unit): (u8, u8, u8, Option<u8>, Option<u8>, &[u8]) =
            match kind % 8 {
                0 => (me, 2, 0x6D, Some(sap::SET_PRM), Some(62), &prm),
                1 => {
                    scratch.extend_from_slice(&prm[..7]);
                    scratch.extend_from_slice(body);
                    (me, 2, 0x6D, Some(sap::SET_PRM), Some(62), &scratch)
                }
                2 => (me, 2, 0x5D, Some(sap::CHK_CFG), Some(62), cfg),
                3 => (me, 2, 0x5D, Some(sap::CHK_CFG), Some(62), body),
                4 => {
                    if exact {
                        scratch.extend_from_slice(body);
                        scratch.resize(slave.outputs().len(), 0);
                        (me, 2, 0x7D, None, None, &scratch)
                    } else {
                        (me, 2, 0x7D, None, None, body)
                    }
                }
                5 => {
                    scratch.extend_from_slice(body);
                    if exact {
                        if let Some(b) = scratch.first_mut() {
                            *b = 0x5E | (*b & 1);
                        }
                    }
                    (
                        me,
                        2,
                        0x7D,
                        Some(sap::MSAC_C1),
                        Some(sap::MSAC_C1),
                        &scratch,
                    )
                }
                6 => {
                    inbox.push(String::from_utf8_lossy(body).into_owned());
                    continue;
                }
                _ => {
                    let [da, sa, fc, dsap, ssap, unit @ ..] = body else {
                        continue;
                    };
                    (
                        da & 0x7F,
                        sa & 0x7F,
                        *fc,
                        (*dsap != 0xFF).then_some(*dsap),
                        (*ssap != 0xFF).then_some(*ssap),
                        unit,
                    )
                }
            };
        let req = DataTelegram {
            da,
            sa,
            fc: FunctionCode::from_byte(fc),
            dsap,
            ssap,
            data: unit,
            format: None,
        };
        let FunctionCode::Request { kind, .. } = req.fc else {
            continue;
        };
        let silent = da == 127 || !kind.expects_reply();
        let out: &mut [u8] = if silent { &mut [] } else { &mut buf };
        match slave.on_request(now, &req, out) {
            Reply::Data { len, .. } => {
                assert!(!silent, "answered a broadcast/SDN");
                assert!(len <= 244, "{len} bytes of response data");
            }
            Reply::ShortAck => assert!(!silent, "acknowledged a broadcast/SDN"),
            Reply::Silence => {}
        }
        if slave.state() != SlaveState::DataExch {
            assert!(slave.outputs().iter().all(|&b| b == 0), "stale outputs");
        }
        while slave.poll_event().is_some() {}
        if let Some(map) = &channels {
            for d in [Direction::Input, Direction::Output] {
                for (_, v) in map.decode(d, body) {
                    std::hint::black_box(v);
                }
            }
        }
    }
}

/// The fixture of profile `name`, built once per process.
pub fn cached(cell: &'static OnceLock<Fixture>, make: fn() -> Fixture) -> &'static Fixture {
    cell.get_or_init(make)
}
