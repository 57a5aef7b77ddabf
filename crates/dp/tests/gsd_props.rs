//! Property tests of the GSD parser and writer:
//! - any model the parser can produce, written and parsed again, is the
//!   same model;
//! - arbitrary text (GSD-like token soup, random edits of the real files)
//!   never makes the parser panic, in either mode, and whatever it parses
//!   survives write → parse unchanged.

use profibus_dp::config::gsd::*;
use proptest::prelude::*;
use proptest::sample::select;

// ---- models ----

/// Text the writer can represent: printable ASCII and some Latin-1
/// letters, no `"`.
fn text() -> impl Strategy<Value = String> {
    "[ !#-~äöüÄÖÜß°µ]{0,24}"
}

fn opt_text() -> impl Strategy<Value = Option<String>> {
    proptest::option::of(text())
}

/// One configuration identifier that decodes.
fn identifier() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        any::<u8>().prop_map(|b| vec![b | 0x10]),
        Just(vec![0x00]),
        (1u8..=3, 0u8..=3, any::<[u8; 5]>()).prop_map(|(kind, mfr, b)| {
            let lens = if kind == 3 { 2 } else { 1 };
            let mut v = vec![kind << 6 | mfr];
            v.extend_from_slice(&b[..lens]);
            v.extend(std::iter::repeat_n(0xA5, mfr as usize));
            v
        }),
    ]
}

fn cfg() -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(identifier(), 1..4).prop_map(|v| v.concat())
}

fn prm_const() -> impl Strategy<Value = PrmConst> {
    (0u16..300, prop::collection::vec(any::<u8>(), 1..6))
        .prop_map(|(offset, data)| PrmConst { offset, data })
}

fn prm_ref() -> impl Strategy<Value = PrmRef> {
    (0u16..300, 0u16..8).prop_map(|(offset, reference)| PrmRef { offset, reference })
}

fn data_type() -> impl Strategy<Value = PrmDataType> {
    prop_oneof![
        Just(PrmDataType::Unsigned8),
        Just(PrmDataType::Unsigned16),
        Just(PrmDataType::Unsigned32),
        Just(PrmDataType::Signed8),
        Just(PrmDataType::Signed16),
        Just(PrmDataType::Signed32),
        (0u8..8).prop_map(PrmDataType::Bit),
        (0u8..8, 0u8..8).prop_map(|(a, b)| PrmDataType::BitArea(a.min(b), a.max(b))),
    ]
}

fn allowed() -> impl Strategy<Value = Allowed> {
    prop_oneof![
        Just(Allowed::Any),
        (-70000i64..70000, 0i64..70000).prop_map(|(a, d)| Allowed::Range(a, a + d)),
        prop::collection::vec(-70000i64..70000, 1..4).prop_map(Allowed::Values),
    ]
}

fn ext_prm() -> impl Strategy<Value = ExtUserPrmData> {
    (
        0u16..8,
        text(),
        data_type(),
        any::<u32>(),
        allowed(),
        proptest::option::of(0u16..4),
        proptest::option::of(any::<bool>()),
        proptest::option::of(any::<bool>()),
    )
        .prop_map(
            |(reference, name, data_type, d, allowed, prm_text_ref, changeable, visible)| {
                let (lo, hi) = data_type.limits();
                let default = lo + (d as i64).rem_euclid(hi - lo + 1);
                ExtUserPrmData {
                    reference,
                    name,
                    data_type,
                    default,
                    allowed,
                    prm_text_ref,
                    changeable,
                    visible,
                }
            },
        )
}

fn value_texts() -> impl Strategy<Value = Vec<PrmTextValue>> {
    prop::collection::vec(
        (-1_000_000i64..1_000_000, text()).prop_map(|(value, text)| PrmTextValue { value, text }),
        0..4,
    )
}

fn other_lines(prefix: &'static str) -> impl Strategy<Value = Vec<String>> {
    prop::collection::vec(
        (0u32..100, any::<u16>()).prop_map(move |(n, v)| format!("{prefix}{n}={v}")),
        0..3,
    )
}

