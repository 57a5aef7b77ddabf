//! Writing a [`Gsd`] as GSD text.
//!
//! The output is a `#Profibus_DP` section in the standard's syntax:
//! double-quoted strings, hex bytes, long byte lists continued with `\`,
//! keywords in the usual order, then the parameter texts and
//! definitions, the unmodelled lines (`other`), the modules and the slot
//! definitions. Parsing the output gives the same model (for any model
//! the parser can produce: strings without `"` or line breaks, non-empty
//! byte lists).

use super::encode_latin1;
use super::model::*;
use profibus_fdl::timing::Baud;
use std::fmt::Write;

/// Bytes per line in byte lists before a `\` continuation.
const BYTES_PER_LINE: usize = 16;

/// A string in double quotes; `"` (which GSD strings cannot hold) becomes
/// `'` and line breaks become blanks.
fn quoted(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        out.push(match c {
            '"' => '\'',
            '\r' | '\n' => ' ',
            c => c,
        });
    }
    out.push('"');
    out
}

/// `0x01,0x02,…` with a continuation after every [`BYTES_PER_LINE`]
/// bytes.
fn byte_list(bytes: &[u8]) -> String {
    let mut out = String::new();
    for (i, b) in bytes.iter().enumerate() {
        if i > 0 {
            out.push(',');
            if i % BYTES_PER_LINE == 0 {
                out.push_str("\\\n    ");
            }
        }
        let _ = write!(out, "0x{b:02X}");
    }
    out
}

fn allowed(a: &Allowed) -> String {
    match a {
        Allowed::Any => String::new(),
        Allowed::Range(lo, hi) => format!(" {lo}-{hi}"),
        Allowed::Values(v) => format!(
            " {}",
            v.iter().map(i64::to_string).collect::<Vec<_>>().join(",")
        ),
    }
}

struct Out(String);

impl Out {
    fn line(&mut self, s: impl AsRef<str>) {
        self.0.push_str(s.as_ref());
        self.0.push('\n');
    }

    fn text(&mut self, key: &str, v: &Option<String>) {
        if let Some(v) = v {
            self.line(format!("{key}={}", quoted(v)));
        }
    }

    fn num<T: std::fmt::Display>(&mut self, key: &str, v: Option<T>) {
        if let Some(v) = v {
            self.line(format!("{key}={v}"));
        }
    }

    fn flag(&mut self, key: &str, v: bool) {
        if v {
            self.line(format!("{key}=1"));
        }
    }

    fn flag_always(&mut self, key: &str, v: bool) {
        self.line(format!("{key}={}", u8::from(v)));
    }

    fn prm(&mut self, consts: &[PrmConst], refs: &[PrmRef]) {
        for c in consts {
            self.line(format!(
                "Ext_User_Prm_Data_Const({})={}",
                c.offset,
                byte_list(&c.data)
            ));
        }
        for r in refs {
            self.line(format!(
                "Ext_User_Prm_Data_Ref({})={}",
                r.offset, r.reference
            ));
        }
    }
}

impl Gsd {
    /// Whether [`Gsd::write`] reproduces this model: every text of it can
    /// be written as a GSD string (a GSD string cannot contain `"`; the
    /// writer turns it into `'`).
    pub fn is_writable(&self) -> bool {
        let g = self;
        let mut s: Vec<&str> = [
            &g.vendor_name,
            &g.model_name,
            &g.revision,
            &g.hardware_release,
            &g.software_release,
            &g.order_number,
            &g.info_text,
            &g.implementation_type,
            &g.bitmap_device,
            &g.bitmap_diag,
            &g.bitmap_sf,
        ]
        .iter()
        .filter_map(|o| o.as_deref())
        .collect();
        for m in &g.modules {
            s.push(&m.name);
            s.extend(m.info_text.as_deref());
        }
        s.extend(g.ext_user_prm_data.iter().map(|p| p.name.as_str()));
        s.extend(
            g.prm_texts
                .iter()
                .flat_map(|t| t.texts.iter().map(|v| v.text.as_str())),
        );
        s.extend(g.slots.iter().map(|x| x.name.as_str()));
        s.extend(
            g.unit_diag_bits
                .iter()
                .chain(&g.unit_diag_not_bits)
                .map(|t| t.text.as_str()),
        );
        s.extend(
            g.unit_diag_areas
                .iter()
                .flat_map(|a| a.values.iter().map(|v| v.text.as_str())),
        );
        s.extend(
            g.slave_family
                .iter()
                .flat_map(|f| f.sub.iter().map(String::as_str)),
        );
        s.iter().all(|x| !x.contains('"'))
    }

