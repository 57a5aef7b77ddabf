//! The terminal views as a person sees them: `dpctl master`, `dpctl demo`
//! and `dpctl sniff` run in a tmux pane; the test types keys
//! (`send-keys`) and reads the screen (`capture-pane`), waiting for what
//! should appear. tmux is a test peer: missing, the tests fail (run
//! `scripts/setup-test-env`).

mod common;

use common::{dpctl, require, Bus, Proc, TempDir};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How long a screen may take to show what it should (a loaded 2-core
/// machine, a debug build).
const WAIT: Duration = Duration::from_secs(90);

/// A tmux server of its own (socket in a temp dir) with one session
/// running one command in a pane of a fixed size. The pane stays open
/// after the command exits and shows `[exit N]`.
struct Tmux {
    socket: PathBuf,
    _dir: TempDir,
}

/// `s` quoted for `sh`.
fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

impl Tmux {
    fn start(args: &[&str]) -> Tmux {
        require("tmux");
        let dir = TempDir::new("tmux");
        let socket = dir.path("sock");
        let mut line = quote(&dpctl().to_string_lossy());
        for a in args {
            line.push(' ');
            line.push_str(&quote(a));
        }
        // `exec cat` keeps the pane (and what the command left on the
        // screen) until the server is killed.
        let shell = format!("{line}; echo \"[exit $?]\"; exec cat");
        let st = Command::new("tmux")
            .arg("-S")
            .arg(&socket)
            .args([
                "-f",
                "/dev/null",
                "new-session",
                "-d",
                "-s",
                "t",
                "-x",
                "170",
                "-y",
                "60",
            ])
            .arg(shell)
            .env("TERM", "xterm-256color")
            .status()
            .expect("running tmux");
        assert!(st.success(), "tmux new-session failed: {st}");
        Tmux { socket, _dir: dir }
    }

    fn tmux(&self) -> Command {
        let mut c = Command::new("tmux");
        c.arg("-S").arg(&self.socket);
        c
    }

    /// Press keys (tmux key names: `Up`, `Enter`, `Escape`, `q`, …).
    fn keys(&self, keys: &[&str]) {
        let st = self
            .tmux()
            .args(["send-keys", "-t", "t"])
            .args(keys)
            .status()
            .unwrap();
        assert!(st.success());
    }

    /// Type text literally.
    fn type_text(&self, text: &str) {
        let st = self
            .tmux()
            .args(["send-keys", "-t", "t", "-l", text])
            .status()
            .unwrap();
        assert!(st.success());
    }

    /// What the pane shows now.
    fn screen(&self) -> String {
        let out = self
            .tmux()
            .args(["capture-pane", "-p", "-t", "t"])
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// Wait until the screen satisfies `cond`; the screen then.
    fn wait(&self, what: &str, cond: impl Fn(&str) -> bool) -> String {
        let end = Instant::now() + WAIT;
        loop {
            let s = self.screen();
            if cond(&s) {
                return s;
            }
            assert!(
                Instant::now() < end,
                "timed out waiting for {what}; the screen:\n{s}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Wait until the screen shows every one of `needles`.
    fn wait_for(&self, needles: &[&str]) -> String {
        self.wait(&format!("{needles:?}"), |s| {
            needles.iter().all(|n| s.contains(n))
        })
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = self
            .tmux()
            .arg("kill-server")
            .stderr(Stdio::null())
            .status();
    }
}

/// The line of the screen that contains `needle`.
fn line_with<'a>(screen: &'a str, needle: &str) -> &'a str {
    screen
        .lines()
        .find(|l| l.contains(needle))
        .unwrap_or_else(|| panic!("no line with {needle:?} in\n{screen}"))
}

/// Table rows of slaves in Data_Exchange: lines with the state that are
/// not state changes in the event log ("check_diag → data_exchange").
fn rows_in_data_exchange(screen: &str) -> usize {
    screen
        .lines()
        .filter(|l| l.contains("data_exchange") && !l.contains('→'))
        .count()
}

fn gen_gsd() -> PathBuf {
    common::repo().join("crates/devices/gsd/DPCTL_GEN.GSD")
}

/// A bus file: a GSD slave at 8 ("2 words in/out") and an Omega drive
/// at 25 (a device profile with named channels).
fn bus_file(dir: &Path) -> PathBuf {
    let t = format!(
        "[master]\naddress = 2\nbaud = \"1.5M\"\n[options]\nreprobe_ms = 50\n\
         [[slave]]\naddress = 8\nname = \"echo\"\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\nwatchdog_ms = 5000\n\
         [[slave]]\naddress = 25\nname = \"drive\"\ndevice = \"omega\"\nwatchdog_ms = 5000\n",
        gen_gsd().display()
    );
    let p = dir.join("bus.toml");
    std::fs::write(&p, t).unwrap();
    p
}

/// A bus file with only the GSD slave at 8 ("2 words in/out"), in `dir`.
fn echo_bus_file(dir: &TempDir) -> PathBuf {
    let config = dir.path("bus.toml");
    let text = format!(
        "[master]\naddress = 2\nbaud = \"1.5M\"\n[[slave]]\naddress = 8\ngsd = \"{}\"\nmodules = [\"2 words in/out\"]\nwatchdog_ms = 5000\n",
        gen_gsd().display()
    );
    std::fs::write(&config, text).unwrap();
    config
}

/// `dpctl master` on the first link of `bus` in tmux, with `extra`
/// options.
fn tmux_master(bus: &Bus, config: &Path, extra: &[&str]) -> Tmux {
    let (port, config) = (bus.link_str(0), config.to_string_lossy());
    let args = [
        "master",
        "--port",
        &port,
        "--config",
        &config,
        "--latency",
        "100",
    ];
    Tmux::start(&[&args[..], extra].concat())
}

/// `dpctl master --json` on `port` (its output dropped).
fn json_master(port: &Path, config: &Path) -> Proc {
    Proc::spawn(
        "dpctl master",
        Command::new(dpctl())
            .args(["master", "--json", "--latency", "100", "--port"])
            .arg(port)
            .arg("--config")
            .arg(config)
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
}

/// The GSD slave at 8 ("2 words in/out") on `port`.
fn echo_slave(port: &Path) -> Proc {
    let gsd = gen_gsd();
    let args = [
        "--addr",
        "8",
        "--gsd",
        &gsd.to_string_lossy(),
        "--module",
        "2 words in/out",
    ];
    slave(port, &args)
}

fn slave(port: &Path, args: &[&str]) -> Proc {
    Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--baud", "1.5M", "--port"])
            .arg(port)
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
}

#[test]
fn master_shows_a_table_selects_details_writes_pauses_and_quits() {
    let bus = Bus::start(3, &[]);
    let _echo = echo_slave(&bus.link(1));
    let _drive = slave(
        &bus.link(2),
        &[
            "--addr",
            "25",
            "--device",
            "omega",
            "--device-opt",
            "drive-enable=auto",
        ],
    );
    let config = bus_file(&bus.dir().0);
    let t = tmux_master(&bus, &config, &[]);
    // Both slaves in Data_Exchange, in a table with its headings.
    let s = t.wait("both slaves in data exchange", |s| {
        rows_in_data_exchange(s) >= 2
    });
    for h in profibus_tui::bus::COLUMNS {
        assert!(s.contains(h), "heading {h} missing:\n{s}");
    }
    assert!(s.contains("dpctl master  master 2 at 1.5Mbit/s"), "{s}");
    let echo = line_with(&s, "echo");
    assert!(echo.contains("  8 "), "{echo}");
    // The GSD slave decoded by module, the drive by its channels.
    assert!(s.contains("2 words in/out: 00 00 00 00"), "{s}");
    assert!(s.contains("setpoint1="), "{s}");
    // A cycle time in ms.
    t.wait("a cycle time", |s| line_with(s, "echo").contains(" ms "));

    // Write the echo slave's outputs: its inputs echo them.
    t.keys(&["w"]);
    t.wait_for(&["write outputs of slave 8 echo"]);
    t.type_text("01 02 03 04");
    t.keys(&["Enter"]);
    t.wait_for(&["slave 8: outputs 01 02 03 04"]);
    t.wait("the echo", |s| {
        line_with(s, "echo").matches("01 02 03 04").count() == 2
    });

    // Select the drive, open its details, close them.
    t.keys(&["Down", "Enter"]);
    // The whole popup, not only its title (a redraw may arrive in parts).
    t.wait_for(&[
        "details (Esc closes",
        "slave 25 drive",
        "ident number 0x",
        "data exchanges ",
        "diagnosis: ",
    ]);
    t.keys(&["Escape"]);
    t.wait("details closed", |s| !s.contains("details (Esc"));
    // Named channels at the prompt.
    t.keys(&["w"]);
    t.type_text("setpoint1=1234");
    t.keys(&["Enter"]);
    t.wait_for(&["setpoint1=1234"]);
    // A short image is refused with the reason, as the gateway refuses
    // it: written by position it would overwrite the drive's PKW header.
    t.keys(&["w"]);
    t.type_text("01 02");
    t.keys(&["Enter"]);
    let s = t.wait_for(&["not written: slave 25 has ", "the write has 2"]);
    assert!(
        s.contains("setpoint1=1234"),
        "the drive's outputs changed:\n{s}"
    );

    // Pause: the header says so and the cycle counter stands still.
    t.keys(&["p"]);
    let s = t.wait_for(&["PAUSED"]);
    let cycles = |s: &str| line_with(s, "cycles ").to_string();
    let before = cycles(&s);
    // The bus runs on: a Data_Exchange later the screen is the same.
    let again = t.screen();
    assert_eq!(cycles(&again), before);
    t.keys(&["p"]);
    t.wait("running again", |s| {
        !s.contains("PAUSED") && cycles(s) != before
    });

    t.keys(&["q"]);
    let s = t.wait_for(&["[exit 0]"]);
    assert!(!s.contains("Addr"), "the table is gone after q:\n{s}");
    drop(bus);
}

#[test]
fn master_plain_prints_lines_on_a_terminal() {
    let bus = Bus::start(2, &[]);
    let _echo = echo_slave(&bus.link(1));
    let dir = TempDir::new("plain");
    let config = echo_bus_file(&dir);
    let t = tmux_master(&bus, &config, &["--plain", "--exchanges", "20"]);
    let s = t.wait_for(&["[exit 0]"]);
    assert!(s.contains("master 2 at 1.5Mbit/s"), "{s}");
    assert!(s.contains("data_exchange"), "{s}");
    assert!(!s.contains("Addr"), "no table with --plain:\n{s}");
}

#[test]
fn demo_shows_every_device_profile_moving() {
    let t = Tmux::start(&["demo"]);
    let s = t.wait("seven slaves in data exchange", |s| {
        rows_in_data_exchange(s) >= 7
    });
    assert!(s.contains("dpctl demo"), "{s}");
    for profile in [
        "(generic)",
        "(bm4)",
        "(omega)",
        "(bk3000)",
        "(jx2)",
        "(rfid)",
    ] {
        assert!(s.contains(profile), "{profile} missing:\n{s}");
    }
    // The Omega drive's actual value follows its setpoint.
    t.wait("the drive's actual speed near its setpoint", omega_follows);
    // The BM4's variables move: one written by the master, one by the
    // module's own PLC program.
    t.wait("the BM4's variables changing", |s| {
        value(s, "u_MyWriteVar2").is_some_and(|v| v >= 10.0)
            && value(s, "ud_MyReadVar1").is_some_and(|v| v >= 70.0)
    });
    // The person's write to the echo slave stays (the PLC program leaves
    // it) and comes back as its inputs.
    t.keys(&["w"]);
    t.wait_for(&["write outputs of slave 3 echo (generic)"]);
    t.type_text("AA BB CC DD");
    t.keys(&["Enter"]);
    t.wait("the echo of the written outputs", |s| {
        line_with(s, "echo (generic)")
            .matches("AA BB CC DD")
            .count()
            == 2
    });
    // The details of the first slave, then quit.
    t.keys(&["Enter"]);
    t.wait_for(&["details (Esc closes", "slave 3 "]);
    t.keys(&["Escape", "q"]);
    let s = t.wait_for(&["[exit 0]"]);
    assert!(s.contains("demo: "), "the summary after the view:\n{s}");
}

/// The number shown after `NAME=` (the first on the screen).
fn value(s: &str, name: &str) -> Option<f64> {
    let at = s.find(&format!("{name}="))? + name.len() + 1;
    let rest = &s[at..];
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || c == '-' || c == '.'))
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// Whether the screen shows the Omega drive's actual value 1 within a
/// few percent of (and not zero like) setpoint 1.
fn omega_follows(s: &str) -> bool {
    match (value(s, "setpoint1"), value(s, "actual1")) {
        (Some(sp), Some(av)) => sp != 0.0 && (av - sp).abs() <= sp.abs() * 0.2 + 2.0,
        _ => false,
    }
}

/// Sniff's live list shows an FMS telegram with its LLI/FMS PDUs in
/// words (issue 35), service `FMS`: `dpctl fms read` on a mixed-mode
/// BK3000, the list filtered to station 5.
#[test]
fn sniff_lists_fms_telegrams_in_words() {
    let bus = Bus::start(3, &[]);
    let mut coupler = Proc::spawn(
        "dpctl slave (bk3000, fms=mixed)",
        Command::new(dpctl())
            .args(["slave", "--baud", "1.5M", "--json", "--addr", "5"])
            .args(["--device", "bk3000", "--terminals", "KL3102,KL4002,KL9010"])
            .args(["--device-opt", "fms=mixed", "--port"])
            .arg(bus.link(1))
            .stdout(Stdio::piped())
            .stderr(Stdio::null()),
    );
    let _events = common::started(&mut coupler, WAIT);
    let port = bus.link_str(2);
    let t = Tmux::start(&["sniff", "--port", &port, "--baud", "1.5M"]);
    t.wait_for(&["dpctl sniff", "stations"]);
    t.keys(&["a"]);
    t.type_text("5");
    t.keys(&["Enter"]);
    t.wait_for(&["filter: address 5"]);
    let link = bus.link_str(0);
    let read = common::run_dpctl(&[
        "fms",
        "--port",
        &link,
        "--station",
        "5",
        "--addr",
        "3",
        "--baud",
        "1.5M",
        "--latency",
        "100",
        "read",
        "2020",
    ]);
    assert!(read.status.success(), "{read:?}");
    // The meaning first (the column is narrow), the service `FMS`.
    let s = t.wait_for(&[
        "FMS Read.req invoke",
        "index 2020 | SD2 3→5",
        "FMS Read.resp invoke",
        "LLI Abort",
    ]);
    let req = line_with(&s, "FMS Read.req");
    assert!(!req.contains("MSAC_C2"), "{req}");
    t.keys(&["q"]);
    t.wait_for(&["[exit 0]"]);
}

#[test]
fn sniff_lists_telegrams_with_filters_and_station_statistics() {
    let bus = Bus::start(3, &[]);
    let _echo = echo_slave(&bus.link(1));
    let dir = TempDir::new("sniff");
    let config = echo_bus_file(&dir);
    let _master = json_master(&bus.link(0), &config);
    let port = bus.link_str(2);
    let t = Tmux::start(&["sniff", "--port", &port]);
    let s = t.wait_for(&["dpctl sniff", "stations", "Data_Exchange", "token 2→2"]);
    assert!(
        s.contains("Req") && s.contains("Resp") && s.contains("NoAns"),
        "{s}"
    );
    // Both stations counted.
    t.wait("both stations in the statistics", |s| {
        s.lines().any(|l| l.contains("│  2 ")) && s.lines().any(|l| l.contains("│  8 "))
    });

    // Only telegrams of station 8: no tokens.
    t.keys(&["a"]);
    t.type_text("8");
    t.keys(&["Enter"]);
    // Waited for as a whole: tmux may show the new header above the
    // previous frame's list while the redraw is still arriving.
    t.wait("station 8's telegrams and no tokens", |s| {
        s.contains("filter: address 8") && s.contains("2→8") && !s.contains("token 2→2")
    });
    // Only tokens.
    t.keys(&["c", "s"]);
    t.type_text("token");
    t.keys(&["Enter"]);
    t.wait("only tokens", |s| {
        s.contains("filter: service \"token\"") && s.contains("token 2→2") && !s.contains("2→8")
    });
    // Errors only: nothing went wrong on this bus.
    t.keys(&["c", "e"]);
    t.wait("errors only, and none on this bus", |s| {
        s.contains("filter: errors only") && !s.contains("token 2→2") && !s.contains("2→8")
    });
    t.keys(&["q"]);
    let s = t.wait_for(&["[exit 0]"]);
    assert!(s.contains("summary: "), "the summary after the view:\n{s}");
}

#[test]
fn monitor_shows_another_masters_slaves_and_the_token_ring_and_never_writes() {
    let bus = Bus::start(4, &[]);
    let _echo = echo_slave(&bus.link(1));
    let _drive = slave(
        &bus.link(2),
        &[
            "--addr",
            "25",
            "--device",
            "omega",
            "--device-opt",
            "drive-enable=auto",
        ],
    );
    let config = bus_file(&bus.dir().0);
    let _master = json_master(&bus.link(0), &config);
    let port = bus.link_str(3);
    let t = Tmux::start(&[
        "monitor",
        "--port",
        &port,
        "--config",
        &config.to_string_lossy(),
    ]);
    // Both slaves in Data_Exchange in the table (not just in the event
    // log), decoded, and master 2 in the ring.
    let s = t.wait(
        "both slaves in data exchange, their data decoded, master 2 in the ring",
        |s| {
            rows_in_data_exchange(s) >= 2
                && s.contains("token ring: masters 2 (")
                && s.contains("2 words in/out: ")
                && s.contains("setpoint1=")
                && s.contains("actual1=")
        },
    );
    assert!(s.contains("dpctl monitor  listening at 1.5Mbit/s"), "{s}");
    assert!(!s.contains("master 2 at"), "the monitor is no master:\n{s}");
    assert!(s.contains("line: telegrams "), "{s}");
    assert!(line_with(&s, "echo").contains("  8 "), "{s}");
    assert!(s.contains("2 words in/out: "), "{s}");
    assert!(s.contains("setpoint1=") && s.contains("actual1="), "{s}");
    assert!(s.contains("listening only: no writes"), "{s}");
    t.wait("a cycle time", |s| line_with(s, "echo").contains(" ms "));
    // Role and health per station, without --stats: each slave's row,
    // and master 2 on the token ring line.
    let s = t.wait("role and health bars", |s| {
        let has = |needle: &str, parts: &[&str]| {
            (s.lines()).any(|l| l.contains(needle) && parts.iter().all(|p| l.contains(p)))
        };
        s.contains("Role")
            && s.contains("Health")
            && has("drive", &[" slave ", "█"])
            && has("token ring: masters 2 (", &["█"])
    });
    assert!(line_with(&s, "echo").contains(" slave "), "{s}");

    // No write prompt: the monitor never sends.
    t.keys(&["w"]);
    // Details of the drive: who polls it.
    t.keys(&["Down", "Enter"]);
    let s = t.wait_for(&[
        "details (Esc closes",
        "slave 25 drive",
        "polled by master 2",
    ]);
    assert!(!s.contains("write outputs of"), "{s}");
    t.keys(&["Escape"]);
    t.wait("details closed", |s| !s.contains("details (Esc"));

    // Pause: the telegram counter stands still, then runs on.
    t.keys(&["p"]);
    let s = t.wait_for(&["PAUSED"]);
    let counted = |s: &str| line_with(s, "line: telegrams").to_string();
    let before = counted(&s);
    t.wait("a frame later, the same", |s| counted(s) == before);
    t.keys(&["p"]);
    t.wait("running again", |s| {
        !s.contains("PAUSED") && counted(s) != before
    });
    t.keys(&["q"]);
    let s = t.wait_for(&["[exit 0]"]);
    assert!(!s.contains("Addr"), "the table is gone after q:\n{s}");
}

#[test]
fn monitor_plain_prints_lines_on_a_terminal() {
    let bus = Bus::start(2, &[]);
    let config = bus_file(&bus.dir().0);
    let port = bus.link_str(0);
    let t = Tmux::start(&[
        "monitor",
        "--plain",
        "--interval",
        "100",
        "--port",
        &port,
        "--config",
        &config.to_string_lossy(),
    ]);
    let s = t.wait_for(&["status t=", "masters in ring: []"]);
    assert!(s.contains("  8 echo"), "{s}");
    assert!(!s.contains("Addr"), "no table with --plain:\n{s}");
}
