//! The `bm4` profile: `dpctl slave --device bm4`, `device = "bm4"` in a
//! bus file.

use super::vars::{IecType, VarModule, VarTable};
use super::{Addressing, Bm4, CfgLayout, IDENT, PKW};
use crate::channels::{ChannelMap, ChannelType, Direction};
use crate::pkw::{Dialect, PKW_MODULE};
use crate::profile::{opt_int, read_table, ControlInbox, DeviceOptions, Profile, ProfileError};
use crate::BoxedDevice;
use profibus_dp::config::gsd::Gsd;
use serde::Deserialize;
use std::path::PathBuf;

/// The options of the `bm4` profile.
#[derive(Debug, Default, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Options {
    /// The PLC's variable table (TOML); default: the configuration of
    /// `BM4OPRO1.GSD`.
    pub vars: Option<PathBuf>,
    /// The manual's example table (MyGSDFile.gsd), built in, instead of
    /// `vars`.
    pub example: bool,
    /// us_DEVICE of PROFIBUS_INIT_SL (1..125 fixed, 126 set once and kept
    /// in `state_dir`, 127 set after every start, 128 the rotary switch);
    /// default: the caller's address.
    #[serde(deserialize_with = "opt_int")]
    pub us_device: Option<u8>,
    /// The rotary switch (for us_DEVICE 128; alone it means 128).
    #[serde(deserialize_with = "opt_int")]
    pub switch: Option<u8>,
    /// Directory of the state file keeping a set-once address.
    pub state_dir: Option<PathBuf>,
    /// Write the GSD file of this configuration here when configured.
    pub write_gsd: Option<PathBuf>,
    /// Master side: the variables (names) a master configures, in slot
    /// order; default: all of them. (Not `modules`: in a bus file that
    /// key is the slave's GSD modules, which a profile chooses itself.)
    pub variables: Option<Vec<String>>,
    /// Master side: configure the PKW module first (default: where it
    /// fits the GSD's lengths next to the variables, so not with the
    /// default table, which fills them).
    pub pkw: Option<bool>,
}

/// The BM4-O-PRO-01 with a variable table and an addressing mode.
#[derive(Debug)]
pub struct Bm4Profile {
    options: Options,
    table: VarTable,
    addressing: Addressing,
    gsd: Gsd,
    gsd_file: Vec<u8>,
}

impl Profile for Bm4Profile {
    type Options = Options;
    const NAME: &'static str = "bm4";
    const SUMMARY: &'static str = "Baumüller b maXX PLC module BM4-O-PRO-01 (ident 0x0008): PLC variables as modules, PKW channel, SDIAG user diagnosis";
    const OPTIONS_HELP: &'static str = "--vars FILE.toml (variable table; default: BM4OPRO1.GSD's configuration), \
