//! `dpctl gateway`: a DP master's slaves on an MQTT broker (the
//! `profibus-gateway` crate), on a line (`--port`) or on the in-process
//! simulated bus with the bus file's slaves emulated (`--sim`); and/or
//! as an OPC UA server (`--opcua`, the `profibus-opcua` crate, behind
//! the `opcua` cargo feature, on by default).

use crate::common;
use crate::ops::{self, Operated, ReloadSender, Stopping};
use anyhow::{Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::master::DpMaster;
use profibus_dp::monitor::alert::AlertRule;
use profibus_gateway::sim::slave_infos;
use profibus_gateway::{
    link, sparkplug, Connection, EdgeNode, Gateway, MqttLink, MqttSettings, MqttVersion, Session,
    SparkplugId,
};
use profibus_io::driver::{self, Clock};
#[cfg(feature = "opcua")]
use profibus_opcua::{Face, OpcuaServer, OpcuaSettings};
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
    /// MQTT protocol version: 4 (MQTT 3.1.1) or 5 (MQTT 5: answers on the
    /// request's response topic with its correlation data, units as user
    /// properties, message expiry) (default: `[mqtt] version`, else 4).
    #[arg(long, value_name = "4|5", value_parser = mqtt_version)]
    mqtt_version: Option<MqttVersion>,
    /// Sparkplug B mode: publish as edge node EDGE of group GROUP
    /// (default: `[mqtt] sparkplug`; without either, plain JSON topics).
    #[arg(long, value_name = "GROUP/EDGE")]
    sparkplug: Option<SparkplugId>,
    /// Extra milliseconds on the slot time for the transport's latency
    /// (with --port).
    #[arg(long, value_name = "MS")]
    latency: Option<f64>,
    #[command(flatten)]
    control: crate::control::ControlArgs,
    /// Keep the gateway's health in this file (JSON, rewritten every
    /// second: state, healthy, bus, slaves, data_exchange,
    /// broker_connected, last_cycle_age_ms) for a supervisor to check.
    #[arg(long, value_name = "PATH")]
    health_file: Option<PathBuf>,
    /// OPC UA server endpoint, opc.tcp://HOST[:PORT] (default: `[opcua]
    /// endpoint`; with an `[opcua]` table the server runs without it too),
    /// alone or beside --mqtt.
    #[arg(long, value_name = "URL")]
    opcua: Option<String>,
    /// Offer the OPC UA endpoint without security (policy None) instead of
    /// Basic256Sha256 Sign and SignAndEncrypt.
    #[arg(long)]
    opcua_insecure: bool,
    /// Publish an alert when RULE holds for a slave over an interval
    /// (`[mqtt] alert_interval_ms`, default 1 s), on
    /// `<prefix>/<bus>/alert` (Sparkplug B: node metric `Bus/Alert`);
    /// repeatable, added to `[mqtt] alerts`. RULE as in `dpctl sniff
    /// --alert`: `[ADDR:]STATISTIC [OP VALUE[%|ms|us|s]]` on the master's
    /// counters, e.g. `no_answer>0`, `retries>1%`, `restart`, `health<80`.
    #[arg(long, value_name = "RULE", value_parser = AlertRule::parse)]
    alert: Vec<AlertRule>,
}

/// `--mqtt-version`: 4 or 5.
fn mqtt_version(s: &str) -> Result<MqttVersion, String> {
    s.parse()
        .ok()
        .and_then(MqttVersion::from_level)
        .ok_or_else(|| "must be 4 (MQTT 3.1.1) or 5 (MQTT 5)".to_string())
}

