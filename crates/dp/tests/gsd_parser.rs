//! GSD parser behaviour: syntax, errors with positions, strict and lenient
//! mode, limits on input size.

use profibus_dp::config::gsd::{
    decode_latin1, encode_latin1, Allowed, DiagKind, Gsd, GsdError, ParseOptions, Parsed,
    PrmDataType, Quirk, MAX_FILE_LEN, MAX_LINE_LEN,
};

const HEAD: &str =
    "#Profibus_DP\nGSD_Revision=3\nVendor_Name=\"V\"\nModel_Name=\"M\"\nIdent_Number=0x1234\n";

fn lenient(text: &str) -> Parsed {
    Gsd::parse(text, ParseOptions::LENIENT).unwrap_or_else(|e| panic!("{e:?}"))
}

fn strict(text: &str) -> Parsed {
    Gsd::parse(text, ParseOptions::STRICT).unwrap_or_else(|e| panic!("{e:?}"))
}

fn strict_err(text: &str) -> GsdError {
    Gsd::parse(text, ParseOptions::STRICT).expect_err("expected an error")
}

#[test]
fn keywords_numbers_strings_comments_continuations() {
    let text = format!(
        "{HEAD}ident_number = 0X00d0 ; comment\n\
         FREEZE_MODE_SUPP=1\n\
         Info_Text = \"a ; not a comment\" ; a comment\n\
         MaxTsdr_1.5M=150\n1.5m_SUPP = 1\n\
         Module = \"m\" 0xC0,\\\n   81, 0x51 ; decimal 81 after hex\n\
         EndModule\n"
    );
    let g = strict(&text).gsd;
    assert_eq!(g.ident_number, 0x00D0);
    assert!(g.freeze_mode_supp);
    assert_eq!(g.info_text.as_deref(), Some("a ; not a comment"));
    assert_eq!(g.max_tsdr(profibus_fdl::timing::Baud::B1500000), Some(150));
    assert_eq!(g.supported_bauds(), [profibus_fdl::timing::Baud::B1500000]);
    assert_eq!(g.modules[0].cfg, [0xC0, 81, 0x51]);
}

#[test]
fn signed_parameters_and_bit_areas() {
    // profirust's parser rejects a negative Signed16 default; we read it.
    let text = format!(
        "{HEAD}ExtUserPrmData=1 \"Offset\"\nSigned16 -100 -1000-1000\nEndExtUserPrmData\n\
         ExtUserPrmData=2 \"Neg\"\nSigned8 -5 -128--1\nEndExtUserPrmData\n\
         ExtUserPrmData=3 \"Area\"\nBitArea( 2 - 4 ) 3 1,3,5\nEndExtUserPrmData\n\
         ExtUserPrmData=4 \"Big\"\nUnsigned32 0xFFFFFFFF\nEndExtUserPrmData\n\
         Ext_User_Prm_Data_Const(0)=0x00,0x00,0x00\n\
         Ext_User_Prm_Data_Ref(0)=1\nExt_User_Prm_Data_Ref(2)=2\n"
    );
    let g = strict(&text).gsd;
    let p = &g.ext_user_prm_data;
    assert_eq!(
        (p[0].data_type, p[0].default),
        (PrmDataType::Signed16, -100)
    );
    assert_eq!(p[0].allowed, Allowed::Range(-1000, 1000));
    assert_eq!(p[1].allowed, Allowed::Range(-128, -1));
    assert_eq!(p[2].data_type, PrmDataType::BitArea(2, 4));
    assert_eq!(p[2].allowed, Allowed::Values(vec![1, 3, 5]));
    assert_eq!(
        (p[3].default, p[3].allowed.clone()),
        (0xFFFF_FFFF, Allowed::Any)
    );
    assert_eq!(g.user_prm_data(&[], &[]).unwrap(), [0xFF, 0x9C, 0xFB]);
}