--us-device N (1..125 fixed, 126 set once by the master and kept in --state-dir, 127 set after every start, \
128 rotary switch; default: --addr), --switch N (rotary switch for us_DEVICE 128), --state-dir DIR, \
--write-gsd FILE (write the generated GSD), --control FILE|- (commands: sdiag HEX..., sdiag-clear, set NAME VALUE, get NAME, status); \
example = true (the manual's example table instead of --vars); master side: variables = [names] (default all), \
pkw = true|false (default: true where the PKW module fits next to the variables, not with the default table)";
    const IDENT: Option<u16> = Some(IDENT);
    const PATH_OPTIONS: &'static [&'static str] = &["vars", "state_dir", "write_gsd"];
    const PKW: Option<&'static Dialect> = Some(&PKW);

    /// The variables and the PKW module from the identifiers: the
    /// default table's GSD modules (BM4OPRO1.GSD) that give them, the PKW
    /// module first where configured.
    fn options_for_cfg(cfg: &[u8]) -> Vec<DeviceOptions> {
        use profibus_dp::config::discover::{modules_for_cfg, CfgMatch};
        let mut out = vec![DeviceOptions::new()];
        let Ok(gsd) = crate::gsd_files::parse(crate::gsd_files::BM4OPRO1) else {
            return out;
        };
        if let CfgMatch::Found { best, .. } = modules_for_cfg(&gsd, cfg) {
            let pkw = cfg.first() == Some(&crate::pkw::PKW_MODULE);
            let names: Vec<String> = best
                .names(&gsd)
                .into_iter()
                .skip(usize::from(pkw))
                .map(str::to_string)
                .collect();
            let mut o = DeviceOptions::new();
            o.set("pkw", pkw);
            o.set("variables", names);
            out.push(o);
        }
        out
    }

    fn configure(options: Options, address: Option<u8>) -> Result<Self, ProfileError> {
        let table = match &options.vars {
            Some(_) if options.example => {
                return Err(ProfileError::Invalid(
                    "give --vars FILE or example = true, not both".into(),
                ))
            }
            Some(path) => read_table(path, VarTable::parse)?,
            None if options.example => VarTable::example(),
            None => VarTable::default_table(),
        };
        let us = match (options.us_device, options.switch) {
            (Some(u), _) => u,
            (None, Some(_)) => 128,
            (None, None) => address.ok_or_else(|| {
                ProfileError::Invalid(
                    "give --us-device N, --switch N (us_DEVICE 128) or --addr N".into(),
                )
            })?,
        };
        let addressing =
            Addressing::from_us_device(us, options.switch, options.state_dir.as_deref())
                .map_err(|e| ProfileError::Invalid(e.to_string()))?;
        let dev = Bm4::new(table.clone(), addressing.clone());
        let (gsd, gsd_file) = (dev.gsd().clone(), dev.gsd_file());
        if let Some(path) = &options.write_gsd {
            std::fs::write(path, &gsd_file).map_err(|error| ProfileError::File {
                path: path.clone(),
                error,
            })?;
        }
        Ok(Bm4Profile {
            options,
            table,
            addressing,
            gsd,
            gsd_file,
        })
    }

    fn gsd(&self) -> &Gsd {
        &self.gsd
    }

    fn gsd_file(&self) -> Vec<u8> {
        self.gsd_file.clone()
    }

    fn modules(&self) -> Vec<String> {
        let name_of = |cfg: &[u8]| {
            self.gsd
                .modules
                .iter()
                .find(|m| m.cfg == cfg)
                .map(|m| m.name.clone())
        };
        let vars: Vec<String> = match &self.options.variables {
            Some(names) => names.clone(),
            None => (0..self.table.vars.len())
                .filter_map(|i| name_of(&self.table.identifier(i)))
                .collect(),
        };
        let pkw: Vec<String> = name_of(&[PKW_MODULE]).into_iter().collect();
        let with_pkw = [pkw.clone(), vars.clone()].concat();
        // Default: the PKW module first where it fits next to the
        // variables. The manual's default variables (5.03058.03, L2101-
        // 2109) are 112 bytes each way, all that its default GSD allows
        // (BM4OPRO1.GSD, L2255-2257: Max_Input_Len=112,
        // Max_Output_Len=112, Max_Data_Len=224; its "all modules" module,
        // L2260, is that configuration): with the 8 PKW bytes it would be
        // refused, so the default table goes without the PKW module.
        let fits = |names: &[String]| {
            self.gsd
                .select(names)
                .is_ok_and(|sel| self.gsd.check_selection(&sel).is_empty())
        };
        match self.options.pkw {
            Some(true) => with_pkw,
            Some(false) => vars,
            None if fits(&with_pkw) || !fits(&vars) => with_pkw,
            None => vars,
        }
    }

    fn address(&self) -> Option<u8> {
        Some(self.addressing.address)
    }

    fn address_file(&self) -> Option<PathBuf> {
        self.addressing.store.clone()
    }

    fn device(&self, control: Option<ControlInbox>) -> Result<BoxedDevice, ProfileError> {
        let mut dev = Bm4::new(self.table.clone(), self.addressing.clone());
        if let Some(inbox) = control {
            dev = dev.with_inbox(inbox);
        }
        Ok(Box::new(dev))
    }

    /// A variable module of the GSD: its identifier's 4th byte is the
    /// variable's parameter number.
    fn pkw_parameter(gsd: &Gsd, name: &str) -> Option<u16> {
        let m = gsd
            .modules
            .iter()
            .find(|m| m.name == name && m.cfg.len() == 4)?;
        Some(m.cfg[3] as u16)
    }

    fn pkw_parameters(gsd: &Gsd) -> Vec<crate::pkw::PkwParameter> {
        (gsd.modules.iter())
            .filter(|m| m.cfg.len() == 4)
            .map(|m| crate::pkw::PkwParameter {
                pnu: m.cfg[3] as u16,
                name: m.name.clone(),
                details: format!(
                    "module {}",
                    m.cfg
                        .iter()
                        .map(|b| format!("{b:02X}"))
                        .collect::<Vec<_>>()
                        .join(" ")
                ),
            })
            .collect()
    }

    fn channels(&self, cfg: &[u8]) -> Result<ChannelMap, ProfileError> {
        let l = CfgLayout::new(&self.table, cfg).map_err(|e| ProfileError::Config(e.0))?;
        let mut m = ChannelMap::new();
        if l.pkw {
            crate::pkw::channels(&mut m);
        }
        for (module, dir) in [
            (VarModule::Input, Direction::Input),
            (VarModule::Output, Direction::Output),
        ] {
            for (pnu, offset) in l.slots(module) {
                let v = &self.table.vars[pnu];
                let ty = channel_type(v.ty);
                for i in 0..v.length {
                    let name = if v.is_array() {
                        format!("{}[{i}]", v.name)
                    } else {
                        v.name.clone()
                    };
                    m.push(name, dir, offset + i * v.ty.size(), ty);
                }
            }
        }
        Ok(m)
    }
}

