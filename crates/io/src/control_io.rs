//! Feeding a [`ControlInbox`] from outside the program: command lines
//! from a file, stdin, or a Unix socket whose connections each send lines
//! (`dpctl slave --control`). Needs a tokio runtime (feature `tokio`).

use profibus_devices::ControlInbox;
use std::io;
use std::path::{Path, PathBuf};
use tokio::io::{AsyncBufReadExt, AsyncRead, BufReader};

/// Where control lines come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ControlSource {
    /// Standard input (`-`).
    Stdin,
    /// A file (or a FIFO) that exists.
    File(PathBuf),
    /// A Unix socket this program creates (and removes at the end):
    /// every connection sends lines.
    Socket(PathBuf),
}

/// Why a control source cannot be opened.
#[derive(Debug, thiserror::Error)]
pub enum ControlSourceError {
    /// The file cannot be opened.
    #[error("cannot open {}: {error}", path.display())]
    Open {
        /// The file.
        path: PathBuf,
        /// Why.
        error: io::Error,
    },
    /// The socket cannot be created.
    #[error("cannot listen on {}: {error}", path.display())]
    Listen {
        /// The socket.
        path: PathBuf,
        /// Why.
        error: io::Error,
    },
}

fn is_socket(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_socket())
}

impl ControlSource {
    /// `-` is stdin; a path that does not exist, or is a socket (left
    /// over from an earlier run), a socket to create; else a file.
    pub fn of(src: &str) -> ControlSource {
        let path = PathBuf::from(src);
        if src == "-" {
            ControlSource::Stdin
        } else if !path.exists() || is_socket(&path) {
            ControlSource::Socket(path)
        } else {
            ControlSource::File(path)
        }
    }

    /// Open the source and feed `inbox` from tokio tasks until it ends.
    /// Must be called inside a runtime.
    pub fn spawn(&self, inbox: ControlInbox) -> Result<(), ControlSourceError> {
        match self {
            ControlSource::Stdin => feed(tokio::io::stdin(), inbox),
            ControlSource::File(path) => {
                let f = std::fs::File::open(path).map_err(|error| ControlSourceError::Open {
                    path: path.clone(),
                    error,
                })?;
                feed(tokio::fs::File::from_std(f), inbox);
            }
            ControlSource::Socket(path) => {
                let _ = std::fs::remove_file(path);
                let listen = |error| ControlSourceError::Listen {
                    path: path.clone(),
                    error,
                };
                let listener = tokio::net::UnixListener::bind(path).map_err(listen)?;
                tokio::spawn(async move {
                    while let Ok((conn, _)) = listener.accept().await {
                        feed(conn, inbox.clone());
                    }
                });
            }
        }
        Ok(())
    }

    /// Remove the socket this created, if any (its listener may outlive
    /// the runtime).
    pub fn remove_socket(&self) {
        if let ControlSource::Socket(path) = self {
            if is_socket(path) {
                let _ = std::fs::remove_file(path);
            }
        }
    }
}

/// The non-empty lines of `src` (a file, or `-` for stdin), read on a
/// plain thread so that a blocking read of stdin never keeps a runtime
/// from shutting down; the channel closes at the end of the input.
pub fn lines_on_a_thread(
    src: &str,
) -> Result<tokio::sync::mpsc::Receiver<String>, ControlSourceError> {
    use std::io::BufRead;
    let reader: Box<dyn io::Read + Send> = if src == "-" {
        Box::new(io::stdin())
    } else {
        let f = std::fs::File::open(src).map_err(|error| ControlSourceError::Open {
            path: src.into(),
            error,
        })?;
        Box::new(f)
    };
    let (tx, rx) = tokio::sync::mpsc::channel(256);
    std::thread::spawn(move || {
        for l in io::BufReader::new(reader).lines().map_while(Result::ok) {
            if !l.trim().is_empty() && tx.blocking_send(l).is_err() {
                break;
            }
        }
    });
    Ok(rx)
}

/// Lines from `r` into `inbox`, in a task.
fn feed(r: impl AsyncRead + Unpin + Send + 'static, inbox: ControlInbox) {
    tokio::spawn(async move {
        let mut lines = BufReader::new(r).lines();
        while let Ok(Some(l)) = lines.next_line().await {
            inbox.push(l);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::AsyncWriteExt;

    /// The next line in `inbox`, as soon as it is there.
    async fn next(inbox: &ControlInbox) -> String {
        let wait = async {
            loop {
                match inbox.take() {
                    Some(l) => return l,
                    None => tokio::task::yield_now().await,
                }
            }
        };
        tokio::time::timeout(std::time::Duration::from_secs(60), wait)
            .await
            .expect("no line within 60 s")
    }

    #[tokio::test]
    async fn lines_from_a_socket_and_a_file_reach_the_inbox() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().to_path_buf();
        let sock = dir.join("ctl.sock");
        let source = ControlSource::of(sock.to_str().unwrap());
        assert_eq!(source, ControlSource::Socket(sock.clone()));
        let inbox = ControlInbox::new();
        source.spawn(inbox.clone()).unwrap();
        let mut c = tokio::net::UnixStream::connect(&sock).await.unwrap();
        c.write_all(b"status\nset x 1\n").await.unwrap();
        drop(c);
        assert_eq!(next(&inbox).await, "status");
        assert_eq!(next(&inbox).await, "set x 1");
        source.remove_socket();
        assert!(!sock.exists());

        let file = dir.join("commands");
        std::fs::write(&file, "leave\n").unwrap();
        let source = ControlSource::of(file.to_str().unwrap());
        assert_eq!(source, ControlSource::File(file.clone()));
        source.spawn(inbox.clone()).unwrap();
        assert_eq!(next(&inbox).await, "leave");
        std::fs::write(&file, "a\n\n  \nb\n").unwrap();
        let mut rx = lines_on_a_thread(file.to_str().unwrap()).unwrap();
        assert_eq!(rx.recv().await.as_deref(), Some("a"));
        assert_eq!(rx.recv().await.as_deref(), Some("b"));
        assert_eq!(rx.recv().await, None);
        let missing = ControlSource::File(dir.join("missing"));
        let err = missing.spawn(inbox).unwrap_err().to_string();
        assert!(err.starts_with("cannot open "), "{err}");
    }
}
