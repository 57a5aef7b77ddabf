//! Helpers for the process tests of the `dpctl` package (one copy, used
//! by every file in `crates/cli/tests/` and `crates/cli/benches/`): the
//! `dpctl` binary cargo built for them, the repository root, socat pty
//! pairs, `dpctl bus` in a temp dir, the Python venv with pyprofibus,
//! child processes that are stopped and cleaned up even when a test fails.
//!
//! Missing peers (socat, the venv) make a test FAIL with a message that
//! says how to install them (`scripts/setup-test-env`); they never skip.

#![allow(dead_code)]

pub mod mqtt;

use serde_json::Value;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver, Sender};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// The lines of `lines` that are JSON values (a command's `--json`
/// output), parsed; other lines are passed over.
pub fn json_lines<S: AsRef<str>>(lines: impl IntoIterator<Item = S>) -> Vec<serde_json::Value> {
    let parsed = lines
        .into_iter()
        .map(|l| serde_json::from_str(l.as_ref()).ok());
    parsed.flatten().collect()
}

/// Write `line` to the stdin of `p` (started with a piped stdin).
pub fn send(p: &mut Proc, line: &str) {
    use std::io::Write;
    let stdin = p.child.as_mut().unwrap().stdin.as_mut().unwrap();
    writeln!(stdin, "{line}").unwrap();
    stdin.flush().unwrap();
}

/// The slave at `addr` in a status line of `dpctl master --json`.
pub fn slave_of(status: &serde_json::Value, addr: u8) -> &serde_json::Value {
    let slaves = status["slaves"].as_array().unwrap();
    slaves.iter().find(|s| s["address"] == addr).unwrap()
}

/// Whether every slave of a status line of `dpctl master --json` is in
/// Data_Exchange.
pub fn all_dx(status: &serde_json::Value) -> bool {
    let slaves = status["slaves"].as_array().unwrap();
    slaves.iter().all(|s| s["state"] == "data_exchange")
}

/// Run `cmd` to its end: it must succeed (its stderr is the message when
/// it does not).
pub fn run_ok(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "{:?} failed: {stderr}",
        cmd.get_program()
    );
    out
}

/// Run a pyprofibus peer script (`cmd`, stdout piped) to its end, at
/// most 90 s: it must succeed. Its output lines.
pub fn run_pyprofibus(cmd: &mut Command) -> Vec<String> {
    let mut p = Proc::spawn("pyprofibus", cmd);
    let mut out = Lines::from(&mut p);
    let st = p.wait(Duration::from_secs(90));
    let lines = out.rest().to_vec();
    assert!(st.success(), "pyprofibus: {lines:?}");
    lines
}

/// The output lines of `slave`, a `dpctl slave --json` just spawned
/// (stdout piped), once it printed its start event (within `timeout`).
pub fn started(slave: &mut Proc, timeout: Duration) -> Lines {
    let mut out = Lines::from(slave);
    let start = out.wait_for("\"event\":\"start\"", timeout);
    assert!(start, "dpctl slave did not start: {:?}", out.1);
    out
}

/// The repository root (this package lives in `crates/cli`).
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .expect("crates/cli inside the repository")
        .to_path_buf()
}

/// Path of the `dpctl` binary cargo built for these tests.
pub fn dpctl() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_dpctl"))
}

/// Fail with how to set up the test environment.
pub fn need(what: &str) -> ! {
    panic!("{what} is missing: run scripts/setup-test-env (scripts/test does it)");
}

/// Fail the test with a clear message when `tool` is not installed.
/// External peers are never skipped silently.
pub fn require(tool: &str) {
    let found = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).any(|d| d.join(tool).is_file()))
        .unwrap_or(false);
    if !found {
        need(&format!("`{tool}` (required by this test)"));
    }
}

/// The venv's Python with pyprofibus and pyserial importable.
pub fn python() -> PathBuf {
    let py = repo().join(".venv/bin/python");
    if !py.exists() {
        need(".venv with pyprofibus");
    }
    let ok = Command::new(&py)
        .args(["-c", "import pyprofibus, serial"])
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if !ok {
        need("pyprofibus/pyserial in .venv");
    }
    py
}

/// A temporary directory of its own, removed on drop: made by the
/// `tempfile` crate, which picks a random name and creates it only if no
/// such entry exists, so tests on parallel threads (or processes) never
/// share one. `.0` is its path.
pub struct TempDir(pub PathBuf, tempfile::TempDir);

