//! `dpctl slave`: emulate a DP slave on a serial line or pty.
//!
//! The device is a profile (`--device NAME`) or the generic device a GSD
//! file describes (`--gsd FILE --module NAME …`). The slave runs as
//! `PassiveStation<DpSlave<…>>` on the port through the tokio driver and
//! prints its state changes, faults and Global_Control commands (one JSON
//! object per line with `--json`).
//!
//! Baud rate: `--baud auto` (the default) searches on a serial line like
//! a real slave with `Auto_Baud_supp` (fastest rate first, lock on the
//! first valid telegram, search again after a watchdog expiry or 10 s
//! without a valid telegram; `profibus_fdl::runner::PassiveRunner`).
//! A pty carries bytes, not bits, so there the
//! rate is nominal: the slave locks at once, at 19.2 kbit/s unless
//! `--baud` names a rate (the rate sets the bit times of min TSDR and of
//! the receive timeouts). `--latency` (default 5 ms on a pty, 20 ms on a
//! serial adapter) lengthens the time an incomplete telegram may take to
//! arrive, for transports that deliver bytes late.

use crate::common;
use anyhow::{bail, Context};
use profibus_devices::address::StoredAddress;
use profibus_devices::generic::InputPattern;
use profibus_devices::{
    BoxedDevice, Configured, ControlInbox, DeviceOptions, ProfileError, PROFILES, STATE_EVENT,
};
use profibus_dp::slave::{Device, DpSlave, OwnAddress, SlaveEvent};
use profibus_fdl::driver::Clock;
use profibus_fdl::runner::{PassiveRunner, RunnerEvent, Step};
use profibus_fdl::wire::Hex;
use profibus_fdl::{Baud, Instant};
use std::io::Write;
use std::path::PathBuf;

