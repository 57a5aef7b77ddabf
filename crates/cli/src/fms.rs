//! `dpctl fms`: one PROFIBUS-FMS service on a server (a BK3000 in DP/FMS
//! mixed mode): a master of its own at `--addr` joins the token ring next
//! to the running masters, connects to the server's communication
//! relationship on `--lsap` (LLI Associate with Initiate), runs the
//! service and releases the connection (`profibus_io::fms::run`).
//!
//! Output in words or one JSON object; exit 1 with the reason in words:
//! the server's error (class and code), a Reject or an Abort, no answer,
//! a station that serves no FMS on the LSAP, a master not taken into the
//! ring. The encodings marked (unverified) in docs/fms.md apply.

use crate::common::{self, RtsArg};
use anyhow::{bail, Context, Result};
use profibus_devices::bus::ProfiledBus;
use profibus_dp::class2::Class2Config;
use profibus_dp::fms::client::{FmsMaster, FmsRun, FmsRunError};
use profibus_dp::fms::od::{self, Description, ObjectCode, OdHeader};
use profibus_dp::fms::pdu::{GetOdRequest, Request, Response, ServiceError};
use profibus_fdl::station::active::ActiveConfig;
use profibus_fdl::wire::Hex;
use profibus_fdl::{Baud, BusParams};
use serde_json::{json, Map, Value};
use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Duration;

/// Run one FMS service on a server (Identify, Status, Get-OD, Read, Write).
#[derive(clap::Args)]
pub struct Args {
    /// Serial device or pty path (e.g. /dev/ttyUSB0, a `dpctl bus` link),
    /// or tcp://HOST:PORT (serial device server).
    #[arg(long, value_name = "PATH")]
    port: String,
    /// Station address of the FMS server.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=125))]
    station: u8,
    /// The server's LSAP of the communication relationship (its KBL
    /// entry) [default: 40, the BK3000's first].
    #[arg(long, value_name = "LSAP", default_value_t = 40, value_parser = clap::value_parser!(u8).range(0..=62))]
    lsap: u8,
    /// This master's station address in the token ring (not the address
    /// of a running master) [default: 1].
    #[arg(long, visible_alias = "address", value_name = "ADDR", value_parser = clap::value_parser!(u8).range(0..=125))]
    addr: Option<u8>,
    /// Bus file (TOML): gives the baud rate and the bus parameters.
    #[arg(long, value_name = "BUS.toml")]
    config: Option<PathBuf>,
    /// The bus's baud rate (9600 … 12000000, 1.5M, 187.5k, …)
    /// [default: the bus file's, else 19200].
    #[arg(long, value_name = "B")]
    baud: Option<Baud>,
    /// Connection monitoring interval the client chooses in ms: the
    /// server aborts the connection when nothing comes for this long;
    /// Idle keeps it open at half of it. 0: no monitoring [default: 2000
    /// at 1.5 Mbit/s and above, 4000 at 500k, 8000 below].
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(0..=655_350))]
    monitoring: Option<u64>,
    /// Give up after this many seconds (joining the ring included).
    #[arg(long, default_value_t = 20.0, value_name = "SECS")]
    timeout: f64,
    /// Extra milliseconds on the slot time for the transport's latency
    /// (default: 5 on a pty, 20 on a serial adapter).
    #[arg(long, value_name = "MS")]
    latency: Option<f64>,
    #[command(flatten)]
    rts: RtsArg,
    /// Print one JSON object (after one per Information-Report the
    /// server sent during the run).
    #[arg(long, global = true)]
    json: bool,
    #[command(subcommand)]
    op: Op,
}

