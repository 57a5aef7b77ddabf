//! Feeding a [`ControlInbox`] from outside the program: command lines
//! from a file, stdin, or a Unix socket whose connections each send lines
//! (`dpctl slave --control`); and a [`ControlServer`], the control socket
//! of `dpctl master --control` and `dpctl gateway --control`, where each
//! request line gets exactly one answer line. Needs a tokio runtime.

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
    /// Another live process listens on the socket.
    #[error("{} is the control socket of a running process (another dpctl?): give another path, or stop that process", path.display())]
    Live {
        /// The socket.
        path: PathBuf,
    },
    /// The path exists and is no socket.
    #[error("{} exists and is not a socket: give another path", path.display())]
    NotASocket {
        /// The path.
        path: PathBuf,
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

/// A request line from a client of a [`ControlServer`], and where its
/// answer goes.
#[derive(Debug)]
pub struct ControlRequest {
    /// The line as sent (without its newline).
    pub line: String,
    reply: tokio::sync::oneshot::Sender<String>,
}

impl ControlRequest {
    /// Send the answer line (one line of JSON, no newline). A client that
    /// went away is no error: the answer is dropped.
    pub fn answer(self, answer: String) {
        let _ = self.reply.send(answer);
    }

    /// Whether the client still waits for the answer.
    pub fn is_waiting(&self) -> bool {
        !self.reply.is_closed()
    }
}

/// A control socket: a Unix socket at a path, created with mode 0600
/// (owner only) and removed when the server is dropped. Any number of
/// clients; each sends request lines and gets exactly one answer line per
/// request, in order (a client's next line is read once its last one is
/// answered). A client that disconnects while its request runs harms
/// nothing: the answer is dropped. A socket file left by a dead process
/// is replaced; one that a live process listens on is an error.
#[derive(Debug)]
pub struct ControlServer {
    path: PathBuf,
    requests: tokio::sync::mpsc::Receiver<ControlRequest>,
}

/// Requests waiting for the program to take them, over all clients.
const REQUEST_QUEUE: usize = 64;

impl ControlServer {
    /// Listen at `path`. Must be called inside a runtime.
    pub fn bind(path: &Path) -> Result<ControlServer, ControlSourceError> {
        use std::os::unix::fs::PermissionsExt;
        let path = path.to_path_buf();
        if std::fs::symlink_metadata(&path).is_ok() {
            if !is_socket(&path) {
                return Err(ControlSourceError::NotASocket { path });
            }
            match std::os::unix::net::UnixStream::connect(&path) {
                Ok(_) => return Err(ControlSourceError::Live { path }),
                // Nobody listens: left over from a process that died.
                Err(_) => {
                    let _ = std::fs::remove_file(&path);
                }
            }
        }
        let listen = |error| ControlSourceError::Listen {
            path: path.clone(),
            error,
        };
        let listener = tokio::net::UnixListener::bind(&path).map_err(listen)?;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).map_err(listen)?;
        let (tx, requests) = tokio::sync::mpsc::channel(REQUEST_QUEUE);
        tokio::spawn(async move {
            while let Ok((conn, _)) = listener.accept().await {
                tokio::spawn(serve_client(conn, tx.clone()));
            }
        });
        Ok(ControlServer { path, requests })
    }

    /// The next request, if one waits.
    pub fn try_next(&mut self) -> Option<ControlRequest> {
        self.requests.try_recv().ok()
    }

    /// The socket's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for ControlServer {
    fn drop(&mut self) {
        if is_socket(&self.path) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// One client: its lines become requests, each answer a line back.
async fn serve_client(
    conn: tokio::net::UnixStream,
    requests: tokio::sync::mpsc::Sender<ControlRequest>,
) {
    use tokio::io::AsyncWriteExt;
    let (r, mut w) = conn.into_split();
    let mut lines = BufReader::new(r).lines();
    while let Ok(Some(line)) = lines.next_line().await {
        if line.trim().is_empty() {
            continue;
        }
        let (reply, answer) = tokio::sync::oneshot::channel();
        if requests.send(ControlRequest { line, reply }).await.is_err() {
            return;
        }
        let Ok(mut answer) = answer.await else {
            return;
        };
        answer.push('\n');
        if w.write_all(answer.as_bytes()).await.is_err() {
            return;
        }
    }
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

    #[tokio::test]
    async fn a_control_server_answers_each_line_once_and_replaces_a_stale_socket() {
        use std::os::unix::fs::PermissionsExt;
        use tokio::io::AsyncBufReadExt;
        let tmp = tempfile::tempdir().unwrap();
        let sock = tmp.path().join("ctl.sock");
        // A stale socket: bound, then its process "died".
        drop(std::os::unix::net::UnixListener::bind(&sock).unwrap());
        let mut server = ControlServer::bind(&sock).unwrap();
        let mode = std::fs::metadata(&sock).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o600);
        // A live one is refused.
        let e = ControlServer::bind(&sock).unwrap_err().to_string();
        assert!(e.contains("control socket of a running process"), "{e}");
        // A client that goes away mid-request harms nothing.
        let mut gone = tokio::net::UnixStream::connect(&sock).await.unwrap();
        gone.write_all(b"first\n").await.unwrap();
        drop(gone);
        let c = tokio::net::UnixStream::connect(&sock).await.unwrap();
        let (r, mut w) = c.into_split();
        w.write_all(b"a\n\nb\n").await.unwrap();
        let mut answers = tokio::io::BufReader::new(r).lines();
        let mut seen = vec![];
        while seen.len() < 3 {
            match server.try_next() {
                Some(req) => {
                    seen.push(req.line.clone());
                    let answer = format!("{{\"echo\":\"{}\"}}", req.line);
                    req.answer(answer);
                }
                None => tokio::task::yield_now().await,
            }
        }
        // Two clients: their lines in any order, each client's in its own.
        seen.retain(|l| l != "first");
        assert_eq!(seen, ["a", "b"]);
        assert_eq!(
            answers.next_line().await.unwrap().unwrap(),
            r#"{"echo":"a"}"#
        );
        assert_eq!(
            answers.next_line().await.unwrap().unwrap(),
            r#"{"echo":"b"}"#
        );
        drop(server);
        assert!(!sock.exists(), "removed on exit");
    }
}
