//! What several subcommands share: the runtime, shutdown signals, opening
//! a port with the line options every station command takes.

use crate::out::outln;
use anyhow::{Context, Result};
use profibus_fdl::Baud;
use profibus_io::transport::{Port, PortOptions, RtsControl, TransportError};
use std::time::Duration;

/// Line options of every command that runs a station.
#[derive(clap::Args, Debug, Clone)]
pub struct LineArgs {
    /// Serial device or pty path (e.g. /dev/ttyUSB0, a `dpctl bus` link:
    /// waited for up to 10 s if not made yet), or tcp://HOST:PORT (RS-485
    /// serial device server in raw TCP mode).
    #[arg(long, value_name = "PATH")]
    pub port: String,
    /// Baud rate: 9600 … 12000000, or 1.5M, 187.5k, … (on a pty the rate
    /// only sets the bus timing); `auto` (dpctl scan only) finds it.
    #[arg(long, default_value = "19200", value_name = "B")]
    pub baud: BaudArg,
    /// Extra milliseconds added to the slot time and token timeouts for the
    /// transport's latency (default: 5 on a pty, 20 on a serial adapter).
    #[arg(long, value_name = "MS")]
    pub latency: Option<f64>,
    #[command(flatten)]
    pub rts: RtsArg,
}

/// `--rts MODE`: RS-485 direction control, for commands that send.
#[derive(clap::Args, Debug, Clone, Copy, Default)]
pub struct RtsArg {
    /// RS-485 direction control (transmit enable on RTS): `off` leaves RTS
    /// alone (adapters that switch direction themselves, ptys, tcp://);
    /// `on-send` asserts RTS while sending (the kernel's RS-485 mode, else
    /// RTS toggled around each write). See docs/hardware.md.
    #[arg(long, value_enum, default_value_t, value_name = "MODE")]
    pub rts: Rts,
}

/// The values of `--rts`, named as `RtsControl::as_str` names them.
#[derive(clap::ValueEnum, Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Rts {
    #[default]
    Off,
    OnSend,
}

impl RtsArg {
    /// The transport's setting.
    pub fn control(self) -> RtsControl {
        match self.rts {
            Rts::Off => RtsControl::Off,
            Rts::OnSend => RtsControl::OnSend,
        }
    }

    /// Open `path` at `baud` with this RTS control (after taking its
    /// lock: [`lock_port`]).
    pub fn open(self, path: &str, baud: Baud) -> Result<Port> {
        lock_port(path)?;
        let rts = self.control();
        match Port::open_with(path, PortOptions { baud, rts }) {
            Err(TransportError::Rts { error: source, .. }) => anyhow::bail!(
                "{path}: --rts {} needs an RTS line the port can drive, and this one has none \
                 (a pty, a serial device server, or a driver without modem lines: {source}); \
                 leave --rts off, and see `dpctl doctor --port {path} --rts {0}`",
                rts.as_str()
            ),
            // Every TransportError names the path itself.
            r => Ok(r?),
        }
    }
}

/// The control socket of this process (`--control`), written into the
/// lock of each port it opens.
static CONTROL_PATH: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();

/// The ports this process holds, by canonical path; held until it exits.
static HELD_PORTS: std::sync::Mutex<Vec<profibus_io::port_lock::PortLock>> =
    std::sync::Mutex::new(Vec::new());

/// Name `path` as this process's control socket in the port locks it
/// takes from now on (call before opening the port).
pub fn set_control_path(path: &std::path::Path) {
    let _ = CONTROL_PATH.set(std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf()));
}

/// Take the advisory lock of `port` for the rest of this process
/// (`profibus_io::port_lock`): a port another dpctl process holds is an
/// error naming that process and suggesting `--via`. Taking a port this
/// process holds already is a no-op.
pub fn lock_port(port: &str) -> Result<()> {
    use profibus_io::port_lock::{canonical, Holder, PortLock};
    let mut held = HELD_PORTS.lock().unwrap_or_else(|e| e.into_inner());
    let key = canonical(port);
    if held.iter().any(|l| l.key() == key) {
        return Ok(());
    }
    let holder = Holder::this_process(CONTROL_PATH.get().map(|p| p.as_path()));
    if let Some(lock) = PortLock::take(port, &holder)? {
        held.push(lock);
    }
    Ok(())
}

