//! `dpctl demo`: a whole virtual plant in one process, no hardware and no
//! files: an in-process simulated PROFIBUS line at 1.5 Mbit/s (paced on
//! virtual time that follows the wall clock), a DP master and emulated
//! slaves, shown live.

use crate::common;
use crate::view::{drain_events, hex, Line, SlaveInfo, View};
use anyhow::{Context, Result};
use profibus_devices::channels::ChannelMap;
use profibus_devices::generic::{GenericDevice, InputPattern};
use profibus_devices::gsd_files;
use profibus_devices::jx2::{self, script::Interpreter};
use profibus_devices::pkw::{self, client::PkwClient};
use profibus_devices::DeviceOptions;
use profibus_dp::gsd::Gsd;
use profibus_dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams, SlaveState};
use profibus_dp::slave::{Device, DpSlave};
use profibus_fdl::medium::MediumConfig;
use profibus_fdl::pcap::PcapWriter;
use profibus_fdl::sim::SimBus;
use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
use profibus_fdl::station::passive::PassiveStation;
use profibus_fdl::tap::{Tap, TapEvent};
use profibus_fdl::{Baud, BusParams, Instant};
use std::cell::RefCell;
use std::io::IsTerminal;
use std::rc::Rc;
use std::time::Duration;

/// Run a virtual plant: a DP master and emulated slaves on an in-process
/// simulated bus, with live process data. No hardware, no files.
#[derive(clap::Args)]
pub struct Args {
    /// Stop after this many poll cycles of the master.
    #[arg(long, value_name = "N")]
    cycles: Option<u64>,
    /// Run on virtual time as fast as the computer can, instead of in
    /// step with the clock.
    #[arg(long)]
    fast: bool,
    /// Print JSON lines instead of text.
    #[arg(long)]
    json: bool,
    /// Record every telegram on the simulated line into a pcap file
    /// (link type 257, readable by Wireshark/tshark).
    #[arg(long, value_name = "FILE")]
    pcap: Option<std::path::PathBuf>,
    /// Milliseconds between status prints (JSON or non-terminal output).
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    interval: u64,
}

type Slave = PassiveStation<DpSlave<Box<dyn Device + Send>>>;
type Master = ActiveStation<DpMaster>;

/// A slave of the demo plant.
struct PlantSlave {
    address: u8,
    name: String,
    gsd: Gsd,
    modules: Vec<String>,
    device: Box<dyn Device + Send>,
    /// Named channels for the view.
    channels: Option<ChannelMap>,
}

/// A plant slave from the profile registry: `name` with `options`
/// (`KEY=VALUE`, as `dpctl slave --device-opt` takes them), as a bus file
/// with `device = "NAME"` would configure it.
fn profiled(address: u8, label: &str, name: &str, options: &[&str]) -> Result<PlantSlave> {
    let mut o = DeviceOptions::new();
    for kv in options {
        o.set_pair(kv)?;
    }
    let p = profibus_devices::profile(name)?.configure(&o, Some(address))?;
    Ok(PlantSlave {
        address,
        name: label.into(),
        gsd: p.gsd().clone(),
        modules: p.modules(),
        device: p.device(None)?,
        channels: Some(p.channels(&p.chk_cfg()?)?),
    })
}