#[test]
fn errors_carry_line_column_and_expectation() {
    let e = strict_err(&format!("{HEAD}Max_Module=x\n"));
    let d = e.first();
    assert_eq!((d.pos.line, d.pos.col), (6, 12));
    assert_eq!(d.kind, DiagKind::Syntax);
    assert_eq!(d.message, "expected a number for `Max_Module`, found `x`");

    let e = strict_err(&format!("{HEAD}Module=\"m\" 0x10,0x1FF\nEndModule\n"));
    assert_eq!((e.first().pos.line, e.first().pos.col), (6, 17));
    assert!(
        e.first().message.contains("outside 0..=255"),
        "{}",
        e.first()
    );

    let e = strict_err(&format!("{HEAD}Vendor_Name=\"open\n"));
    assert!(e.first().message.contains("not closed"), "{}", e.first());

    let e = strict_err(&format!(
        "{HEAD}ExtUserPrmData=1 \"p\"\nUnsigned8 1 5-2\nEndExtUserPrmData\n"
    ));
    let d = e
        .errors
        .iter()
        .find(|d| d.kind == DiagKind::Syntax)
        .unwrap();
    assert_eq!((d.pos.line, d.pos.col), (7, 13));
    assert_eq!(d.message, "the range 5-2 is empty");

    // Several errors are all reported, in file order; Display names the
    // first and counts the rest.
    let e = strict_err(&format!(
        "{HEAD}Max_Module=300\nMax_Input_Len=-1\nSync_Mode_supp=\n"
    ));
    assert_eq!(e.errors.len(), 3);
    assert_eq!(
        e.to_string(),
        "6:12: a number for `Max_Module` 300 is outside 0..=255 (and 2 more errors)"
    );
    // A continuation line maps positions back to its own line.
    let e = strict_err(&format!("{HEAD}Module=\"m\" 0x10,\\\n  0xZZ\nEndModule\n"));
    assert_eq!((e.first().pos.line, e.first().pos.col), (7, 3));

    let e = strict_err("#Profibus_DP\nGSD_Revision=1\n");
    assert_eq!(e.first().message, "the file has no `Ident_Number`");
}

#[test]
fn quirks_are_warnings_when_lenient_and_errors_when_strict() {
    let cases: &[(&str, Quirk)] = &[
        (";#Profibus_DP\nIdent_Number=1\n", Quirk::CommentedSectionHeader),
        ("Ident_Number=1\n", Quirk::MissingSectionHeader),
        ("#Profibus_DP\nIdent_Number=1\nMaxTsd_12M=800\n", Quirk::MaxTsdSpelling),
        ("#Profibus_DP\nIdent_Number=1\nModules=\"a\" 0x10\nEndModule\n", Quirk::ModulesKeyword),
        ("#Profibus_DP\nIdent_Number=1\nModule='a' 0x10\nEndModule\n", Quirk::SingleQuotes),
        ("#Profibus_DP\nIdent_Number=1\nVendor_Name=ACME GmbH\n", Quirk::UnquotedString),
        ("#Profibus_DP\nIdent_Number=1\n=====\n", Quirk::StrayText),
        ("#Profibus_DP\nIdent_Number=1\nModule=\"a\" 0x10\n", Quirk::MissingEnd),
        ("#Profibus_DP\nIdent_Number=1\nModule=\"a\" 0x10\nModule=\"b\" 0x20\nEndModule\n", Quirk::MissingEnd),
        ("#Profibus_DP\nIdent_Number=1\nEndModule\n", Quirk::UnmatchedEnd),
        ("#Profibus_DP\nIdent_Number=1\nSync_Mode_supp=2\n", Quirk::BadBoolean),
        ("#Profibus_DP\nIdent_Number=1\nExt_User_Prm_Data_Ref(0)=7\n", Quirk::DanglingReference),
        ("#Profibus_DP\nIdent_Number=1\nModule=\"a\" 0x4F\nEndModule\n", Quirk::BadIdentifier),
        ("#Profibus_DP\nIdent_Number=1\nExtUserPrmData=1 \"x\"\nFloat32 1\nEndExtUserPrmData\n", Quirk::BadParameter),
        ("#Profibus_DP\nIdent_Number=1\nExtUserPrmData=1 \"x\"\nUnsigned8 300\nEndExtUserPrmData\n", Quirk::BadParameter),
    ];
    for (text, quirk) in cases {
        let p = Gsd::parse(text, ParseOptions::LENIENT)
            .unwrap_or_else(|e| panic!("lenient {quirk:?}: {e}"));
        assert!(
            p.warnings.iter().any(|w| w.kind == DiagKind::Quirk(*quirk)),
            "{quirk:?}: {:?}",
            p.warnings
        );
        let e = Gsd::parse(text, ParseOptions::STRICT).expect_err(&format!("strict {quirk:?}"));
        assert!(
            e.errors.iter().any(|d| d.kind == DiagKind::Quirk(*quirk)),
            "{quirk:?}: {:?}",
            e.errors
        );
    }
    // What lenient mode makes of the quirks.
    let g = lenient("Modules = 'a b' 0x10\nEndModule\nIdent_Number=7\nMaxTsd_12M=800\n").gsd;
    assert_eq!((g.modules[0].name.as_str(), g.ident_number), ("a b", 7));
    assert_eq!(g.max_tsdr(profibus_fdl::timing::Baud::B12000000), Some(800));
    let g = lenient("#Profibus_DP\nIdent_Number=1\nModule=\"a\" 0x10\nModule=\"b\" 0x20\n").gsd;
    assert_eq!(g.modules.len(), 2);
}

