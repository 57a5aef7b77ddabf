//! Commissioning from the live bus (issue 29), end to end on `dpctl bus`
//! with real `dpctl slave` processes: `dpctl scan --write-config` reads
//! each slave's Slave_Diag and Get_Cfg, finds its GSD in the library and
//! writes a bus file that `dpctl master --config` takes unchanged to
//! Data_Exchange; slaves it cannot configure are reported, not guessed;
//! the same scan from a second master while a first one holds every
//! slave in Data_Exchange.

mod common;

use common::{all_dx, dpctl, repo, Bus, Lines, Output, Proc, TempDir};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

const GUARD: Duration = Duration::from_secs(120);

fn gen_gsd() -> PathBuf {
    repo().join("crates/devices/gsd/DPCTL_GEN.GSD")
}

/// A GSD file with ident `ident`, compact or modular, with `modules`
/// (name, identifier bytes).
fn gsd_text(ident: u16, modular: bool, modules: &[(&str, &str)]) -> String {
    let mut t = format!(
        "#Profibus_DP\nGSD_Revision=3\nVendor_Name=\"test\"\nModel_Name=\"test 0x{ident:04X}\"\n\
         Ident_Number=0x{ident:04X}\nProtocol_Ident=0\nStation_Type=0\n\
         9.6_supp=1\n19.2_supp=1\n1.5M_supp=1\nMaxTsdr_9.6=60\nMaxTsdr_19.2=60\nMaxTsdr_1.5M=150\n\
         Auto_Baud_supp=1\nModular_Station={}\nMax_Module=4\nMax_Input_Len=64\n\
         Max_Output_Len=64\nMax_Data_Len=128\n",
        modular as u8
    );
    for (name, bytes) in modules {
        t.push_str(&format!("Module=\"{name}\" {bytes}\nEndModule\n"));
    }
    t
}

/// `dpctl gsd install FILES` with the user library under `data`.
fn install(data: &Path, files: &[&Path]) -> Output {
    let mut cmd = Command::new(dpctl());
    cmd.args(["gsd", "install"])
        .args(files)
        .env("XDG_DATA_HOME", data);
    Proc::spawn_captured(cmd).finish(GUARD)
}

#[test]
fn gsd_install_refuses_a_file_that_does_not_parse() {
    let dir = TempDir::new("gsd-install");
    let data = dir.path("data");
    let good = dir.path("GOOD.gsd");
    std::fs::write(&good, gsd_text(0x0DC7, false, &[("m", "0x10")])).unwrap();
    let bad = dir.path("BAD.gsd");
    std::fs::write(&bad, "#Profibus_DP\nIdent_Number=zz\n").unwrap();
    // One bad file: nothing is installed, the error has file:line:col.
    let out = install(&data, &[&good, &bad]);
    assert!(!out.status.success());
    assert_eq!(
        out.stderr.trim(),
        format!(
            "dpctl: {}:2:14: expected a number for `Ident_Number`, found `zz` (not installed)",
            bad.display()
        )
    );
    assert!(!data.join("dpctl/gsd/GOOD.gsd").exists());
    let out = install(&data, &[&good]);
    assert!(out.status.success(), "{}", out.stderr);
    assert_eq!(
        out.stdout.trim(),
        format!(
            "installed {} (ident 0x0DC7, test 0x0DC7)",
            data.join("dpctl/gsd/GOOD.gsd").display()
        )
    );
}

/// `dpctl slave` on link `i` at `addr` from `gsd` with `modules`.
fn slave(bus: &Bus, i: usize, addr: u8, gsd: &Path, modules: &[&str]) -> Proc {
    let mut cmd = Command::new(dpctl());
    cmd.args(["slave", "--port", &bus.link_str(i)])
        .args(["--addr", &addr.to_string(), "--gsd"])
        .arg(gsd);
    for m in modules {
        cmd.args(["--module", m]);
    }
    Proc::spawn(
        &format!("dpctl slave {addr}"),
        cmd.stdout(Stdio::null()).stderr(Stdio::null()),
    )
}

/// `dpctl scan --write-config` from link `i` at address `addr`.
fn scan(bus: &Bus, i: usize, addr: u8, gsd_dir: &Path, out: &Path, data: &Path) -> Output {
    let mut cmd = Command::new(dpctl());
    cmd.args([
        "scan",
        "--json",
        "--latency",
        "50",
        "--addr",
        &addr.to_string(),
    ])
    .args(["--port", &bus.link_str(i), "--gsd-dir"])
    .arg(gsd_dir)
    .arg("--write-config")
    .arg(out)
    // An empty user library of the test's own.
    .env("XDG_DATA_HOME", data);
    Proc::spawn_captured(cmd).finish(GUARD)
}

