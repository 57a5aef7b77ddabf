//! The typed model of a GSD file: what [`super::Gsd::parse`] produces and
//! [`Gsd::write`] emits.
//!
//! Field names follow the GSD keywords (`Freeze_Mode_supp` →
//! `freeze_mode_supp`). Keywords that are optional in the standard are
//! `Option`s; boolean keywords that are absent read as `false`, as the
//! standard's defaults say. Lines the model does not interpret are kept
//! verbatim in `other` so that writing the model back loses nothing.

use profibus_fdl::timing::Baud;

/// Number of baud rates in [`Baud::ALL`] (the length of
/// [`Gsd::baud_rates`]).
pub const BAUD_COUNT: usize = Baud::ALL.len();

/// The position of `baud` in [`Baud::ALL`] and [`Gsd::baud_rates`].
pub fn baud_index(baud: Baud) -> usize {
    Baud::ALL
        .iter()
        .position(|&b| b == baud)
        .expect("Baud::ALL lists every baud rate")
}

/// Support of one baud rate: `<rate>_supp` and `MaxTsdr_<rate>`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct BaudRate {
    /// `<rate>_supp = 1`: the slave works at this rate.
    pub supported: bool,
    /// `MaxTsdr_<rate>`: the longest station delay of responders, in bit
    /// times, at this rate.
    pub max_tsdr: Option<u16>,
}

/// `Slave_Family = main@sub@sub…`: the device class (0 general, 1 drives,
/// 2 switching devices, 3 I/O, 4 valves, 5 controllers, 6 HMI, 7 encoders,
/// 8 NC/RC, 9 gateways, 10 PLCs, 11 ident systems, 12 PA profile) and the
/// vendor's sub-families for the configurator's catalogue tree.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct SlaveFamily {
    /// The main family number.
    pub main: u8,
    /// Sub-family names, outermost first.
    pub sub: Vec<String>,
}

/// `Ext_User_Prm_Data_Const(offset) = bytes`: constant bytes of the
/// User_Prm_Data at a byte offset (counted from the first byte after the
/// 7 standard Set_Prm bytes; for a module, from the module's first byte).
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct PrmConst {
    /// Byte offset.
    pub offset: u16,
    /// The bytes (at least one).
    pub data: Vec<u8>,
}

/// `Ext_User_Prm_Data_Ref(offset) = reference`: the parameter described by
/// the `ExtUserPrmData` block `reference` lives at byte `offset`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct PrmRef {
    /// Byte offset.
    pub offset: u16,
    /// Reference number of an [`ExtUserPrmData`].
    pub reference: u16,
}

/// The data type of a parameter (`Data_Type_Name` of an `ExtUserPrmData`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PrmDataType {
    /// One unsigned byte.
    Unsigned8,
    /// Two bytes, unsigned, most significant first.
    Unsigned16,
    /// Four bytes, unsigned, most significant first.
    Unsigned32,
    /// One signed byte (two's complement).
    Signed8,
    /// Two bytes, signed, most significant first.
    Signed16,
    /// Four bytes, signed, most significant first.
    Signed32,
    /// `Bit(n)`: bit n (0..=7) of the byte at the offset.
    Bit(u8),
    /// `BitArea(first-last)`: bits first..=last (0..=7) of the byte at
    /// the offset, as an unsigned number.
    BitArea(u8, u8),
}

impl PrmDataType {
    /// Bytes the parameter occupies at its offset.
    pub const fn size(self) -> usize {
        match self {
            PrmDataType::Unsigned8
            | PrmDataType::Signed8
            | PrmDataType::Bit(_)
            | PrmDataType::BitArea(..) => 1,
            PrmDataType::Unsigned16 | PrmDataType::Signed16 => 2,
            PrmDataType::Unsigned32 | PrmDataType::Signed32 => 4,
        }
    }

    /// The smallest and largest value the type can hold.
    pub const fn limits(self) -> (i64, i64) {
        match self {
            PrmDataType::Unsigned8 => (0, u8::MAX as i64),
            PrmDataType::Unsigned16 => (0, u16::MAX as i64),
            PrmDataType::Unsigned32 => (0, u32::MAX as i64),
            PrmDataType::Signed8 => (i8::MIN as i64, i8::MAX as i64),
            PrmDataType::Signed16 => (i16::MIN as i64, i16::MAX as i64),
            PrmDataType::Signed32 => (i32::MIN as i64, i32::MAX as i64),
            PrmDataType::Bit(_) => (0, 1),
            PrmDataType::BitArea(first, last) => (0, (1i64 << (last - first + 1)) - 1),
        }
    }