/// The service.
#[derive(clap::Subcommand)]
enum Op {
    /// Vendor, model and revision of the server (Identify).
    Identify,
    /// The server's logical and physical status in words (Status).
    Status,
    /// The object dictionary as a table: index, object code, data type,
    /// length, access, name (Get-OD of the header, then of every object
    /// from index 1 on).
    GetOd {
        /// Short form: without the names.
        #[arg(long)]
        short: bool,
    },
    /// An object's value in hex, decoded by its description where the
    /// data type is a standard one (Get-OD of the object, then Read).
    Read {
        /// Object index.
        index: u16,
        /// One element of an array or record (1-based) instead of the
        /// whole object.
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=255))]
        subindex: Option<u8>,
    },
    /// Write a value (hex, e.g. `00 20 00` or `002000`) to an object.
    Write {
        /// Object index.
        index: u16,
        /// The value, hex.
        #[arg(value_name = "HEX", required = true)]
        data: Vec<String>,
        /// Write one element of an array or record (1-based); the
        /// others stay.
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=255))]
        subindex: Option<u8>,
    },
}

impl Op {
    fn name(&self) -> &'static str {
        match self {
            Op::Identify => "identify",
            Op::Status => "status",
            Op::GetOd { .. } => "get-od",
            Op::Read { .. } => "read",
            Op::Write { .. } => "write",
        }
    }

    fn requests(&self) -> Result<Vec<Request>> {
        Ok(match self {
            Op::Identify => vec![Request::Identify],
            Op::Status => vec![Request::Status],
            Op::GetOd { short } => vec![
                Request::GetOd(GetOdRequest {
                    long_form: false,
                    from_index: false,
                    index: 0,
                }),
                Request::GetOd(GetOdRequest {
                    long_form: !short,
                    from_index: true,
                    index: 1,
                }),
            ],
            Op::Read { index, subindex } => vec![
                Request::GetOd(GetOdRequest {
                    long_form: true,
                    from_index: false,
                    index: *index,
                }),
                Request::Read {
                    index: *index,
                    subindex: *subindex,
                },
            ],
            Op::Write {
                index,
                data,
                subindex,
            } => {
                let data = profibus_fdl::wire::parse_hex(&data.join(" "))?;
                if data.is_empty() {
                    bail!("write: no bytes to write");
                }
                // Type, invoke ID, service, index, subindex.
                let room = profibus_dp::fms::pdu::MAX_PDU_LEN - 6;
                if data.len() > room {
                    bail!(
                        "write: {} bytes do not fit one FMS PDU (at most {room})",
                        data.len()
                    );
                }
                vec![Request::Write {
                    index: *index,
                    subindex: *subindex,
                    data,
                }]
            }
        })
    }
}