/// Emulate a PROFIBUS-DP slave.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial port or pty path (e.g. /dev/ttyUSB0, or one end of a socat
    /// pty pair), or tcp://HOST:PORT (serial device server, raw TCP).
    #[arg(long, value_name = "PATH", required_unless_present = "list_devices")]
    port: Option<String>,
    /// Station address of the slave (0..=126). The bm4 profile takes its
    /// address from --us-device / --switch instead when given, the omega
    /// profile from --switch.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=126),
          required_unless_present_any = ["list_devices", "us_device", "switch", "device"])]
    addr: Option<u8>,
    /// Baud rate (9600 … 12M), or `auto` to search for the rate of the
    /// traffic on a serial line (on a pty: nominal 19.2 kbit/s), or
    /// `search` to search even on a pty (where every rate passes the
    /// bytes, so it locks at the first rate that sees a valid telegram).
    #[arg(long, value_name = "B", default_value = "auto")]
    baud: String,
    /// GSD file of the device to emulate (the generic device; `.gsd` or a
    /// localised `.gse`, `.gsg`, …).
    #[arg(long, value_name = "FILE", conflicts_with = "device")]
    gsd: Option<PathBuf>,
    /// A module of the GSD file, in slot order (repeat for each module;
    /// names match approximately). None: the file's fixed configuration.
    #[arg(long = "module", value_name = "NAME", requires = "gsd")]
    modules: Vec<String>,
    /// Accept known vendor quirks in the GSD file (with a warning).
    #[arg(long, requires = "gsd")]
    lenient: bool,
    /// Input pattern of the generic device: `echo` (the outputs) or
    /// `counter` (a 32-bit counter, one step per Data_Exchange).
    #[arg(long, value_name = "PATTERN", default_value = "echo")]
    inputs: InputPattern,
    /// Device profile to emulate (see --list-devices).
    #[arg(long, value_name = "NAME")]
    device: Option<String>,
    /// An option of the device profile, KEY=VALUE (repeatable).
    #[arg(long = "device-opt", value_name = "KEY=VALUE", requires = "device")]
    device_opts: Vec<String>,
    /// List the device profiles and exit.
    #[arg(long)]
    list_devices: bool,
    /// bm4: the PLC's variable table (TOML, see
    /// crates/devices/data/bm4_example_vars.toml); default: the
    /// configuration of BM4OPRO1.GSD.
    #[arg(long, value_name = "FILE.toml", requires = "device")]
    vars: Option<PathBuf>,
    /// bm4: us_DEVICE of PROFIBUS_INIT_SL: 1..125 fixed address, 126 set
    /// once by the master (Set_Slave_Add) and kept in --state-dir, 127 set
    /// by the master after every start, 128 the rotary switch (--switch).
    /// Default: --addr.
    #[arg(long, value_name = "N", requires = "device")]
    us_device: Option<u8>,
    /// bm4: rotary switch value for us_DEVICE 128 (0 error, 1..125 the
    /// address, 126..255 set once by the master). omega: the rotary
    /// switches S40/S41 (hex allowed, e.g. 0x19 = 25) instead of --addr.
    #[arg(long, value_name = "N", requires = "device")]
    switch: Option<String>,
    /// bm4: directory of the state file keeping a set-once address.
    #[arg(long, value_name = "DIR", requires = "device")]
    state_dir: Option<PathBuf>,
    /// bm4: write the GSD file of this configuration (generated from
    /// --vars, or BM4OPRO1.GSD) before starting.
    #[arg(long, value_name = "FILE", requires = "device")]
    write_gsd: Option<PathBuf>,
    /// omega: the V controller's parameter set (TOML, see
    /// crates/devices/data/omega_vparams.toml); default: the shipped one.
    #[arg(long, value_name = "FILE.toml", requires = "device")]
    params: Option<PathBuf>,
    /// omega: number of setpoints the drive expects (si_NR_WR_VALUE,
    /// 1..8; with --actual-values). Default: any valid configuration.
    #[arg(long, value_name = "N", requires = "actual_values")]
    setpoints: Option<u8>,
    /// omega: number of actual values (si_NR_RD_VALUE, 1..8).
    #[arg(long, value_name = "N", requires = "setpoints")]
    actual_values: Option<u8>,
    /// rfid: the tags file (TOML: tags with UID and memory, which one is
    /// in the antenna field, the reader's timing), rewritten when the
    /// field changes.
    #[arg(long, value_name = "FILE.toml", requires = "device")]
    tags: Option<PathBuf>,
    /// bk3000: the terminal strip in plug order, end terminal last, e.g.
    /// KL1104,KL2134,KL3102,KL4002,KL9010 (a name may end in `:complete`
    /// or `:compact`); or `--device-opt terminals-file=FILE`.
    #[arg(long, value_name = "LIST", requires = "device")]
    terminals: Option<String>,
    /// bk3000: the rotary switch for the ones of the address (0..9).
    #[arg(long, value_name = "N", requires = "device")]
    switch_ones: Option<u8>,
    /// bk3000: the rotary switch for the tens of the address (0..9).
    #[arg(long, value_name = "N", requires = "device")]
    switch_tens: Option<u8>,
    /// Control commands for the device, one per line, from FILE, `-`
    /// (stdin), or a Unix socket dpctl creates when the path does not
    /// exist (each connection sends lines; removed at the end). bm4: `sdiag EF CD AB 90 78 56 34 12 [overflow]` (user
    /// diagnosis, FB SDIAG), `sdiag-clear`, `set NAME VALUE`, `get NAME`,
    /// `status`. omega: `status`, `quit` (x_QUIT), `get P`. rfid: `enter UID`,
    /// `leave`, `tags`, `status`. jx2: a Unix socket to create for register
    /// commands (`read 12100`, `write 12102 16`, ...; stdin always takes
    /// them too). bk3000: `status`, `outputs`, `set NAME VALUE`, `release
    /// NAME|all`, `pull N`, `plug N`, `run`.
    #[arg(long, value_name = "FILE", requires = "device")]
    control: Option<String>,
    /// jx2: the module number x of the registers 1x100..1x999 (1..9,
    /// default 2).
    #[arg(long, value_name = "N", requires = "device")]
    module_number: Option<u32>,
    /// jx2: register commands run as the PLC program at start.
    #[arg(long, value_name = "FILE", requires = "device")]
    script: Option<PathBuf>,
    /// File in which the generic device keeps an address set by
    /// Set_Slave_Add (`address=N`, `no_add_chg=0|1`); when it exists its
    /// address overrides --addr.
    #[arg(long, value_name = "FILE", requires = "gsd")]
    address_file: Option<PathBuf>,
    /// Print the process data whenever the outputs change.
    #[arg(long)]
    show_data: bool,
    /// Stop after this many Data_Exchange cycles (0: run until Ctrl-C).
    #[arg(long, value_name = "N", default_value_t = 0)]
    cycles: u64,
    /// Extra milliseconds an incomplete telegram may take to arrive, for
    /// the transport's latency (default: 5 on a pty, 20 on a serial
    /// adapter).
    #[arg(long, value_name = "MS")]
    latency: Option<f64>,
    #[command(flatten)]
    rts: common::RtsArg,
    /// After each telegram keep polling the port for this many µs instead
    /// of sleeping: faster answers on ptys and USB adapters, a busy CPU.
    #[arg(long, default_value_t = 0, value_name = "US")]
    busy_poll: u64,
    /// Benchmark option for ptys: gather telegrams due within 100 µs into
    /// one write (see `dpctl master --gather`).
    #[arg(long)]
    gather: bool,
    /// Print one JSON object per line.
    #[arg(long)]
    json: bool,
}