#[test]
fn repeated_quirks_fold_into_one_warning() {
    let mut text = String::from("#Profibus_DP\nIdent_Number=1\n");
    for i in 0..10 {
        text.push_str(&format!("Modules=\"m{i}\" 0x10\nEndModule\n"));
    }
    let p = lenient(&text);
    let q: Vec<_> = p
        .warnings
        .iter()
        .filter(|w| w.kind == DiagKind::Quirk(Quirk::ModulesKeyword))
        .collect();
    assert_eq!(q.len(), 4);
    assert!(
        q[3].message.contains("7 more line(s): 9, 11, 13"),
        "{}",
        q[3].message
    );
    assert_eq!(p.gsd.modules.len(), 10);
}

#[test]
fn unknown_keywords_and_blocks_are_kept() {
    let text = format!(
        "{HEAD}Vendor_Specific_Thing=42\n\
         UnitDiagType=5\nX_Unit_Diag_Bit(3)=\"x\"\nEndUnitDiagType\n\
         Module=\"m\" 0x10\n7\nData_Area_Beg\nArea_Name=\"a\"\nData_Area_End\nSomething_Else=1\nEndModule\n\
         Unit_Diag_Bit(3)=\"real\"\n"
    );
    let p = strict(&text);
    let g = &p.gsd;
    assert_eq!(
        g.other,
        [
            "Vendor_Specific_Thing=42",
            "UnitDiagType=5",
            "X_Unit_Diag_Bit(3)=\"x\"",
            "EndUnitDiagType"
        ]
    );
    assert_eq!(
        g.unit_diag_bits.len(),
        1,
        "the block's lines are not read as station keywords"
    );
    assert_eq!(g.modules[0].reference, Some(7));
    assert_eq!(
        g.modules[0].other,
        [
            "Data_Area_Beg",
            "Area_Name=\"a\"",
            "Data_Area_End",
            "Something_Else=1"
        ]
    );
    let unknown: Vec<_> = p
        .warnings
        .iter()
        .filter(|w| w.kind == DiagKind::UnknownKeyword)
        .map(|w| w.pos.line)
        .collect();
    assert_eq!(unknown, [6, 15]);
    // Written back and read again: the same model.
    assert_eq!(strict(&g.write()).gsd, *g);
}

#[test]
fn section_boundaries() {
    // Text before the header is not read; another section ends this one.
    let p = strict("junk = \"x\n#Profibus_DP\nIdent_Number=1\n#Profibus_PA\nIdent_Number=2\n");
    assert_eq!(p.gsd.ident_number, 1);
    assert!(p
        .warnings
        .iter()
        .any(|w| w.message.contains("another section")));
    // Lone CR line ends (old Mac files) and a UTF-8 byte order mark.
    let p = strict("\u{FEFF}#Profibus_DP\rIdent_Number=3\rModule=\"m\" 0x10\rEndModule\r");
    assert_eq!((p.gsd.ident_number, p.gsd.modules.len()), (3, 1));
}

#[test]
fn latin1_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.gsd");
    let mut bytes = b"#Profibus_DP\r\nIdent_Number=1\r\nVendor_Name=\"Baum".to_vec();
    bytes.push(0xFC); // ü in Latin-1
    bytes.extend_from_slice(b"ller\"\r\n");
    std::fs::write(&path, &bytes).unwrap();
    let g = Gsd::from_file(&path, ParseOptions::STRICT).unwrap().gsd;
    assert_eq!(g.vendor_name.as_deref(), Some("Baumüller"));
    assert!(g.write_latin1().windows(9).any(|w| w == b"Baum\xFCller"));
    // Errors name the file.
    std::fs::write(&path, b"#Profibus_DP\nIdent_Number=zz\n").unwrap();
    let e = Gsd::from_file(&path, ParseOptions::STRICT).unwrap_err();
    assert!(
        e.to_string()
            .starts_with(&format!("{}:2:14: ", path.display())),
        "{e}"
    );
}

