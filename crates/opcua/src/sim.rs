//! `dpctl gateway --sim --opcua` without `--mqtt`: the bus file's
//! slaves emulated on the in-process simulated bus
//! ([`profibus_plant::Plant::from_bus`]), paced on the wall clock, the
//! [`Face`](crate::Face) (or the CLI's wrapper around it) stepped after
//! every turn. (With `--mqtt` too, the gateway crate's
//! [`profibus_gateway::sim::serve`] steps the face.)

use profibus_devices::bus::ProfiledBus;
use profibus_gateway::link::wall_ms;
use profibus_gateway::Session;
use profibus_io::pace::Pacer;
use profibus_plant::{Plant, PlantError};
use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Run the plant of `profiled` on a thread of its own with `face`
/// stepped after every turn, until `shutdown` ends. No broker: the
/// face's publishes are not asked for.
pub async fn serve<S: Session + Send + 'static>(
    profiled: ProfiledBus,
    mut face: S,
    shutdown: impl Future<Output = ()>,
) -> Result<(), PlantError> {
    let stop = Arc::new(AtomicBool::new(false));
    let (done, mut ended) = tokio::sync::oneshot::channel();
    let flag = stop.clone();
    std::thread::spawn(move || {
        let run = Plant::from_bus(&profiled).map(|mut plant| {
            let pacer = Pacer::new();
            while !flag.load(Ordering::Relaxed) {
                let pause = pacer.turn(plant.now(), |t| plant.run_until(t));
                let now = plant.now();
                face.step(plant.master(), now, wall_ms());
                // Pacing the simulated line, not waiting for an event.
                std::thread::sleep(pause);
            }
        });
        let _ = done.send(run);
    });
    tokio::select! {
        _ = shutdown => {
            stop.store(true, Ordering::Relaxed);
            (&mut ended).await.expect("the bus thread answers")
        }
        r = &mut ended => r.expect("the bus thread answers"),
    }
}
