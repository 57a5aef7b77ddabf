//! Helpers for end-to-end tests: the `dpctl` binary, socat pty pairs,
//! the Python venv with pyprofibus, child processes that are stopped and
//! cleaned up even when a test fails.
//!
//! Missing peers (socat, the venv) make a test FAIL with a message that
//! says how to install them (`scripts/setup-test-env`); they never skip.

#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `target/<profile>/dpctl`, next to this test binary's `deps` directory.
pub fn dpctl() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    let dir = exe
        .parent()
        .and_then(|d| d.parent())
        .expect("target/<profile>/deps");
    let p = dir.join(format!("dpctl{}", std::env::consts::EXE_SUFFIX));
    assert!(
        p.exists(),
        "{} is missing: build it with `cargo build -p dpctl` (cargo test --workspace does)",
        p.display()
    );
    p
}

/// Fail with how to set up the test environment.
pub fn need(what: &str) -> ! {
    panic!("{what} is missing: run scripts/setup-test-env (scripts/test does it)");
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

/// A temporary directory removed on drop.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        let p = std::env::temp_dir().join(format!(
            "dpctl-{tag}-{}-{}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_nanos()
        ));
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A child process killed (by its pid) on drop.
pub struct Proc {
    pub child: Option<Child>,
    pub name: String,
}

impl Proc {
    pub fn spawn(name: &str, cmd: &mut Command) -> Proc {
        let child = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
        Proc {
            child: Some(child),
            name: name.to_string(),
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().unwrap().id()
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

    /// Everything until the child closed its stdout.
    pub fn rest(&mut self) -> &[String] {
        while let Ok(l) = self.0.recv_timeout(Duration::from_secs(10)) {
            self.1.push(l);
        }
        &self.1
    }
}
