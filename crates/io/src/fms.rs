//! An FMS client on a port: the FDL active station with an [`FmsMaster`]
//! joins the token ring next to the running masters, connects to one
//! FMS server (Associate with Initiate over the LLI, on the server's LSAP
//! of its communication relationship list), runs a [`FmsRun`]'s requests
//! and releases the connection (LLI Abort, reason user) — `dpctl fms`.
//!
//! Bounded in time: the connection's own monitoring ends a silent
//! server's run, and the whole run (joining the ring included) ends after
//! `limit`.

use crate::driver::{self, Clock, Stop};
use profibus_dp::fms::client::{FmsMaster, FmsRun};
use profibus_fdl::station::active::{ActiveConfig, ActiveStation, RingState};
use std::future::Future;
use std::ops::ControlFlow;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite};

/// How [`run`] ended.
#[derive(Debug)]
pub struct FmsDone {
    /// The run: its confirmations, or why it failed ([`FmsRun::error`]).
    pub run: FmsRun,
    /// Why the driver stopped: [`Stop::Done`] once the run ended (or
    /// `limit` passed: then the run is not done), [`Stop::Shutdown`] on
    /// `shutdown`.
    pub stop: Stop,
    /// Where the station was in the ring at the end ([`RingState::ListenToken`]:
    /// never taken into the ring).
    pub ring: RingState,
    /// Whether the station held the token at least once.
    pub had_token: bool,
}

/// How long a finished run waits for the token to send its release.
const RELEASE_WAIT: Duration = Duration::from_secs(1);

/// Run `run` on `master`'s connection: an active station of `station`
/// (its address, bus parameters, latency allowance) on `port`, until the
/// run ended and its release went out, `limit` passed, or `shutdown`
/// completes.
pub async fn run<P>(
    port: &mut P,
    station: ActiveConfig,
    master: FmsMaster,
    run: FmsRun,
    limit: Duration,
    shutdown: impl Future<Output = ()>,
) -> std::io::Result<FmsDone>
where
    P: AsyncRead + AsyncWrite + Unpin + driver::Waitable,
{
    // The connection starts once this station has held the token: a
    // lone master holding the token for several cycles per visit may
    // take up to `join_bound` (docs/timing.md) to take it into the ring,
    // a busy machine longer; `limit` bounds the wait.
    let mut st = ActiveStation::new(station, master);
    let mut run = run;
    let mut first = None;
    let mut ended = None;
    let stop = driver::run_with(
        &mut st,
        port,
        Clock::start(),
        driver::Options::default(),
        shutdown,
        |st, now| {
            let since = *first.get_or_insert(now);
            let waited = now.saturating_duration_since(since);
            if waited >= limit {
                return ControlFlow::Break(());
            }
            if st.stats().tokens == 0 {
                return ControlFlow::Continue(());
            }
            run.tick(st.app_mut(), now);
            if !run.is_done() {
                return ControlFlow::Continue(());
            }
            let end = *ended.get_or_insert(now);
            // The release (Abort) goes out with the next token.
            if !st.app_mut().lli().has_queued()
                || now.saturating_duration_since(end) >= RELEASE_WAIT
            {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
    )
    .await?;
    Ok(FmsDone {
        had_token: st.stats().tokens > 0,
        ring: st.ring_state(),
        run,
        stop,
    })
}