fn rows(out: &Output) -> Vec<Value> {
    assert!(
        out.status.success(),
        "dpctl scan failed: {}{}",
        out.stdout,
        out.stderr
    );
    common::json_lines(out.stdout.lines())
}

fn row(rows: &[Value], addr: u8) -> &Value {
    rows.iter()
        .find(|r| r["address"] == addr)
        .unwrap_or_else(|| panic!("slave {addr} not in {rows:#?}"))
}

/// The segment: a modular generic slave, a compact one, an Omega drive
/// (device profile), a slave whose GSD is not in the library, one whose
/// configuration matches no module combination of its file.
struct Segment {
    bus: Bus,
    _slaves: Vec<Proc>,
    gsd_dir: PathBuf,
    data: PathBuf,
}

fn segment(dir: &TempDir) -> Segment {
    let bus = Bus::start(7, &[]);
    let gsd_dir = dir.path("library");
    std::fs::create_dir(&gsd_dir).unwrap();
    let data = dir.path("data");
    // The library's files: a compact station (a localised variant), and
    // the "no fit" station's file with other modules than the slave has.
    let compact = gsd_text(0x0DC8, false, &[("4 in", "0x13"), ("4 in 4 out", "0x33")]);
    // The compact station's file (a localised variant) comes from the
    // user library, where `dpctl gsd install` puts it.
    let gse = dir.path("COMPACT.gse");
    std::fs::write(&gse, &compact).unwrap();
    let out = install(&data, &[&gse]);
    assert!(out.status.success(), "{}", out.stderr);
    assert!(out.stdout.starts_with("installed "), "{}", out.stdout);
    std::fs::write(
        gsd_dir.join("NOFIT.gsd"),
        gsd_text(0x0DC9, true, &[("8 DI", "0x10"), ("8 DO", "0x20")]),
    )
    .unwrap();
    // The slaves' own files, outside the library.
    let own = dir.path("own");
    std::fs::create_dir(&own).unwrap();
    let nofit = own.join("NOFIT_REAL.gsd");
    std::fs::write(
        &nofit,
        gsd_text(0x0DC9, true, &[("8 DI", "0x10"), ("2 words in", "0x51")]),
    )
    .unwrap();
    let missing = own.join("MISSING.gsd");
    std::fs::write(&missing, gsd_text(0x0DCA, false, &[("1 byte in", "0x10")])).unwrap();
    let compact_own = own.join("COMPACT.gsd");
    std::fs::write(&compact_own, &compact).unwrap();
    let slaves = vec![
        slave(
            &bus,
            1,
            8,
            &gen_gsd(),
            &["2 words in/out", "1 byte in", "16 bytes out"],
        ),
        slave(&bus, 2, 9, &compact_own, &["4 in 4 out"]),
        Proc::spawn(
            "dpctl slave 10 (omega)",
            Command::new(dpctl())
                .args(["slave", "--port", &bus.link_str(3)])
                .args(["--addr", "10", "--device", "omega"])
                .stdout(Stdio::null())
                .stderr(Stdio::null()),
        ),
        slave(&bus, 4, 11, &missing, &["1 byte in"]),
        slave(&bus, 5, 12, &nofit, &["8 DI", "2 words in"]),
    ];
    bus.wait_connected(5);
    Segment {
        bus,
        _slaves: slaves,
        gsd_dir,
        data,
    }
}

/// Every slave was listed (a slave process descheduled past its FDL
/// Status wait twice is missed; the scan is repeated, at most 3 times).
fn scan_all(s: &Segment, i: usize, addr: u8, out: &Path) -> Vec<Value> {
    let mut found = vec![];
    for _ in 0..3 {
        found = rows(&scan(&s.bus, i, addr, &s.gsd_dir, out, &s.data));
        if found.len() == 5 {
            break;
        }
    }
    assert_eq!(found.len(), 5, "{found:#?}");
    found
}