/// How the baud rate is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum BaudChoice {
    Fixed(Baud),
    /// Search on a serial line, nominal rate on a pty or tcp:// port.
    Auto,
    /// Search even on a pty.
    Search,
}

fn parse_baud(s: &str) -> anyhow::Result<BaudChoice> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(BaudChoice::Auto);
    }
    if s.eq_ignore_ascii_case("search") {
        return Ok(BaudChoice::Search);
    }
    Ok(BaudChoice::Fixed(s.parse::<Baud>()?))
}

/// Nominal rate on a pty with `--baud auto`.
const PTY_NOMINAL: Baud = Baud::B19200;

/// What the shell reports besides the slave's own events.
#[derive(serde::Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
enum Shell<'a> {
    GsdWarning {
        text: &'a str,
    },
    Start {
        device: &'a str,
        ident: String,
        address: Option<u8>,
        port: &'a str,
        baud: String,
        pty: bool,
        #[serde(skip)]
        text: String,
    },
    AddressStoreError {
        text: String,
    },
    StateSaved {
        text: String,
    },
    StateStoreError {
        text: String,
    },
    Data {
        #[serde(serialize_with = "profibus_fdl::ser::hex_compact")]
        outputs: &'a [u8],
        #[serde(serialize_with = "profibus_fdl::ser::hex_compact")]
        inputs: &'a [u8],
        cycle: u64,
    },
    Stopped {
        state: profibus_dp::slave::SlaveState,
        #[serde(flatten)]
        stats: profibus_dp::slave::SlaveStats,
    },
}

impl std::fmt::Display for Shell<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Shell::GsdWarning { text } => f.write_str(text),
            Shell::Start { text, .. }
            | Shell::AddressStoreError { text }
            | Shell::StateSaved { text }
            | Shell::StateStoreError { text } => f.write_str(text),
            Shell::Data {
                outputs,
                inputs,
                cycle,
            } => write!(
                f,
                "data: outputs {:#} inputs {:#} (cycle {cycle})",
                Hex(outputs),
                Hex(inputs)
            ),
            Shell::Stopped { state, stats: s } => write!(
                f,
                "stopped in {state}: {} Data_Exchange cycles, {} Slave_Diag, {} refused, {} watchdog expiries",
                s.data_exchanges, s.diag_requests, s.refused, s.watchdog_expiries
            ),
        }
    }
}

/// A slave event as printed: its fields, its text.
#[derive(serde::Serialize)]
struct WithText<'a> {
    #[serde(flatten)]
    event: &'a SlaveEvent,
    text: String,
}

impl std::fmt::Display for WithText<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

/// A line with its time (`"t"`, in s since the start).
#[derive(serde::Serialize)]
struct Timed<'a, E: serde::Serialize> {
    #[serde(flatten)]
    event: &'a E,
    t: f64,
}

/// Prints events as text or JSON lines.
struct Printer {
    json: bool,
    clock: Clock,
}

