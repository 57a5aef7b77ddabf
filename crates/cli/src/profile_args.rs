//! The device `dpctl slave` emulates, as flags: clap types live in the
//! command line; [`DeviceChoice`] is what the library takes. The flags
//! named after a profile's options (`--vars`, `--switch` …) are
//! shorthands for `--device-opt KEY=VALUE`; a new profile needs none of
//! them (its options come through `--device-opt`).

use profibus_devices::generic::InputPattern;
use profibus_devices::DeviceOptions;
use profibus_io::emulation::{DeviceChoice, EmulationError};
use std::path::PathBuf;

/// The device a slave emulates: a profile (`device`) or the generic
/// device of a GSD file (`gsd` with `modules`), and the profile's
/// options. The field docs are the help of `dpctl slave`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ProfileArgs {
    /// GSD file of the device to emulate (the generic device; `.gsd` or a
    /// localised `.gse`, `.gsg`, …).
    #[arg(long, value_name = "FILE", conflicts_with = "device")]
    pub gsd: Option<PathBuf>,
    /// A module of the GSD file, in slot order (repeat for each module;
    /// the GSD's exact module names). None: the file's fixed configuration.
    #[arg(long = "module", value_name = "NAME", requires = "gsd")]
    pub modules: Vec<String>,
    /// Accept known vendor quirks in the GSD file (with a warning).
    #[arg(long, requires = "gsd")]
    pub lenient: bool,
    /// Input pattern of the generic device: `echo` (the outputs) or
    /// `counter` (a 32-bit counter, one step per Data_Exchange).
    #[arg(long, value_name = "PATTERN", default_value = "echo")]
    pub inputs: InputPattern,
    /// Device profile to emulate (see --list-devices).
    #[arg(long, value_name = "NAME")]
    pub device: Option<String>,
    /// An option of the device profile, KEY=VALUE (repeatable). Every
    /// profile also takes ident=0x… (the ident number it reports) and
    /// gsd=FILE (a vendor's GSD file: ident number, modules, parameters).
    /// With --gsd: an option of the generic device (I&M0: order_id,
    /// serial_number, manufacturer_id).
    #[arg(long = "device-opt", value_name = "KEY=VALUE")]
    pub device_opts: Vec<String>,
    /// List the device profiles and exit.
    #[arg(long)]
    pub list_devices: bool,
    /// bm4: the PLC's variable table (TOML, see
    /// crates/devices/data/bm4_example_vars.toml); default: the
    /// configuration of BM4OPRO1.GSD.
    #[arg(long, value_name = "FILE.toml", requires = "device")]
    pub vars: Option<PathBuf>,
    /// bm4: us_DEVICE of PROFIBUS_INIT_SL: 1..125 fixed address, 126 set
    /// once by the master (Set_Slave_Add) and kept in --state-dir, 127 set
    /// by the master after every start, 128 the rotary switch (--switch).
    /// Default: --addr.
    #[arg(long, value_name = "N", requires = "device")]
    pub us_device: Option<u8>,
    /// bm4: rotary switch value for us_DEVICE 128 (0 error, 1..125 the
    /// address, 126..255 set once by the master). omega: the rotary
    /// switches S40/S41 (hex allowed, e.g. 0x19 = 25) instead of --addr.
    #[arg(long, value_name = "N", requires = "device")]
    pub switch: Option<String>,
    /// bm4: directory of the state file keeping a set-once address. With
    /// --gsd (a DP-V1 device): directory of `im.toml`, which keeps the
    /// I&M1..I&M4 records masters write across restarts.
    #[arg(long, value_name = "DIR")]
    pub state_dir: Option<PathBuf>,
    /// bm4: write the GSD file of this configuration (generated from
    /// --vars, or BM4OPRO1.GSD) before starting.
    #[arg(long, value_name = "FILE", requires = "device")]
    pub write_gsd: Option<PathBuf>,
    /// omega: the V controller's parameter set (TOML, see
    /// crates/devices/data/omega_vparams.toml); default: the shipped one.
    #[arg(long, value_name = "FILE.toml", requires = "device")]
    pub params: Option<PathBuf>,
    /// omega: number of setpoints the drive expects (si_NR_WR_VALUE,
    /// 1..8; with --actual-values). Default: any valid configuration.
    #[arg(long, value_name = "N", requires = "actual_values")]
    pub setpoints: Option<u8>,
    /// omega: number of actual values (si_NR_RD_VALUE, 1..8).
    #[arg(long, value_name = "N", requires = "setpoints")]
    pub actual_values: Option<u8>,
    /// rfid: the tags file (TOML: tags with UID and memory, which one is
    /// in the antenna field, the reader's timing), rewritten when the
    /// field changes.
    #[arg(long, value_name = "FILE.toml", requires = "device")]
    pub tags: Option<PathBuf>,
    /// bk3000: the terminal strip in plug order, end terminal last, e.g.
    /// KL1104,KL2134,KL3102,KL4002,KL9010 (a name may end in `:complete`
    /// or `:compact`); or `--device-opt terminals-file=FILE`.
    #[arg(long, value_name = "LIST", requires = "device")]
    pub terminals: Option<String>,
    /// bk3000: the rotary switch for the ones of the address (0..9).
    #[arg(long, value_name = "N", requires = "device")]
    pub switch_ones: Option<u8>,
    /// bk3000: the rotary switch for the tens of the address (0..9).
    #[arg(long, value_name = "N", requires = "device")]
    pub switch_tens: Option<u8>,
    /// Control commands for the device, one per line, from FILE, `-`
    /// (stdin), or a Unix socket dpctl creates when the path does not
    /// exist (each connection sends lines; removed at the end). bm4: `sdiag EF CD AB 90 78 56 34 12 [overflow]` (user
    /// diagnosis, FB SDIAG), `sdiag-clear`, `set NAME VALUE`, `get NAME`,
    /// `status`. omega: `status`, `quit` (x_QUIT), `get P`. rfid: `enter UID`,
    /// `leave`, `tags`, `status`. jx2: a Unix socket to create for register
    /// commands (`read 12100`, `write 12102 16`, ...; stdin always takes
    /// them too). bk3000: `status`, `outputs`, `set NAME VALUE`, `release
    /// NAME|all`, `pull N`, `plug N`, `run`. generic (--gsd): `alarm TYPE
    /// SLOT appears|disappears [HEX]` (a DP-V1 alarm: diagnostic, process,
    /// pull, plug, status, update, manufacturer or a type number; the GSD
    /// must declare it, the master enable it).
    #[arg(long, value_name = "FILE")]
    pub control: Option<String>,
    /// jx2: the module number x of the registers 1x100..1x999 (1..9,
    /// default 2).
    #[arg(long, value_name = "N", requires = "device")]
    pub module_number: Option<u32>,
    /// jx2: register commands run as the PLC program at start.
    #[arg(long, value_name = "FILE", requires = "device")]
    pub script: Option<PathBuf>,
    /// File in which the generic device keeps an address set by
    /// Set_Slave_Add (`address=N`, `no_add_chg=0|1`); when it exists its
    /// address overrides --addr.
    #[arg(long, value_name = "FILE", requires = "gsd")]
    pub address_file: Option<PathBuf>,
}

