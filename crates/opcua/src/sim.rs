//! `dpctl gateway --sim --opcua` without `--mqtt`: the bus file's
//! slaves emulated on the in-process simulated bus
//! ([`profibus_plant::Plant::from_bus`]), paced on the wall clock, the
//! [`Face`](crate::Face) (or the CLI's wrapper around it) stepped after
//! every turn. (With `--mqtt` too, the gateway crate's
//! [`profibus_gateway::sim::serve`] steps the face.)

use profibus_devices::bus::ProfiledBus;
use profibus_gateway::link::wall_ms;
use profibus_gateway::sim::run_plant;
use profibus_gateway::Session;
use profibus_plant::PlantError;
use std::future::Future;

/// Run the plant of `profiled` on a thread of its own with `face`
/// stepped after every turn, until `shutdown` ends. No broker: the
/// face's publishes are not asked for.
pub async fn serve<S: Session + Send + 'static>(
    profiled: ProfiledBus,
    face: S,
    shutdown: impl Future<Output = ()>,
) -> Result<(), PlantError> {
    let step = |face: &mut S, master: &mut _, now| face.step(master, now, wall_ms());
    run_plant(profiled, face, step, shutdown).await.map(drop)
}
