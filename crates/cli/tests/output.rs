//! How `dpctl` prints: a standard output nobody reads any more ends a
//! command quietly (status 0, no panic, no message), and logs carry no
//! colour codes off a terminal or with `NO_COLOR`.

mod common;

use common::{dpctl, repo, require, Bus, Proc};
use profibus::fdl::Baud;
use profibus_io::transport::Port;
use std::io::Read;
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;

/// A hang guard, generous for a loaded machine.
const T: Duration = Duration::from_secs(60);

/// `dpctl args` started with a standard output whose reader is gone
/// before it starts (the read end of the pipe is closed: every write
/// fails with EPIPE, as after `| head -1` has read its line), and its
/// stderr collected.
struct ClosedStdout {
    proc: Proc,
    stderr: std::thread::JoinHandle<String>,
    args: String,
}

impl ClosedStdout {
    fn start(args: &[&str]) -> ClosedStdout {
        let (reader, writer) = std::io::pipe().expect("pipe");
        drop(reader);
        let (mut err_r, err_w) = std::io::pipe().expect("pipe");
        let mut cmd = Command::new(dpctl());
        cmd.args(args)
            .stdin(Stdio::null())
            .stdout(writer)
            .stderr(err_w);
        let proc = Proc::spawn(&format!("dpctl {}", args.join(" ")), &mut cmd);
        // The pipes' write ends now live in the child only.
        drop(cmd);
        let stderr = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = err_r.read_to_string(&mut s);
            s
        });
        ClosedStdout {
            proc,
            stderr,
            args: args.join(" "),
        }
    }

    fn exited(&mut self) -> bool {
        self.proc.exited()
    }

    /// Its exit status (within [`T`]) and stderr.
    fn finish(mut self) -> (ExitStatus, String) {
        let status = self.proc.wait(T);
        (status, self.stderr.join().unwrap_or_default())
    }

    /// It ended quietly: status 0, nothing on stderr.
    fn assert_quiet(self) {
        let args = self.args.clone();
        let (status, stderr) = self.finish();
        assert!(
            !stderr.contains("panicked"),
            "dpctl {args} panicked:\n{stderr}"
        );
        assert!(status.success(), "dpctl {args}: {status}\n{stderr}");
        assert_eq!(stderr, "", "dpctl {args} printed on stderr");
    }
}

#[test]
fn one_shot_commands_end_quietly_when_nobody_reads_their_output() {
    let gsd = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let gsd = gsd.to_str().unwrap();
    for args in [
        &["gsd", "show", gsd][..],
        &["gsd", "show", "--json", gsd],
        &["gsd", "check", gsd],
        &["decode", "10", "02", "08", "00", "0A", "16"],
        &["decode", "--json", "DC 02 01"],
        &["completions", "bash"],
        &["slave", "--list-devices"],
    ] {
        ClosedStdout::start(args).assert_quiet();
    }
}

#[test]
fn bus_ends_quietly_and_removes_its_links_when_nobody_reads_its_output() {
    let dir = common::TempDir::new("closed-bus");
    let prefix = dir.path("st");
    let p = ClosedStdout::start(&["bus", "--stations", "2", "--link", prefix.to_str().unwrap()]);
    p.assert_quiet();
    for i in 0..2 {
        let link = format!("{}{i}", prefix.display());
        assert!(
            std::fs::symlink_metadata(&link).is_err(),
            "{link} left behind"
        );
    }
}

#[test]
fn demo_ends_quietly_when_nobody_reads_its_output() {
    // Without --cycles it would run until a signal: the closed output
    // stops it.
    ClosedStdout::start(&["demo", "--fast", "--plain"]).assert_quiet();
    ClosedStdout::start(&["demo", "--fast", "--json"]).assert_quiet();
}

#[test]
fn sniff_ends_quietly_when_nobody_reads_its_output() {
    let bus = Bus::start(2, &[]);
    let mut sniff = ClosedStdout::start(&["sniff", "--plain", "--port", &bus.link_str(0)]);
    // Tokens from station 1 until the sniffer has heard one and stopped
    // (the ones sent before it opened its link are not heard).
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let mut station = {
        let _guard = rt.enter();
        Port::open(&bus.link_str(1), Baud::B19200).expect("open bus link")
    };
    let end = Instant::now() + T;
    while !sniff.exited() {
        assert!(Instant::now() < end, "dpctl sniff still runs");
        rt.block_on(async {
            station.write_all(&[0xDC, 0x02, 0x01]).await.unwrap();
            // The pause between tries.
            tokio::time::sleep(Duration::from_millis(20)).await;
        });
    }
    sniff.assert_quiet();
    drop(station);
    bus.stop();
}

/// Whether `s` holds an ANSI escape sequence (a colour).
fn has_ansi(s: &str) -> bool {
    s.contains("\x1b[")
}

