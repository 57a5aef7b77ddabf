//! `dpctl slave --device jx2`: the JX2-PROFI1's register interface while
//! the slave runs.
//!
//! One [`SharedJx2`] is the slave's device and the PLC the register
//! clients play: stdin (always), each connection to the Unix socket of
//! `--control SOCKET`, and the program of `--script FILE`. Each client has
//! its own [`Interpreter`]; replies are JSON lines (on stdout for stdin
//! and the script, with `"src"`; on the connection for socket clients).
//! A client waiting on a bit wakes at each bus event and each register
//! write of another client.

use anyhow::{Context, Result};
use profibus_devices::jx2::script::{Interpreter, Progress, Reply};
use profibus_devices::jx2::{Plc, SharedJx2};
use profibus_devices::BoxedDevice;
use profibus_fdl::driver::Clock;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tokio::io::{AsyncBufRead, AsyncBufReadExt, AsyncWrite, AsyncWriteExt, BufReader};
use tokio::sync::Notify;

/// What `dpctl slave` passes on for the jx2 profile.
#[derive(Debug, Clone)]
pub struct Options {
    /// Module number (registers `1x…` with x = it).
    pub module_number: u32,
    /// Unix socket for register clients.
    pub control: Option<PathBuf>,
    /// PLC program run at start.
    pub script: Option<PathBuf>,
}

#[derive(Clone)]
struct Ctx {
    shared: SharedJx2,
    notify: Arc<Notify>,
    clock: Clock,
}

/// Build the module, start the register clients; the device for the
/// slave, and the PLC (e.g. to set the baud rate register).
pub fn start(opts: &Options, clock: Clock) -> Result<(BoxedDevice, SharedJx2)> {
    let plc = Plc::new(opts.module_number)?;
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
    if let Some(path) = &opts.script {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let it = Interpreter::script(&text).with_context(|| format!("{}", path.display()))?;
        let c = ctx.clone();
        tokio::spawn(async move {
            let mut out = tokio::io::stdout();
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
            let mut out = tokio::io::stdout();
            let input = BufReader::new(tokio::io::stdin());
            serve(c, Interpreter::new(), input, &mut out, Some("stdin")).await;
        });
    }
    if let Some(path) = &opts.control {
        let listener = bind(path)?;
        let guard = SocketFile(path.clone());
        let c = ctx;
        tokio::spawn(async move {
            let _guard = guard;
            while let Ok((stream, _)) = listener.accept().await {
                let c = c.clone();
                tokio::spawn(async move {
                    let (r, mut w) = stream.into_split();
                    serve(c, Interpreter::new(), BufReader::new(r), &mut w, None).await;
                });
            }
        });
    }
    Ok((Box::new(shared.clone()), shared))
}

fn bind(path: &Path) -> Result<tokio::net::UnixListener> {
    if path.exists() {
        // A socket left behind by a killed run: replace it; anything
        // else is not ours to remove.
        use std::os::unix::fs::FileTypeExt;
        let meta = std::fs::symlink_metadata(path)?;
        anyhow::ensure!(
            meta.file_type().is_socket(),
            "{} exists and is not a socket",
            path.display()
        );
        std::fs::remove_file(path)?;
    }
    tokio::net::UnixListener::bind(path)
        .with_context(|| format!("cannot listen on {}", path.display()))
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
