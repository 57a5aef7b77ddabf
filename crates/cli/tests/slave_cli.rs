//! `dpctl slave` as a process, driven byte by byte from the other end of a
//! socat pty pair: the baud-rate search, Set_Slave_Add with the address
//! file, watchdog expiry, clean stop on SIGTERM, usage errors.
//!
//! Needs socat; fails when it is missing.

mod common;

use common::*;
use profibus::fdl::{DataTelegram, FunctionCode, Telegram};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

const GEN_IDENT: [u8; 2] = [0x0D, 0xCE];

fn request(da: u8, fc: u8, saps: Option<(u8, u8)>, data: &[u8]) -> Vec<u8> {
    let (dsap, ssap) = saps.unzip();
    let t = DataTelegram::new(da, 2, FunctionCode::from_byte(fc), data).with_saps(dsap, ssap);
    Telegram::Data(t).to_vec().unwrap()
}

/// The master's end of the pty pair.
type Line = RawStation;

fn diag(line: &mut Line, addr: u8) -> Vec<u8> {
    let r = line.ask(
        &request(addr, 0x6D, Some((60, 62)), &[]),
        Duration::from_secs(2),
    );
    match Telegram::parse(&r) {
        Ok((Telegram::Data(d), _)) => d.data.to_vec(),
        other => panic!("no Slave_Diag answer from {addr}: {r:02X?} {other:?}"),
    }
}

/// Set_Slave_Add of station 21 to `new` (FCB 0, after a 6D frame) is
/// refused with RS: No_Add_Chg holds.
fn change_refused(line: &mut Line, new: u8) {
    let set = request(
        21,
        0x5D,
        Some((55, 62)),
        &[new, GEN_IDENT[0], GEN_IDENT[1], 0],
    );
    let r = line.ask(&set, Duration::from_secs(2));
    assert_eq!(r, vec![0x10, 0x02, 21, 0x03, 0x1A, 0x16], "RS");
}

fn start_slave(port: &Path, extra: &[&str]) -> (Proc, Lines) {
    let mut p = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--port"])
            .arg(port)
            .arg("--gsd")
            .arg(repo().join("crates/devices/gsd/DPCTL_GEN.GSD"))
            .args(["--module", "2 words in/out", "--json"])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit()),
    );
    let lines = started(&mut p, Duration::from_secs(10));
    (p, lines)
}

fn events(lines: &[String]) -> Vec<Value> {
    json_lines(lines)
}

#[test]
fn baud_search_locks_on_a_valid_telegram_and_searches_again_after_the_watchdog() {
    let dir = TempDir::new("slave-search");
    let (a, b) = (dir.path("m"), dir.path("s"));
    let _socat = pty_pair(&a, &b);
    let (mut slave, mut out) = start_slave(&b, &["--addr", "5", "--baud", "search"]);
    let mut line = RawStation::open(&a);
    // Garbage and a token do not lock the search; nothing is answered.
    assert!(line
        .ask(
            &[0x00, 0x68, 0x99, 0xDC, 0x05, 0x02],
            Duration::from_millis(300)
        )
        .is_empty());
    assert!(!out.wait_for("baud_locked", Duration::from_millis(100)));
    // A valid telegram locks it (on a pty at the first rate tried); the
    // slave then answers.
    line.ask(&request(5, 0x49, None, &[]), Duration::from_millis(300));
    assert!(
        out.wait_for("baud_locked", Duration::from_secs(3)),
        "{:?}",
        out.1
    );
    let d = diag(&mut line, 5);
    assert_eq!(
        &d[..6],
        &[0x02, 0x05, 0x00, 0xFF, GEN_IDENT[0], GEN_IDENT[1]]
    );
    // Set_Prm with a 50 ms watchdog and the GSD's User_Prm_Data, Chk_Cfg.
    let prm = [
        &[0x88, 5, 1, 11, GEN_IDENT[0], GEN_IDENT[1], 0][..],
        &[0x80, 0x00, 0x00, 0x01, 0xFF, 0x9C],
    ]
    .concat();
    assert_eq!(
        line.ask(
            &request(5, 0x5D, Some((61, 62)), &prm),
            Duration::from_secs(2)
        ),
        vec![0xE5]
    );
    assert_eq!(
        line.ask(
            &request(5, 0x7D, Some((62, 62)), &[0x71]),
            Duration::from_secs(2)
        ),
        vec![0xE5]
    );
    let d = diag(&mut line, 5);
    assert_eq!(&d[..4], &[0x00, 0x0C, 0x00, 0x02], "ready, WD_On, master 2");
    // Silence: the watchdog expires, the slave searches again.
    assert!(
        out.wait_for("\"event\":\"watchdog\"", Duration::from_secs(3)),
        "{:?}",
        out.1
    );
    assert!(out.wait_for("\"event\":\"baud_search\"", Duration::from_secs(3)));
    line.ask(&request(5, 0x49, None, &[]), Duration::from_millis(300));
    let d = diag(&mut line, 5);
    assert_eq!(&d[..4], &[0x02, 0x05, 0x00, 0xFF], "back in Wait_Prm");

    let st = slave.terminate(Duration::from_secs(10));
    assert!(st.success(), "{st}");
    let ev = events(out.rest());
    assert_eq!(ev.iter().filter(|v| v["event"] == "baud_locked").count(), 2);
    assert!(ev.iter().any(|v| v["event"] == "stopped"));
}

