//! One process owns a line: an advisory lock per port that every `dpctl`
//! command opening a port takes, so that a second command on a port held
//! by another process fails at once with one line naming that process
//! (its pid, command line and control socket) instead of fighting it for
//! the line.
//!
//! The lock is `flock(2)` (through [`nix::fcntl::Flock`]) on a lock
//! file in `$XDG_RUNTIME_DIR/dpctl` (else `/tmp/dpctl-$USER`), named after
//! the port's canonical path, so that a `dpctl bus` link and the pty it
//! points to are the same port. The kernel drops the lock when the holder
//! exits, however it exits; the file then holds stale text that the next
//! holder overwrites. The holder writes its pid, command line and control
//! socket path into the file. `tcp://` ports are not locked (the serial
//! server is shared by design).

use nix::errno::Errno;
use nix::fcntl::{Flock, FlockArg};
use std::fs::{File, OpenOptions};
use std::io::{self, Read, Seek, Write};
use std::path::{Path, PathBuf};

/// The process that holds a port, as it wrote itself into the lock file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Holder {
    /// Its process id.
    pub pid: u32,
    /// Its command line (`dpctl master --port … --config plant.toml`).
    pub command: String,
    /// Its control socket (`--control PATH`), if it has one.
    pub control: Option<PathBuf>,
}

impl Holder {
    /// This process, with its control socket `control`.
    pub fn this_process(control: Option<&Path>) -> Holder {
        let command = std::fs::read("/proc/self/cmdline")
            .map(|raw| command_line(&raw))
            .unwrap_or_else(|_| "dpctl".into());
        Holder {
            pid: std::process::id(),
            command,
            control: control.map(Path::to_path_buf),
        }
    }

    fn to_text(&self) -> String {
        let control = self
            .control
            .as_ref()
            .map(|c| c.display().to_string())
            .unwrap_or_default();
        format!("{}\n{}\n{}\n", self.pid, self.command, control)
    }

    fn from_text(text: &str) -> Option<Holder> {
        let mut lines = text.lines();
        let pid = lines.next()?.trim().parse().ok()?;
        let command = lines.next()?.to_string();
        let control = lines.next().filter(|c| !c.is_empty()).map(PathBuf::from);
        Some(Holder {
            pid,
            command,
            control,
        })
    }
}

/// `/proc/PID/cmdline` as one line: NUL-separated words joined by
/// blanks, the program by its file name (`dpctl`, not its path).
fn command_line(raw: &[u8]) -> String {
    let mut words = raw
        .split(|b| *b == 0)
        .filter(|w| !w.is_empty())
        .map(|w| String::from_utf8_lossy(w).into_owned());
    let program = words.next().unwrap_or_default();
    let program = Path::new(&program)
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or(program);
    std::iter::once(program)
        .chain(words)
        .collect::<Vec<_>>()
        .join(" ")
}

/// Why a port could not be locked.
#[derive(Debug, thiserror::Error)]
pub enum PortLockError {
    /// Another process holds the port.
    #[error("{port} is in use by {}", held_by(.holder))]
    Held {
        /// The port as given.
        port: String,
        /// Who holds it (`None`: it wrote nothing readable yet).
        holder: Option<Holder>,
    },
    /// The lock file cannot be made.
    #[error("cannot lock {port} ({}): {error}", lock.display())]
    Io {
        /// The port as given.
        port: String,
        /// The lock file.
        lock: PathBuf,
        /// Why.
        error: io::Error,
    },
}

fn held_by(holder: &Option<Holder>) -> String {
    match holder {
        None => "another dpctl process".into(),
        Some(h) => {
            let via = match &h.control {
                Some(c) => format!("run this command through it with --via {}", c.display()),
                None => "it has no control socket: start it with --control PATH and run \
                         this command with --via PATH"
                    .into(),
            };
            format!("dpctl process {} ({}); {via}", h.pid, h.command)
        }
    }
}

/// A held port; the lock goes with the value (and with the process).
#[derive(Debug)]
pub struct PortLock {
    _file: Flock<File>,
    key: PathBuf,
}

