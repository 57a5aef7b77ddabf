//! `dpctl gateway`: a DP master's slaves on an MQTT broker (the
//! `profibus-gateway` crate), on a line (`--port`) or on the in-process
//! simulated bus with the bus file's slaves emulated (`--sim`).

use crate::common;
use anyhow::{Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::master::DpMaster;
use profibus_fdl::driver::{self, Clock};
use profibus_fdl::Instant;
use profibus_gateway::link::{flush, pump, wall_ms};
use profibus_gateway::sim::{slave_infos, SimPlant};
use profibus_gateway::{
    sparkplug, Connection, EdgeNode, Gateway, MqttLink, MqttSettings, Session, SparkplugId,
};
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::Duration;

/// Publish a DP master's slaves on an MQTT broker and take output writes.
#[derive(clap::Args)]
#[command(group = clap::ArgGroup::new("line").required(true).args(["port", "sim"]))]
pub struct Args {
    /// Bus file (TOML) with an optional `[mqtt]` table.
    #[arg(long, value_name = "BUS.toml")]
    config: PathBuf,
    /// Serial device, pty or tcp:// serial server of the line.
    #[arg(long, value_name = "PATH")]
    port: Option<String>,
    /// Emulate the bus file's slaves on an in-process simulated bus.
    #[arg(long)]
    sim: bool,
    /// Broker URL, mqtt://HOST[:PORT] or mqtts://HOST[:PORT] (TLS)
    /// (default: `[mqtt] broker`).
    #[arg(long, value_name = "URL")]
    mqtt: Option<String>,
    /// Sparkplug B mode: publish as edge node EDGE of group GROUP
    /// (default: `[mqtt] sparkplug`; without either, plain JSON topics).
    #[arg(long, value_name = "GROUP/EDGE")]
    sparkplug: Option<SparkplugId>,
    /// Extra milliseconds on the slot time for the transport's latency
    /// (with --port).
    #[arg(long, value_name = "MS")]
    latency: Option<f64>,
}

pub fn run(args: Args) -> Result<()> {
    let profiled = ProfiledBus::load(&args.config)?;
    for w in &profiled.file.warnings {
        eprintln!("dpctl gateway: warning: {w}");
    }
    let stem = args
        .config
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("bus")
        .replace(['/', '+', '#'], "_");
    let mut settings = MqttSettings::from_table(profiled.file.mqtt.as_ref(), &stem)
        .with_context(|| args.config.display().to_string())?;
    if let Some(dir) = args.config.parent() {
        settings.relative_to(dir);
    }
    let url = args
        .mqtt
        .clone()
        .or_else(|| settings.broker.clone())
        .context("no broker: give --mqtt mqtt://HOST:PORT (or mqtts://) or [mqtt] broker")?;
    let conn = Connection::from_settings(&settings, &url)?;
    match args
        .sparkplug
        .clone()
        .or_else(|| settings.sparkplug.clone())
    {
        Some(id) => {
            let node = EdgeNode::new(settings, id, sparkplug::devices(&profiled)?);
            serve(args, profiled, node, conn)
        }
        None => {
            let gateway = Gateway::new(settings, slave_infos(&profiled)?);
            serve(args, profiled, gateway, conn)
        }
    }
}

fn serve<S: Session>(
    args: Args,
    profiled: ProfiledBus,
    gateway: S,
    conn: Connection,
) -> Result<()> {
    common::runtime()?.block_on(async move {
        let link = MqttLink::connect(&conn, &gateway);
        match &args.port {
            Some(p) => on_line(&args, p, &profiled, gateway, link).await,
            None => on_sim(&profiled, gateway, link).await,
        }
    })
}

/// One step of the gateway at a cycle boundary.
fn step(link: &mut MqttLink, gw: &mut impl Session, m: &mut DpMaster, now: Instant) {
    let ts = wall_ms();
    pump(link, gw, ts);
    gw.step(m, now, ts);
    flush(link, gw);
}

async fn on_sim(profiled: &ProfiledBus, mut gw: impl Session, mut link: MqttLink) -> Result<()> {
    let mut plant = SimPlant::new(profiled)?;
    let start = tokio::time::Instant::now();
    let shutdown = common::shutdown();
    tokio::pin!(shutdown);
    // The simulated line follows the wall clock in steps of 2 ms, at
    // most 20 ms of bus time per step: on a machine too busy to keep up
    // the line runs slower than real time, and the MQTT link (its keep
    // alive) still gets its turn after every step.
    let tick = Duration::from_millis(2);
    let most = Duration::from_millis(20);
    loop {
        let wall = Instant::from_nanos(start.elapsed().as_nanos() as u64);
        let behind = wall > plant.now() + most;
        plant.run_until(if behind { plant.now() + most } else { wall });
        let now = plant.now();
        step(&mut link, &mut gw, plant.master(), now);
        let pause = if behind { Duration::ZERO } else { tick };
        tokio::select! {
            _ = &mut shutdown => break,
            _ = tokio::time::sleep(pause) => {}
        }
    }
    let last = gw.last_will();
    link.close(last).await;
    Ok(())
}

async fn on_line(
    args: &Args,
    port: &str,
    profiled: &ProfiledBus,
    mut gw: impl Session,
    mut link: MqttLink,
) -> Result<()> {
    let bus = &profiled.file;
    let dp = DpMaster::new(&bus.master)?;
    let (mut station, mut line) =
        common::master_station(port, bus, dp, args.latency, Default::default())?;
    let options = common::driver_options(&line, 0, false)?;
    let result = driver::run_with(
        &mut station,
        &mut line,
        Clock::start(),
        options,
        common::shutdown(),
        |st, now| {
            step(&mut link, &mut gw, st.app_mut(), now);
            ControlFlow::<()>::Continue(())
        },
    )
    .await;
    let last = gw.last_will();
    link.close(last).await;
    result.with_context(|| format!("on {port}"))?;
    Ok(())
}