fn generic(
    gsd: &Gsd,
    address: u8,
    name: &str,
    modules: &[&'static str],
    inputs: InputPattern,
) -> Result<PlantSlave> {
    let dev = GenericDevice::from_gsd(gsd, modules)
        .with_context(|| format!("building {name}"))?
        .with_inputs(inputs);
    Ok(PlantSlave {
        address,
        name: name.into(),
        gsd: gsd.clone(),
        modules: modules.iter().map(|m| m.to_string()).collect(),
        device: Box::new(dev),
        channels: None,
    })
}

/// The plant's slaves.
fn plant(rfid: crate::rfid::demo::Parts) -> Result<Vec<PlantSlave>> {
    let gen = gsd_files::parse(gsd_files::DPCTL_GEN)?;
    Ok(vec![
        generic(
            &gen,
            3,
            "echo (generic)",
            &["2 words in/out", "8 bytes in consistent"],
            InputPattern::Echo,
        )?,
        generic(
            &gen,
            4,
            "counter (generic)",
            &["2 words in/out"],
            InputPattern::Counter,
        )?,
        // Baumüller BM4-O-PRO-01 with the manual's example variables and
        // its generated GSD; PKW module first.
        profiled(
            6,
            "BM4-O-PRO-01 (bm4)",
            "bm4",
            &[
                "example=true",
                r#"variables=["ud_MyReadVar1", "u_MyWriteVar2"]"#,
            ],
        )?,
        // Omega Drive-Line II: PKW, status / control, 2 values each way.
        profiled(25, "Omega Drive-Line II (omega)", "omega", &[])?,
        // Beckhoff BK3000 with a mixed terminal strip, from its rotary
        // switches (station 9).
        profiled(
            BK3000_ADDRESS,
            "BK3000 bus coupler (bk3000)",
            "bk3000",
            &[&format!("terminals={BK3000_STRIP}"), "switch-ones=9"],
        )?,
        PlantSlave {
            address: JX2_ADDRESS,
            name: "JX2-PROFI1 (jx2)".into(),
            gsd: gsd_files::parse(jx2::GSD)?,
            modules: vec!["INPUT : 4 words".into(), "OUTPUT : 4 words".into()],
            device: Box::new(jx2_plc()?),
            channels: None,
        },
        PlantSlave {
            address: RFID_ADDRESS,
            name: "RFID reader ARE I2 (rfid)".into(),
            gsd: rfid.gsd,
            modules: rfid.modules,
            device: rfid.device,
            channels: Some(rfid.channels),
        },
    ])
}

/// Station address of the demo's RFID reader.
const RFID_ADDRESS: u8 = 12;

/// Station address of the demo's BK3000 (its rotary switches).
const BK3000_ADDRESS: u8 = 9;

/// The BK3000's terminal strip: digital in and out, analog in and out.
const BK3000_STRIP: &str = "KL1104,KL2134,KL3102,KL4002,KL9010";

/// Station address the demo's JX2-PROFI1 gets from its PLC.
const JX2_ADDRESS: u8 = 7;

/// How the PLC configured its JX2-PROFI1 (module 2) before the plant
/// started: 4 input and 4 output words, station 7 (example 1 of the
/// manual with smaller counts).
const JX2_INIT: &str = "write 12102 4\nwrite 12103 4\nwrite 12107 7\n";

/// The demo PLC's program, in the register line protocol.
const JX2_PROGRAM: &str = "\
; in data exchange: input word 0 counts, input word 1 echoes output word 0,
; a data-record read is answered with the area as it is
label loop
wait-bit 12100 3 set 60s
calc 12300 r12300 + 1
copy 1 12400 12301
if-bit 12100 4 set write 12101 11
delay 50ms
goto loop
";

/// The demo's JX2-PROFI1: configured and initialised, its program
/// running.
fn jx2_plc() -> Result<jx2::ScriptedJx2> {
    let mut plc = jx2::Plc::new(2)?;
    let mut init = Interpreter::script(JX2_INIT)?;
    init.run(&mut plc, Instant::ZERO);
    // The PLC was switched on before the plant: initialisation is over.
    plc.module.settle(Instant::ZERO + jx2::INIT_TIME);
    anyhow::ensure!(
        plc.module.station_address() == Some(JX2_ADDRESS),
        "the demo PLC did not configure its JX2-PROFI1"
    );
    Ok(jx2::ScriptedJx2::new(
        plc,
        Interpreter::script(JX2_PROGRAM)?,
        None,
    ))
}

fn master_config(params: BusParams, slaves: &[PlantSlave]) -> Result<MasterConfig> {
    let mut out = Vec::new();
    for s in slaves {
        let sel = s.gsd.select(&s.modules)?;
        let mut p = SlaveParams::new(s.address, s.gsd.ident_number, s.gsd.chk_cfg(&sel)?);
        p.name = s.name.clone();
        p.user_prm_data = s.gsd.user_prm_data(&sel, &[])?;
        p.dpv1 = s.gsd.dpv1_slave;
        p.watchdog = Some(Duration::from_millis(200));
        out.push(p);
    }
    Ok(MasterConfig {
        address: 1,
        params,
        slaves: out,
        options: MasterOptions::default(),
    })
}

pub fn run(args: Args) -> Result<()> {
    common::runtime()?.block_on(demo(args))
}

async fn demo(args: Args) -> Result<()> {
    let baud = Baud::B1500000;
    let params = BusParams::defaults(baud);
    // The RFID reader with a tag that comes and goes, and the PLC's
    // commands to it.
    let (mut reader, parts) = crate::rfid::demo::DemoReader::new(RFID_ADDRESS)?;
    let slaves = plant(parts)?;
    let cfg = master_config(params, &slaves)?;
    let info: Vec<SlaveInfo> = slaves
        .iter()
        .map(|s| SlaveInfo {
            address: s.address,
            name: s.name.clone(),
            gsd: Some(s.gsd.clone()),
            channels: s.channels.clone(),
        })
        .collect();

    let mut bus = SimBus::new(MediumConfig::paced(baud));
    let master = bus.add(ActiveStation::new(
        ActiveConfig::new(1, params),
        DpMaster::new(&cfg)?,
    ));
    for s in slaves {
        bus.add(Slave::new(DpSlave::new(s.device, s.address), params));
    }
    let telegrams = Rc::new(RefCell::new(0u64));
    let pcap = match &args.pcap {
        Some(path) => {
            let f = std::fs::File::create(path)
                .with_context(|| format!("cannot create {}", path.display()))?;
            Some(PcapWriter::new(std::io::BufWriter::new(f), Duration::ZERO)?)
        }
        None => None,
    };
    let pcap = Rc::new(RefCell::new(pcap));
    {
        let (count, pcap) = (telegrams.clone(), pcap.clone());
        let mut tap = Tap::new();
        bus.set_tap(Box::new(move |at, _from, bytes| {
            tap.push(at, bytes);
            while let Some(ev) = tap.poll() {
                if let TapEvent::Telegram { at, bytes } = ev {
                    *count.borrow_mut() += 1;
                    if let Some(w) = pcap.borrow_mut().as_mut() {
                        let _ = w.write_telegram(at, &bytes);
                    }
                }
            }
        }));
    }

    let mut view = View::new(
        args.json,
        !args.json && std::io::stdout().is_terminal(),
        Duration::from_millis(args.interval.max(10)),
    );
    let start = tokio::time::Instant::now();
    let shutdown = common::shutdown();
    tokio::pin!(shutdown);
    let step = Duration::from_millis(20);
    let mut ramp: u16 = 0;
    let mut next_output = Instant::ZERO;
    // The parameter channels: a round of PKW jobs on each drive/PLC.
    let mut pkw = [
        DemoPkw::new(6, &profibus_devices::bm4::PKW, &BM4_JOBS),
        DemoPkw::new(25, &profibus_devices::omega::PKW, &OMEGA_JOBS),
    ];
    loop {
        let target = if args.fast {
            bus.now() + step
        } else {
            Instant::from_nanos(start.elapsed().as_nanos() as u64)
        };
        bus.run_until(target);
        let now = bus.now();
        let m = bus.station_mut::<Master>(master).app_mut();
        // Stop before the application changes outputs: the last status
        // then shows the inputs that answer the outputs shown.
        if args.cycles.is_some_and(|n| m.cycle_stats().cycles >= n) {
            break;
        }
        // The "application": a ramp on the echo slave's outputs.
        if now >= next_output {
            next_output = now + Duration::from_millis(100);
            ramp = ramp.wrapping_add(1);
            let r = ramp.to_be_bytes();
            m.set_outputs(3, &[r[0], r[1], !r[0], !r[1]]);
            m.set_outputs(4, &[0, 0, r[0], r[1]]);
            m.set_outputs(JX2_ADDRESS, &[r[0], r[1], 0, 0, 0, 0, 0, 0]);
            // BK3000: a 0..10 V ramp on KL4002 channel 1, a walking bit
            // on the KL2134.
            let v = ((ramp % 100) as u32 * 32767 / 100) as u16;
            let v = v.to_be_bytes();
            m.set_outputs(BK3000_ADDRESS, &[v[0], v[1], 0, 0, 1 << (ramp % 4)]);
        }
        for p in pkw.iter_mut() {
            if let Some(e) = p.step(m, now, ramp) {
                view.event(&e);
            }
        }
        for e in reader.step(m, now, ramp) {
            view.event(&e);
        }
        drain_events(m, &info, &mut view);
        view.status(m, &info, baud, now, false);
        if !args.fast {
            tokio::select! {
                _ = &mut shutdown => break,
                _ = tokio::time::sleep(step) => {}
            }
        } else if common::stop_requested() {
            break;
        }
    }
    let now = bus.now();
    let m = bus.station_mut::<Master>(master).app_mut();
    drain_events(m, &info, &mut view);
    view.status(m, &info, baud, now, true);
    let c = m.cycle_stats();
    let summary = format!(
        "demo: {} cycles in {:.3} s of bus time, cycle min/avg/max {}/{}/{} µs, {} telegrams on the line",
        c.cycles,
        now.as_nanos() as f64 / 1e9,
        c.min_ns / 1000,
        c.avg().as_micros(),
        c.max_ns / 1000,
        telegrams.borrow()
    );
    if args.json {
        let inputs: std::collections::BTreeMap<String, String> = info
            .iter()
            .map(|s| {
                (
                    s.address.to_string(),
                    hex(m.inputs(s.address).unwrap_or(&[])),
                )
            })
            .collect();
        let line = Summary {
            cycles: c.cycles,
            bus_time_s: now,
            telegrams: *telegrams.borrow(),
            inputs,
        };
        println!("{}", common::json_line(&Line::new("summary", line, "")));
    } else {
        println!("{summary}");
    }
    if let Some(mut w) = pcap.borrow_mut().take() {
        w.flush()?;
    }
    Ok(())
}

/// The demo's last line with `--json`.
#[derive(serde::Serialize)]
struct Summary {
    cycles: u64,
    bus_time_s: Instant,
    telegrams: u64,
    inputs: std::collections::BTreeMap<String, String>,
}

/// A PKW job of the demo that ended.
#[derive(serde::Serialize)]
struct PkwDone {
    slave: u8,
    pnu: u16,
    name: &'static str,
    value: Option<u32>,
    error: Option<String>,
}

/// PKW jobs the demo runs in turn: (PNU, command, what it is).
type Job = (u16, fn(u16) -> pkw::Command, &'static str);

/// BM4-O-PRO-01 example variables by parameter number (the 4th identifier
/// byte): di_MyReadVar3 = PNU 4, ud_MyWriteVar1 = PNU 2.
const BM4_JOBS: [Job; 3] = [
    (4, |_| pkw::Command::Read, "di_MyReadVar3"),
    (
        2,
        |r| pkw::Command::WriteDword(0x1234_0000 | r as u32),
        "ud_MyWriteVar1",
    ),
    (2, |_| pkw::Command::Read, "ud_MyWriteVar1"),
];

/// Omega V-controller parameter P003 and the DINT array at PNU 1000.
const OMEGA_JOBS: [Job; 3] = [
    (3, |_| pkw::Command::Read, "P003"),
    (
        1000,
        |r| pkw::Command::WriteDword(r as u32 * 1000),
        "DINT[1000]",
    ),
    (1000, |_| pkw::Command::Read, "DINT[1000]"),
];

/// Runs a round of PKW jobs on one slave through the master's process
/// images, as a PLC program would.
struct DemoPkw {
    address: u8,
    client: PkwClient,
    jobs: &'static [Job],
    next: usize,
    due: Instant,
}

impl DemoPkw {
    fn new(address: u8, dialect: &'static pkw::Dialect, jobs: &'static [Job]) -> DemoPkw {
        DemoPkw {
            address,
            client: PkwClient::new(dialect, Duration::from_millis(500)),
            jobs,
            next: 0,
            due: Instant::ZERO,
        }
    }

    fn step(&mut self, m: &mut DpMaster, now: Instant, ramp: u16) -> Option<Line<PkwDone>> {
        let h = m.handle(self.address)?;
        if m.slave(h).state != SlaveState::DataExchange {
            return None;
        }
        let done = self.client.drive(now, m, h);
        let mut report = None;
        if let Some(r) = done {
            let (pnu, _, name) = self.jobs[(self.next + self.jobs.len() - 1) % self.jobs.len()];
            let text = match &r {
                Ok(a) => format!(
                    "pkw slave {}: {name} (PNU {pnu}) → {} (0x{:X})  [request {} / response {}]",
                    self.address,
                    a.reply.value(),
                    a.reply.value(),
                    a.request,
                    a.response
                ),
                Err(e) => format!("pkw slave {}: {name} (PNU {pnu}) failed: {e}", self.address),
            };
            let done = PkwDone {
                slave: self.address,
                pnu,
                name,
                value: r.as_ref().ok().map(|a| a.reply.value()),
                error: r.as_ref().err().map(|e| e.to_string()),
            };
            report = Some(Line::new("pkw", done, text));
            self.due = now + Duration::from_millis(300);
        }
        if self.client.is_idle() && now >= self.due {
            let (pnu, cmd, _) = self.jobs[self.next];
            self.next = (self.next + 1) % self.jobs.len();
            let _ = self.client.start(now, pnu, cmd(ramp));
        }
        report
    }
}
