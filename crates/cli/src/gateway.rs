//! `dpctl gateway`: a DP master's slaves on an MQTT broker (the
//! `profibus-gateway` crate), on a line (`--port`) or on the in-process
//! simulated bus with the bus file's slaves emulated (`--sim`).

use crate::common;
use anyhow::{Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::master::DpMaster;
use profibus_gateway::sim::slave_infos;
use profibus_gateway::{
    link, sparkplug, Connection, EdgeNode, Gateway, MqttLink, MqttSettings, Session, SparkplugId,
};
use profibus_io::driver::{self, Clock};
use std::ops::ControlFlow;
use std::path::PathBuf;

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
        crate::out::errln!("dpctl gateway: warning: {w}");
    }
    let settings = MqttSettings::for_bus_file(profiled.file.mqtt.as_ref(), &args.config)
        .with_context(|| args.config.display().to_string())?;
    let url = args
        .mqtt
        .clone()
        .or_else(|| settings.broker.clone())
        .context("no broker: give --mqtt mqtt://HOST:PORT (or mqtts://) or [mqtt] broker")?;
    profibus_gateway::traffic::check(&settings, &slave_infos(&profiled)?)
        .with_context(|| args.config.display().to_string())?;
    let conn = Connection::from_settings(&settings, &url)?;
    match args.sparkplug.clone().or(settings.sparkplug.clone()) {
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

fn serve<S: Session + Send + 'static>(
    args: Args,
    profiled: ProfiledBus,
    gw: S,
    conn: Connection,
) -> Result<()> {
    common::runtime()?.block_on(async move {
        let link = MqttLink::connect(&conn, &gw);
        match &args.port {
            Some(p) => on_line(&args, p, &profiled, gw, link).await,
            None => {
                let shutdown = common::shutdown();
                Ok(profibus_gateway::sim::serve(profiled, gw, link, shutdown).await?)
            }
        }
    })
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
            link::step(&mut link, &mut gw, st.app_mut(), now);
            ControlFlow::<()>::Continue(())
        },
    )
    .await;
    let last = gw.last_will();
    link.close(last).await;
    result.with_context(|| format!("on {port}"))?;
    Ok(())
}