impl Printer {
    fn emit<E: serde::Serialize + std::fmt::Display>(&self, now: Instant, e: &E) {
        let t = now.as_nanos() as f64 / 1e9;
        let mut out = std::io::stdout().lock();
        let _ = if self.json {
            let line = Timed {
                event: e,
                t: (t * 1e6).round() / 1e6,
            };
            writeln!(out, "{}", common::json_line(&line))
        } else {
            writeln!(out, "[{t:>11.6}] {e}")
        };
        let _ = out.flush();
    }

    fn now(&self) -> Instant {
        self.clock.now()
    }

    fn event(&self, now: Instant, e: &SlaveEvent) {
        self.emit(
            now,
            &WithText {
                event: e,
                text: e.to_string(),
            },
        );
    }
}

/// The device to emulate, with its name for people.
/// Lines from `src` (a file, or `-` for stdin) into `inbox`.
fn spawn_control_reader(src: String, inbox: ControlInbox) {
    use tokio::io::AsyncBufReadExt;
    let path = std::path::Path::new(&src);
    if src != "-" && (!path.exists() || is_socket(path)) {
        // A Unix socket we create (removed at the end, see `run`): every
        // connection sends lines.
        let _ = std::fs::remove_file(path);
        match tokio::net::UnixListener::bind(path) {
            Ok(listener) => {
                tokio::spawn(async move {
                    while let Ok((conn, _)) = listener.accept().await {
                        let inbox = inbox.clone();
                        tokio::spawn(async move {
                            let mut lines = tokio::io::BufReader::new(conn).lines();
                            while let Ok(Some(l)) = lines.next_line().await {
                                inbox.push(l);
                            }
                        });
                    }
                });
            }
            Err(e) => eprintln!("dpctl slave: cannot listen on {src}: {e}"),
        }
        return;
    }
    tokio::spawn(async move {
        let reader: Box<dyn tokio::io::AsyncRead + Unpin + Send> = if src == "-" {
            Box::new(tokio::io::stdin())
        } else {
            match tokio::fs::File::open(&src).await {
                Ok(f) => Box::new(f),
                Err(e) => {
                    eprintln!("dpctl slave: cannot open {src}: {e}");
                    return;
                }
            }
        };
        let mut lines = tokio::io::BufReader::new(reader).lines();
        while let Ok(Some(l)) = lines.next_line().await {
            inbox.push(l);
        }
    });
}

fn is_socket(path: &std::path::Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_socket())
}

/// The profile's options from the command line: the named flags, then
/// `--device-opt KEY=VALUE` (later ones win).
fn device_options(args: &Args) -> anyhow::Result<DeviceOptions> {
    let mut opts = DeviceOptions::new();
    if args.device.is_none() {
        // The generic device: --gsd FILE --module NAME ...
        let gsd = args
            .gsd
            .as_ref()
            .context("give --gsd FILE (with --module NAME …) or --device NAME")?;
        opts.set("gsd", gsd.display().to_string());
        opts.set("modules", args.modules.clone());
        opts.set("lenient", args.lenient);
        let inputs = match args.inputs {
            InputPattern::Echo => "echo",
            InputPattern::Counter => "counter",
        };
        opts.set("inputs", inputs);
    }
    let path = |p: &Option<PathBuf>| p.as_ref().map(|p| p.display().to_string());
    for (k, v) in [
        ("vars", path(&args.vars)),
        ("state_dir", path(&args.state_dir)),
        ("write_gsd", path(&args.write_gsd)),
        ("params", path(&args.params)),
        ("address_file", path(&args.address_file)),
        ("script", path(&args.script)),
        ("tags", path(&args.tags)),
    ] {
        if let Some(v) = v {
            opts.set(k, v);
        }
    }
    for (k, v) in [
        ("us_device", args.us_device.map(i64::from)),
        ("setpoints", args.setpoints.map(i64::from)),
        ("actual_values", args.actual_values.map(i64::from)),
        ("module_number", args.module_number.map(i64::from)),
        ("switch_ones", args.switch_ones.map(i64::from)),
        ("switch_tens", args.switch_tens.map(i64::from)),
    ] {
        if let Some(v) = v {
            opts.set(k, v);
        }
    }
    if let Some(s) = &args.switch {
        opts.set_text("switch", s);
    }
    if let Some(t) = &args.terminals {
        opts.set("terminals", t.as_str());
    }
    for o in &args.device_opts {
        opts.set_pair(o)?;
    }
    Ok(opts)
}

