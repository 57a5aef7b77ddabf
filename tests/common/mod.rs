//! Helpers for end-to-end tests of real `dpctl` processes.
//!
//! - [`dpctl`]: the path of a fresh `dpctl` binary (built once per test
//!   binary with the same cargo and profile as the tests).
//! - [`TempDir`]: a scratch directory removed on drop.
//! - [`Proc`]: a child process killed on drop, with its output collected.
//! - [`Bus`]: a running `dpctl bus` with links in a temp dir.
//! - [`require`]: fail (never skip) when an external tool is missing.
//!
//! Each test file uses a subset, hence the `dead_code` allowance.
#![allow(dead_code)]

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// Path of the `dpctl` binary, built on first use.
///
/// The binary lives next to the test executable's `deps/` directory
/// (`target/<profile>/dpctl`). It is (re)built with `cargo build -p dpctl`
/// for that profile, so a test never runs a stale binary; when cargo is
/// not available (tests run by hand) an existing binary is used.
pub fn dpctl() -> PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let exe = std::env::current_exe().expect("test executable path");
        // target/<profile>/deps/<test> → target/<profile>
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("test executable in target/<profile>/deps")
            .to_path_buf();
        let bin = profile_dir.join(format!("dpctl{}", std::env::consts::EXE_SUFFIX));
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = Command::new(cargo);
        cmd.args(["build", "--quiet", "-p", "dpctl", "--bin", "dpctl"]);
        match profile_dir.file_name().and_then(|n| n.to_str()) {
            Some("debug") => {}
            Some("release") => {
                cmd.arg("--release");
            }
            Some(other) => {
                cmd.args(["--profile", other]);
            }
            None => {}
        }
        // Build into the same target directory as the tests.
        if let Some(target) = profile_dir.parent() {
            cmd.env("CARGO_TARGET_DIR", target);
        }
        cmd.current_dir(env!("CARGO_MANIFEST_DIR"));
        match cmd.status() {
            Ok(s) if s.success() => {}
            Ok(s) => panic!("building dpctl failed ({s})"),
            Err(e) if bin.exists() => {
                eprintln!("cannot run cargo ({e}); using {}", bin.display())
            }
            Err(e) => panic!("cannot run cargo to build dpctl: {e}"),
        }
        assert!(bin.exists(), "{} missing after the build", bin.display());
        bin
    })
    .clone()
}

/// Fail the test with a clear message when `tool` is not installed.
/// External peers are never skipped silently.
pub fn require(tool: &str) {
    let found = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).any(|d| d.join(tool).is_file()))
        .unwrap_or(false);
    assert!(
        found,
        "`{tool}` is required by this test but not installed; run scripts/setup-test-env"
    );
}

/// A scratch directory, removed with its contents on drop.
pub struct TempDir(PathBuf);

impl TempDir {
    /// A new empty directory under the system temp dir.
    pub fn new(tag: &str) -> TempDir {
        static N: AtomicU32 = AtomicU32::new(0);
        let p = std::env::temp_dir().join(format!(
            "dpctl-test-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).expect("create temp dir");
        TempDir(p)
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.0
    }

    /// A path inside the directory.
    pub fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
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

/// A child process that is killed when dropped.
pub struct Proc {
    child: Option<Child>,
    name: String,
}

impl Proc {
    /// Spawn `cmd` with piped stdout and stderr.
    pub fn spawn(mut cmd: Command) -> Proc {
        let name = format!("{cmd:?}");
        let child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
        Proc {
            child: Some(child),
            name,
        }
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().expect("running").id()
    }

    /// Send a signal (`libc` number, e.g. 15 for SIGTERM).
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

    /// Wait for the process to end (at most `timeout`, then kill it and
    /// fail) and collect its output.
    pub fn wait(mut self, timeout: Duration) -> Output {
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
        let mut stdout = String::new();
        let mut stderr = String::new();
        if let Some(mut o) = child.stdout.take() {
            let _ = o.read_to_string(&mut stdout);
        }
        if let Some(mut e) = child.stderr.take() {
            let _ = e.read_to_string(&mut stderr);
        }
        Output {
            status,
            stdout,
            stderr,
        }
    }

    /// SIGTERM, then wait.
    pub fn stop(self) -> Output {
        self.signal(15);
        self.wait(Duration::from_secs(10))
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

/// Run `dpctl` with `args` to completion (at most 30 s).
pub fn run_dpctl(args: &[&str]) -> Output {
    let mut cmd = Command::new(dpctl());
    cmd.args(args);
    Proc::spawn(cmd).wait(Duration::from_secs(30))
}

/// Wait until `cond` holds, polling every 5 ms; panic after `timeout`.
pub fn wait_for(what: &str, timeout: Duration, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + timeout;
    while !cond() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
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
        let prefix = dir.join("st");
        let mut cmd = Command::new(dpctl());
        cmd.arg("bus")
            .args(["--stations", &stations.to_string()])
            .arg("--link")
            .arg(&prefix)
            .args(extra);
        let mut proc = Proc::spawn(cmd);
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
