//! The keywords of GSD revisions 1–5 that the model does not interpret.
//!
//! The parser reads the keywords a DP master and slave need into the
//! model ([`super::model`]). Every other keyword of the GSD specification
//! is listed here: the parser keeps its line verbatim in `other` (of the
//! station or of the module) without a warning, so that writing the model
//! back loses nothing. Only a keyword found neither in the model nor here
//! is reported as unknown (a vendor's own keyword, or a misspelling).
//!
//! Groups follow the chapters of the GSD specification: general keywords,
//! DP master keywords (a master's GSD file), basic DP slave keywords,
//! DP-V1 (acyclic services and alarms), DP-V2 (data exchange broadcast,
//! isochronous mode, redundancy), identification & maintenance, PROFIsafe
//! (`F_…`), extended parameterisation (`X_…`), subsystems, and the
//! diagnosis texts. Every `X_` and `F_` keyword is known: the standard
//! defines them as the extended and fail-safe forms of base keywords.
//! Blocks (`Physical_Interface`, `UnitDiagType`, `X_Unit_Diag_Area`,
//! `Data_Area_Beg`, …) are copied whole by the parser.

use profibus_fdl::timing::Baud;

/// Station-level keywords kept as raw text, lower case.
const STATION: &[&str] = &[
    // General (besides the identity and baud rate keywords in the model).
    "periphery",
    "family_name",
    // DP master (GSD of a class 1 master).
    "master_freeze_mode_supp",
    "master_sync_mode_supp",
    "master_fail_safe_supp",
    "download_supp",
    "upload_supp",
    "act_para_brct_supp",
    "act_param_supp",
    "max_mps_length",
    "max_lsdu_ms",
    "max_lsdu_mm",
    "min_poll_timeout",
    "las_len",
    "max_slaves_supp",
    "max_master_input_len",
    "max_master_output_len",
    "max_master_data_len",
    "dpv1_master",
    "dpv1_conformance_class",
    "c1_master_read_write_supp",
    "master_dpv1_alarm_supp",
    "master_diagnostic_alarm_supp",
    "master_process_alarm_supp",
    "master_pull_plug_alarm_supp",
    "master_status_alarm_supp",
    "master_update_alarm_supp",
    "master_manufacturer_specific_alarm_supp",
    "master_manufacturer_alarm_supp",
    "master_extra_alarm_sap_supp",
    "master_alarm_sequence_mode",
    "master_alarm_type_mode_supp",
    "isochron_mode_synchronised",
    "dxb_master_supp",
    // Basic DP slave.
    "diag_update_delay",
    "fail_safe_required",
    "max_cfg_data_len",
    // DP-V1.
    "c1_read_write_required",
    "c2_read_write_required",
    "extra_alarm_sap_supp",
    "diagnostic_alarm_required",
    "process_alarm_required",
    "pull_plug_alarm_required",
    "status_alarm_required",
    "update_alarm_required",
    "manufacturer_specific_alarm_required",
    "dpv1_data_types",
    "prm_block_structure_supp",
    "prm_block_structure_req",
    "jokerblock_slot",
    "jokerblock_location",
    "max_iparameter_size",
    // DP-V2: data exchange broadcast (publisher/subscriber).
    "publisher_supp",
    "subscriber_supp",
    "dxb_max_link_count",
    "dxb_max_data_length",
    "dxb_subscribertable_block_location",
    // DP-V2: isochronous mode.
    "isochron_mode_supp",
    "isochron_mode_required",
    "tbase_dp",
    "tdp_max",
    "tdp_min",
    "tbase_io",
    "ti_min",
    "to_min",
    "t_pll_w_max",
    "ti_to_equal",
    "max_iso_input_len",
    "max_iso_output_len",
    // DP-V2: redundancy, time synchronisation.
    "prmcmd_supp",
    "slave_redundancy_supp",
    "slave_max_switch_over_time",
    "time_sync_supp",
    // Identification & maintenance, firmware download.
    "ident_maintenance_supp",
    "firmware_download_supp",
    "web_server_supp",
    // Subsystems.
    "subsys_dir_index",
    // Diagnosis texts.
    "unit_diag_bit_help",
    "unit_diag_not_bit_help",
    "unit_diag_type",
    "channel_diag",
    "channel_diag_help",
];

/// Module-level keywords kept as raw text, lower case.
const MODULE: &[&str] = &[
    "module_class",
    "subsys_module_dir_index",
    "channel_diag",
    "channel_diag_help",
];

/// Keywords with one form per baud rate (`Trdy_1.5M`, …): master timing
/// and the `Physical_Interface` delays, lower case with the `_`.
const PER_BAUD: &[&str] = &[
    "trdy_",
    "tqui_",
    "tset_",
    "tsdi_",
    "transmission_delay_",
    "reaction_delay_",
];

/// Whether `key` (lower case) is an `X_` or `F_` keyword.
fn extension(key: &str) -> bool {
    key.starts_with("x_") || key.starts_with("f_")
}

/// Whether `key` (lower case) is a keyword of the standard that a station
/// section may hold and the model keeps as raw text.
pub(crate) fn known_station(key: &str) -> bool {
    STATION.contains(&key)
        || extension(key)
        || PER_BAUD.iter().any(|p| {
            key.strip_prefix(p).is_some_and(|rate| {
                Baud::ALL
                    .iter()
                    .any(|b| b.gsd_suffix().eq_ignore_ascii_case(rate))
            })
        })
}

/// Whether `key` (lower case) is a keyword of the standard that a module
/// body may hold and the model keeps as raw text.
pub(crate) fn known_module(key: &str) -> bool {
    MODULE.contains(&key) || extension(key)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_is_lower_case_and_has_no_duplicates() {
        for list in [STATION, MODULE, PER_BAUD] {
            for (i, k) in list.iter().enumerate() {
                assert_eq!(*k, k.to_ascii_lowercase());
                assert!(!list[..i].contains(k), "{k} twice");
            }
        }
    }

    #[test]
    fn families() {
        assert!(known_station("trdy_1.5m"));
        assert!(known_station("transmission_delay_12m"));
        assert!(!known_station("trdy_2m"));
        assert!(known_station("x_unit_diag_bit"));
        assert!(known_station("f_paramdesccrc"));
        assert!(known_station("prmcmd_supp"));
        assert!(!known_station("foo_supp"));
        assert!(known_module("x_ext_module_prm_data_len"));
        assert!(!known_module("fail_safe_required"));
    }
}