#[test]
fn oversized_input_is_refused() {
    // A 100 MB file (sparse: nothing is written) is refused from its
    // length, without being read (how fast: `cargo bench -p profibus-dp
    // --bench gsd`).
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.gsd");
    std::fs::File::create(&path)
        .unwrap()
        .set_len(100 << 20)
        .unwrap();
    let e = Gsd::from_file(&path, ParseOptions::LENIENT).unwrap_err();
    assert_eq!(e.first().kind, DiagKind::TooLarge);
    drop(dir);

    // Text in memory: over the file limit, refused before parsing.
    let big = "a".repeat(MAX_FILE_LEN + 1);
    let e = Gsd::parse(&big, ParseOptions::LENIENT).unwrap_err();
    assert_eq!(e.first().kind, DiagKind::TooLarge);

    // One line of 10 MB in a text under the file limit cannot exist, so
    // test a line just over the line limit, and a 10 MB line given as
    // text (refused by the file limit).
    let long = format!(
        "#Profibus_DP\nIdent_Number=1\nInfo_Text=\"{}\"\n",
        "x".repeat(MAX_LINE_LEN)
    );
    let e = Gsd::parse(&long, ParseOptions::LENIENT).unwrap_err();
    assert_eq!(
        (e.first().kind, e.first().pos.line),
        (DiagKind::TooLarge, 3)
    );
    let line10m = format!("#Profibus_DP\n{}", "y".repeat(10 << 20));
    assert_eq!(
        Gsd::parse(&line10m, ParseOptions::LENIENT)
            .unwrap_err()
            .first()
            .kind,
        DiagKind::TooLarge
    );
    // Continuations cannot build a logical line over the limit either.
    let mut cont = String::from("#Profibus_DP\nIdent_Number=1\nUser_Prm_Data=0x00");
    for _ in 0..(MAX_LINE_LEN / 8 + 10) {
        cont.push_str(",\\\n0x01,0x02");
    }
    let e = Gsd::parse(&cont, ParseOptions::LENIENT).unwrap_err();
    assert_eq!(e.first().kind, DiagKind::TooLarge);
}

#[test]
fn module_lookup() {
    let g = strict(&format!(
        "{HEAD}Module=\"INPUT (consistent) : 4 words\" 0xD3\nEndModule\n\
         Module=\"INPUT : 4 words\" 0x53\nEndModule\nModule=\"OUTPUT : 4 words\" 0x63\nEndModule\n"
    ))
    .gsd;
    assert_eq!(g.module("INPUT : 4 words").unwrap().cfg, [0x53]);
    assert!(g.module("input : 4 words").is_none());
    // Names match exactly: a near name is an error naming the closest.
    for near in ["input : 4 words", "OUTPUT", "INPUT (consistnet) : 4 words"] {
        assert!(g.find_module(near).is_err(), "{near}");
    }
    let e = g.find_module("INPUT (consistnet) : 4 words").unwrap_err();
    assert_eq!(
        e.to_string(),
        "no module named `INPUT (consistnet) : 4 words`; did you mean `INPUT (consistent) : 4 words`?"
    );
    let e = g.find_module("OUTPUT").unwrap_err();
    assert!(
        e.to_string().ends_with("did you mean `OUTPUT : 4 words`?"),
        "{e}"
    );
    let e = g.find_module("temperature").unwrap_err();
    assert!(
        e.to_string().starts_with("no module named `temperature`"),
        "{e}"
    );
}

#[test]
fn continuation_after_an_empty_piece() {
    // Found by the fuzzer: ` \` followed by an indented line used to keep
    // the indentation, so the line read differently once written back.
    let text = "#Profibus_DP\nIdent_Number=1\n \\\n    Vendor_Key=\"x\"\n\
                Module=\"m\" 0x10\n \\\n  7\nEndModule\n";
    let p = strict(text);
    assert_eq!(p.gsd.other, ["Vendor_Key=\"x\""]);
    assert_eq!(p.gsd.modules[0].reference, Some(7));
    assert_eq!(p.warnings[0].pos.line, 4);
    assert_eq!(p.warnings[0].pos.col, 5);
    assert_eq!(strict(&p.gsd.write()).gsd, p.gsd);
}