    /// The model as GSD text (a `#Profibus_DP` section with a short
    /// header comment).
    pub fn write(&self) -> String {
        let mut o = Out(String::new());
        let g = self;
        o.line("; GSD file written by profibus-dp");
        o.line("#Profibus_DP");
        o.num("GSD_Revision", g.gsd_revision);
        o.text("Vendor_Name", &g.vendor_name);
        o.text("Model_Name", &g.model_name);
        o.text("Revision", &g.revision);
        o.num("Revision_Number", g.revision_number);
        o.line(format!("Ident_Number=0x{:04X}", g.ident_number));
        o.line(format!("Protocol_Ident={}", g.protocol_ident));
        o.line(format!("Station_Type={}", g.station_type));
        o.flag("FMS_supp", g.fms_supp);
        o.text("Hardware_Release", &g.hardware_release);
        o.text("Software_Release", &g.software_release);
        o.text("OrderNumber", &g.order_number);
        o.text("Info_Text", &g.info_text);
        for (b, r) in Baud::ALL.iter().zip(&g.baud_rates) {
            o.flag(&format!("{}_supp", b.gsd_suffix()), r.supported);
        }
        for (b, r) in Baud::ALL.iter().zip(&g.baud_rates) {
            o.num(&format!("MaxTsdr_{}", b.gsd_suffix()), r.max_tsdr);
        }
        o.flag("Redundancy", g.redundancy);
        o.num("Repeater_Ctrl_Sig", g.repeater_ctrl_sig);
        o.num("24V_Pins", g.pins_24v);
        o.text("Implementation_Type", &g.implementation_type);
        o.text("Bitmap_Device", &g.bitmap_device);
        o.text("Bitmap_Diag", &g.bitmap_diag);
        o.text("Bitmap_SF", &g.bitmap_sf);
        o.flag_always("Freeze_Mode_supp", g.freeze_mode_supp);
        o.flag_always("Sync_Mode_supp", g.sync_mode_supp);
        o.flag_always("Auto_Baud_supp", g.auto_baud_supp);
        o.flag_always("Set_Slave_Add_supp", g.set_slave_add_supp);
        o.flag("Fail_Safe", g.fail_safe);
        o.num("Min_Slave_Intervall", g.min_slave_intervall);
        o.num("Max_Diag_Data_Len", g.max_diag_data_len);
        if let Some(f) = &g.slave_family {
            let mut s = f.main.to_string();
            for sub in &f.sub {
                s.push('@');
                s.push_str(&sub.replace(['@', ';', '"'], " "));
            }
            o.line(format!("Slave_Family={s}"));
        }
        o.flag_always("Modular_Station", g.modular_station);
        o.num("Max_Module", g.max_module);
        o.num("Max_Input_Len", g.max_input_len);
        o.num("Max_Output_Len", g.max_output_len);
        o.num("Max_Data_Len", g.max_data_len);
        o.num("Modul_Offset", g.modul_offset);
        o.flag("FixPresetModules", g.fix_preset_modules);
        o.flag("DPV1_Slave", g.dpv1_slave);
        o.flag("C1_Read_Write_supp", g.c1_read_write_supp);
        o.flag("C1_Read_Write_required", g.c1_read_write_required);
        o.num("C1_Max_Data_Len", g.c1_max_data_len);
        o.num("C1_Response_Timeout", g.c1_response_timeout);
        o.flag("C2_Read_Write_supp", g.c2_read_write_supp);
        o.num("C2_Max_Data_Len", g.c2_max_data_len);
        o.num("C2_Response_Timeout", g.c2_response_timeout);
        o.num("C2_Max_Count_Channels", g.c2_max_count_channels);
        o.num("Max_Initiate_PDU_Length", g.max_initiate_pdu_length);
        o.flag("WD_Base_1ms_supp", g.wd_base_1ms_supp);
        o.flag("Check_Cfg_Mode", g.check_cfg_mode);
        o.flag("Diagnostic_Alarm_supp", g.diagnostic_alarm_supp);
        o.flag("Process_Alarm_supp", g.process_alarm_supp);
        o.flag("Pull_Plug_Alarm_supp", g.pull_plug_alarm_supp);
        o.flag("Status_Alarm_supp", g.status_alarm_supp);
        o.flag("Update_Alarm_supp", g.update_alarm_supp);
        o.flag(
            "Manufacturer_Specific_Alarm_supp",
            g.manufacturer_specific_alarm_supp,
        );
        o.flag("Alarm_Type_Mode_supp", g.alarm_type_mode_supp);
        o.num("Alarm_Sequence_Mode_Count", g.alarm_sequence_mode_count);
        o.num("User_Prm_Data_Len", g.user_prm_data_len);
        if let Some(d) = g.user_prm_data.as_ref().filter(|d| !d.is_empty()) {
            o.line(format!("User_Prm_Data={}", byte_list(d)));
        }
        o.num("Max_User_Prm_Data_Len", g.max_user_prm_data_len);
        for t in &g.prm_texts {
            o.line(format!("PrmText={}", t.reference));
            for v in &t.texts {
                o.line(format!("Text({})={}", v.value, quoted(&v.text)));
            }
            o.line("EndPrmText");
        }
        for p in &g.ext_user_prm_data {
            o.line(format!(
                "ExtUserPrmData={} {}",
                p.reference,
                quoted(&p.name)
            ));
            o.line(format!(
                "{} {}{}",
                p.data_type.gsd_name(),
                p.default,
                allowed(&p.allowed)
            ));
            o.num("Prm_Text_Ref", p.prm_text_ref);
            o.num("Changeable", p.changeable.map(u8::from));
            o.num("Visible", p.visible.map(u8::from));
            o.line("EndExtUserPrmData");
        }
        o.prm(&g.ext_user_prm_data_const, &g.ext_user_prm_data_ref);
        for t in &g.unit_diag_bits {
            o.line(format!("Unit_Diag_Bit({})={}", t.bit, quoted(&t.text)));
        }
        for t in &g.unit_diag_not_bits {
            o.line(format!("Unit_Diag_Not_Bit({})={}", t.bit, quoted(&t.text)));
        }
        for a in &g.unit_diag_areas {
            o.line(format!("Unit_Diag_Area={}-{}", a.first, a.last));
            for v in &a.values {
                o.line(format!("Value({})={}", v.value, quoted(&v.text)));
            }
            o.line("Unit_Diag_Area_End");
        }
        for l in &g.other {
            o.line(l);
        }
        for m in &g.modules {
            o.line(format!("Module={} {}", quoted(&m.name), byte_list(&m.cfg)));
            if let Some(r) = m.reference {
                o.line(r.to_string());
            }
            if m.preset {
                o.line("Preset=1");
            }
            o.text("Info_Text", &m.info_text);
            o.num("Ext_Module_Prm_Data_Len", m.ext_module_prm_data_len);
            o.prm(&m.ext_user_prm_data_const, &m.ext_user_prm_data_ref);
            for l in &m.other {
                o.line(l);
            }
            o.line("EndModule");
        }
        if !g.slots.is_empty() {
            o.line("SlotDefinition");
            for s in &g.slots {
                o.line(format!(
                    "Slot({})={} {}{}",
                    s.number,
                    quoted(&s.name),
                    s.default_module,
                    allowed(&s.allowed)
                ));
            }
            o.line("EndSlotDefinition");
        }
        o.0
    }

    /// [`write`](Self::write) encoded as Latin-1, ready to be saved as a
    /// `.gsd` file.
    pub fn write_latin1(&self) -> Vec<u8> {
        encode_latin1(&self.write())
    }
}