#[test]
fn logs_into_a_pipe_have_no_colour_codes() {
    let out = Command::new(dpctl())
        .args(["demo", "--fast", "--cycles", "20", "--plain"])
        .env("DPCTL_LOG", "debug")
        .env_remove("NO_COLOR")
        .stdin(Stdio::null())
        .output()
        .expect("dpctl demo");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("DEBUG"), "no log lines:\n{stderr}");
    assert!(!has_ansi(&stderr), "colour codes in a pipe:\n{stderr}");
}

#[test]
fn no_color_turns_colours_off_on_a_terminal() {
    // `script` runs the command on a pty (its stderr a terminal) and
    // copies what it wrote.
    require("script");
    let on_terminal = |no_color: Option<&str>| {
        let mut cmd = Command::new("script");
        cmd.args(["-q", "-e", "-c"])
            .arg(format!(
                "'{}' demo --fast --cycles 20 --plain",
                dpctl().display()
            ))
            .arg("/dev/null")
            .env("DPCTL_LOG", "debug")
            .env_remove("NO_COLOR")
            .stdin(Stdio::null());
        if let Some(v) = no_color {
            cmd.env("NO_COLOR", v);
        }
        let out = cmd.output().expect("script");
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(out.status.success(), "{text}");
        assert!(text.contains("DEBUG"), "no log lines:\n{text}");
        text
    };
    assert!(has_ansi(&on_terminal(None)), "no colours on a terminal");
    assert!(
        !has_ansi(&on_terminal(Some("1"))),
        "colours with NO_COLOR=1"
    );
}

#[test]
fn an_error_names_its_cause_once_and_in_words() {
    // The profile's refusal is in the message once, not again as its
    // chained source.
    let out = common::run_dpctl(&[
        "slave",
        "--port",
        "/nonexistent/link",
        "--addr",
        "5",
        "--device",
        "bm4",
        "--device-opt",
        "foo=1",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", out.stderr);
    for once in ["`foo`", "device `bm4`"] {
        assert_eq!(out.stderr.matches(once).count(), 1, "{}", out.stderr);
    }
    // A device profile's built-in GSD is named in words, not as a
    // made-up path.
    let dir = common::TempDir::new("words");
    let bus = dir.path("bus.toml");
    std::fs::write(
        &bus,
        "[master]\naddress = 1\nbaud = \"45.45k\"\n[[slave]]\naddress = 5\ndevice = \"omega\"\n",
    )
    .unwrap();
    let out = common::run_dpctl(&[
        "master",
        "--port",
        "/nonexistent/link",
        "--config",
        bus.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", out.stderr);
    assert!(
        out.stderr.contains("`omega` does not support 45.45kbit/s"),
        "{}",
        out.stderr
    );
    assert!(!out.stderr.contains("<omega>"), "{}", out.stderr);
    // A port that cannot be opened is named once (the transport's error
    // names it; the command adds no "opening PATH" before it).
    for cmd in ["scan", "sniff"] {
        let out = common::run_dpctl(&[cmd, "--port", "/nonexistent/link"]);
        assert_eq!(out.status.code(), Some(1), "{}", out.stderr);
        assert_eq!(
            out.stderr.matches("/nonexistent/link").count(),
            1,
            "{}",
            out.stderr
        );
    }
}

#[test]
fn the_master_status_line_names_the_operating_state_in_words() {
    let out = common::run_dpctl(&["demo", "--fast", "--cycles", "20", "--plain"]);
    assert!(out.status.success(), "{}", out.stderr);
    let status = out
        .stdout
        .lines()
        .find(|l| l.starts_with("master 1 at "))
        .unwrap_or_else(|| panic!("no status line:\n{}", out.stdout));
    assert!(status.contains("  operate  cycles "), "{status}");
}

#[test]
fn station_commands_end_quietly_when_nobody_reads_their_output() {
    let bus = Bus::start(3, &[]);
    let config = bus.dir().path("bus.toml");
    std::fs::write(
        &config,
        "[master]\naddress = 2\nbaud = \"1.5M\"\n[[slave]]\naddress = 25\ndevice = \"omega\"\n",
    )
    .unwrap();
    let config = config.to_str().unwrap();
    // Each would run until a signal; the closed output stops it.
    let (l0, l1, l2) = (bus.link_str(0), bus.link_str(1), bus.link_str(2));
    let slave = ClosedStdout::start(&[
        "slave", "--port", &l1, "--baud", "1.5M", "--addr", "25", "--device", "omega",
    ]);
    let master = ClosedStdout::start(&["master", "--plain", "--port", &l0, "--config", config]);
    let monitor = ClosedStdout::start(&["monitor", "--json", "--port", &l2, "--config", config]);
    for p in [slave, master, monitor] {
        p.assert_quiet();
    }
    bus.stop();
}

#[test]
fn a_closed_stderr_loses_the_message_but_keeps_the_exit_status() {
    // `dpctl decode zz 2>&1 | true`: the failure's one line cannot be
    // written; the status still says "failed" (1), not a panic (101).
    let (reader, writer) = std::io::pipe().expect("pipe");
    drop(reader);
    let status = Command::new(dpctl())
        .args(["decode", "zz"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(writer)
        .status()
        .expect("dpctl decode");
    assert_eq!(status.code(), Some(1), "{status}");
}