impl TempDir {
    /// A new directory `dpctl-TAG-XXXXXX` in the system's temp dir.
    pub fn new(tag: &str) -> TempDir {
        let dir = tempfile::Builder::new()
            .prefix(&format!("dpctl-{tag}-"))
            .tempdir()
            .unwrap_or_else(|e| panic!("cannot create a temp dir for {tag}: {e}"));
        TempDir(dir.path().to_path_buf(), dir)
    }

    /// The path of `name` in the directory.
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

/// Output of a finished process.
#[derive(Debug)]
pub struct Output {
    /// Exit status.
    pub status: ExitStatus,
    /// Standard output.
    pub stdout: String,
    /// Standard error.
    pub stderr: String,
}

/// A child process killed (by its pid) on drop.
pub struct Proc {
    pub child: Option<Child>,
    pub name: String,
    /// [`Proc::spawn_captured`]: threads collecting stdout and stderr
    /// while the process runs (so it never blocks on a full pipe).
    captured: Option<(Drain, Drain)>,
    /// [`Proc::spawn_captured`]: the lines of stdout and stderr as they
    /// come (they are in [`Output`] too).
    lines: Option<(Receiver<String>, Receiver<String>)>,
}

type Drain = std::thread::JoinHandle<String>;

/// Collect all `r` yields; each line also goes to `tx` as it arrives.
fn drain(r: impl Read + Send + 'static, tx: Option<Sender<String>>) -> Drain {
    std::thread::spawn(move || {
        let mut r = BufReader::new(r);
        let (mut all, mut line) = (Vec::new(), Vec::new());
        while r.read_until(b'\n', &mut line).is_ok_and(|n| n > 0) {
            if let Some(tx) = &tx {
                let l = String::from_utf8_lossy(&line);
                let _ = tx.send(l.trim_end().to_string());
            }
            all.append(&mut line);
        }
        String::from_utf8_lossy(&all).into_owned()
    })
}

impl Proc {
    pub fn spawn(name: &str, cmd: &mut Command) -> Proc {
        let child = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
        Proc {
            child: Some(child),
            name: name.to_string(),
            captured: None,
            lines: None,
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().unwrap().id()
    }

    /// Spawn `cmd` with stdout and stderr captured (see [`Proc::finish`]).
    pub fn spawn_captured(mut cmd: Command) -> Proc {
        let name = format!("{cmd:?}");
        cmd.stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut p = Proc::spawn(&name, &mut cmd);
        let c = p.child.as_mut().expect("just spawned");
        let (out_tx, out_rx) = std::sync::mpsc::channel();
        let (err_tx, err_rx) = std::sync::mpsc::channel();
        let out = drain(c.stdout.take().expect("piped"), Some(out_tx));
        let err = drain(c.stderr.take().expect("piped"), Some(err_tx));
        p.captured = Some((out, err));
        p.lines = Some((out_rx, err_rx));
        p
    }

    /// The next line on stdout of a [`Proc::spawn_captured`] process,
    /// waiting at most `timeout`.
    pub fn stdout_line(&self, timeout: Duration) -> Option<String> {
        let (rx, _) = self.lines.as_ref().expect("spawn_captured");
        rx.recv_timeout(timeout).ok()
    }

    /// The next line on stderr, as [`Proc::stdout_line`].
    pub fn stderr_line(&self, timeout: Duration) -> Option<String> {
        let (_, rx) = self.lines.as_ref().expect("spawn_captured");
        rx.recv_timeout(timeout).ok()
    }

    /// Wait until `n` lines on stdout satisfied `ok` (counted from the
    /// last call); fails after 30 s.
    pub fn wait_stdout(&self, what: &str, n: usize, ok: impl Fn(&str) -> bool) {
        let end = Instant::now() + Duration::from_secs(30);
        let mut seen = 0;
        while seen < n {
            let left = end.saturating_duration_since(Instant::now());
            let l = self.stdout_line(left);
            let l = l.unwrap_or_else(|| panic!("{}: {seen} of {n} {what}", self.name));
            seen += ok(&l) as usize;
        }
    }

    /// Send signal number `sig` (e.g. 2 SIGINT, 15 SIGTERM).
    pub fn signal(&self, sig: i32) {
        let ok = Command::new("kill")
            .arg(format!("-{sig}"))
            .arg(self.pid().to_string())
            .status()
            .map(|s| s.success())
            .unwrap_or(false);
        assert!(ok, "cannot signal {}", self.name);
    }

    /// Whether the process has exited.
    pub fn exited(&mut self) -> bool {
        self.child
            .as_mut()
            .is_none_or(|c| c.try_wait().ok().flatten().is_some())
    }

    /// Wait for the end (at most `timeout`, then kill and fail) and collect
    /// the captured output.
    pub fn finish(mut self, timeout: Duration) -> Output {
        let mut child = self.child.take().expect("running");
        let deadline = Instant::now() + timeout;
        let status = loop {
            if let Some(s) = child.try_wait().expect("try_wait") {
                break s;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                panic!("{} did not exit within {timeout:?}", self.name);
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        let (stdout, stderr) = match self.captured.take() {
            Some((o, e)) => (o.join().unwrap_or_default(), e.join().unwrap_or_default()),
            None => (String::new(), String::new()),
        };
        Output {
            status,
            stdout,
            stderr,
        }
    }

    /// SIGTERM, then [`Proc::finish`] within 10 s.
    pub fn stop(self) -> Output {
        self.signal(15);
        self.finish(Duration::from_secs(10))
    }

    /// Send SIGTERM and wait up to `timeout` for the exit status.
    pub fn terminate(&mut self, timeout: Duration) -> std::process::ExitStatus {
        let pid = self.pid().to_string();
        let _ = Command::new("kill").args(["-TERM", &pid]).status();
        self.wait(timeout)
    }

    /// Wait up to `timeout` for the exit status (kill after that).
    pub fn wait(&mut self, timeout: Duration) -> std::process::ExitStatus {
        let child = self.child.as_mut().unwrap();
        let end = Instant::now() + timeout;
        loop {
            if let Some(s) = child.try_wait().unwrap() {
                self.child = None;
                return s;
            }
            if Instant::now() > end {
                let _ = child.kill();
                let _ = child.wait();
                self.child = None;
                panic!("{} did not exit within {timeout:?}", self.name);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Some(c) = self.child.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// A socat pty pair linked at `a` and `b`.
pub fn pty_pair(a: &Path, b: &Path) -> Proc {
    if Command::new("socat")
        .arg("-V")
        .stdout(Stdio::null())
        .status()
        .is_err()
    {
        need("socat");
    }
    let p = Proc::spawn(
        "socat",
        Command::new("socat")
            .arg(format!("pty,raw,echo=0,link={}", a.display()))
            .arg(format!("pty,raw,echo=0,link={}", b.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    let end = Instant::now() + Duration::from_secs(5);
    while !(a.exists() && b.exists()) {
        assert!(Instant::now() < end, "socat made no pty pair");
        std::thread::sleep(Duration::from_millis(10));
    }
    p
}

/// Lines of a child's stdout, collected on a thread.
pub struct Lines(std::sync::mpsc::Receiver<String>, pub Vec<String>);

impl Lines {
    pub fn from(child: &mut Proc) -> Lines {
        let out = child.child.as_mut().unwrap().stdout.take().unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(l).is_err() {
                    break;
                }
            }
        });
        Lines(rx, vec![])
    }

    /// Wait until a line contains `needle`; true when it came in time.
    pub fn wait_for(&mut self, needle: &str, timeout: Duration) -> bool {
        if self.1.iter().any(|l| l.contains(needle)) {
            return true;
        }
        let end = Instant::now() + timeout;
        while let Ok(l) = self
            .0
            .recv_timeout(end.saturating_duration_since(Instant::now()))
        {
            let hit = l.contains(needle);
            self.1.push(l);
            if hit {
                return true;
            }
        }
        false
    }

    /// The next line within `timeout` (kept in the history too).
    pub fn next_line(&mut self, timeout: Duration) -> Option<String> {
        let l = self.0.recv_timeout(timeout).ok()?;
        self.1.push(l.clone());
        Some(l)
    }

    /// The first JSON line from line `*pos` on that satisfies `ok`
    /// (waiting up to 60 s for more lines); `*pos` moves past it.
    pub fn json_from(
        &mut self,
        pos: &mut usize,
        what: &str,
        mut ok: impl FnMut(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let end = Instant::now() + Duration::from_secs(60);
        loop {
            while *pos < self.1.len() {
                *pos += 1;
                if let Ok(v) = serde_json::from_str::<serde_json::Value>(&self.1[*pos - 1]) {
                    if ok(&v) {
                        return v;
                    }
                }
            }
            assert!(
                Instant::now() < end,
                "timed out waiting for {what}; last lines: {:#?}",
                &self.1[self.1.len().saturating_sub(5)..]
            );
            self.next_line(Duration::from_millis(100));
        }
    }

    /// The first status line of `dpctl master --json` from line `*pos`
    /// on that satisfies `ok`; `*pos` moves past it.
    pub fn status_from(
        &mut self,
        pos: &mut usize,
        what: &str,
        ok: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        self.json_from(pos, what, |v| v["event"] == "status" && ok(v))
    }

    /// Everything until the child closed its stdout.
    pub fn rest(&mut self) -> &[String] {
        while let Ok(l) = self.0.recv_timeout(Duration::from_secs(10)) {
            self.1.push(l);
        }
        &self.1
    }
}

/// Run `dpctl` with `args` to completion (killed after 2 min: a hang
/// guard, generous for a busy machine).
pub fn run_dpctl(args: &[&str]) -> Output {
    let mut cmd = Command::new(dpctl());
    cmd.args(args);
    Proc::spawn_captured(cmd).finish(Duration::from_secs(120))
}

/// Wait until `cond` holds, polling every 5 ms; panic after `timeout`.
pub fn wait_for(what: &str, timeout: Duration, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + timeout;
    while !cond() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The number after `key` in a status line of `dpctl bus`
/// (`counter(s, "chars ")`).
pub fn counter(status: &str, key: &str) -> Option<u64> {
    let rest = status.split(key).nth(1)?;
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    digits.parse().ok()
}

/// A running `dpctl bus` whose links live in a temp dir.
pub struct Bus {
    /// The hub process.
    pub proc: Proc,
    /// The link prefix.
    pub prefix: PathBuf,
    /// Number of stations.
    pub stations: usize,
    dir: TempDir,
}

impl Bus {
    /// Start `dpctl bus --stations N --link <tmp>/st` with `extra`
    /// arguments and wait until every link exists.
    pub fn start(stations: usize, extra: &[&str]) -> Bus {
        let dir = TempDir::new("bus");
        let prefix = dir.path("st");
        let mut cmd = Command::new(dpctl());
        cmd.arg("bus")
            .args(["--stations", &stations.to_string()])
            .arg("--link")
            .arg(&prefix)
            .args(extra);
        let mut proc = Proc::spawn_captured(cmd);
        let bus_links: Vec<PathBuf> = (0..stations)
            .map(|i| PathBuf::from(format!("{}{i}", prefix.display())))
            .collect();
        wait_for("the bus links", Duration::from_secs(20), || {
            assert!(!proc.exited(), "dpctl bus exited early");
            bus_links.iter().all(|l| l.exists())
        });
        Bus {
            proc,
            prefix,
            stations,
            dir,
        }
    }

    /// Link of station `i`.
    pub fn link(&self, i: usize) -> PathBuf {
        PathBuf::from(format!("{}{i}", self.prefix.display()))
    }

    /// Link of station `i` as a string.
    pub fn link_str(&self, i: usize) -> String {
        self.link(i).to_string_lossy().into_owned()
    }

    /// The hub's counters now: asks with SIGUSR1 and returns the line it
    /// prints (`transmissions …, chars N, …, k/N stations connected …`;
    /// read numbers with [`counter`]).
    pub fn status(&self) -> String {
        self.proc.signal(10);
        let end = Instant::now() + Duration::from_secs(30);
        loop {
            let left = end.saturating_duration_since(Instant::now());
            let l = self
                .proc
                .stderr_line(left)
                .expect("a status line from dpctl bus");
            if l.starts_with("dpctl bus: transmissions") {
                return l;
            }
        }
    }

    /// Wait until the hub's counters satisfy `ok` (see [`Bus::status`]):
    /// the event a test needs (the hub saw a station open its pty, carried
    /// N characters), never a guessed time.
    pub fn wait_status(&self, what: &str, ok: impl Fn(&str) -> bool) -> String {
        let end = Instant::now() + Duration::from_secs(30);
        loop {
            let s = self.status();
            if ok(&s) {
                return s;
            }
            assert!(Instant::now() < end, "timed out waiting for {what}: {s}");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Wait until exactly `n` stations have their pty open as the hub
    /// sees it (it checks for openers every few ms).
    pub fn wait_connected(&self, n: u64) {
        let connected = |s: &str| {
            let head = s.split(" stations connected").next()?;
            head.rsplit(' ').next()?.split('/').next()?.parse().ok()
        };
        self.wait_status(&format!("{n} stations connected"), |s| {
            connected(s) == Some(n)
        });
    }

    /// The temp dir holding the links (for other files of the test).
    pub fn dir(&self) -> &TempDir {
        &self.dir
    }

    /// SIGTERM the hub and collect its output (the links must be gone).
    pub fn stop(self) -> Output {
        let Bus {
            proc,
            prefix,
            stations,
            dir,
        } = self;
        let out = proc.stop();
        for i in 0..stations {
            let l = PathBuf::from(format!("{}{i}", prefix.display()));
            assert!(
                std::fs::symlink_metadata(&l).is_err(),
                "{} left behind",
                l.display()
            );
        }
        drop(dir);
        out
    }
}
/// Open a tty (a pty link) for reading and writing, not as the
/// controlling terminal.
pub fn open_tty(path: &Path) -> std::fs::File {
    use std::os::unix::fs::OpenOptionsExt;
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(nix::libc::O_NOCTTY)
        .open(path)
        .unwrap_or_else(|e| panic!("open {}: {e}", path.display()))
}

/// A station played by hand on a pty link (non-blocking, raw): writes a
/// request telegram and reads the one answer.
pub struct RawStation {
    pub f: std::fs::File,
}

/// What a station answered: a data telegram's (DSAP, SSAP, data unit),
/// or `None` for a short acknowledge.
pub type Answer = Option<(Option<u8>, Option<u8>, Vec<u8>)>;

impl RawStation {
    pub fn open(path: &Path) -> RawStation {
        use std::os::unix::fs::OpenOptionsExt;
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(nix::fcntl::OFlag::O_NONBLOCK.bits() | nix::libc::O_NOCTTY)
            .open(path)
            .unwrap_or_else(|e| panic!("open {}: {e}", path.display()));
        make_raw(&f);
        RawStation { f }
    }

    /// Write `req`, then read until one whole telegram has come or
    /// `wait` has passed: its bytes (what came so far, maybe nothing,
    /// when none did).
    pub fn ask(&mut self, req: &[u8], wait: Duration) -> Vec<u8> {
        use profibus::fdl::wire::frame_len;
        use std::io::Write;
        self.f.write_all(req).unwrap();
        let end = Instant::now() + wait;
        let mut buf = vec![];
        let mut chunk = [0u8; 256];
        while Instant::now() < end {
            match self.f.read(&mut chunk) {
                Ok(n) if n > 0 => buf.extend_from_slice(&chunk[..n]),
                _ => std::thread::sleep(Duration::from_millis(1)),
            }
            if let Ok(len) = frame_len(&buf) {
                if buf.len() >= len {
                    buf.truncate(len);
                    return buf;
                }
            }
        }
        buf
    }

    /// Write the telegram `req`, then read its answer within `timeout`;
    /// panics on no answer or on anything but a data telegram or a short
    /// acknowledge.
    pub fn exchange(&mut self, req: &[u8], timeout: Duration) -> Answer {
        use profibus::fdl::Telegram;
        let buf = self.ask(req, timeout);
        match Telegram::parse(&buf) {
            Ok((Telegram::Data(d), _)) => Some((d.dsap, d.ssap, d.data.to_vec())),
            Ok((Telegram::ShortAck, _)) => None,
            _ if buf.is_empty() => panic!("no answer to {req:02X?} within {timeout:?}"),
            other => panic!("answer to {req:02X?}: {buf:02X?} {other:?}"),
        }
    }
}

/// Put a tty in raw mode (no line discipline, no echo).
pub fn make_raw(f: &std::fs::File) {
    use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
    let mut t = tcgetattr(f).unwrap();
    cfmakeraw(&mut t);
    tcsetattr(f, SetArg::TCSANOW, &t).unwrap();
}

/// `dpctl slave --port PORT --addr ADDR --baud BAUD` with the generic GSD
/// (`crates/devices/gsd/DPCTL_GEN.GSD`) and one `--module` per entry;
/// stdin and stdout are null, stderr is inherited (set it to keep a
/// test's output quiet).
pub fn generic_slave(
    port: impl AsRef<std::ffi::OsStr>,
    addr: u8,
    baud: &str,
    modules: &[&str],
) -> Command {
    let mut cmd = Command::new(dpctl());
    cmd.args(["slave", "--port"])
        .arg(port)
        .args(["--addr", &addr.to_string(), "--baud", baud, "--gsd"])
        .arg(repo().join("crates/devices/gsd/DPCTL_GEN.GSD"));
    for m in modules {
        cmd.args(["--module", m]);
    }
    cmd.stdin(Stdio::null()).stdout(Stdio::null());
    cmd
}

/// Seconds since the Unix epoch (to compare the read times of [`Timed`]
/// lines across processes).
pub fn wall() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// Lines of a child's stdout with the wall time each was read; waits of
/// at most [`TIMED_WAIT`] (generous: processes on a loaded 2-core machine).
pub struct Timed {
    rx: mpsc::Receiver<(f64, String)>,
    lines: Vec<(f64, String)>,
    pos: usize,
}

impl Timed {
    pub fn from(p: &mut Proc) -> Timed {
        let out = p.child.as_mut().unwrap().stdout.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send((wall(), l)).is_err() {
                    break;
                }
            }
        });
        Timed {
            rx,
            lines: vec![],
            pos: 0,
        }
    }

    /// The next JSON line after the last one returned that satisfies
    /// `ok`, with the wall time it was read.
    pub fn wait(&mut self, what: &str, ok: impl Fn(&Value) -> bool) -> (f64, Value) {
        let end = Instant::now() + TIMED_WAIT;
        loop {
            while self.pos < self.lines.len() {
                let (t, l) = &self.lines[self.pos];
                self.pos += 1;
                if let Ok(v) = serde_json::from_str::<Value>(l) {
                    if ok(&v) {
                        return (*t, v);
                    }
                }
            }
            let left = end.saturating_duration_since(Instant::now());
            assert!(
                !left.is_zero(),
                "timed out waiting for {what}; last lines: {:#?}",
                &self.lines[self.lines.len().saturating_sub(8)..]
            );
            if let Ok(l) = self.rx.recv_timeout(left.min(Duration::from_millis(200))) {
                self.lines.push(l);
            }
        }
    }

    /// Forget what arrived so far: the next [`Timed::wait`] looks at
    /// lines read from now on.
    pub fn skip_to_end(&mut self) {
        while let Ok(l) = self.rx.try_recv() {
            self.lines.push(l);
        }
        self.pos = self.lines.len();
    }

    /// Offset from the child's `"t"` (s since its start) to wall time:
    /// the smallest (read time − t) over its lines so far (reading only
    /// ever adds delay).
    pub fn offset(&self) -> f64 {
        self.lines
            .iter()
            .filter_map(|(w, l)| {
                let v: Value = serde_json::from_str(l).ok()?;
                Some(w - v["t"].as_f64()?)
            })
            .fold(f64::INFINITY, f64::min)
    }
}

/// How long [`Timed::wait`] waits for a line.
pub const TIMED_WAIT: Duration = Duration::from_secs(60);

#[cfg(test)]
mod tempdir_tests {
    /// Tests run on parallel threads and ask for temp dirs at the same
    /// moment (two tests of `rfid.rs` once got the same one, and then the
    /// same pty link): every `TempDir` is a directory of its own.
    #[test]
    fn temp_dirs_made_at_once_on_many_threads_are_distinct() {
        use super::TempDir;
        use std::collections::BTreeSet;
        const THREADS: usize = 8;
        const EACH: usize = 200;
        let start = std::sync::Barrier::new(THREADS);
        let dirs: Vec<TempDir> = std::thread::scope(|s| {
            let made: Vec<_> = (0..THREADS)
                .map(|_| {
                    s.spawn(|| {
                        start.wait();
                        (0..EACH).map(|_| TempDir::new("same")).collect::<Vec<_>>()
                    })
                })
                .collect();
            made.into_iter().flat_map(|t| t.join().unwrap()).collect()
        });
        let paths: BTreeSet<_> = dirs.iter().map(|d| d.0.clone()).collect();
        assert_eq!(paths.len(), THREADS * EACH, "two TempDirs share a path");
        assert!(dirs.iter().all(|d| d.0.is_dir()));
    }
}