impl ProfileArgs {
    /// The profile's options: the named fields, then `device_opts`
    /// (`KEY=VALUE`, later ones win).
    pub fn options(&self) -> Result<DeviceOptions, EmulationError> {
        let mut opts = DeviceOptions::new();
        if self.device.is_none() {
            let gsd = self.gsd.as_ref().ok_or(EmulationError::NoDevice)?;
            opts.set("gsd", gsd.display().to_string());
            opts.set("modules", self.modules.clone());
            opts.set("lenient", self.lenient);
            let inputs = match self.inputs {
                InputPattern::Echo => "echo",
                InputPattern::Counter => "counter",
            };
            opts.set("inputs", inputs);
        }
        let path = |p: &Option<PathBuf>| p.as_ref().map(|p| p.display().to_string());
        for (k, v) in [
            ("vars", path(&self.vars)),
            ("state_dir", path(&self.state_dir)),
            ("write_gsd", path(&self.write_gsd)),
            ("params", path(&self.params)),
            ("address_file", path(&self.address_file)),
            ("script", path(&self.script)),
            ("tags", path(&self.tags)),
        ] {
            if let Some(v) = v {
                opts.set(k, v);
            }
        }
        for (k, v) in [
            ("us_device", self.us_device.map(i64::from)),
            ("setpoints", self.setpoints.map(i64::from)),
            ("actual_values", self.actual_values.map(i64::from)),
            ("module_number", self.module_number.map(i64::from)),
            ("switch_ones", self.switch_ones.map(i64::from)),
            ("switch_tens", self.switch_tens.map(i64::from)),
        ] {
            if let Some(v) = v {
                opts.set(k, v);
            }
        }
        if let Some(s) = &self.switch {
            opts.set_text("switch", s);
        }
        if let Some(t) = &self.terminals {
            opts.set("terminals", t.as_str());
        }
        for o in &self.device_opts {
            opts.set_pair(o)?;
        }
        Ok(opts)
    }

    /// The device these flags choose: `--device` and its options, or the
    /// generic device of `--gsd`.
    pub fn choice(&self) -> Result<DeviceChoice, EmulationError> {
        Ok(DeviceChoice {
            device: self.device.clone(),
            options: self.options()?,
        })
    }
}