pub fn run(args: Args) -> Result<()> {
    let requests = args.op.requests()?;
    let bus = match &args.config {
        Some(path) => Some(ProfiledBus::load(path)?.file),
        None => None,
    };
    let addr = args.addr.unwrap_or(1);
    if addr == args.station {
        bail!("--addr {addr} is the server's address: the FMS client needs its own");
    }
    if let Some(b) = bus.as_ref().filter(|b| b.master.address == addr) {
        bail!(
            "--addr {addr} is the address of the bus file's master in {}: \
             the FMS client needs its own (e.g. --addr {})",
            b.path.display(),
            (0..=125u8)
                .find(|a| *a != addr && *a != args.station && *a != b.master.address)
                .unwrap_or(0)
        );
    }
    let params = match (args.baud, &bus) {
        (Some(b), _) => BusParams::defaults(b),
        (None, Some(bus)) => bus.master.params,
        (None, None) => BusParams::defaults(Baud::B19200),
    };
    let monitoring = match args.monitoring {
        Some(0) => None,
        Some(ms) => Some(Duration::from_millis(ms)),
        None => Some(Class2Config::for_baud(params.baud).send_timeout),
    };
    let limit = Duration::from_secs_f64(args.timeout.max(0.0));
    let path = args.port.as_str();
    let rt = common::runtime()?;
    let done = rt.block_on(async {
        let mut port = args.rts.open(path, params.baud)?;
        let mut acfg = ActiveConfig::new(addr, params);
        common::allow_for_port(&mut acfg, args.latency, &port)?;
        let master = FmsMaster::new(args.station, args.lsap, monitoring);
        profibus_io::fms::run(
            &mut port,
            acfg,
            master,
            FmsRun::new(requests),
            limit,
            common::shutdown(),
        )
        .await
        .with_context(|| format!("on {path}"))
    })?;
    if done.stop == profibus_io::driver::Stop::Shutdown {
        bail!("interrupted");
    }
    let n = args.station;
    let run = done.run;
    // What the server published while the run waited: a line each,
    // before the service's result.
    for r in &run.reports {
        if args.json {
            let mut o = Map::new();
            o.insert("station".into(), n.into());
            o.insert("lsap".into(), args.lsap.into());
            o.insert("service".into(), "information_report".into());
            o.insert("index".into(), r.index.into());
            o.insert("data".into(), Hex(&r.data).to_string().into());
            crate::out::outln!("{}", common::json_line(&o))?;
        } else {
            crate::out::outln!("station {n}: {r}")?;
        }
    }
    if !done.had_token {
        return args.fail(format!(
            "master {addr} was not taken into the token ring within {:.1} s \
             (check --baud and that the ring has room for address {addr})",
            limit.as_secs_f64()
        ));
    }
    if let Some(e) = &run.error {
        let hint = match e {
            FmsRunError::NotServer { .. } => {
                " (is FMS on? a BK3000 serves it only in DP/FMS mixed or FMS-only mode: \
                 table 0 register 16, --device-opt fms=mixed when emulated)"
            }
            _ => "",
        };
        return args.fail(format!("station {n}: {e}{hint}"));
    }
    if !run.is_done() {
        return args.fail(format!(
            "station {n}: no end within {:.1} s",
            limit.as_secs_f64()
        ));
    }
    let results = run.results;
    match &args.op {
        Op::Identify => match result(&results, 0)? {
            Ok(Response::Identify(i)) => args.print(
                json!({"vendor": i.vendor, "model": i.model, "revision": i.revision}),
                format!(
                    "vendor {}, model {}, revision {}",
                    i.vendor, i.model, i.revision
                ),
            ),
            other => args.service_failed("Identify", other),
        },
        Op::Status => match result(&results, 0)? {
            Ok(Response::Status(s)) => args.print(
                json!({
                    "logical_status": s.logical,
                    "logical": s.logical_text(),
                    "physical_status": s.physical,
                    "physical": s.physical_text(),
                    "local_detail": Hex(&s.local_detail).to_string(),
                }),
                format!(
                    "logical status: {} (0x{:02X}); physical status: {} (0x{:02X}); \
                     local detail {}",
                    s.logical_text(),
                    s.logical,
                    s.physical_text(),
                    s.physical,
                    Hex(&s.local_detail)
                ),
            ),
            other => args.service_failed("Status", other),
        },
        Op::GetOd { .. } => {
            let header = match result(&results, 0)? {
                Ok(Response::GetOd { descriptions, .. }) => {
                    descriptions.first().and_then(|d| OdHeader::parse(d).ok())
                }
                _ => None,
            };
            match result(&results, 1)? {
                Ok(Response::GetOd {
                    descriptions,
                    more_follows,
                }) => args.print_od(header, descriptions, *more_follows),
                other => args.service_failed("Get-OD", other),
            }
        }
        Op::Read { index, subindex } => {
            let desc = match result(&results, 0)? {
                Ok(Response::GetOd { descriptions, .. }) => descriptions
                    .first()
                    .and_then(|d| Description::parse(d).ok())
                    .filter(|d| d.index == *index),
                _ => None,
            };
            match result(&results, 1)? {
                Ok(Response::Read(data)) => args.print_read(*index, *subindex, desc.as_ref(), data),
                other => args.service_failed(&format!("Read {}", at(*index, *subindex)), other),
            }
        }
        Op::Write {
            index,
            data,
            subindex,
        } => match result(&results, 0)? {
            Ok(Response::Write) => {
                let data = profibus_fdl::wire::parse_hex(&data.join(" "))?;
                let mut fields = json!({"index": index, "data": Hex(&data).to_string()});
                if let Some(s) = subindex {
                    fields["subindex"] = (*s).into();
                }
                args.print(
                    fields,
                    format!("{}: ok (wrote {})", at(*index, *subindex), Hex(&data)),
                )
            }
            other => args.service_failed(&format!("Write {}", at(*index, *subindex)), other),
        },
    }
}