#[test]
fn strings_continued_over_lines_then_a_comment() {
    // The Siemens CP 342-5 files continue an `Info_Text` string with `\`
    // over several lines and put a `; comment` after the closing quote:
    // the quote on the last continuation line closes the string.
    let text = format!(
        "{HEAD}Info_Text=\"first part, \\\n  second part, \\\n  last part\" ; comment\n\
         Module=\"m\" 0x10\nEndModule\n"
    );
    let g = strict(&text).gsd;
    assert_eq!(
        g.info_text.as_deref(),
        Some("first part,   second part,   last part")
    );
    assert_eq!(g.modules.len(), 1);

    // `;` inside the continued string is text, `;` after it a comment;
    // a continuation line outside a string still has its comment
    // removed.
    let text = format!(
        "{HEAD}Info_Text=\"a;b \\\n;c; \\\nd\";\"e\" \\\n\n\
         Module=\"m\" 0x10, \\\n 0x20 ; one; two \"three\n\
         EndModule\n\
         Model_Name=\"x;\\\ny\" ; z \"\n"
    );
    let g = strict(&text).gsd;
    assert_eq!(g.info_text.as_deref(), Some("a;b ;c; d"));
    assert_eq!(g.modules[0].cfg, [0x10, 0x20]);
    assert_eq!(g.model_name.as_deref(), Some("x;y"));
    // Positions still point into the right physical line.
    let e = strict_err(&format!("{HEAD}Info_Text=\"a;\\\nb\" x ; c\n"));
    assert_eq!(e.first().pos.line, 7);
    assert_eq!(e.first().pos.col, 4);
}

/// Warnings of `p` that mention `needle`.
fn warnings_with<'a>(p: &'a Parsed, needle: &str) -> Vec<&'a str> {
    p.warnings
        .iter()
        .filter(|w| w.message.contains(needle))
        .map(|w| w.message.as_str())
        .collect()
}

#[test]
fn compact_station_modules_are_alternatives() {
    use profibus_dp::config::gsd::Problem;
    // A drive that offers three PPO types: one is configured, never the
    // three together, so their sizes are not added.
    let text = format!(
        "{HEAD}Max_Input_Len=20\nMax_Output_Len=20\n\
         Module=\"PPO 1\" 0xF3,0xF1\nEndModule\n\
         Module=\"PPO 2\" 0xF3,0xF5\nEndModule\n\
         Module=\"PPO 3\" 0xF5\nEndModule\n"
    );
    let p = strict(&text);
    assert!(
        p.warnings.iter().all(|w| w.kind != DiagKind::Semantic),
        "{:?}",
        p.warnings
    );
    let g = p.gsd;
    assert!(!g.modular_station);
    assert_eq!(g.default_selection(), [0]);
    for i in 0..3 {
        assert_eq!(g.check_selection(&[i]), vec![], "module {i}");
    }
    // All three in file order is the other reading of such a file: it
    // breaks the limits here.
    assert_eq!(g.check_selection(&[0, 1, 2]).len(), 2);
    let two = g.check_selection(&[0, 2]);
    assert!(
        matches!(two.as_slice(), [Problem::FixedConfiguration { .. }]),
        "{two:?}"
    );
    assert_eq!(
        two[0].to_string(),
        "this is a compact station (no Modular_Station=1): it is configured with exactly \
         one of its modules (`PPO 1`, `PPO 2`, `PPO 3`), or all of them in file order"
    );
}

#[test]
fn max_module_without_modular_station_names_the_cause() {
    let modules: String = (0..6)
        .map(|i| format!("Module=\"M{i}\" 0x13\nEndModule\n"))
        .collect();
    let p = lenient(&format!("{HEAD}Max_Module=4\nMax_Input_Len=8\n{modules}"));
    let w = warnings_with(&p, "Max_Module");
    assert_eq!(w.len(), 1, "{:?}", p.warnings);
    assert!(
        w[0].contains("`Max_Module = 4` describes a modular station, but the file has no `Modular_Station = 1`")
            && w[0].contains("exactly one of its 6 modules"),
        "{w:?}"
    );
    assert_eq!(p.warnings[0].pos.line, 6);
    // Every module alone is a valid configuration: no limit is broken.
    for i in 0..6 {
        assert_eq!(p.gsd.check_selection(&[i]), vec![]);
    }
    // With `Modular_Station = 1` the file is consistent.
    let p = lenient(&format!(
        "{HEAD}Modular_Station=1\nMax_Module=4\nMax_Input_Len=8\n{modules}"
    ));
    assert!(warnings_with(&p, "Max_Module").is_empty());
    // `Modular_Station = 0` said outright is named as such.
    let p = lenient(&format!("{HEAD}Modular_Station=0\nMax_Module=4\n{modules}"));
    assert!(warnings_with(&p, "Max_Module")[0].contains("the file has `Modular_Station = 0`"));
}