/// What every one-shot command on one slave takes (`dpctl pkw`, `dpv1`,
/// `rfid`): the line, the bus file, the slave, and how long it may take
/// the slave to reach Data_Exchange.
#[derive(clap::Args, Debug, Clone)]
pub struct SlaveArgs {
    /// Serial device or pty path, or tcp://HOST:PORT (serial device server).
    #[arg(long, value_name = "PATH", required_unless_present = "via")]
    pub port: Option<String>,
    /// Run the job through the running `dpctl master` or `dpctl gateway`
    /// whose control socket (`--control PATH`) this is, instead of opening
    /// the port: its slaves stay in Data_Exchange.
    #[arg(long, value_name = "PATH", conflicts_with_all = ["port", "latency"])]
    pub via: Option<std::path::PathBuf>,
    /// Bus file (TOML) with the slave (GSD modules, or `device = "…"`).
    /// With --via: the master's own bus file is used.
    #[arg(long, value_name = "BUS.toml", required_unless_present = "via")]
    pub config: Option<std::path::PathBuf>,
    /// Station address of the slave.
    #[arg(long, value_name = "ADDR")]
    pub slave: u8,
    /// Milliseconds to wait for the slave to reach Data_Exchange.
    #[arg(long, value_name = "MS", default_value_t = 10000)]
    pub startup_timeout: u64,
    /// Extra milliseconds on the slot time for the transport's latency
    /// (default: 5 on a pty, 20 on a serial adapter).
    #[arg(long, value_name = "MS")]
    pub latency: Option<f64>,
    #[command(flatten)]
    pub rts: RtsArg,
    /// Print JSON: one object (for `rfid`, one per command).
    #[arg(long, global = true)]
    pub json: bool,
}

impl SlaveArgs {
    /// Print a success (text or JSON); a failure is printed as JSON
    /// with `--json` and is the error.
    pub fn print<T, E>(&self, outcome: std::result::Result<T, E>) -> Result<()>
    where
        T: serde::Serialize + std::fmt::Display,
        E: serde::Serialize + std::fmt::Display,
    {
        match outcome {
            Ok(a) if self.json => outln!("{}", json_line(&a))?,
            Ok(a) => outln!("{a}")?,
            Err(r) => {
                if self.json {
                    outln!("{}", json_line(&r))?;
                }
                anyhow::bail!("{r}")
            }
        }
        Ok(())
    }

    /// The slave in the bus file.
    pub fn slave_of<'a>(
        &self,
        bus: &'a profibus_dp::config::busfile::BusFile,
    ) -> Result<&'a profibus_dp::config::busfile::BusSlave> {
        bus.slaves
            .iter()
            .find(|s| s.params.address == self.slave)
            .with_context(|| format!("slave {} is not in {}", self.slave, bus.path.display()))
    }

    /// The bus file (`--config`; needed without `--via`).
    pub fn config(&self) -> Result<&std::path::Path> {
        self.config
            .as_deref()
            .context("--config BUS.toml is needed (or --via PATH)")
    }

    /// The port (`--port`; needed without `--via`).
    pub fn port(&self) -> Result<&str> {
        self.port
            .as_deref()
            .context("--port PATH is needed (or --via PATH)")
    }

    /// Waiting for the slave with the start-up timeout.
    pub fn wait(&self) -> profibus_dp::master::SlaveWait {
        profibus_dp::master::SlaveWait::new(self.slave, Duration::from_millis(self.startup_timeout))
    }

    /// Run the master of `bus` on the port until `tick` breaks (its
    /// events are dropped: one-shot commands look at the slave only).
    /// An interrupt (Ctrl-C, SIGTERM) is an error.
    pub async fn run_master(
        &self,
        bus: &profibus_dp::config::busfile::BusFile,
        mut tick: impl FnMut(
            &mut profibus_dp::master::DpMaster,
            profibus_fdl::Instant,
        ) -> std::ops::ControlFlow<()>,
    ) -> Result<()> {
        use profibus_io::driver::{self, Clock, Stop};
        let dp = profibus_dp::master::DpMaster::new(&bus.master)?;
        let port_path = self.port()?;
        let (mut station, mut port) = master_station(port_path, bus, dp, self.latency, self.rts)?;
        let stop = driver::run_with(
            &mut station,
            &mut port,
            Clock::start(),
            driver::Options::default(),
            shutdown(),
            |st, now| {
                let m = st.app_mut();
                while m.poll_event().is_some() {}
                tick(m, now)
            },
        )
        .await;
        match stop.with_context(|| format!("on {port_path}"))? {
            Stop::Shutdown => anyhow::bail!("interrupted"),
            Stop::Done => Ok(()),
        }
    }
}