fn check_plans(rows: &[Value], owner: Option<u8>) {
    let owner = owner.map_or(Value::Null, Value::from);
    let s8 = row(rows, 8);
    assert_eq!(s8["configured"], true, "{s8}");
    assert_eq!(s8["ident"], "0x0DCE");
    assert_eq!(s8["cfg"], "71 10 2F");
    assert_eq!(
        s8["modules"],
        serde_json::json!(["2 words in/out", "1 byte in", "16 bytes out"])
    );
    assert_eq!(s8["gsd"], "DPCTL_GEN.GSD (built in)");
    assert_eq!(s8["owner"], owner);
    let s9 = row(rows, 9);
    assert_eq!(s9["modules"], serde_json::json!(["4 in 4 out"]), "{s9}");
    assert!(
        s9["gsd"]
            .as_str()
            .unwrap()
            .ends_with("dpctl/gsd/COMPACT.gse"),
        "{s9}"
    );
    let s10 = row(rows, 10);
    assert_eq!(s10["device"], "omega", "{s10}");
    assert_eq!(s10["owner"], owner);
    let s11 = row(rows, 11);
    assert_eq!(s11["configured"], false);
    assert_eq!(s11["reason"], "no_gsd");
    assert!(
        s11["why"]
            .as_str()
            .unwrap()
            .starts_with("no GSD for ident 0x0DCA (searched "),
        "{s11}"
    );
    let s12 = row(rows, 12);
    assert_eq!(s12["reason"], "no_fit", "{s12}");
    let why = s12["why"].as_str().unwrap();
    assert!(
        why.starts_with("Get_Cfg `10 51` matches no module combination of ")
            && why.contains("NOFIT.gsd: the modules 8 DI match the first 1 byte(s); identifier 51 matches no module"),
        "{why}"
    );
}