#[test]
fn user_prm_data_shorter_or_longer_than_its_length() {
    let m = "Module=\"m\" 0x10\nEndModule\n";
    let p = strict(&format!(
        "{HEAD}User_Prm_Data_Len=40\nUser_Prm_Data=1,2,3,4,5,6,7,8\n{m}"
    ));
    assert_eq!(
        warnings_with(&p, "User_Prm_Data"),
        ["`User_Prm_Data_Len = 40` but `User_Prm_Data` gives only 8 byte(s); the other 32 byte(s) are sent as 0"]
    );
    assert_eq!(p.warnings[0].pos.line, 6);
    let prm = p.gsd.user_prm_data(&[0], &[]).unwrap();
    assert_eq!(prm.len(), 40);
    let p = strict(&format!(
        "{HEAD}User_Prm_Data_Len=2\nUser_Prm_Data=1,2,3\n{m}"
    ));
    assert_eq!(
        warnings_with(&p, "User_Prm_Data"),
        ["`User_Prm_Data` gives 3 bytes, more than `User_Prm_Data_Len = 2`; only the first 2 are sent"]
    );
    let p = strict(&format!("{HEAD}User_Prm_Data_Len=3\n{m}"));
    assert_eq!(
        warnings_with(&p, "User_Prm_Data"),
        ["`User_Prm_Data_Len = 3` but the file gives no `User_Prm_Data`; 3 zero byte(s) are sent"]
    );
    // Consistent files get no such warning.
    let p = strict(&format!(
        "{HEAD}User_Prm_Data_Len=2\nUser_Prm_Data=1,2\n{m}"
    ));
    assert!(warnings_with(&p, "User_Prm_Data").is_empty());
    let p = strict(&format!("{HEAD}User_Prm_Data_Len=0\n{m}"));
    assert!(warnings_with(&p, "User_Prm_Data").is_empty());
}