type Confirmation = std::result::Result<Response, ServiceError>;

/// `index 2041`, `index 2041 subindex 3`.
fn at(index: u16, subindex: Option<u8>) -> String {
    match subindex {
        Some(s) => format!("index {index} subindex {s}"),
        None => format!("index {index}"),
    }
}

/// The confirmation of the `i`-th request.
fn result(results: &[(Request, Confirmation)], i: usize) -> Result<&Confirmation> {
    results
        .get(i)
        .map(|(_, r)| r)
        .context("the run ended without the service's confirmation")
}

/// A type index's name: the OD's own type descriptions, else the
/// standard numbering.
fn type_name(types: &HashMap<u16, String>, index: u16) -> String {
    types
        .get(&index)
        .cloned()
        .or_else(|| od::standard_type(index).map(str::to_string))
        .unwrap_or_else(|| format!("type {index}"))
}

impl Args {
    /// The object every JSON line starts with.
    fn head(&self, ok: bool) -> Map<String, Value> {
        let mut o = Map::new();
        o.insert("station".into(), self.station.into());
        o.insert("lsap".into(), self.lsap.into());
        o.insert("service".into(), self.op.name().into());
        o.insert("ok".into(), ok.into());
        o
    }

    /// A success: the fields in JSON, else `text` after the station.
    fn print(&self, fields: Value, text: String) -> Result<()> {
        if self.json {
            let mut o = self.head(true);
            if let Value::Object(f) = fields {
                o.extend(f);
            }
            crate::out::outln!("{}", common::json_line(&o))?;
        } else {
            crate::out::outln!("station {}: {text}", self.station)?;
        }
        Ok(())
    }

    /// A failure: as JSON with `--json`, and the error (exit 1).
    fn fail(&self, why: String) -> Result<()> {
        if self.json {
            let mut o = self.head(false);
            o.insert("error".into(), why.clone().into());
            crate::out::outln!("{}", common::json_line(&o))?;
        }
        bail!("{why}")
    }

    /// The server's negative answer (or an answer of another service).
    fn service_failed(&self, what: &str, r: &Confirmation) -> Result<()> {
        let why = match r {
            Err(e) => format!("station {}: {what}: {}", self.station, e.describe()),
            Ok(other) => format!(
                "station {}: {what}: the server answered with {}",
                self.station,
                other.service().name()
            ),
        };
        if self.json {
            let mut o = self.head(false);
            o.insert("error".into(), why.clone().into());
            if let Err(e) = r {
                o.insert("error_class".into(), e.class.into());
                o.insert("error_code".into(), e.code.into());
                o.insert("additional_code".into(), e.additional.into());
            }
            crate::out::outln!("{}", common::json_line(&o))?;
        }
        bail!("{why}")
    }

