//! Hostile files and messages: GSD files, bus files, a BK3000's terminals
//! file, an RFID reader's tags file and MQTT payloads that are huge
//! (50 MB, or an endless stream like `/dev/zero`), binary, not UTF-8 or
//! deeply nested. Each must give a clear error that names the problem,
//! within bounded memory (measured with a counting allocator: far below
//! the input's size) and bounded time. The limits are documented in
//! RELIABILITY.md ("Hostile input").

use profibus_io::alloc_count;

#[global_allocator]
static GLOBAL: alloc_count::Counting = alloc_count::Counting;

use profibus::devices::bus::ProfiledBus;
use profibus::devices::DeviceOptions;
use profibus::dp::config::busfile::BusFile;
use profibus::dp::config::gsd::{Gsd, ParseOptions, MAX_FILE_LEN};
use profibus::dp::config::layout::SlaveLayout;
use profibus_gateway::settings::MqttSettings;
use profibus_gateway::{Gateway, SlaveInfo};
use std::path::Path;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The peak-memory figures are process-wide: one test at a time (each
/// takes this lock first).
static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// Heap allowed while refusing an input by its size or encoding (the
/// inputs are 50 MB or endless; the readers stop one byte after their
/// limit, at most 4 MiB, into a buffer that doubles as it grows).
const MEM_REFUSE: u64 = 16 << 20;

/// Heap allowed for a file under its size limit built to be costly (a
/// megabyte of TOML slaves or tags, whose tables cost up to some 50 times
/// the text; a 4 MiB GSD file of a quarter of a million unclosed modules).
const MEM_PARSE: u64 = 64 << 20;

/// Time allowed on a loaded 2-core machine (typically well under 1 s).
const TIME_BOUND: Duration = Duration::from_secs(30);

const HUGE: u64 = 50 << 20;

/// Run `f`; check the heap it needed at most (`MEM_REFUSE`) and the time
/// it took.
fn bounded<T>(what: &str, f: impl FnOnce() -> T) -> T {
    bounded_by(MEM_REFUSE, what, f)
}

/// [`bounded`] with a heap bound of `mem` bytes.
fn bounded_by<T>(mem: u64, what: &str, f: impl FnOnce() -> T) -> T {
    alloc_count::reset_peak();
    let t0 = Instant::now();
    let r = f();
    let took = t0.elapsed();
    let peak = alloc_count::peak_since_reset();
    assert!(peak <= mem, "{what}: {peak} bytes of heap (bound {mem})");
    assert!(took <= TIME_BOUND, "{what}: took {took:?}");
    eprintln!(
        "{what}: {:.1} MiB of heap, {took:.2?}",
        peak as f64 / (1 << 20) as f64
    );
    r
}

/// A fresh directory for one test, removed on drop.
fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("hostile-{name}-"))
        .tempdir()
        .unwrap()
}

/// A 50 MB file that takes no disk space (sparse, all zero bytes).
fn sparse(path: &Path) {
    std::fs::File::create(path).unwrap().set_len(HUGE).unwrap();
}