#[test]
fn set_slave_add_persists_in_the_address_file() {
    let dir = TempDir::new("slave-addr");
    let (a, b) = (dir.path("m"), dir.path("s"));
    let _socat = pty_pair(&a, &b);
    let file = dir.path("address.txt");
    let file_s = file.to_str().unwrap().to_string();
    let (mut slave, mut out) = start_slave(&b, &["--addr", "7", "--address-file", &file_s]);
    let mut line = RawStation::open(&a);
    diag(&mut line, 7);
    // Set_Slave_Add to 21 with No_Add_Chg: SC from the old address.
    let r = line.ask(
        &request(
            7,
            0x6D,
            Some((55, 62)),
            &[21, GEN_IDENT[0], GEN_IDENT[1], 1],
        ),
        Duration::from_secs(2),
    );
    assert_eq!(r, vec![0xE5]);
    assert!(out.wait_for("\"event\":\"address\"", Duration::from_secs(2)));
    diag(&mut line, 21);
    assert!(
        line.ask(
            &request(7, 0x6D, Some((60, 62)), &[]),
            Duration::from_millis(300)
        )
        .is_empty(),
        "the old address is gone"
    );
    // No_Add_Chg: a further change is refused (RS).
    change_refused(&mut line, 22);
    assert!(slave.terminate(Duration::from_secs(10)).success());
    let stored = std::fs::read_to_string(&file).unwrap();
    assert_eq!(stored, "address = 21\nno_add_chg = true\n");

    // A restart takes the stored address over --addr, and keeps refusing.
    let (mut slave, _out) = start_slave(&b, &["--addr", "7", "--address-file", &file_s]);
    diag(&mut line, 21);
    // (FCB toggled after the first frame 6D: 5D, not 7D, which would be
    // a repeat and get the stored answer.)
    change_refused(&mut line, 23);
    assert!(slave.terminate(Duration::from_secs(10)).success());
}

#[test]
fn usage_and_input_errors() {
    let run = |args: &[&str]| {
        Command::new(dpctl())
            .arg("slave")
            .args(args)
            .output()
            .unwrap()
    };
    let o = run(&["--list-devices"]);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("generic"));
    // Usage errors: exit 2.
    assert_eq!(run(&["--addr", "3"]).status.code(), Some(2));
    assert_eq!(
        run(&["--port", "/dev/null", "--addr", "127"]).status.code(),
        Some(2)
    );
    // Input errors: exit 1 with one line on stderr.
    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let gsd = gsd.to_str().unwrap();
    let no_port = ["--port", "/nonexistent/x", "--addr", "3"];
    for extra in [
        &["--gsd", gsd, "--module", "2 words in/out"][..],
        &["--gsd", gsd, "--module", "no such module"],
        &["--gsd", "/nonexistent.gsd"],
        &["--device", "nope"],
        &[],
    ] {
        let args = [&no_port[..], extra].concat();
        let o = run(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.starts_with("dpctl: "), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    }
}