impl LineArgs {
    /// Open the port (at 19.2 kbit/s for `--baud auto`: [`find_baud`]
    /// sets the rate).
    pub fn open(&self) -> Result<Port> {
        let baud = match self.baud {
            BaudArg::Fixed(b) => b,
            BaudArg::Auto => Baud::B19200,
        };
        self.rts.open(&self.port, baud)
    }
}

/// A `--baud` value: a rate, or `auto` (dpctl scan, sniff and monitor:
/// [`find_baud`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BaudArg {
    /// This rate.
    Fixed(Baud),
    /// Find the rate on the line.
    Auto,
}

impl std::str::FromStr for BaudArg {
    type Err = profibus_fdl::timing::UnknownBaud;
    fn from_str(s: &str) -> std::result::Result<BaudArg, Self::Err> {
        if s.trim().eq_ignore_ascii_case("auto") {
            return Ok(BaudArg::Auto);
        }
        s.parse().map(BaudArg::Fixed)
    }
}

impl BaudArg {
    /// The rate, for a command without a rate search: `auto` is refused
    /// in one line naming the commands that have one.
    pub fn fixed(self) -> Result<Baud> {
        match self {
            BaudArg::Fixed(b) => Ok(b),
            BaudArg::Auto => anyhow::bail!(
                "--baud auto is only for dpctl scan, sniff and monitor; give the line's rate (e.g. --baud 1.5M, as `dpctl scan --baud auto` prints it)"
            ),
        }
    }
}

/// How [`find_baud`] found the rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BaudFound {
    /// A valid telegram decoded at the rate.
    Heard(Baud),
    /// The line was silent; this station answered an FDL Status request
    /// at the rate.
    Answered(Baud, u8),
}

impl BaudFound {
    /// The rate.
    pub fn baud(self) -> Baud {
        match self {
            BaudFound::Heard(b) | BaudFound::Answered(b, _) => b,
        }
    }

    /// The finding as one JSON line (`event` `baud_found`).
    pub fn json(self) -> serde_json::Value {
        match self {
            BaudFound::Heard(b) => serde_json::json!({
                "event": "baud_found", "baud": b.bps(), "how": "heard",
            }),
            BaudFound::Answered(b, st) => serde_json::json!({
                "event": "baud_found", "baud": b.bps(), "how": "answered", "station": st,
            }),
        }
    }
}

impl std::fmt::Display for BaudFound {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BaudFound::Heard(b) => write!(f, "baud rate {b} found (traffic heard)"),
            BaudFound::Answered(b, st) => {
                write!(f, "baud rate {b} found (station {st} answered)")
            }
        }
    }
}