/// A device with its name for people.
struct Built {
    profile: Box<dyn Configured>,
    device: BoxedDevice,
    name: String,
    /// jx2: the PLC, for the baud rate register.
    jx2: Option<profibus_devices::jx2::SharedJx2>,
}

/// The configured profile, its slave device and its name for people.
fn build_device(args: &Args, printer: &Printer) -> anyhow::Result<Built> {
    let entry = match &args.device {
        Some(name) => profibus_devices::profile(name)
            .map_err(|e| anyhow::anyhow!("{e}; or use --gsd FILE"))?,
        None => profibus_devices::profile("generic")?,
    };
    let opts = device_options(args)?;
    let in_words = |e: ProfileError| match &args.device {
        Some(_) => anyhow::anyhow!("device `{}`: {e}", entry.name),
        None => anyhow::anyhow!("{e}"),
    };
    let profile = entry.configure(&opts, args.addr).map_err(in_words)?;
    for w in profile.warnings() {
        let now = printer.now();
        printer.emit(now, &Shell::GsdWarning { text: &w });
    }
    let mut jx2 = None;
    let dev = if entry.name == profibus_devices::jx2::profile::NAME {
        // The register interface runs beside the slave (stdin, a socket).
        let (dev, plc) = crate::jx2::start(&jx2_options(args, &opts)?, printer.clock.clone())?;
        jx2 = Some(plc);
        dev
    } else {
        let control = args.control.as_ref().map(|src| {
            let inbox = ControlInbox::new();
            spawn_control_reader(src.clone(), inbox.clone());
            inbox
        });
        profile.device(control).map_err(in_words)?
    };
    let name = match &args.device {
        Some(_) => entry.name.to_string(),
        None => {
            let gsd = profile.gsd();
            gsd.model_name
                .clone()
                .unwrap_or_else(|| format!("ident 0x{:04X}", gsd.ident_number))
        }
    };
    Ok(Built {
        profile,
        device: dev,
        name,
        jx2,
    })
}

/// What the jx2 register clients need.
fn jx2_options(args: &Args, opts: &DeviceOptions) -> anyhow::Result<crate::jx2::Options> {
    let o: profibus_devices::jx2::profile::Options = opts.decode()?;
    Ok(crate::jx2::Options {
        module_number: o.module_number,
        control: args.control.as_ref().map(PathBuf::from),
        script: o.script,
    })
}