fn module() -> impl Strategy<Value = Module> {
    (
        (text(), cfg(), proptest::option::of(any::<u32>())),
        proptest::option::of(any::<u8>()),
        prop::collection::vec(prm_const(), 0..2),
        prop::collection::vec(prm_ref(), 0..2),
        any::<bool>(),
        opt_text(),
        other_lines("X_Module_Key"),
    )
        .prop_map(
            |((name, cfg, reference), len, consts, refs, preset, info_text, other)| Module {
                name,
                cfg,
                reference,
                ext_module_prm_data_len: len,
                ext_user_prm_data_const: consts,
                ext_user_prm_data_ref: refs,
                preset,
                info_text,
                other,
            },
        )
}

fn slot() -> impl Strategy<Value = Slot> {
    (any::<u8>(), text(), any::<u32>(), allowed()).prop_map(
        |(number, name, default_module, allowed)| Slot {
            number,
            name,
            default_module,
            allowed: match allowed {
                Allowed::Any => Allowed::Values(vec![1]),
                Allowed::Range(a, b) => Allowed::Range(a.abs(), a.abs() + (b - a)),
                Allowed::Values(v) => Allowed::Values(v.into_iter().map(i64::abs).collect()),
            },
        },
    )
}

fn diag_texts() -> impl Strategy<Value = Vec<UnitDiagText>> {
    prop::collection::vec(
        (any::<u32>(), text()).prop_map(|(bit, text)| UnitDiagText { bit, text }),
        0..3,
    )
}

fn family() -> impl Strategy<Value = Option<SlaveFamily>> {
    proptest::option::of(
        (
            any::<u8>(),
            prop::collection::vec("[A-Za-z0-9._-]{0,8}", 0..3),
        )
            .prop_map(|(main, sub)| SlaveFamily { main, sub }),
    )
}