#[test]
fn keywords_of_the_standard_are_known() {
    // One line per group of the GSD specification (revisions 1–5): each
    // is kept as text without a warning; a vendor's own keyword is still
    // reported.
    let station = [
        "Fail_Safe_required = 1",
        "PrmCmd_supp = 1",
        "Diag_Update_Delay = 2",
        "Periphery = \"DPS\"",
        "C1_Read_Write_required = 0",
        "C2_Read_Write_required = 0",
        "Extra_Alarm_SAP_supp = 1",
        "Alarm_Sequence_Mode_Count = 2",
        "Alarm_Type_Mode_supp = 1",
        "Diagnostic_Alarm_required = 0",
        "Manufacturer_Specific_Alarm_required = 0",
        "DPV1_Data_Types = 0",
        "Prm_Block_Structure_supp = 1",
        "Prm_Block_Structure_req = 0",
        "Jokerblock_Slot = 3",
        "Jokerblock_Location = 1",
        "Max_iParameter_Size = 1024",
        "Publisher_supp = 1",
        "Subscriber_supp = 1",
        "DXB_Max_Link_Count = 10",
        "DXB_Max_Data_Length = 32",
        "DXB_Subscribertable_Block_Location = 1",
        "Isochron_Mode_supp = 1",
        "Isochron_Mode_required = 0",
        "TBASE_DP = 375",
        "TDP_MIN = 4",
        "TDP_MAX = 256",
        "T_PLL_W_MAX = 12",
        "TBASE_IO = 375",
        "TI_MIN = 1",
        "TO_MIN = 1",
        "Slave_Redundancy_supp = 0",
        "Slave_Max_Switch_Over_Time = 100",
        "Time_Sync_supp = 0",
        "Ident_Maintenance_supp = 1",
        "Subsys_Dir_Index = 1",
        "F_ParamDescCRC = 0x1234",
        "X_Prm_SAP_supp = 1",
        "X_Max_User_Prm_Data_Len = 100",
        "X_Prm_Block_Structure_supp = 1",
        "X_Unit_Diag_Bit(3) = \"x\"",
        "Unit_Diag_Bit_Help(3) = \"help\"",
        "Unit_Diag_Not_Bit_Help(3) = \"help\"",
        "Channel_Diag(16) = \"Error 16\"",
        "Channel_Diag_Help(16) = \"What to do\"",
        // A master's GSD file.
        "Master_Freeze_Mode_supp = 1",
        "Max_MPS_Length = 1000",
        "Min_Poll_Timeout = 10",
        "Trdy_1.5M = 11",
        "Tqui_12M = 9",
        "Tset_9.6 = 1",
        "Tsdi_500 = 70",
        "LAS_Len = 126",
        "Max_Slaves_supp = 125",
        "DPV1_Master = 1",
        "C1_Master_Read_Write_supp = 1",
        "Master_DPV1_Alarm_supp = 1",
        "Isochron_Mode_Synchronised = 1",
        "DXB_Master_supp = 0",
        "X_Master_Prm_SAP_supp = 0",
    ];
    let module = [
        "Channel_Diag(17) = \"Short circuit\"",
        "F_IO_StructureDescCRC = 0x12345678",
        "F_Ext_Module_Prm_Data_Len = 10",
        "X_Ext_Module_Prm_Data_Len = 4",
        "Subsys_Module_Dir_Index = 2",
    ];
    let text = format!(
        "{HEAD}{}\nVendor_Special = 1\nTrdy_2M = 1\nModule=\"m\" 0x10\n{}\nVendor_Module_Thing = 1\nEndModule\n",
        station.join("\n"),
        module.join("\n")
    );
    let p = strict(&text);
    let unknown: Vec<&str> = p
        .warnings
        .iter()
        .filter(|w| w.kind == DiagKind::UnknownKeyword)
        .map(|w| w.message.as_str())
        .collect();
    assert_eq!(
        unknown,
        [
            "unknown keyword `Vendor_Special`; kept, not interpreted",
            "unknown keyword `Trdy_2M`; kept, not interpreted",
            "unknown keyword `Vendor_Module_Thing` in a module; kept, not interpreted",
        ]
    );
    let g = &p.gsd;
    // Every line but `C1_Read_Write_required`, `Alarm_Sequence_Mode_Count`
    // and `Alarm_Type_Mode_supp` (in the model) is kept, with the two
    // unknown ones.
    assert_eq!(g.other.len(), station.len() - 3 + 2, "{:#?}", g.other);
    assert_eq!(g.alarm_sequence_mode_count, Some(2));
    assert!(g.alarm_type_mode_supp);
    assert!(!g.c1_read_write_required);
    assert_eq!(g.other_flag("fail_safe_required"), Some(true));
    assert_eq!(g.other_flag("PRMCMD_SUPP"), Some(true));
    assert_eq!(g.other_value("Slave_Max_Switch_Over_Time"), Some("100"));
    assert_eq!(g.other_flag("Time_Sync_supp"), Some(false));
    assert_eq!(g.other_value("Periphery"), Some("\"DPS\""));
    assert_eq!(g.other_flag("Isochron_Mode_required"), Some(false));
    assert_eq!(g.other_value("No_Such_Keyword"), None);
    assert_eq!(
        g.modules[0].other_value("F_IO_StructureDescCRC"),
        Some("0x12345678")
    );
    // Written back, the file reads the same.
    assert_eq!(strict(&g.write()).gsd, *g);
}

#[test]
fn a_compact_station_with_many_alternatives_names_a_few() {
    let modules: String = (0..9)
        .map(|i| format!("Module=\"PPO {i}\" 0xF1\nEndModule\n"))
        .collect();
    let g = strict(&format!("{HEAD}{modules}")).gsd;
    let p = g.check_selection(&[0, 1]);
    assert_eq!(
        p[0].to_string(),
        "this is a compact station (no Modular_Station=1): it is configured with exactly \
         one of its modules (`PPO 0`, `PPO 1`, `PPO 2`, `PPO 3`, `PPO 4`, `PPO 5`, … 9 in all), \
         or all of them in file order"
    );
}