    fn print_read(
        &self,
        index: u16,
        subindex: Option<u8>,
        desc: Option<&Description>,
        data: &[u8],
    ) -> Result<()> {
        let ty = desc.map(|d| type_name(&HashMap::new(), d.data_type));
        let value = desc.zip(ty.as_deref()).and_then(|(d, t)| match subindex {
            Some(_) => d.decode_element(t, data),
            None => d.decode_value(t, data),
        });
        let mut fields = json!({
            "index": index,
            "length": data.len(),
            "data": Hex(data).to_string(),
        });
        if let Some(s) = subindex {
            fields["subindex"] = s.into();
        }
        let mut what = Vec::new();
        if let Some(d) = desc {
            if let Some(n) = &d.name {
                fields["name"] = n.clone().into();
                what.push(n.clone());
            }
            let code = d
                .object_code()
                .map_or_else(|| format!("object code {}", d.code), |c| c.name().into());
            let ty = ty.clone().unwrap_or_default();
            fields["object_code"] = code.clone().into();
            fields["type"] = ty.clone().into();
            what.push(if d.object_code() == Some(ObjectCode::Array) {
                format!("Array of {ty}")
            } else {
                format!("{code} {ty}")
            });
        }
        if let Some(v) = &value {
            fields["value"] = serde_json::from_str(v).unwrap_or_else(|_| v.clone().into());
        }
        let mut text = at(index, subindex);
        if !what.is_empty() {
            text.push_str(&format!(" ({})", what.join(", ")));
        }
        text.push_str(&format!(": {}", Hex(data)));
        if let Some(v) = value {
            text.push_str(&format!(" = {v}"));
        }
        self.print(fields, text)
    }

    fn print_od(
        &self,
        header: Option<OdHeader>,
        descriptions: &[Vec<u8>],
        more_follows: bool,
    ) -> Result<()> {
        let mut objects = Vec::new();
        let mut bad = Vec::new();
        for d in descriptions {
            match Description::parse(d) {
                Ok(d) => objects.push(d),
                Err(e) => bad.push(format!("{e}: {}", Hex(d))),
            }
        }
        let types: HashMap<u16, String> = objects
            .iter()
            .filter(|d| {
                matches!(
                    d.object_code(),
                    Some(ObjectCode::DataType | ObjectCode::DataTypeStructure)
                )
            })
            .filter_map(|d| Some((d.index, d.name.clone()?)))
            .collect();
        let code = |d: &Description| {
            d.object_code()
                .map_or_else(|| format!("object code {}", d.code), |c| c.name().into())
        };
        let access = |d: &Description| d.access_rights().map_or("-", |a| a.short());
        if self.json {
            let list: Vec<Value> = objects
                .iter()
                .map(|d| {
                    json!({
                        "index": d.index,
                        "object_code": code(d),
                        "data_type": d.data_type,
                        "type": type_name(&types, d.data_type),
                        "length": d.length,
                        "access": access(d),
                        "name": d.name,
                    })
                })
                .collect();
            let mut o = self.head(true);
            o.insert(
                "header".into(),
                header.map_or(Value::Null, |h| {
                    json!({
                        "objects": h.objects,
                        "first_type": h.first_type,
                        "last_type": h.last_type,
                        "first_object": h.first_object,
                    })
                }),
            );
            o.insert("objects".into(), list.into());
            o.insert("more_follows".into(), more_follows.into());
            if !bad.is_empty() {
                o.insert("undecoded".into(), bad.into());
            }
            crate::out::outln!("{}", common::json_line(&o))?;
            return Ok(());
        }
        match header {
            Some(h) => crate::out::outln!(
                "station {}: object dictionary: {} objects, types {}..{}, objects from index {}",
                self.station,
                h.objects,
                h.first_type,
                h.last_type,
                h.first_object
            )?,
            None => crate::out::outln!("station {}: object dictionary", self.station)?,
        }
        crate::out::outln!(
            "{:>6}  {:<20}  {:<30}  {:>6}  {:<6}  NAME",
            "INDEX",
            "OBJECT",
            "TYPE",
            "LENGTH",
            "ACCESS"
        )?;
        for d in &objects {
            crate::out::outln!(
                "{:>6}  {:<20}  {:<30}  {:>6}  {:<6}  {}",
                d.index,
                code(d),
                type_name(&types, d.data_type),
                d.length,
                access(d),
                d.name.as_deref().unwrap_or("")
            )?;
        }
        for b in bad {
            crate::out::outln!("  undecoded description: {b}")?;
        }
        if more_follows {
            crate::out::outln!("  (more objects follow: the server stopped paging)")?;
        }
        Ok(())
    }
}