fn gsd() -> impl Strategy<Value = Gsd> {
    let identity = (
        proptest::option::of(any::<u8>()),
        (opt_text(), opt_text(), opt_text()),
        proptest::option::of(any::<u8>()),
        any::<u16>(),
        any::<u8>(),
        any::<u8>(),
        any::<bool>(),
        (opt_text(), opt_text(), opt_text(), opt_text()),
    );
    let bus = (
        prop::array::uniform11((any::<bool>(), proptest::option::of(any::<u16>()))).prop_map(|a| {
            a.map(|(supported, max_tsdr)| BaudRate {
                supported,
                max_tsdr,
            })
        }),
        any::<bool>(),
        proptest::option::of(any::<u8>()),
        proptest::option::of(any::<u8>()),
        (opt_text(), opt_text(), opt_text(), opt_text()),
    );
    let slave = (
        any::<[bool; 6]>(),
        proptest::option::of(any::<u16>()),
        proptest::option::of(any::<u8>()),
        family(),
        prop::array::uniform4(proptest::option::of(any::<u8>())),
        proptest::option::of(any::<u16>()),
    );
    let prm = (
        proptest::option::of(any::<u8>()),
        proptest::option::of(prop::collection::vec(any::<u8>(), 1..12)),
        proptest::option::of(any::<u8>()),
        prop::collection::vec(prm_const(), 0..3),
        prop::collection::vec(prm_ref(), 0..3),
        prop::collection::vec(ext_prm(), 0..4),
        prop::collection::vec(
            (0u16..4, value_texts()).prop_map(|(reference, texts)| PrmText { reference, texts }),
            0..3,
        ),
    );
    let dpv1 = (
        any::<[bool; 12]>(),
        prop::array::uniform4(proptest::option::of(any::<u8>())),
        proptest::option::of(any::<u16>()),
        proptest::option::of(any::<u16>()),
    );
    let rest = (
        prop::collection::vec(module(), 0..4),
        prop::collection::vec(slot(), 0..3),
        diag_texts(),
        diag_texts(),
        prop::collection::vec(
            (any::<u32>(), 0u32..100, value_texts()).prop_map(|(first, d, values)| UnitDiagArea {
                first,
                last: first.saturating_add(d),
                values,
            }),
            0..2,
        ),
        other_lines("X_Vendor_Key"),
    );
    (identity, bus, slave, prm, dpv1, rest).prop_map(|(identity, bus, slave, prm, dpv1, rest)| {
        let (
            gsd_revision,
            (vendor_name, model_name, revision),
            revision_number,
            ident_number,
            protocol_ident,
            station_type,
            fms_supp,
            (hardware_release, software_release, order_number, info_text),
        ) = identity;
        let (
            baud_rates,
            redundancy,
            repeater_ctrl_sig,
            pins_24v,
            (implementation_type, bitmap_device, bitmap_diag, bitmap_sf),
        ) = bus;
        let (
            flags,
            min_slave_intervall,
            max_diag_data_len,
            slave_family,
            [max_module, max_input_len, max_output_len, modul_offset],
            max_data_len,
        ) = slave;
        let (
            user_prm_data_len,
            user_prm_data,
            max_user_prm_data_len,
            ext_user_prm_data_const,
            ext_user_prm_data_ref,
            ext_user_prm_data,
            prm_texts,
        ) = prm;
        let (
            f,
            [c1_max_data_len, c2_max_data_len, c2_max_count_channels, max_initiate_pdu_length],
            c1_response_timeout,
            c2_response_timeout,
        ) = dpv1;
        let (modules, slots, unit_diag_bits, unit_diag_not_bits, unit_diag_areas, other) = rest;
        Gsd {
            gsd_revision,
            vendor_name,
            model_name,
            revision,
            revision_number,
            ident_number,
            protocol_ident,
            station_type,
            fms_supp,
            hardware_release,
            software_release,
            order_number,
            info_text,
            baud_rates,
            redundancy,
            repeater_ctrl_sig,
            pins_24v,
            implementation_type,
            bitmap_device,
            bitmap_diag,
            bitmap_sf,
            freeze_mode_supp: flags[0],
            sync_mode_supp: flags[1],
            auto_baud_supp: flags[2],
            set_slave_add_supp: flags[3],
            fail_safe: flags[4],
            min_slave_intervall,
            max_diag_data_len,
            slave_family,
            modular_station: flags[5],
            max_module,
            max_input_len,
            max_output_len,
            max_data_len,
            modul_offset,
            fix_preset_modules: f[11],
            user_prm_data_len,
            user_prm_data,
            max_user_prm_data_len,
            ext_user_prm_data_const,
            ext_user_prm_data_ref,
            ext_user_prm_data,
            prm_texts,
            dpv1_slave: f[0],
            c1_read_write_supp: f[1],
            c1_read_write_required: f[2],
            c1_max_data_len,
            c1_response_timeout,
            c2_read_write_supp: f[3],
            c2_max_data_len,
            c2_response_timeout,
            c2_max_count_channels,
            max_initiate_pdu_length,
            wd_base_1ms_supp: f[4],
            check_cfg_mode: f[5],
            diagnostic_alarm_supp: f[6],
            process_alarm_supp: f[7],
            pull_plug_alarm_supp: f[8],
            status_alarm_supp: f[9],
            update_alarm_supp: f[10],
            manufacturer_specific_alarm_supp: f[11] && f[0],
            alarm_type_mode_supp: f[6] && f[7],
            alarm_sequence_mode_count: c2_max_count_channels,
            modules,
            slots,
            unit_diag_bits,
            unit_diag_not_bits,
            unit_diag_areas,
            other,
        }
    })
}

// ---- text ----

