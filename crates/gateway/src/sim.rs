//! A bus file's slaves as emulated devices on the in-process simulated
//! bus ([`Plant::from_bus`]), paced at the bus file's baud rate: a
//! gateway with no hardware (`dpctl gateway --sim`). Slaves given as a
//! device profile run that profile's device; slaves given by GSD modules
//! run the generic device with inputs that echo the outputs.

use crate::link::MqttLink;
use crate::session::Session;
pub use crate::slave::slave_infos;
use profibus_devices::bus::ProfiledBus;
use profibus_dp::master::DpMaster;
use profibus_fdl::Instant;
use profibus_io::pace::Pacer;
use profibus_plant::{Plant, PlantError};
use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// `dpctl gateway --sim`: the plant of `profiled` paced on the wall clock
/// ([`Pacer`]) on a thread of its own, `gateway` stepped after every turn
/// (at most [`Pacer::TICK`] after an input change), until `shutdown`
/// ends; then the offline status and a clean disconnect. The link's
/// client runs on the caller's tokio runtime.
pub async fn serve<S: Session + Send + 'static>(
    profiled: ProfiledBus,
    gateway: S,
    link: MqttLink,
    shutdown: impl Future<Output = ()>,
) -> Result<(), PlantError> {
    let (gateway, link) = run_plant(
        profiled,
        (gateway, link),
        |(gateway, link), master, now| crate::link::step(link, gateway, master, now),
        shutdown,
    )
    .await?;
    let last = gateway.last_will();
    link.close(last).await;
    Ok(())
}

/// The plant of `profiled` paced on the wall clock ([`Pacer`]) on a
/// thread of its own, `turn` called with `state`, the master and the
/// plant's time after every turn, until `shutdown` ends; returns `state`.
/// [`serve`] and the OPC UA server's simulated bus run on it.
pub async fn run_plant<T: Send + 'static>(
    profiled: ProfiledBus,
    mut state: T,
    mut turn: impl FnMut(&mut T, &mut DpMaster, Instant) + Send + 'static,
    shutdown: impl Future<Output = ()>,
) -> Result<T, PlantError> {
    let stop = Arc::new(AtomicBool::new(false));
    let (done, mut ended) = tokio::sync::oneshot::channel();
    let flag = stop.clone();
    std::thread::spawn(move || {
        let run = Plant::from_bus(&profiled).map(|mut plant| {
            let pacer = Pacer::new();
            while !flag.load(Ordering::Relaxed) {
                let pause = pacer.turn(plant.now(), |t| plant.run_until(t));
                let now = plant.now();
                turn(&mut state, plant.master(), now);
                // Pacing the simulated line, not waiting for an event.
                std::thread::sleep(pause);
            }
        });
        let _ = done.send(run.map(|()| state));
    });
    let result = tokio::select! {
        _ = shutdown => {
            stop.store(true, Ordering::Relaxed);
            (&mut ended).await
        }
        r = &mut ended => r,
    };
    result.expect("the bus thread answers")
}