pub fn run(args: Args) -> Result<()> {
    if args.sim && args.control.control.is_some() {
        anyhow::bail!("--control shares a line's master: give --port, not --sim");
    }
    let profiled = ProfiledBus::load(&args.config)?;
    for w in &profiled.file.warnings {
        crate::out::errln!("dpctl gateway: warning: {w}");
    }
    let mut settings = MqttSettings::for_bus_file(profiled.file.mqtt.as_ref(), &args.config)
        .map_err(|e| e.in_bus_file(&profiled.file))?;
    settings.alerts.extend(args.alert.iter().cloned());
    if let Some(v) = args.mqtt_version {
        settings.version = v;
    }
    if settings.version == MqttVersion::V5
        && (args.sparkplug.is_some() || settings.sparkplug.is_some())
    {
        anyhow::bail!(profibus_gateway::SettingsError::SparkplugNeedsV311);
    }
    if args.opcua.is_some() || profiled.file.opcua.is_some() {
        return with_opcua(args, profiled, settings);
    }
    let url = args
        .mqtt
        .clone()
        .or_else(|| settings.broker.clone())
        .context("no broker: give --mqtt mqtt://HOST:PORT (or mqtts://) or [mqtt] broker")?;
    profibus_gateway::traffic::check(&settings, &slave_infos(&profiled)?)
        .map_err(|e| e.in_bus_file(&profiled.file))?;
    let conn = Connection::from_settings(&settings, &url)?;
    let sparkplug = args.sparkplug.clone().or(settings.sparkplug.clone());
    tracing::info!(
        target: ops::TARGET,
        "dpctl gateway {} (git {}) starting: bus file {}, {}, broker {url}, {}",
        env!("CARGO_PKG_VERSION"),
        env!("DPCTL_GIT_REV"),
        args.config.display(),
        match &args.port {
            Some(p) => format!("port {p}"),
            None => "simulated bus".to_string(),
        },
        match &sparkplug {
            Some(id) => format!("Sparkplug B {id}"),
            None => format!("JSON topics {}/{}", settings.prefix, settings.bus),
        },
    );
    match sparkplug {
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

/// What `--opcua` or `[opcua]` says to a dpctl built without the `opcua`
/// feature.
#[cfg(not(feature = "opcua"))]
pub const NO_OPCUA: &str = "this dpctl was built without OPC UA: rebuild with --features opcua";

/// `dpctl gateway --opcua` in a dpctl built without OPC UA: one line.
#[cfg(not(feature = "opcua"))]
fn with_opcua(_args: Args, _profiled: ProfiledBus, _settings: MqttSettings) -> Result<()> {
    anyhow::bail!(NO_OPCUA)
}

/// `dpctl gateway --opcua`: the OPC UA server, with MQTT when a broker
/// is given.
#[cfg(feature = "opcua")]
fn with_opcua(args: Args, profiled: ProfiledBus, settings: MqttSettings) -> Result<()> {
    let dir = args.config.parent().unwrap_or(std::path::Path::new("."));
    let opcua = OpcuaSettings::new(
        profiled.file.opcua.as_ref(),
        args.opcua.as_deref(),
        args.opcua_insecure,
        dir,
    )
    .map_err(|e| match e.key_path() {
        Some(key) => anyhow::Error::new(profiled.file.error_at(&key, e.to_string())),
        None => anyhow::Error::new(e).context(args.config.display().to_string()),
    })?;
    if args.sparkplug.is_some() || settings.sparkplug.is_some() {
        anyhow::bail!("--opcua goes with plain JSON topics, not with Sparkplug B");
    }
    let infos = slave_infos(&profiled)?;
    profibus_gateway::traffic::check(&settings, &infos)
        .map_err(|e| e.in_bus_file(&profiled.file))?;
    let conn = (args.mqtt.clone().or_else(|| settings.broker.clone()))
        .map(|u| Connection::from_settings(&settings, &u))
        .transpose()?;
    let (server, face) = OpcuaServer::start(&opcua, settings, infos, conn.is_some())?;
    tracing::info!(
        target: ops::TARGET,
        "dpctl gateway {} (git {}) starting: bus file {}, OPC UA {}",
        env!("CARGO_PKG_VERSION"),
        env!("DPCTL_GIT_REV"),
        args.config.display(),
        opcua.url(),
    );
    let result = match conn {
        Some(conn) => serve(args, profiled, face, conn),
        None => opcua_alone(args, profiled, face),
    };
    server.stop();
    result
}

/// The OPC UA face without a broker, on the line or the simulated bus;
/// SIGHUP reloads the bus file's gateway settings as with MQTT (so a
/// changed `[mqtt] writable` reaches the access levels).
#[cfg(feature = "opcua")]
fn opcua_alone(args: Args, profiled: ProfiledBus, face: Face) -> Result<()> {
    let (face, reloads, _) = Operated::new(face, profiled.file.slaves.len());
    common::runtime()?.block_on(async move {
        reload_on_sighup(&args.config, &args.alert, &profiled, reloads)?;
        match args.port.clone() {
            None => Ok(profibus_opcua::sim::serve(profiled, face, common::shutdown()).await?),
            Some(port) => on_line_opcua(&args, &port, &profiled, face).await,
        }
    })
}

/// [`on_line`] without a broker: the OPC UA face stepped alone.
#[cfg(feature = "opcua")]
async fn on_line_opcua(
    args: &Args,
    port: &str,
    profiled: &ProfiledBus,
    mut face: impl Session,
) -> Result<()> {
    let bus = &profiled.file;
    let dp = DpMaster::new(&bus.master)?;
    let (mut station, mut line) =
        common::master_station(port, bus, dp, args.latency, Default::default())?;
    let options = common::driver_options(&line, 0, false)?;
    let mut clean = common::CleanStop::default();
    driver::run_with(
        &mut station,
        &mut line,
        Clock::start(),
        options,
        clean.shutdown(common::shutdown()),
        |st, now| {
            if clean.step(st, now).is_break() {
                return ControlFlow::Break(());
            }
            face.step(st.app_mut(), now, link::wall_ms());
            ControlFlow::<()>::Continue(())
        },
    )
    .await
    .with_context(|| format!("on {port}"))?;
    Ok(())
}

fn serve<S: Session + Send + 'static>(
    args: Args,
    profiled: ProfiledBus,
    gw: S,
    conn: Connection,
) -> Result<()> {
    let (mut gw, reloads, stopping) = Operated::new(gw, profiled.file.slaves.len());
    if let Some(path) = &args.health_file {
        gw.health_file(path.clone());
    }
    let shared = gw.stopped_handle();
    let rt = common::runtime()?;
    let result = rt.block_on(async move {
        reload_on_sighup(&args.config, &args.alert, &profiled, reloads)?;
        let link = MqttLink::connect(&conn, &gw);
        let shutdown = stop(stopping);
        match &args.port {
            Some(p) => on_line(&args, p, &profiled, gw, link, shutdown).await,
            None => Ok(profibus_gateway::sim::serve(profiled, gw, link, shutdown).await?),
        }
    });
    shared();
    match &result {
        Ok(()) => tracing::info!(target: ops::TARGET, "dpctl gateway stopped"),
        Err(e) => tracing::error!(target: ops::TARGET, "dpctl gateway stopped: {e:#}"),
    }
    result
}

/// Completes on SIGTERM or SIGINT once the offline health is handed to
/// the link (at most 500 ms later): the core keeps running until then.
async fn stop(stopping: Stopping) {
    common::shutdown().await;
    tracing::info!(target: ops::TARGET, "stopping");
    stopping.begin();
    let _ = tokio::time::timeout(std::time::Duration::from_millis(500), stopping.sent()).await;
}

/// On every SIGHUP: read the bus file again and hand its `[mqtt]` table
/// to the running core (through `reloads`), or log why not; the bus
/// keeps running either way. The same with or without a broker: the
/// core's settings (`writable` among them) serve the OPC UA face too.
fn reload_on_sighup(
    path: &std::path::Path,
    alerts: &[AlertRule],
    profiled: &ProfiledBus,
    reloads: ReloadSender,
) -> Result<()> {
    use tokio::signal::unix::{signal, SignalKind};
    let mut hup = signal(SignalKind::hangup()).context("installing the SIGHUP handler")?;
    let path = path.to_path_buf();
    let alerts = alerts.to_vec();
    let mut running = profiled.file.mqtt.clone();
    let opcua = profiled.file.opcua.clone();
    tokio::spawn(async move {
        while hup.recv().await.is_some() {
            match reload(&path, running.as_ref(), opcua.as_ref()) {
                Ok((table, mut r)) => {
                    r.settings.alerts.extend(alerts.iter().cloned());
                    running = table;
                    if reloads.send(r).is_err() {
                        return;
                    }
                }
                Err(e) => tracing::error!(
                    target: ops::TARGET,
                    "SIGHUP: not reloaded, the running settings stay: {e:#}"
                ),
            }
        }
    });
    Ok(())
}

/// The `[mqtt]` table of the bus file at `path` and the reload of it
/// over `running`, or why it cannot be taken while running (a changed
/// restart key, or any change of the `[opcua]` table, `opcua` at start).
fn reload(
    path: &std::path::Path,
    running: Option<&toml::Table>,
    opcua: Option<&toml::Table>,
) -> Result<(Option<toml::Table>, ops::Reload)> {
    let file = ProfiledBus::load(path)?;
    if file.file.opcua.as_ref() != opcua {
        anyhow::bail!(
            "{}: [opcua] only changes with a restart (the gateway core's settings, `writable` among them, are in [mqtt])",
            path.display()
        );
    }
    let table = file.file.mqtt.clone();
    let settings =
        MqttSettings::for_bus_file(table.as_ref(), path).map_err(|e| e.in_bus_file(&file.file))?;
    profibus_gateway::traffic::check(&settings, &slave_infos(&file)?)
        .map_err(|e| e.in_bus_file(&file.file))?;
    let changes = ops::changes(running, table.as_ref());
    let fixed: Vec<&str> = changes
        .iter()
        .filter(|(k, _)| ops::RESTART_KEYS.contains(&k.as_str()))
        .map(|(_, c)| c.as_str())
        .collect();
    if !fixed.is_empty() {
        anyhow::bail!(
            "{}: {} only change with a restart",
            path.display(),
            fixed.join(", ")
        );
    }
    let changes = changes.into_iter().map(|(_, c)| c).collect();
    Ok((table, ops::Reload { settings, changes }))
}

async fn on_line(
    args: &Args,
    port: &str,
    profiled: &ProfiledBus,
    mut gw: impl Session,
    mut link: MqttLink,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<()> {
    let bus = &profiled.file;
    let dp = DpMaster::new(&bus.master)?;
    args.control.announce();
    let (mut station, mut line) =
        common::master_station(port, bus, dp, args.latency, Default::default())?;
    let mut control = args.control.open(profiled)?;
    let info = match control {
        Some(_) => crate::view::SlaveInfo::of_bus(profiled)?,
        None => vec![],
    };
    let baud = bus.master.params.baud;
    let options = common::driver_options(&line, 0, false)?;
    tracing::info!(
        target: ops::TARGET,
        "bus: master {} on {port} at {} baud, {} slaves",
        bus.master.address,
        bus.master.params.baud,
        bus.slaves.len()
    );
    // SIGTERM / Ctrl-C: the offline health, then Clear to the slaves and
    // the token passed on.
    let mut clean = common::CleanStop::default();
    let result = driver::run_with(
        &mut station,
        &mut line,
        Clock::start(),
        options,
        clean.shutdown(shutdown),
        |st, now| {
            if clean.step(st, now).is_break() {
                return ControlFlow::Break(());
            }
            if let Some(c) = &mut control {
                c.tick(st.app_mut(), now, profiled, &info, baud);
            }
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