    /// The name as written in a GSD file (`Unsigned8`, `Bit(3)`,
    /// `BitArea(0-2)`).
    pub fn gsd_name(self) -> String {
        match self {
            PrmDataType::Unsigned8 => "Unsigned8".into(),
            PrmDataType::Unsigned16 => "Unsigned16".into(),
            PrmDataType::Unsigned32 => "Unsigned32".into(),
            PrmDataType::Signed8 => "Signed8".into(),
            PrmDataType::Signed16 => "Signed16".into(),
            PrmDataType::Signed32 => "Signed32".into(),
            PrmDataType::Bit(n) => format!("Bit({n})"),
            PrmDataType::BitArea(a, b) => format!("BitArea({a}-{b})"),
        }
    }
}

/// The values a parameter may take.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub enum Allowed {
    /// Not restricted beyond the data type.
    #[default]
    Any,
    /// `min-max`, both inclusive.
    Range(i64, i64),
    /// `a,b,c`: an enumeration.
    Values(Vec<i64>),
}

impl Allowed {
    /// Whether `v` is allowed.
    pub fn contains(&self, v: i64) -> bool {
        match self {
            Allowed::Any => true,
            Allowed::Range(a, b) => (*a..=*b).contains(&v),
            Allowed::Values(vs) => vs.contains(&v),
        }
    }
}

impl std::fmt::Display for Allowed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Allowed::Any => f.write_str("any"),
            Allowed::Range(a, b) => write!(f, "{a}..={b}"),
            Allowed::Values(vs) => {
                for (i, v) in vs.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{v}")?;
                }
                Ok(())
            }
        }
    }
}

/// An `ExtUserPrmData … EndExtUserPrmData` block: one user parameter.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ExtUserPrmData {
    /// Reference number (what `Ext_User_Prm_Data_Ref` points to).
    pub reference: u16,
    /// The parameter's name for people.
    pub name: String,
    /// Data type.
    pub data_type: PrmDataType,
    /// Default value.
    pub default: i64,
    /// Allowed values.
    pub allowed: Allowed,
    /// `Prm_Text_Ref`: the `PrmText` block naming the values.
    pub prm_text_ref: Option<u16>,
    /// `Changeable` (GSD revision 4): whether the user may change it.
    pub changeable: Option<bool>,
    /// `Visible` (GSD revision 4): whether a configurator shows it.
    pub visible: Option<bool>,
}

/// One `Text(value) = "text"` line of a `PrmText` block.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct PrmTextValue {
    /// The parameter value.
    pub value: i64,
    /// Its text.
    pub text: String,
}

/// A `PrmText … EndPrmText` block: texts for the values of parameters.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct PrmText {
    /// Reference number (what `Prm_Text_Ref` points to).
    pub reference: u16,
    /// The texts, in file order.
    pub texts: Vec<PrmTextValue>,
}

/// A `Module … EndModule` block: one selectable module (for a compact
/// station, its fixed configuration).
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct Module {
    /// The module's name as written (spaces kept).
    pub name: String,
    /// Its configuration identifier bytes, as sent in Chk_Cfg; decode them
    /// with [`Module::identifiers`](Module::identifiers).
    pub cfg: Vec<u8>,
    /// The module reference number on the line after `Module` (GSD
    /// revision 3, used by `SlotDefinition`).
    pub reference: Option<u32>,
    /// `Ext_Module_Prm_Data_Len`: bytes this module adds to the
    /// User_Prm_Data.
    pub ext_module_prm_data_len: Option<u8>,
    /// `Ext_User_Prm_Data_Const` lines of the module.
    pub ext_user_prm_data_const: Vec<PrmConst>,
    /// `Ext_User_Prm_Data_Ref` lines of the module.
    pub ext_user_prm_data_ref: Vec<PrmRef>,
    /// `Preset = 1`: the configurator places the module by itself.
    pub preset: bool,
    /// `Info_Text`.
    pub info_text: Option<String>,
    /// Lines of the module body the model does not interpret, verbatim.
    pub other: Vec<String>,
}

/// `Slot(n) = "name" default allowed` inside `SlotDefinition`.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Slot {
    /// Slot number.
    pub number: u8,
    /// Slot name.
    pub name: String,
    /// Module reference number of the default module.
    pub default_module: u32,
    /// Module reference numbers allowed in the slot.
    pub allowed: Allowed,
}

