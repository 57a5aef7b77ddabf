//! A bus file's slaves as emulated devices on the in-process simulated
//! bus ([`Plant::from_bus`]), paced at the bus file's baud rate: a
//! gateway with no hardware (`dpctl gateway --sim`). Slaves given as a
//! device profile run that profile's device; slaves given by GSD modules
//! run the generic device with inputs that echo the outputs.

use crate::link::MqttLink;
use crate::session::Session;
pub use crate::slave::slave_infos;
use profibus_devices::bus::ProfiledBus;
use profibus_fdl::Instant;
use profibus_plant::{Plant, PlantError};
use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Paces a [`Plant`] on the wall clock: each turn runs the line up to
/// the time elapsed since [`Pacer::new`], at most [`Pacer::MOST`] of bus
/// time per turn, so on a machine too busy to keep up the line runs
/// slower than real time and the rest of the loop still gets its turn.
#[derive(Debug, Clone, Copy)]
pub struct Pacer {
    start: std::time::Instant,
}

impl Pacer {
    /// The pause between two turns that keep up: an input change on the
    /// line waits at most this long (plus the sleep's overshoot) for the
    /// gateway's next step.
    pub const TICK: Duration = Duration::from_micros(500);
    /// The most bus time one turn runs.
    pub const MOST: Duration = Duration::from_millis(20);

    /// A pacer whose bus time 0 is now.
    pub fn new() -> Pacer {
        Pacer {
            start: std::time::Instant::now(),
        }
    }

    /// The bus time the next turn runs to, and whether the line is
    /// behind the wall clock by more than [`Pacer::MOST`].
    pub fn target(&self, plant: &Plant) -> (Instant, bool) {
        let wall = self.bus_time(std::time::Instant::now());
        let most = plant.now() + Self::MOST;
        if wall > most {
            (most, true)
        } else {
            (wall, false)
        }
    }

    /// Bus time `at` on the wall clock.
    pub fn bus_time(&self, at: std::time::Instant) -> Instant {
        Instant::from_nanos(at.saturating_duration_since(self.start).as_nanos() as u64)
    }

    /// The wall-clock time of bus time `t`.
    pub fn wall_time(&self, t: Instant) -> std::time::Instant {
        self.start + Duration::from_nanos(t.as_nanos())
    }

    /// One turn: run the line to [`Pacer::target`]; returns the pause
    /// before the next turn ([`Pacer::TICK`], zero when behind).
    pub fn advance(&self, plant: &mut Plant) -> Duration {
        let (t, behind) = self.target(plant);
        plant.run_until(t);
        if behind {
            Duration::ZERO
        } else {
            Self::TICK
        }
    }
}

impl Default for Pacer {
    fn default() -> Pacer {
        Pacer::new()
    }
}

/// `dpctl gateway --sim`: the plant of `profiled` paced on the wall clock
/// ([`Pacer`]) on a thread of its own, `gateway` stepped after every turn
/// (at most [`Pacer::TICK`] after an input change), until `shutdown`
/// ends; then the offline status and a clean disconnect. The link's
/// client runs on the caller's tokio runtime.
pub async fn serve<S: Session + Send + 'static>(
    profiled: ProfiledBus,
    mut gateway: S,
    mut link: MqttLink,
    shutdown: impl Future<Output = ()>,
) -> Result<(), PlantError> {
    let stop = Arc::new(AtomicBool::new(false));
    let (done, mut ended) = tokio::sync::oneshot::channel();
    let flag = stop.clone();
    std::thread::spawn(move || {
        let run = Plant::from_bus(&profiled).map(|mut plant| {
            let pacer = Pacer::new();
            while !flag.load(Ordering::Relaxed) {
                let pause = pacer.advance(&mut plant);
                let now = plant.now();
                crate::link::step(&mut link, &mut gateway, plant.master(), now);
                // Pacing the simulated line, not waiting for an event.
                std::thread::sleep(pause);
            }
        });
        let _ = done.send(run.map(|()| (gateway, link)));
    });
    let result = tokio::select! {
        _ = shutdown => {
            stop.store(true, Ordering::Relaxed);
            (&mut ended).await
        }
        r = &mut ended => r,
    };
    let (gateway, link) = result.expect("the bus thread answers")?;
    let last = gateway.last_will();
    link.close(last).await;
    Ok(())
}