#[test]
fn scan_writes_a_bus_file_the_master_runs_unchanged() {
    let dir = TempDir::new("commissioning");
    let s = segment(&dir);
    let bus_toml = dir.path("bus.toml");
    let found = scan_all(&s, 0, 1, &bus_toml);
    check_plans(&found, None);
    let text = std::fs::read_to_string(&bus_toml).unwrap();
    assert!(text.contains("gsd = \"gsd/DPCTL_GEN.GSD\""), "{text}");
    assert!(
        dir.path("gsd/DPCTL_GEN.GSD").is_file(),
        "built-in file written"
    );
    assert!(text.contains("device = \"omega\""), "{text}");
    assert!(
        text.contains("# slave 11 (ident 0x0DCA): no GSD for ident 0x0DCA"),
        "{text}"
    );
    assert!(
        text.contains("# slave 12 (ident 0x0DC9): Get_Cfg `10 51` matches no module"),
        "{text}"
    );
    // The written file, unchanged, takes slaves 8, 9 and 10 to
    // Data_Exchange.
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--latency", "50"])
            .args(["--port", &s.bus.link_str(0), "--config"])
            .arg(&bus_toml)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut lines = Lines::from(&mut master);
    let mut from = 0;
    let v = lines.status_from(&mut from, "every written slave in Data_Exchange", |v| {
        all_dx(v) && v["slaves"].as_array().unwrap().len() == 3
    });
    let addrs: Vec<u64> = v["slaves"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["address"].as_u64().unwrap())
        .collect();
    assert_eq!(addrs, [8, 9, 10]);

    // A second master scans the same segment while the first holds every
    // slave: Slave_Diag and Get_Cfg of locked slaves.
    let second = dir.path("second.toml");
    let found = scan_all(&s, 6, 3, &second);
    check_plans(&found, Some(1));
    let text2 = std::fs::read_to_string(&second).unwrap();
    assert!(text2.contains("parameterised by master 1"), "{text2}");
    // Both files configure the slaves alike (the master address aside).
    let body = |t: &str| {
        t.lines()
            .filter(|l| !l.starts_with("address = 1") && !l.starts_with("address = 3"))
            .filter(|l| !l.starts_with('#'))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(body(&text), body(&text2));
    // No slave left Data_Exchange while the second master scanned.
    let mut after = lines.1.len();
    lines.status_from(&mut after, "a status line after the scan", |_| true);
    for l in &lines.1[from..] {
        if let Ok(v) = serde_json::from_str::<Value>(l) {
            if v["event"] == "status" {
                assert!(all_dx(&v), "a slave left Data_Exchange: {v}");
            }
        }
    }
    master.terminate(Duration::from_secs(5));
}

/// I&M0 and a device profile's options from the live bus: a DP-V1 slave
/// with class-2 services (C2PEER.GSD) gives its I&M0 to the scan (JSON
/// with the keys of `dpctl im --json`, and a comment in the bus file); a
/// BK3000 with a strip other than the default is written as `device =
/// "bk3000"` with a strip of the same configuration, which the coupler
/// takes from `dpctl master --config` unchanged; `--no-im` skips I&M0.
#[test]
fn scan_reads_im0_and_a_bk3000_strip() {
    let dir = TempDir::new("commissioning-im");
    let bus = Bus::start(4, &[]);
    let gsd_dir = dir.path("library");
    std::fs::create_dir(&gsd_dir).unwrap();
    let c2 = repo().join("crates/cli/tests/data/C2PEER.GSD");
    std::fs::copy(&c2, gsd_dir.join("C2PEER.GSD")).unwrap();
    let data = dir.path("data");
    let _c2 = slave(&bus, 1, 8, &c2, &["2 words in/out"]);
    let strip = "KL1104,KL2134,KL3102,KL4002,KL9010";
    let _bk = Proc::spawn(
        "dpctl slave 9 (bk3000)",
        Command::new(dpctl())
            .args(["slave", "--port", &bus.link_str(2)])
            .args(["--addr", "9", "--device", "bk3000", "--terminals", strip])
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    bus.wait_connected(2);
    let bus_toml = dir.path("bus.toml");
    let mut found = vec![];
    for _ in 0..3 {
        found = rows(&scan(&bus, 0, 1, &gsd_dir, &bus_toml, &data));
        if found.len() == 2 {
            break;
        }
    }
    assert_eq!(found.len(), 2, "{found:#?}");
    let s8 = row(&found, 8);
    assert_eq!(s8["configured"], true, "{s8}");
    assert_eq!(s8["im0"]["order_id"], "DPCTL-C2-PEER", "{s8}");
    assert_eq!(s8["im0"]["software_revision"], "V1.2.3", "{s8}");
    assert_eq!(s8["im0"]["hardware_revision"], 3, "{s8}");
    let s9 = row(&found, 9);
    assert_eq!(s9["device"], "bk3000", "{s9}");
    // The coupler's configuration: KL3102 and KL4002 compact, one byte
    // of digital inputs and one of outputs.
    assert_eq!(s9["cfg"], "50 50 60 60 10 20", "{s9}");
    assert_eq!(
        s9["options"]["terminals"],
        serde_json::json!(["KL3002", "KL4002", "KL1408", "KL2408", "KL9010"]),
        "{s9}"
    );
    assert!(
        s9["im0"]["skipped"]
            .as_str()
            .is_some_and(|w| w.contains("has no class-2 services")),
        "{s9}"
    );
    let text = std::fs::read_to_string(&bus_toml).unwrap();
    assert!(
        text.contains("# I&M0: order DPCTL-C2-PEER, serial "),
        "{text}"
    );
    assert!(
        text.contains(", V1.2.3 (hardware revision 3, manufacturer 0x"),
        "{text}"
    );
    assert!(
        text.contains("device = \"bk3000\"\nterminals = [\"KL3002\", \"KL4002\", \"KL1408\", \"KL2408\", \"KL9010\"]"),
        "{text}"
    );
    assert!(
        text.lines()
            .any(|l| l.starts_with("# terminal 1 (KL3002): ") && l.contains("KL3102")),
        "{text}"
    );
    // The written file, unchanged, takes both to Data_Exchange: the
    // coupler with the strip it was started with accepts its Chk_Cfg.
    let mut master = Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--interval", "100", "--latency", "50"])
            .args(["--port", &bus.link_str(3), "--config"])
            .arg(&bus_toml)
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let mut lines = Lines::from(&mut master);
    lines.status_from(&mut 0, "both written slaves in Data_Exchange", |v| {
        all_dx(v) && v["slaves"].as_array().unwrap().len() == 2
    });
    // While the master holds them: I&M0 through class 2 all the same;
    // with --no-im none is asked.
    let second = dir.path("second.toml");
    let found = rows(&scan(&bus, 0, 3, &gsd_dir, &second, &data));
    let s8 = row(&found, 8);
    assert_eq!(s8["im0"]["order_id"], "DPCTL-C2-PEER", "{s8}");
    assert_eq!(row(&found, 8)["owner"], 1);
    let mut cmd = Command::new(dpctl());
    cmd.args([
        "scan",
        "--json",
        "--latency",
        "50",
        "--addr",
        "3",
        "--no-im",
    ])
    .args(["--port", &bus.link_str(0), "--gsd-dir"])
    .arg(&gsd_dir)
    .arg("--write-config")
    .arg(dir.path("third.toml"))
    .env("XDG_DATA_HOME", &data);
    let found = rows(&Proc::spawn_captured(cmd).finish(GUARD));
    assert!(row(&found, 8).get("im0").is_none(), "{found:#?}");
    master.terminate(Duration::from_secs(5));
}