/// `Unit_Diag_Bit(bit) = "text"` or `Unit_Diag_Not_Bit(bit) = "text"`.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct UnitDiagText {
    /// Bit number in the device-related diagnosis, as the GSD numbers it
    /// (this stack reads bit 0 as bit 0 of the first byte after the
    /// block's header byte; see [`crate::pdu::diag::describe`]).
    pub bit: u32,
    /// Text shown when the bit is set (`Unit_Diag_Bit`) or clear
    /// (`Unit_Diag_Not_Bit`).
    pub text: String,
}

/// `Unit_Diag_Area = first-last` … `Unit_Diag_Area_End`: texts for the
/// values of a bit field of the device-related diagnosis.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct UnitDiagArea {
    /// First bit.
    pub first: u32,
    /// Last bit (inclusive).
    pub last: u32,
    /// `Value(v) = "text"` lines.
    pub values: Vec<PrmTextValue>,
}

/// A GSD file of a DP slave (`#Profibus_DP` section), typed.
///
/// Build one with [`Gsd::parse`](super::Gsd::parse) or
/// [`Gsd::from_file`](super::Gsd::from_file), or by hand from
/// `Gsd::default()` (a device profile generating its GSD), and write it
/// with [`Gsd::write`].
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct Gsd {
    // ---- identity ----
    /// `GSD_Revision`.
    pub gsd_revision: Option<u8>,
    /// `Vendor_Name`.
    pub vendor_name: Option<String>,
    /// `Model_Name`.
    pub model_name: Option<String>,
    /// `Revision`.
    pub revision: Option<String>,
    /// `Revision_Number`.
    pub revision_number: Option<u8>,
    /// `Ident_Number`: the PNO ident number, checked by Set_Prm and
    /// reported in Slave_Diag.
    pub ident_number: u16,
    /// `Protocol_Ident` (0 = DP).
    pub protocol_ident: u8,
    /// `Station_Type` (0 = DP slave).
    pub station_type: u8,
    /// `FMS_supp`: mixed DP/FMS device.
    pub fms_supp: bool,
    /// `Hardware_Release`.
    pub hardware_release: Option<String>,
    /// `Software_Release`.
    pub software_release: Option<String>,
    /// `OrderNumber`.
    pub order_number: Option<String>,
    /// `Info_Text`.
    pub info_text: Option<String>,

    // ---- bus ----
    /// `<rate>_supp` and `MaxTsdr_<rate>`, indexed like [`Baud::ALL`]
    /// (see [`baud_index`]).
    pub baud_rates: [BaudRate; BAUD_COUNT],
    /// `Redundancy`.
    pub redundancy: bool,
    /// `Repeater_Ctrl_Sig` (0 none, 1 RS-485, 2 TTL).
    pub repeater_ctrl_sig: Option<u8>,
    /// `24V_Pins` (0 none, 1 input, 2 output).
    pub pins_24v: Option<u8>,
    /// `Implementation_Type` (the ASIC, e.g. "SPC3").
    pub implementation_type: Option<String>,
    /// `Bitmap_Device`.
    pub bitmap_device: Option<String>,
    /// `Bitmap_Diag`.
    pub bitmap_diag: Option<String>,
    /// `Bitmap_SF`.
    pub bitmap_sf: Option<String>,

    // ---- DP slave ----
    /// `Freeze_Mode_supp`.
    pub freeze_mode_supp: bool,
    /// `Sync_Mode_supp`.
    pub sync_mode_supp: bool,
    /// `Auto_Baud_supp`.
    pub auto_baud_supp: bool,
    /// `Set_Slave_Add_supp`.
    pub set_slave_add_supp: bool,
    /// `Fail_Safe`: accepts Data_Exchange without outputs in the Clear
    /// state.
    pub fail_safe: bool,
    /// `Min_Slave_Intervall`: shortest time between two polls of the
    /// slave, in units of 100 µs.
    pub min_slave_intervall: Option<u16>,
    /// `Max_Diag_Data_Len`: longest Slave_Diag response (6..=244).
    pub max_diag_data_len: Option<u8>,
    /// `Slave_Family`.
    pub slave_family: Option<SlaveFamily>,
    /// `Modular_Station`: modules are selected by the user.
    pub modular_station: bool,
    /// `Max_Module`.
    pub max_module: Option<u8>,
    /// `Max_Input_Len`: input bytes over all modules.
    pub max_input_len: Option<u8>,
    /// `Max_Output_Len`: output bytes over all modules.
    pub max_output_len: Option<u8>,
    /// `Max_Data_Len`: input plus output bytes.
    pub max_data_len: Option<u16>,
    /// `Modul_Offset`: number of the first slot.
    pub modul_offset: Option<u8>,
    /// `FixPresetModules`: preset modules may not be removed.
    pub fix_preset_modules: bool,

    // ---- user parameters ----
    /// `User_Prm_Data_Len` (legacy format).
    pub user_prm_data_len: Option<u8>,
    /// `User_Prm_Data` (legacy format).
    pub user_prm_data: Option<Vec<u8>>,
    /// `Max_User_Prm_Data_Len`.
    pub max_user_prm_data_len: Option<u8>,
    /// Station-level `Ext_User_Prm_Data_Const` lines.
    pub ext_user_prm_data_const: Vec<PrmConst>,
    /// Station-level `Ext_User_Prm_Data_Ref` lines.
    pub ext_user_prm_data_ref: Vec<PrmRef>,
    /// `ExtUserPrmData` blocks.
    pub ext_user_prm_data: Vec<ExtUserPrmData>,
    /// `PrmText` blocks.
    pub prm_texts: Vec<PrmText>,

    // ---- DP-V1 ----
    /// `DPV1_Slave`: the Set_Prm carries the 3 DPV1 status bytes (the
    /// first 3 bytes of the User_Prm_Data).
    pub dpv1_slave: bool,
    /// `C1_Read_Write_supp`: MSAC_C1 read/write.
    pub c1_read_write_supp: bool,
    /// `C1_Read_Write_required`.
    pub c1_read_write_required: bool,
    /// `C1_Max_Data_Len`: longest MSAC_C1 data (0..=240).
    pub c1_max_data_len: Option<u8>,
    /// `C1_Response_Timeout`, in units of 10 ms.
    pub c1_response_timeout: Option<u16>,
    /// `C2_Read_Write_supp`.
    pub c2_read_write_supp: bool,
    /// `C2_Max_Data_Len`.
    pub c2_max_data_len: Option<u8>,
    /// `C2_Response_Timeout`, in units of 10 ms.
    pub c2_response_timeout: Option<u16>,
    /// `C2_Max_Count_Channels`.
    pub c2_max_count_channels: Option<u8>,
    /// `Max_Initiate_PDU_Length`.
    pub max_initiate_pdu_length: Option<u8>,
    /// `WD_Base_1ms_supp`.
    pub wd_base_1ms_supp: bool,
    /// `Check_Cfg_Mode`.
    pub check_cfg_mode: bool,
    /// `Diagnostic_Alarm_supp`.
    pub diagnostic_alarm_supp: bool,
    /// `Process_Alarm_supp`.
    pub process_alarm_supp: bool,
    /// `Pull_Plug_Alarm_supp`.
    pub pull_plug_alarm_supp: bool,
    /// `Status_Alarm_supp`.
    pub status_alarm_supp: bool,
    /// `Update_Alarm_supp`.
    pub update_alarm_supp: bool,
    /// `Manufacturer_Specific_Alarm_supp`.
    pub manufacturer_specific_alarm_supp: bool,
    /// `Alarm_Type_Mode_supp`: the slave keeps one alarm per type
    /// outstanding (Alarm_Mode 0 in DPV1_Status_3).
    pub alarm_type_mode_supp: bool,
    /// `Alarm_Sequence_Mode_Count`: how many alarms the slave keeps
    /// outstanding in sequence mode (2..=32; Alarm_Mode 1..=7 in
    /// DPV1_Status_3).
    pub alarm_sequence_mode_count: Option<u8>,

    // ---- modules ----
    /// `Module` blocks, in file order.
    pub modules: Vec<Module>,
    /// `SlotDefinition` entries.
    pub slots: Vec<Slot>,

    // ---- diagnosis texts ----
    /// `Unit_Diag_Bit` lines.
    pub unit_diag_bits: Vec<UnitDiagText>,
    /// `Unit_Diag_Not_Bit` lines.
    pub unit_diag_not_bits: Vec<UnitDiagText>,
    /// `Unit_Diag_Area` blocks.
    pub unit_diag_areas: Vec<UnitDiagArea>,

    /// Lines of the section the model does not interpret (other
    /// keywords, blocks of later GSD revisions), verbatim and in order.
    pub other: Vec<String>,
}