impl PortLock {
    /// Lock `port` for `holder`. `Ok(None)` for a `tcp://` port (not
    /// locked).
    pub fn take(port: &str, holder: &Holder) -> Result<Option<PortLock>, PortLockError> {
        if port.contains("://") {
            return Ok(None);
        }
        let key = canonical(port);
        let lock = lock_dir().join(file_name(&key));
        let io_err = |error| PortLockError::Io {
            port: port.to_string(),
            lock: lock.clone(),
            error,
        };
        if let Some(dir) = lock.parent() {
            std::fs::create_dir_all(dir).map_err(io_err)?;
        }
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&lock)
            .map_err(io_err)?;
        let mut file = match Flock::lock(file, FlockArg::LockExclusiveNonblock) {
            Ok(f) => f,
            Err((mut file, Errno::EWOULDBLOCK)) => {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                return Err(PortLockError::Held {
                    port: port.to_string(),
                    holder: Holder::from_text(&text),
                });
            }
            Err((_, e)) => return Err(io_err(io::Error::from(e))),
        };
        file.set_len(0).map_err(io_err)?;
        file.rewind().map_err(io_err)?;
        file.write_all(holder.to_text().as_bytes())
            .map_err(io_err)?;
        Ok(Some(PortLock { _file: file, key }))
    }

    /// The port's canonical path (the lock's key).
    pub fn key(&self) -> &Path {
        &self.key
    }
}

/// The canonical path of `port` (a link resolved), else `port` itself.
pub fn canonical(port: &str) -> PathBuf {
    std::fs::canonicalize(port).unwrap_or_else(|_| PathBuf::from(port))
}

/// `$XDG_RUNTIME_DIR/dpctl`, else `/tmp/dpctl-$USER`.
fn lock_dir() -> PathBuf {
    match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d).join("dpctl"),
        None => {
            let user = std::env::var("USER").unwrap_or_else(|_| "user".into());
            std::env::temp_dir().join(format!("dpctl-{user}"))
        }
    }
}

/// The lock file's name for a canonical port path: `/dev/pts/5` →
/// `dev%pts%5.lock` (`%` itself as `%%`).
fn file_name(key: &Path) -> String {
    let s = key.to_string_lossy();
    let mut name = String::new();
    for c in s.trim_start_matches('/').chars() {
        match c {
            '%' => name.push_str("%%"),
            '/' => name.push('%'),
            c => name.push(c),
        }
    }
    name + ".lock"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_on_the_same_port_names_the_first_holder() {
        let tmp = tempfile::tempdir().unwrap();
        let port = tmp.path().join("tty");
        std::fs::write(&port, "").unwrap();
        let link = tmp.path().join("link0");
        std::os::unix::fs::symlink(&port, &link).unwrap();
        let first = Holder {
            pid: 4242,
            command: "dpctl master --config plant.toml".into(),
            control: Some("/run/plant.sock".into()),
        };
        let held = PortLock::take(port.to_str().unwrap(), &first)
            .unwrap()
            .unwrap();
        // The link is the same port.
        let e = PortLock::take(link.to_str().unwrap(), &Holder::this_process(None)).unwrap_err();
        let PortLockError::Held { holder, .. } = &e else {
            panic!("{e}")
        };
        assert_eq!(holder.as_ref(), Some(&first));
        let text = e.to_string();
        assert!(
            text.contains("dpctl process 4242 (dpctl master --config plant.toml)")
                && text.contains("--via /run/plant.sock"),
            "{text}"
        );
        drop(held);
        // Free again once the holder is gone.
        assert!(PortLock::take(link.to_str().unwrap(), &first).is_ok());
        assert!(PortLock::take("tcp://localhost:1", &first)
            .unwrap()
            .is_none());
    }

    #[test]
    fn command_lines_name_the_program_by_its_file_name() {
        assert_eq!(
            command_line(b"/usr/bin/dpctl\0master\0--config\0plant.toml\0"),
            "dpctl master --config plant.toml"
        );
        assert_eq!(file_name(Path::new("/dev/pts/5")), "dev%pts%5.lock");
        let no_control = Holder {
            pid: 1,
            command: "dpctl pkw".into(),
            control: None,
        };
        let text = held_by(&Some(no_control));
        assert!(text.contains("start it with --control PATH"), "{text}");
    }
}