/// `n` pseudo-random bytes (xorshift; deterministic).
fn binary(n: usize) -> Vec<u8> {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

fn contains(e: impl std::fmt::Display, words: &[&str]) -> String {
    let text = e.to_string();
    for w in words {
        assert!(text.contains(w), "`{text}` does not say `{w}`");
    }
    text
}

const BUS_HEAD: &str = "[master]\naddress = 2\nbaud = \"1.5M\"\n\n";

#[test]
fn gsd_files_huge_endless_binary_nested() {
    let _g = serial();
    let tmp = scratch("gsd");
    let d = tmp.path();
    let big = d.join("big.gsd");
    sparse(&big);
    let e = bounded("50 MB GSD", || Gsd::from_file(&big, ParseOptions::LENIENT)).unwrap_err();
    contains(
        e,
        &["big.gsd", "52428800 bytes long", "4194304 bytes a GSD file"],
    );

    // An endless stream whose metadata says 0 bytes.
    let e = bounded("/dev/zero as GSD", || {
        Gsd::from_file("/dev/zero", ParseOptions::LENIENT)
    })
    .unwrap_err();
    contains(e, &["longer than the 4194304 bytes a GSD file"]);

    // Binary: the bytes of an image, not text.
    let bin = d.join("binary.gsd");
    std::fs::write(&bin, binary(1 << 20)).unwrap();
    let e = bounded("binary GSD", || Gsd::from_file(&bin, ParseOptions::LENIENT)).unwrap_err();
    contains(e, &["binary.gsd:"]);

    // Not Latin-1 text: UTF-16 with a byte-order mark.
    let utf16: Vec<u8> = "\u{FEFF}#Profibus_DP\r\nGSD_Revision=1\r\n"
        .encode_utf16()
        .flat_map(|u| u.to_le_bytes())
        .collect();
    let f = d.join("utf16.gsd");
    std::fs::write(&f, utf16).unwrap();
    let e = bounded("UTF-16 GSD", || Gsd::from_file(&f, ParseOptions::LENIENT)).unwrap_err();
    contains(e, &["utf16.gsd:"]);

    // Deeply nested: 200 000 modules opened and never closed, just under
    // the file limit.
    let mut text = String::from("#Profibus_DP\nGSD_Revision=1\nIdent_Number=0x1234\n");
    while text.len() < MAX_FILE_LEN - 40 {
        text.push_str("Module=\"m\" 0x10\n");
    }
    let f = d.join("nested.gsd");
    std::fs::write(&f, &text).unwrap();
    let r = bounded_by(MEM_PARSE, "nested GSD", || {
        Gsd::from_file(&f, ParseOptions::STRICT)
    });
    contains(
        r.unwrap_err(),
        &[
            "nested.gsd:5:1: expected `EndModule`",
            "(and 999 more errors)",
        ],
    );

    // References: 32 768 parameter definitions and, up to the file
    // limit, 73 291 references to numbers none of them has (checked
    // each against every definition, that was over 10^9 comparisons).
    let mut text = String::from("#Profibus_DP\nGSD_Revision=1\nIdent_Number=0x1234\n");
    for r in 0..1 << 15 {
        text.push_str(&format!(
            "ExtUserPrmData={r} \"p\"\nUnsigned8 0 0-1\nEndExtUserPrmData\n"
        ));
    }
    let mut r = 1u32 << 15;
    while text.len() < MAX_FILE_LEN - 40 {
        text.push_str(&format!("Ext_User_Prm_Data_Ref(0)={r}\n"));
        r = (r + 1).min(0xFFFF);
    }
    let f = d.join("references.gsd");
    std::fs::write(&f, &text).unwrap();
    let p = bounded_by(MEM_PARSE, "GSD references", || {
        let p = Gsd::from_file(&f, ParseOptions::LENIENT).unwrap();
        assert_eq!(p.gsd.parameters(&[]).map(|v| v.len()), Ok(0));
        p
    });
    assert_eq!(p.gsd.ext_user_prm_data.len(), 1 << 15);
    assert!(p.gsd.ext_user_prm_data_ref.len() > 50_000);
    assert!(
        p.warnings
            .iter()
            .any(|w| w.message.contains("names `ExtUserPrmData` 32768")),
        "{:?}",
        p.warnings.iter().take(3).collect::<Vec<_>>()
    );
}

#[test]
fn bus_files_huge_endless_binary_not_utf8_nested() {
    let _g = serial();
    let tmp = scratch("bus");
    let d = tmp.path();
    let big = d.join("big.toml");
    sparse(&big);
    let e = bounded("50 MB bus file", || BusFile::load(&big)).unwrap_err();
    contains(
        e,
        &[
            "big.toml",
            "52428800 bytes long",
            "1048576 bytes a bus file",
        ],
    );

    let e = bounded("/dev/zero as bus file", || BusFile::load("/dev/zero")).unwrap_err();
    contains(
        e,
        &["/dev/zero", "longer than the 1048576 bytes a bus file"],
    );

    let bin = d.join("binary.toml");
    std::fs::write(&bin, binary(1 << 20)).unwrap();
    let e = bounded("binary bus file", || BusFile::load(&bin)).unwrap_err();
    contains(e, &["binary.toml:1:", "not UTF-8 text: byte 0x"]);

    // Latin-1 where UTF-8 is expected: a name with an umlaut.
    let latin1 = d.join("latin1.toml");
    let mut b = BUS_HEAD.as_bytes().to_vec();
    b.extend_from_slice(b"[[slave]]\naddress = 8\nname = \"M\xFCller\"\n");
    std::fs::write(&latin1, b).unwrap();
    let e = bounded("Latin-1 bus file", || BusFile::load(&latin1)).unwrap_err();
    contains(e, &["latin1.toml:7:10:", "byte 0xFC at line 7, column 10"]);

    // Deeply nested arrays and inline tables in the raw [mqtt] table.
    for (name, open, close) in [("arrays", "[", "]"), ("tables", "{a=", "}")] {
        let depth = 100_000;
        let text = format!(
            "{BUS_HEAD}[mqtt]\nx = {}1{}\n",
            open.repeat(depth),
            close.repeat(depth)
        );
        let f = d.join(format!("nested-{name}.toml"));
        std::fs::write(&f, text).unwrap();
        let e = bounded("nested bus file", || ProfiledBus::load(&f)).unwrap_err();
        contains(e, &[&format!("nested-{name}.toml:6:")]);
    }

    // A GSD path that is an endless stream.
    let f = d.join("zero-gsd.toml");
    std::fs::write(
        &f,
        format!("{BUS_HEAD}[[slave]]\naddress = 8\ngsd = \"/dev/zero\"\nmodules = []\n"),
    )
    .unwrap();
    let e = bounded("bus file naming /dev/zero as GSD", || BusFile::load(&f)).unwrap_err();
    contains(e, &["longer than the 4194304 bytes a GSD file"]);

    // A megabyte of slaves: the second one with the same address is the
    // error.
    let mut text = BUS_HEAD.to_string();
    while text.len() < (1 << 20) - 100 {
        text.push_str("[[slave]]\naddress = 8\ndevice = \"rfid\"\n");
    }
    let f = d.join("many.toml");
    std::fs::write(&f, text).unwrap();
    let e = bounded_by(MEM_PARSE, "1 MB of slaves", || ProfiledBus::load(&f)).unwrap_err();
    contains(e, &["many.toml:", "a second slave with address 8"]);
}

/// Configure profile `device` with its option `key` naming `file`.
fn configure(device: &str, key: &str, file: &Path) -> Result<(), String> {
    let mut o = DeviceOptions::new();
    o.set(key, file.display().to_string());
    profibus::devices::profile(device)
        .unwrap()
        .configure(&o, Some(8))
        .map(|_| ())
        .map_err(|e| e.to_string())
}

#[test]
fn terminal_and_tag_files_huge_endless_binary_nested() {
    let _g = serial();
    let tmp = scratch("tables");
    let d = tmp.path();
    let big = d.join("big.txt");
    sparse(&big);
    let bin = d.join("binary.txt");
    std::fs::write(&bin, binary(1 << 20)).unwrap();
    let zero = Path::new("/dev/zero");
    for (device, key) in [
        ("bk3000", "terminals_file"),
        ("rfid", "tags"),
        ("bm4", "vars"),
        ("omega", "params"),
        ("jx2", "script"),
    ] {
        let what = format!("{device} {key}");
        let e = bounded(&what, || configure(device, key, &big)).unwrap_err();
        contains(
            e,
            &[
                "big.txt",
                "52428800 bytes long",
                "1048576 bytes a device option file",
            ],
        );
        let e = bounded(&what, || configure(device, key, zero)).unwrap_err();
        contains(e, &["/dev/zero", "longer than the 1048576 bytes"]);
        let e = bounded(&what, || configure(device, key, &bin)).unwrap_err();
        contains(e, &["binary.txt", "not UTF-8 text: byte 0x"]);
    }

    // A terminals file of a megabyte of names: the strip's limit is the
    // error.
    let f = d.join("terminals.txt");
    std::fs::write(&f, "KL1104,".repeat((1 << 20) / 8) + "KL9010\n").unwrap();
    let e = bounded_by(MEM_PARSE, "1 MB terminal strip", || {
        configure("bk3000", "terminals_file", &f)
    })
    .unwrap_err();
    contains(e, &["terminals.txt", "64"]);

    // A tags file nested 100 000 deep.
    let f = d.join("nested-tags.toml");
    std::fs::write(
        &f,
        format!("x = {}1{}\n", "[".repeat(100_000), "]".repeat(100_000)),
    )
    .unwrap();
    let e = bounded("nested tags", || configure("rfid", "tags", &f)).unwrap_err();
    contains(e, &["nested-tags.toml"]);

    // A tags file of a megabyte declaring tags of the largest memory: more
    // tags than a tags file may list.
    let mut text = String::new();
    let mut i = 0u64;
    while text.len() < (1 << 20) - 100 {
        text.push_str(&format!("[[tag]]\nuid = \"{i:016X}\"\nblocks = 256\n"));
        i += 1;
    }
    let f = d.join("many-tags.toml");
    std::fs::write(&f, text).unwrap();
    let e = bounded_by(MEM_PARSE, "1 MB of tags", || configure("rfid", "tags", &f)).unwrap_err();
    contains(e, &["many-tags.toml", "a tags file may list at most 1024"]);
}

/// A gateway with slave 8 (4 output bytes) writable, and its answers.
fn gateway() -> Gateway {
    let table: toml::Table = toml::from_str("writable = [8]").unwrap();
    let settings = MqttSettings::from_table(Some(&table), "hostile").unwrap();
    let mut gw = Gateway::new(
        settings,
        vec![SlaveInfo {
            layout: SlaveLayout {
                address: 8,
                name: "s8".into(),
                ident_number: 0x0815,
                dpv1: true,
                ..SlaveLayout::default()
            },
            channels: None,
            pkw: None,
        }],
    );
    gw.connected(0);
    while gw.poll_publish().is_some() {}
    gw
}

/// The error text the gateway answers to `payload` on `topic`.
fn refusal(gw: &mut Gateway, topic: &str, payload: &[u8]) -> String {
    gw.handle_message(topic, payload, 1);
    let p = gw.poll_publish().expect("an answer");
    assert!(gw.poll_publish().is_none());
    let v: serde_json::Value = serde_json::from_slice(&p.payload).unwrap();
    assert_eq!(v["ok"], false, "{v}");
    v["error"].as_str().unwrap().to_string()
}

#[test]
fn mqtt_payloads_huge_binary_malformed_nested() {
    let _g = serial();
    let mut gw = gateway();
    let set = "profibus/hostile/8/outputs/set";
    let dpv1 = "profibus/hostile/8/dpv1/request";

    // 50 MB: hex digits, a JSON string of them, and a JSON object.
    let huge_hex = vec![b'0'; HUGE as usize];
    let e = bounded("50 MB hex payload", || refusal(&mut gw, set, &huge_hex));
    contains(e, &["52428800 bytes", "65536"]);
    let mut huge_json = b"{\"hex\": \"".to_vec();
    huge_json.resize(HUGE as usize, b'a');
    huge_json.extend_from_slice(b"\"}");
    let e = bounded("50 MB JSON payload", || refusal(&mut gw, dpv1, &huge_json));
    contains(e, &["bytes", "65536"]);
    drop((huge_hex, huge_json));

    // Binary and not UTF-8.
    let e = bounded("binary payload", || refusal(&mut gw, set, &binary(4096)));
    contains(e, &["not UTF-8"]);
    let e = refusal(&mut gw, set, b"{\"hex\": \"0a\xFF\"}");
    contains(e, &["not UTF-8"]);

    // Nested 100 000 deep (under the size limit only when shallower).
    let nested = format!("{}1{}", "[".repeat(30_000), "]".repeat(30_000));
    let e = bounded("nested JSON", || refusal(&mut gw, dpv1, nested.as_bytes()));
    contains(e, &["malformed request"]);
    let nested = format!("{}1{}", "{\"a\":".repeat(10_000), "}".repeat(10_000));
    let e = bounded("nested JSON objects", || {
        refusal(&mut gw, set, nested.as_bytes())
    });
    contains(e, &["malformed request"]);

    // Malformed: truncated, wrong types, out of range, odd hex.
    for (topic, payload, says) in [
        (
            set,
            &b"{\"hex\": \"0a0b"[..],
            "neither a JSON object nor hex",
        ),
        (set, b"0a0", "neither a JSON object nor hex"),
        (set, b"", "neither a JSON object nor hex"),
        (set, b"[1, 2]", "expected a JSON object"),
        (set, b"{\"hex\": 12}", "malformed request"),
        (set, b"{\"channels\": {\"x\": 1e999}}", "malformed request"),
        (
            dpv1,
            b"{\"op\": \"read\", \"slot\": 99999999999999999999, \"index\": 1}",
            "slot",
        ),
        (
            dpv1,
            b"{\"op\": \"read\", \"slot\": 0, \"index\": 0, \"length\": -1}",
            "length",
        ),
        (dpv1, b"null", "expected a JSON object"),
    ] {
        let e = refusal(&mut gw, topic, payload);
        contains(e, &[says]);
    }
}