fn channel_type(t: IecType) -> ChannelType {
    match t {
        IecType::Bool | IecType::Usint | IecType::Byte => ChannelType::U8,
        IecType::Sint => ChannelType::I8,
        IecType::Int => ChannelType::I16,
        IecType::Uint | IecType::Word => ChannelType::U16,
        IecType::Dint => ChannelType::I32,
        IecType::Udint | IecType::Dword => ChannelType::U32,
        IecType::Real => ChannelType::F32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::channels::Value;
    use crate::{Configured, DeviceOptions};

    fn example() -> Box<dyn Configured> {
        let mut o = DeviceOptions::new();
        o.set_text(
            "vars",
            concat!(env!("CARGO_MANIFEST_DIR"), "/data/bm4_example_vars.toml"),
        );
        crate::profile("bm4")
            .unwrap()
            .configure(&o, Some(6))
            .unwrap()
    }

    #[test]
    fn master_side_from_the_variable_table() {
        let p = example();
        assert_eq!(p.address(), Some(6));
        assert_eq!(p.modules()[0], "Bedarfsdaten PKW");
        let cfg = p.chk_cfg().unwrap();
        assert_eq!(cfg[0], PKW_MODULE);
        assert_eq!(p.user_prm_data().unwrap().len(), super::super::USER_PRM_LEN);
        let ch = p.channels(&cfg).unwrap();
        assert!(ch.find(Direction::Input, "pke").is_some());
        let first_in = ch.of(Direction::Input).nth(4).unwrap();
        assert_eq!(
            (first_in.name.as_str(), first_in.offset),
            ("ud_MyReadVar1", 8)
        );
        let mut img = vec![0u8; 64];
        ch.write_output("ud_MyWriteVar1", Value::Int(0x0102_0304), &mut img)
            .unwrap();
        let w = ch.find(Direction::Output, "ud_MyWriteVar1").unwrap();
        assert_eq!(&img[w.offset..w.offset + 4], &[1, 2, 3, 4]);
        assert!(p.channels(&[0x42]).is_err());
        assert_eq!(
            crate::pkw_parameter(IDENT, p.gsd(), "di_MyReadVar3"),
            Some(4)
        );
        assert_eq!(crate::pkw_parameter(IDENT, p.gsd(), "nope"), None);
        assert_eq!(crate::pkw_parameter(0x00D0, p.gsd(), "di_MyReadVar3"), None);
    }

    #[test]
    fn options_are_typed_and_checked() {
        let entry = crate::profile("bm4").unwrap();
        let mut o = DeviceOptions::new();
        o.set_pair("us-device=0x7F").unwrap();
        let p = entry.configure(&o, None).unwrap();
        assert_eq!(p.address(), Some(126), "us_DEVICE 127 waits at 126");
        let mut o = DeviceOptions::new();
        o.set_pair("switch=0X19").unwrap();
        assert_eq!(entry.configure(&o, None).unwrap().address(), Some(25));
        let mut o = DeviceOptions::new();
        o.set_pair("no-such-option=1").unwrap();
        let e = entry.configure(&o, Some(6)).unwrap_err().to_string();
        assert!(e.contains("no_such_option"), "{e}");
        let mut o = DeviceOptions::new();
        o.set_pair("us-device=300").unwrap();
        assert!(entry.configure(&o, None).is_err());
        assert!(
            entry.configure(&DeviceOptions::new(), None).is_err(),
            "no address"
        );
    }
}