#[test]
fn decode_latin1_maps_every_byte_to_its_character() {
    let all: Vec<u8> = (0..=255).collect();
    let text = decode_latin1(&all);
    assert!(text.chars().map(u32::from).eq(0..=255));
    assert_eq!(encode_latin1(&text), all);
    assert_eq!(
        decode_latin1(b"Model_Name=\"x\"\r\n"),
        "Model_Name=\"x\"\r\n"
    );
    assert_eq!(decode_latin1(b""), "");
    assert_eq!(decode_latin1(b"a\xB5b\xFF\x80"), "a\u{B5}b\u{FF}\u{80}");
}

#[test]
fn numbers_at_the_limits_of_64_bits() {
    // Values beyond the keyword's range are reported with the number;
    // beyond 64 bits as too large.
    for (value, message) in [
        ("9223372036854775807", "outside"),
        ("0x7FFFFFFFFFFFFFFF", "outside"),
        ("-9223372036854775807", "outside"),
        ("9223372036854775808", "too large"),
        ("0x8000000000000000", "too large"),
        ("-9223372036854775808", "too large"),
        ("0x10000000000000000", "too large"),
    ] {
        let e = strict_err(&format!("{HEAD}Max_Module={value}\n"));
        assert!(e.first().message.contains(message), "{value}: {e}");
    }
    assert_eq!(
        lenient(&format!("{HEAD}Max_Module=0x0000000000000000000FF\n"))
            .gsd
            .max_module,
        Some(255)
    );
    assert_eq!(
        lenient(&format!("{HEAD}Max_Module=+007\n")).gsd.max_module,
        Some(7)
    );
}

#[test]
fn references_and_duplicate_definitions_are_checked_in_file_order() {
    let def = |r: u16, default: u8, text: Option<u16>| {
        let text = text.map_or(String::new(), |t| format!("Prm_Text_Ref={t}\n"));
        format!("ExtUserPrmData={r} \"p{r}\"\nUnsigned8 {default} 0-3\n{text}EndExtUserPrmData\n")
    };
    let text = format!(
        "{HEAD}PrmText=5\nText(0)=\"off\"\nEndPrmText\n{}{}{}{}{}\
         Ext_User_Prm_Data_Ref(0)=1\nExt_User_Prm_Data_Ref(1)=9\n\
         Ext_User_Prm_Data_Ref(2)=2\nExt_User_Prm_Data_Ref(3)=9\n",
        def(1, 1, None),
        def(2, 2, Some(5)),
        def(1, 3, Some(6)),
        def(2, 3, None),
        def(1, 3, None),
    );
    let p = lenient(&text);
    let twice: Vec<&str> = p
        .warnings
        .iter()
        .filter(|w| w.message.contains("defined twice"))
        .map(|w| w.message.as_str())
        .collect();
    assert_eq!(
        twice,
        [
            "`ExtUserPrmData` 1 is defined twice; the first definition counts",
            "`ExtUserPrmData` 2 is defined twice; the first definition counts",
            "`ExtUserPrmData` 1 is defined twice; the first definition counts",
        ]
    );
    let dangling: Vec<(u32, &str)> = p
        .warnings
        .iter()
        .filter(|w| w.kind == DiagKind::Quirk(Quirk::DanglingReference))
        .map(|w| (w.pos.line, w.message.as_str()))
        .collect();
    assert_eq!(
        dangling,
        [
            (
                18,
                "`Prm_Text_Ref` names `PrmText` 6, which the file does not define"
            ),
            (
                27,
                "`Ext_User_Prm_Data_Ref` names `ExtUserPrmData` 9, which the file does not define"
            ),
            (
                29,
                "`Ext_User_Prm_Data_Ref` names `ExtUserPrmData` 9, which the file does not define"
            ),
        ]
    );
    // The first definition of each number counts; references to none are
    // left out of the parameters.
    let g = &p.gsd;
    assert_eq!(g.user_prm_data(&[], &[]).unwrap(), [1, 0, 2]);
    let params = g.parameters(&[]).unwrap();
    let names: Vec<&str> = params.iter().map(|p| p.definition.name.as_str()).collect();
    assert_eq!(names, ["p1", "p2"]);
    assert_eq!(params[1].definition.prm_text_ref, Some(5));
    let e = strict_err(&text);
    assert_eq!(
        e.errors
            .iter()
            .filter(|d| d.kind == DiagKind::Quirk(Quirk::DanglingReference))
            .count(),
        3
    );
}