/// GSD-like text: keywords, punctuation, numbers, line breaks and a few
/// odd characters, in any order.
fn token_soup() -> impl Strategy<Value = String> {
    let tokens = select(vec![
        "#Profibus_DP\n",
        ";#Profibus_DP\n",
        "#Other\n",
        "Ident_Number=",
        "0x",
        "0X",
        "1",
        "255",
        "-",
        "9999999999999999999999",
        ",",
        "=",
        "(",
        ")",
        "\"",
        "'",
        ";",
        "\\\n",
        "\n",
        "\r",
        "\r\n",
        " ",
        "\t",
        "Module=\"m\" ",
        "Modules='m' ",
        "EndModule\n",
        "ExtUserPrmData=1 \"p\"\n",
        "EndExtUserPrmData\n",
        "Unsigned8 ",
        "Signed16 ",
        "Bit(",
        "BitArea(",
        "Prm_Text_Ref=",
        "PrmText=1\n",
        "Text(",
        "EndPrmText\n",
        "Ext_User_Prm_Data_Const(",
        "Ext_User_Prm_Data_Ref(",
        "User_Prm_Data=",
        "Max_User_Prm_Data_Len=",
        "MaxTsdr_12M=",
        "MaxTsd_1.5M=",
        "12M_supp=",
        "UnitDiagType=1\n",
        "EndUnitDiagType\n",
        "Data_Area_Beg\n",
        "Data_Area_End\n",
        "SlotDefinition\n",
        "Slot(",
        "EndSlotDefinition\n",
        "Unit_Diag_Area=",
        "Value(",
        "Unit_Diag_Area_End\n",
        "Unit_Diag_Bit(",
        "Slave_Family=",
        "@",
        "Vendor_Name=",
        "=====\n",
        "é",
        "\u{0}",
        "\u{FEFF}",
        "\u{a0}",
        "Ω",
        "0xC0,81,81",
        "Preset=1\n",
    ]);
    prop::collection::vec(tokens, 0..80).prop_map(|v| v.concat())
}

/// The real files, with random edits.
fn edited_file() -> impl Strategy<Value = String> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../devices/gsd");
    let mut texts = Vec::new();
    for d in [dir.clone(), dir.join("corpus")] {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if profibus_dp::config::gsd::is_gsd_file_name(&p) {
                texts.push(decode_latin1(&std::fs::read(p).unwrap()));
            }
        }
    }
    let edits = prop::collection::vec(
        (any::<prop::sample::Index>(), 0usize..4, "(?s).{0,3}"),
        0..12,
    );
    (select(texts), edits).prop_map(|(mut t, edits)| {
        for (at, cut, ins) in edits {
            let chars: Vec<char> = t.chars().collect();
            let i = at.index(chars.len() + 1);
            let j = (i + cut).min(chars.len());
            t = chars[..i]
                .iter()
                .chain(ins.chars().collect::<Vec<_>>().iter())
                .chain(&chars[j..])
                .collect();
        }
        t
    })
}

/// Parse in both modes without panicking; what parses must round-trip.
fn check_text(text: &str) -> Result<(), TestCaseError> {
    for opts in [ParseOptions::LENIENT, ParseOptions::STRICT] {
        match Gsd::parse(text, opts) {
            Ok(p) => {
                if p.gsd.is_writable() {
                    let written = p.gsd.write();
                    let again = Gsd::parse(&written, ParseOptions::LENIENT).map_err(|e| {
                        TestCaseError::fail(format!("written text does not parse: {e}\n{written}"))
                    })?;
                    prop_assert_eq!(&again.gsd, &p.gsd, "{}", written);
                }
            }
            Err(e) => prop_assert!(!e.errors.is_empty()),
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn write_then_parse_gives_the_model(g in gsd()) {
        let text = g.write();
        let p = Gsd::parse(&text, ParseOptions::LENIENT)
            .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
        prop_assert_eq!(&p.gsd, &g, "{}", text);
        // Latin-1 bytes read back the same way.
        prop_assert_eq!(decode_latin1(&g.write_latin1()), text);
    }

    #[test]
    fn token_soup_never_panics(t in token_soup()) {
        check_text(&t)?;
    }

    #[test]
    fn arbitrary_text_never_panics(t in "(?s).{0,300}") {
        check_text(&t)?;
    }

    #[test]
    fn edited_real_files_never_panic(t in edited_file()) {
        check_text(&t)?;
    }
}
