//! The JX2-PROFI1's register interface while the slave runs (`dpctl slave
//! --device jx2`; feature `tokio`).
//!
//! One [`SharedJx2`] is the slave's device and the PLC the register
//! clients play: the [`Console`] (for `dpctl slave`: stdin and stdout),
//! each connection to the Unix socket of `--control SOCKET`, and the
//! program of the profile option `script`. Each client has its own
//! [`Interpreter`]; replies are JSON lines (on the console for it and the
//! script, with `"src"`; on the connection for socket clients). A client
//! waiting on a bit wakes at each bus event and each register write of
//! another client.

use crate::driver::Clock;
use profibus_devices::jx2::profile::Options;
use profibus_devices::jx2::script::{Interpreter, ParseError, Progress, Reply};
use profibus_devices::jx2::{BadModuleNumber, Plc, SharedJx2};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tokio::io::{AsyncBufRead, AsyncBufReadExt, AsyncRead, AsyncWrite, AsyncWriteExt, BufReader};
use tokio::sync::Notify;

/// Why the register clients cannot start.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The module number is out of range.
    #[error(transparent)]
    Module(#[from] BadModuleNumber),
    /// The script file cannot be read.
    #[error("cannot read {}: {error}", path.display())]
    Read {
        /// The script file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// The script has a line that is not a command.
    #[error("{}: {error}", path.display())]
    Script {
        /// The script file.
        path: PathBuf,
        /// The bad line.
        error: ParseError,
    },
    /// The control path exists and is not a socket (not ours to remove).
    #[error("{} exists and is not a socket", .0.display())]
    NotASocket(PathBuf),
    /// The control socket cannot be created.
    #[error("cannot listen on {}: {error}", path.display())]
    Listen {
        /// The socket.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
}

#[derive(Clone)]
struct Ctx {
    shared: SharedJx2,
    notify: Arc<Notify>,
    clock: Clock,
}

/// The console of the register clients: where the console client reads
/// its lines, and where it and the script write their replies (`dpctl
/// slave`: stdin and stdout). Each opens a new handle.
#[derive(Debug, Clone, Copy)]
pub struct Console<I, O> {
    /// The console client's input.
    pub input: fn() -> I,
    /// The replies of the console client and the script.
    pub output: fn() -> O,
}

/// Build the module of the profile's `options` and start its register
/// clients (the console, the script, the Unix socket `control`) as tokio
/// tasks (call inside a runtime). The result is at once the slave's
/// device and the PLC (e.g. to set the baud rate register).
pub fn start<I, O>(
    options: &Options,
    control: Option<&Path>,
    console: Console<I, O>,
    clock: Clock,
) -> Result<SharedJx2, ClientError>
where
    I: AsyncRead + Unpin + Send + 'static,
    O: AsyncWrite + Unpin + Send + 'static,
{
    let plc = Plc::new(options.module_number)?;
    let notify = Arc::new(Notify::new());
    let shared = SharedJx2::new(plc).with_on_change({
        let n = notify.clone();
        move || n.notify_waiters()
    });
    let ctx = Ctx {
        shared: shared.clone(),
        notify,
        clock,
    };
    if let Some(path) = &options.script {
        let text = std::fs::read_to_string(path).map_err(|error| ClientError::Read {
            path: path.clone(),
            error,
        })?;
        let it = Interpreter::script(&text).map_err(|error| ClientError::Script {
            path: path.clone(),
            error,
        })?;
        let c = ctx.clone();
        tokio::spawn(async move {
            let mut out = (console.output)();
            let none = BufReader::new(tokio::io::empty());
            serve(c, it, none, &mut out, Some("script")).await;
            let end = Reply {
                src: Some("script"),
                ..Reply::new("end", true)
            };
            let _ = out.write_all(format!("{end}\n").as_bytes()).await;
            let _ = out.flush().await;
        });
    }
    {
        let c = ctx.clone();
        tokio::spawn(async move {
            let mut out = (console.output)();
            let input = BufReader::new((console.input)());
            serve(c, Interpreter::new(), input, &mut out, Some("stdin")).await;
        });
    }
    if let Some(path) = control {
        let listener = bind(path)?;
        let guard = SocketFile(path.to_path_buf());
        tokio::spawn(async move {
            let _guard = guard;
            while let Ok((stream, _)) = listener.accept().await {
                let c = ctx.clone();
                tokio::spawn(async move {
                    let (r, mut w) = stream.into_split();
                    serve(c, Interpreter::new(), BufReader::new(r), &mut w, None).await;
                });
            }
        });
    }
    Ok(shared)
}

/// Listen on `path`, replacing a socket left behind by a killed run
/// (anything else there is not ours to remove).
fn bind(path: &Path) -> Result<tokio::net::UnixListener, ClientError> {
    let listen = |error| ClientError::Listen {
        path: path.to_path_buf(),
        error,
    };
    if path.exists() {
        use std::os::unix::fs::FileTypeExt;
        let meta = std::fs::symlink_metadata(path).map_err(listen)?;
        if !meta.file_type().is_socket() {
            return Err(ClientError::NotASocket(path.to_path_buf()));
        }
        std::fs::remove_file(path).map_err(listen)?;
    }
    tokio::net::UnixListener::bind(path).map_err(listen)
}

/// Removes the control socket when the listener goes away.
struct SocketFile(PathBuf);

impl Drop for SocketFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Run `it` with lines from `input`, writing replies to `out`, until the
/// input ends and everything queued ran.
async fn serve<R, W>(
    ctx: Ctx,
    mut it: Interpreter,
    input: R,
    out: &mut W,
    src: Option<&'static str>,
) where
    R: AsyncBufRead + Unpin,
    W: AsyncWrite + Unpin,
{
    let mut lines = input.lines();
    let mut input_open = true;
    loop {
        // Register before running, so that no change is missed.
        let notified = ctx.notify.notified();
        tokio::pin!(notified);
        notified.as_mut().enable();
        let progress = {
            let mut plc = ctx.shared.lock();
            it.run(&mut plc, ctx.clock.now())
        };
        let mut wrote = false;
        while let Some(mut r) = it.take_reply() {
            wrote = true;
            r.src = src;
            if out.write_all(format!("{r}\n").as_bytes()).await.is_err() {
                return;
            }
        }
        if wrote {
            let _ = out.flush().await;
            // Other clients may wait on what this one wrote.
            ctx.notify.notify_waiters();
        }
        match progress {
            Progress::Idle if input_open => match lines.next_line().await {
                Ok(Some(l)) => it.push(&l),
                _ => input_open = false,
            },
            Progress::Idle => return,
            Progress::Busy => tokio::task::yield_now().await,
            Progress::Waiting(until) => {
                tokio::select! {
                    _ = &mut notified => {}
                    _ = tokio::time::sleep_until(ctx.clock.to_tokio(until)) => {}
                }
            }
        }
    }
}