/// `--baud auto`: listen at each rate (fastest first) for a valid
/// telegram. A command that may send (`probe`: its own address and the
/// transport's latency allowance) listens one round and, on a silent
/// line, sends FDL Status requests at each rate until a station answers;
/// a listener keeps listening until Ctrl-C. The port is left at the rate
/// found.
pub async fn find_baud(port: &mut Port, probe: Option<(u8, Duration)>) -> Result<BaudFound> {
    use profibus_fdl::station::autobaud::BaudSet;
    use profibus_io::baud::{listen_for_baud, listen_round, probe_baud};
    let clock = profibus_io::driver::Clock::start();
    let name = port.name().to_string();
    if port.is_tcp() {
        anyhow::bail!("--baud auto cannot work on {name}: the serial device server sets the rate; give --baud");
    }
    let Some((own, latency)) = probe else {
        return match listen_for_baud(port, &clock, BaudSet::ALL, shutdown())
            .await
            .with_context(|| format!("searching the rate on {name}"))?
        {
            Some(b) => Ok(BaudFound::Heard(b)),
            None => anyhow::bail!("interrupted before a telegram was heard at any rate"),
        };
    };
    let round = tokio::time::sleep(listen_round(BaudSet::ALL));
    let stop = async {
        tokio::select! {
            _ = shutdown() => {}
            _ = round => {}
        }
    };
    if let Some(b) = listen_for_baud(port, &clock, BaudSet::ALL, stop)
        .await
        .with_context(|| format!("searching the rate on {name}"))?
    {
        return Ok(BaudFound::Heard(b));
    }
    tracing::info!(port = %name, "silent line: asking at each rate");
    let found = tokio::select! {
        r = probe_baud(port, own, latency, BaudSet::ALL) => r.with_context(|| format!("asking on {name}"))?,
        _ = shutdown() => anyhow::bail!("interrupted"),
    };
    match found {
        Some(p) => Ok(BaudFound::Answered(p.baud, p.station)),
        None => {
            anyhow::bail!("no traffic and no station answered FDL Status at any rate on {name}")
        }
    }
}

/// The latency allowance from a `--latency MS` option, or the port's
/// default ([`Port::default_latency`]).
pub fn latency(ms: Option<f64>, port: &Port) -> Result<Duration> {
    match ms {
        Some(ms) if ms >= 0.0 && ms.is_finite() => Ok(Duration::from_secs_f64(ms / 1000.0)),
        Some(ms) => anyhow::bail!("--latency {ms} must be a non-negative number"),
        None => Ok(port.default_latency()),
    }
}

/// The FDL master station of a bus file (running `dp`) and its port
/// (opened with `rts`).
pub fn master_station(
    port: &str,
    bus: &profibus_dp::config::busfile::BusFile,
    dp: profibus_dp::master::DpMaster,
    latency_ms: Option<f64>,
    rts: RtsArg,
) -> Result<(
    profibus_fdl::station::active::ActiveStation<profibus_dp::master::DpMaster>,
    Port,
)> {
    use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
    let port_ = rts.open(port, bus.master.params.baud)?;
    let mut cfg = ActiveConfig::new(bus.master.address, bus.master.params);
    allow_for_port(&mut cfg, latency_ms, &port_)?;
    Ok((ActiveStation::new(cfg, dp), port_))
}

/// Fit an active station's timeouts to its port: the latency from
/// `--latency MS` (see [`latency`]) and whether the port hands over whole
/// telegrams ([`Port::whole_telegrams`]; then each request's wait allows
/// for the wire time of its longest answer).
pub fn allow_for_port(
    cfg: &mut profibus_fdl::station::active::ActiveConfig,
    latency_ms: Option<f64>,
    port: &Port,
) -> Result<()> {
    cfg.latency_allowance = latency(latency_ms, port)?;
    cfg.whole_telegrams = port.whole_telegrams();
    Ok(())
}

/// Driver options: busy polling for `busy_poll_us` µs after each event;
/// with `gather` (a benchmark option) telegrams are gathered into one
/// write where the port allows it ([`Port::may_gather`]).
pub fn driver_options(
    port: &Port,
    busy_poll_us: u64,
    gather: bool,
) -> Result<profibus_io::driver::Options> {
    if gather && !port.may_gather() {
        anyhow::bail!(
            "--gather is for ptys only: {} is a serial line",
            port.name()
        );
    }
    Ok(profibus_io::driver::Options {
        gather,
        busy_poll: Duration::from_micros(busy_poll_us),
        ..Default::default()
    })
}

/// A single-threaded tokio runtime for one command.
pub fn runtime() -> Result<tokio::runtime::Runtime> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the runtime")?;
    install_shutdown(&rt).context("installing the SIGINT/SIGTERM handlers")?;
    Ok(rt)
}

/// Set once SIGINT or SIGTERM arrived, or [`request_stop`] was called.
static STOP: std::sync::OnceLock<tokio::sync::watch::Sender<bool>> = std::sync::OnceLock::new();

