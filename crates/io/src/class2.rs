//! A class-2 master on a port: the FDL active station with a
//! [`Class2Master`] joins the token ring next to the running masters and
//! runs one connection's requests ([`Class2Run`] of a [`RecordOps`]) to
//! their end (`dpctl dpv1 --class2`, `dpctl im --class2`).

use crate::driver::{self, Clock, Stop};
use profibus_dp::class2::{Class2Config, Class2Master, Class2Run, RecordOps};
use profibus_dp::master::join_bound;
use profibus_fdl::station::active::{ActiveConfig, ActiveStation, RingState};
use std::future::Future;
use tokio::io::{AsyncRead, AsyncWrite};

/// How [`run`] ended.
#[derive(Debug)]
pub struct Class2Done<O> {
    /// The run: its requests and answers, or why the connection failed
    /// ([`Class2Run::finish`]).
    pub run: Class2Run<O>,
    /// Why the driver stopped: [`Stop::Done`] once the connection is
    /// closed, [`Stop::Shutdown`] on `shutdown`.
    pub stop: Stop,
    /// Where the station was in the ring at the end ([`RingState::ListenToken`]:
    /// never taken into the ring).
    pub ring: RingState,
}

/// Run `ops` on a connection to `slave`: an active station of `station`
/// (its address, bus parameters, latency allowance) with a class-2
/// master of `cfg`, on `port`, until the connection is closed or
/// `shutdown` completes.
pub async fn run<P, O>(
    port: &mut P,
    station: ActiveConfig,
    cfg: Class2Config,
    slave: u8,
    ops: O,
    shutdown: impl Future<Output = ()>,
) -> std::io::Result<Class2Done<O>>
where
    P: AsyncRead + AsyncWrite + Unpin + driver::Waitable,
    O: RecordOps,
{
    // A lone master holds the token for several cycles per visit
    // (docs/timing.md), so joining its ring can take up to
    // `join_bound`: the connection's timers start once this station has
    // held the token, or once that bound has passed without it (then
    // the Initiate times out and `ring` says why).
    let join_wait = join_bound(&station.params);
    let mut st = ActiveStation::new(station, Class2Master::new(cfg));
    let mut run = Class2Run::new(slave, ops);
    let mut waiting_since = None;
    let stop = driver::run_with(
        &mut st,
        port,
        Clock::start(),
        driver::Options::default(),
        shutdown,
        |st, now| {
            if st.stats().tokens == 0 {
                let since = *waiting_since.get_or_insert(now);
                if now.saturating_duration_since(since) < join_wait {
                    return std::ops::ControlFlow::Continue(());
                }
            }
            run.tick(st.app_mut(), now)
        },
    )
    .await?;
    Ok(Class2Done {
        run,
        stop,
        ring: st.ring_state(),
    })
}