fn list_devices() {
    for p in PROFILES {
        println!("{:<8} {}", p.name, p.summary);
        if !p.options_help.is_empty() {
            println!("         options: {}", p.options_help);
        }
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.list_devices {
        list_devices();
        return Ok(());
    }
    let rt = common::runtime()?;
    let socket = args.control.clone().filter(|c| {
        let p = std::path::Path::new(c);
        c != "-" && (!p.exists() || is_socket(p))
    });
    let result = rt.block_on(run_async(args));
    if let Some(s) = socket.filter(|s| is_socket(std::path::Path::new(s))) {
        // The control socket we created (its listener may outlive the
        // runtime).
        let _ = std::fs::remove_file(s);
    }
    // A --control reader may be blocked on stdin: do not wait for it.
    rt.shutdown_background();
    result
}

async fn run_async(args: Args) -> anyhow::Result<()> {
    let clock = Clock::start();
    let printer = Printer {
        json: args.json,
        clock: clock.clone(),
    };
    let path = args.port.clone().expect("clap requires --port");
    let choice = parse_baud(&args.baud)?;
    let Built {
        profile,
        device,
        name,
        jx2,
    } = build_device(&args, &printer)?;
    let addr = match profile.address().or(args.addr) {
        Some(a) => a,
        // A device that sets its address itself (jx2: its PLC writes it).
        None if device.own_address() != OwnAddress::Slave => 0,
        None => bail!("give --addr N"),
    };
    let address_file = profile.address_file();
    let state_file = profile.state_file();
    let mut port = args.rts.open(&path, PTY_NOMINAL)?;
    let pty = port.is_pty();
    // Through a serial device server (tcp://) every byte arrives intact
    // whatever the rate: the server's setting is the rate, no search.
    let nominal = pty || port.is_tcp();
    let latency = common::latency(args.latency, &port)?;
    let options = common::driver_options(&port, args.busy_poll, args.gather)?;
    let search = choice == BaudChoice::Search || (choice == BaudChoice::Auto && !nominal);
    let first = match choice {
        BaudChoice::Fixed(b) => b,
        BaudChoice::Auto if nominal => PTY_NOMINAL,
        BaudChoice::Auto | BaudChoice::Search => profibus_fdl::autobaud::SEARCH_ORDER[0],
    };
    port.set_baud(first)?;
    let slave = DpSlave::new(device, addr);
    {
        let ident = slave.device().ident_number();
        let now = printer.now();
        let baud_text = if search {
            "auto-baud".to_string()
        } else if pty {
            format!("{first}, pty")
        } else {
            first.to_string()
        };
        let (address, at) = match slave.device().own_address() {
            OwnAddress::NoneYet => (None, "with no address yet".to_string()),
            OwnAddress::Set(a) => (Some(a), format!("at address {a}")),
            OwnAddress::Slave => (Some(addr), format!("at address {addr}")),
        };
        printer.emit(
            now,
            &Shell::Start {
                device: &name,
                ident: format!("0x{ident:04X}"),
                address,
                port: &path,
                baud: if search {
                    "auto".to_string()
                } else {
                    first.bps().to_string()
                },
                pty,
                text: format!("{name} (ident 0x{ident:04X}) {at} on {path} ({baud_text})"),
            },
        );
    }

    let mut last_outputs: Vec<u8> = vec![];
    let runner = PassiveRunner::new(search, latency, options);
    if let (Some(plc), false) = (&jx2, search) {
        plc.lock().module.set_baud(first.bps());
    }
    let (slave, _) = runner
        .run(
            slave,
            &mut port,
            clock.clone(),
            common::shutdown(),
            |now, e| {
                if let (Some(plc), RunnerEvent::BaudLocked { baud }) = (&jx2, e) {
                    plc.lock().module.set_baud(baud.bps());
                }
                printer.emit(now, &e);
            },
            |st, now| {
                let mut step = Step::Continue;
                while let Some(e) = st.app_mut().poll_event() {
                    if matches!(e, SlaveEvent::WatchdogExpired { .. }) {
                        step = Step::SearchAgain;
                    }
                    if let (
                        SlaveEvent::AddressChanged {
                            new, no_add_chg, ..
                        },
                        Some(f),
                    ) = (&e, &address_file)
                    {
                        // The device only accepted it: the shell keeps it.
                        let stored = StoredAddress {
                            address: *new,
                            no_add_chg: *no_add_chg,
                        };
                        if let Err(err) = stored.save(f) {
                            printer.emit(
                                now,
                                &Shell::AddressStoreError {
                                    text: err.to_string(),
                                },
                            );
                        }
                    }
                    if let (SlaveEvent::Device(d), Some(f)) = (&e, &state_file) {
                        if d.kind == STATE_EVENT {
                            // The device's new state: the shell keeps it.
                            let e = match std::fs::write(f, &d.text) {
                                Ok(()) => Shell::StateSaved {
                                    text: format!("state saved to {}", f.display()),
                                },
                                Err(err) => Shell::StateStoreError {
                                    text: format!(
                                        "cannot save the state to {}: {err}",
                                        f.display()
                                    ),
                                },
                            };
                            printer.emit(now, &e);
                            continue;
                        }
                    }
                    printer.event(now, &e);
                }
                let app = st.app();
                if args.show_data && app.outputs() != last_outputs.as_slice() {
                    last_outputs.clear();
                    last_outputs.extend_from_slice(app.outputs());
                    printer.emit(
                        now,
                        &Shell::Data {
                            outputs: app.outputs(),
                            inputs: app.inputs(),
                            cycle: app.stats().data_exchanges,
                        },
                    );
                }
                if args.cycles > 0 && app.stats().data_exchanges >= args.cycles {
                    return Step::Stop;
                }
                step
            },
        )
        .await
        .with_context(|| path.clone())?;
    let now = printer.now();
    printer.emit(
        now,
        &Shell::Stopped {
            state: slave.state(),
            stats: slave.stats(),
        },
    );
    Ok(())
}