/// Catch SIGINT and SIGTERM from now on, before the command prints
/// anything: a signal that arrives at any later moment stops the command
/// cleanly (nothing is missed between start-up and the first wait).
fn install_shutdown(rt: &tokio::runtime::Runtime) -> std::io::Result<()> {
    use tokio::signal::unix::{signal, SignalKind};
    let _guard = rt.enter();
    let mut int = signal(SignalKind::interrupt())?;
    let mut term = signal(SignalKind::terminate())?;
    let _ = STOP.set(tokio::sync::watch::Sender::new(false));
    rt.spawn(async move {
        tokio::select! {
            _ = int.recv() => {}
            _ = term.recv() => {}
        }
        request_stop();
    });
    Ok(())
}

/// Stop the command as SIGTERM would (its [`shutdown`] completes): for
/// a standard output nobody reads any more ([`crate::out::Closed`]).
pub fn request_stop() {
    if let Some(tx) = STOP.get() {
        tx.send_replace(true);
    }
}

/// Whether SIGINT or SIGTERM has arrived (or [`request_stop`] was
/// called), without waiting.
pub fn stop_requested() -> bool {
    STOP.get().is_some_and(|tx| *tx.borrow())
}

/// Completes once SIGINT (Ctrl-C) or SIGTERM has arrived, or
/// [`request_stop`] was called (also when that happened before this was
/// called).
pub async fn shutdown() {
    let Some(tx) = STOP.get() else {
        return std::future::pending().await;
    };
    let mut rx = tx.subscribe();
    if rx.wait_for(|&stop| stop).await.is_err() {
        std::future::pending::<()>().await;
    }
}

/// `v` as one JSON line, its keys in alphabetical order (the order
/// scripts and tests have always seen).
pub fn json_line<T: serde::Serialize + ?Sized>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(v) => v.to_string(),
        Err(e) => {
            tracing::warn!(%e, "not serialisable");
            String::new()
        }
    }
}

/// The clean stop of a master on a line on SIGTERM or Ctrl-C
/// ([`profibus_dp::master::Farewell`]): Global_Control Clear_Data to the
/// slaves, one poll cycle in Clear, the token passed on; then the driver
/// stops. Hand [`CleanStop::shutdown`] to the driver instead of the
/// plain stop future and call [`CleanStop::step`] at every step.
#[derive(Default)]
pub struct CleanStop {
    asked: std::sync::Arc<std::sync::atomic::AtomicBool>,
    farewell: Option<profibus_dp::master::Farewell>,
}

impl CleanStop {
    /// The driver's stop future: `stop` (the signal) starts the farewell;
    /// the driver is stopped regardless half a second after its bound
    /// ([`profibus_dp::master::FAREWELL_LIMIT`]), should no step come.
    pub fn shutdown(
        &self,
        stop: impl std::future::Future<Output = ()>,
    ) -> impl std::future::Future<Output = ()> {
        let asked = self.asked.clone();
        async move {
            stop.await;
            asked.store(true, std::sync::atomic::Ordering::Relaxed);
            let bound = profibus_dp::master::FAREWELL_LIMIT + Duration::from_millis(500);
            tokio::time::sleep(bound).await;
        }
    }

    /// One step of the stop, once asked: `Break` when the master may
    /// fall silent.
    pub fn step(
        &mut self,
        st: &mut profibus_fdl::station::active::ActiveStation<profibus_dp::master::DpMaster>,
        now: profibus_fdl::Instant,
    ) -> std::ops::ControlFlow<()> {
        use std::ops::ControlFlow;
        if !self.asked.load(std::sync::atomic::Ordering::Relaxed) {
            return ControlFlow::Continue(());
        }
        let f = *self.farewell.get_or_insert_with(|| {
            tracing::info!("stopping: Global_Control Clear_Data to the slaves");
            profibus_dp::master::Farewell::begin(st.app_mut(), now)
        });
        let alone = st.next_station() == st.config().address;
        if !f.done(st.app(), st.ring_state(), alone, now) {
            return ControlFlow::Continue(());
        }
        if f.timed_out(now) {
            tracing::warn!(
                cleared = f.cleared(st.app()),
                "stopped without a clean farewell within {:?}",
                profibus_dp::master::FAREWELL_LIMIT
            );
        } else {
            tracing::info!("slaves cleared, token passed on: stopping");
        }
        ControlFlow::Break(())
    }
}
