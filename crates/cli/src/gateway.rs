//! `dpctl gateway`: a DP master's slaves on an MQTT broker (the
//! `profibus-gateway` crate), on a line (`--port`) or on the in-process
//! simulated bus with the bus file's slaves emulated (`--sim`); and/or
//! as an OPC UA server (`--opcua`, the `profibus-opcua` crate).

use crate::common;
use anyhow::{Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::master::DpMaster;
use profibus_gateway::sim::slave_infos;
use profibus_gateway::{
    link, sparkplug, Connection, EdgeNode, Gateway, MqttLink, MqttSettings, Session, SparkplugId,
};
use profibus_io::driver::{self, Clock};
use profibus_opcua::{OpcuaServer, OpcuaSettings};
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
    /// OPC UA server endpoint, opc.tcp://HOST[:PORT] (default: `[opcua]
    /// endpoint`; with an `[opcua]` table the server runs without it too),
    /// alone or beside --mqtt.
    #[arg(long, value_name = "URL")]
    opcua: Option<String>,
    /// Offer the OPC UA endpoint without security (policy None) instead of
    /// Basic256Sha256 Sign and SignAndEncrypt.
    #[arg(long)]
    opcua_insecure: bool,
}

pub fn run(args: Args) -> Result<()> {
    let profiled = ProfiledBus::load(&args.config)?;
    for w in &profiled.file.warnings {
        crate::out::errln!("dpctl gateway: warning: {w}");
    }
    let settings = MqttSettings::for_bus_file(profiled.file.mqtt.as_ref(), &args.config)
        .with_context(|| args.config.display().to_string())?;
    let opcua = match (&args.opcua, &profiled.file.opcua) {
        (None, None) => None,
        (endpoint, table) => {
            let dir = args.config.parent().unwrap_or(std::path::Path::new("."));
            let s = OpcuaSettings::new(
                table.as_ref(),
                endpoint.as_deref(),
                args.opcua_insecure,
                dir,
            )
            .with_context(|| args.config.display().to_string())?;
            Some(s)
        }
    };
    let url = args.mqtt.clone().or_else(|| settings.broker.clone());
    let Some(opcua) = opcua else {
        let url =
            url.context("no broker: give --mqtt mqtt://HOST:PORT (or mqtts://) or [mqtt] broker")?;
        let conn = Connection::from_settings(&settings, &url)?;
        return match args.sparkplug.clone().or(settings.sparkplug.clone()) {
            Some(id) => {
                let node = EdgeNode::new(settings, id, sparkplug::devices(&profiled)?);
                serve(args, profiled, node, Some(conn))
            }
            None => {
                let gateway = Gateway::new(settings, slave_infos(&profiled)?);
                serve(args, profiled, gateway, Some(conn))
            }
        };
    };
    if args.sparkplug.is_some() || settings.sparkplug.is_some() {
        anyhow::bail!("--opcua goes with plain JSON topics, not with Sparkplug B");
    }
    let conn = url
        .map(|u| Connection::from_settings(&settings, &u))
        .transpose()?;
    let infos = slave_infos(&profiled)?;
    let (server, face) = OpcuaServer::start(&opcua, settings, infos, conn.is_some())?;
    let result = match (&args.port, conn) {
        (None, None) => common::runtime()?
            .block_on(profibus_opcua::sim::serve(
                profiled,
                face,
                common::shutdown(),
            ))
            .map_err(Into::into),
        (_, conn) => serve(args, profiled, face, conn),
    };
    server.stop();
    result
}

fn serve<S: Session + Send + 'static>(
    args: Args,
    profiled: ProfiledBus,
    gw: S,
    conn: Option<Connection>,
) -> Result<()> {
    common::runtime()?.block_on(async move {
        let link = conn.map(|c| MqttLink::connect(&c, &gw));
        match (&args.port, link) {
            (Some(p), link) => on_line(&args, p, &profiled, gw, link).await,
            (None, Some(link)) => {
                let shutdown = common::shutdown();
                Ok(profibus_gateway::sim::serve(profiled, gw, link, shutdown).await?)
            }
            (None, None) => anyhow::bail!("no broker and no --port"),
        }
    })
}

async fn on_line(
    args: &Args,
    port: &str,
    profiled: &ProfiledBus,
    mut gw: impl Session,
    mut link: Option<MqttLink>,
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
            match &mut link {
                Some(l) => link::step(l, &mut gw, st.app_mut(), now),
                None => gw.step(st.app_mut(), now, link::wall_ms()),
            }
            ControlFlow::<()>::Continue(())
        },
    )
    .await;
    if let Some(link) = link {
        let last = gw.last_will();
        link.close(last).await;
    }
    result.with_context(|| format!("on {port}"))?;
    Ok(())
}
