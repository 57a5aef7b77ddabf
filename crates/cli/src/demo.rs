//! `dpctl demo`: a whole virtual plant in one process, no hardware and no
//! files: an in-process simulated PROFIBUS line at 1.5 Mbit/s (paced on
//! virtual time that follows the wall clock), a DP master and emulated
//! slaves, shown live.

use crate::common;
use crate::view::{bus_view, drain_events, Line, SlaveInfo, View};
use anyhow::{Context, Result};
use profibus_fdl::capture::pcap::PcapWriter;
use profibus_fdl::Instant;
use profibus_plant::demo::{DemoPlant, BAUD};
use profibus_plant::PlantSlave;
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
    /// Print status lines even on a terminal. Without it a terminal shows
    /// the plant as a refreshing table: `q` quit, `p` pause, up/down
    /// select a slave, Enter its details, `w` write its outputs.
    #[arg(long, conflicts_with = "json")]
    plain: bool,
    /// Record every telegram on the simulated line into a pcap file
    /// (link type 257, readable by Wireshark/tshark).
    #[arg(long, value_name = "FILE")]
    pcap: Option<std::path::PathBuf>,
    /// Milliseconds between status prints (JSON or non-terminal output).
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    interval: u64,
}

/// The demo's RFID reader at this address.
const RFID_ADDRESS: u8 = 12;

pub fn run(args: Args) -> Result<()> {
    common::runtime()?.block_on(demo(args))
}

async fn demo(args: Args) -> Result<()> {
    // The RFID reader with a tag that comes and goes, and the PLC's
    // commands to it.
    let (mut reader, parts) = profibus_devices::rfid::demo::DemoReader::new(RFID_ADDRESS)?;
    let rfid = PlantSlave {
        address: RFID_ADDRESS,
        name: "RFID reader ARE I2 (rfid)".into(),
        gsd: Some(parts.gsd),
        modules: parts.modules,
        channels: Some(parts.channels),
        profile: Some("rfid"),
    };
    let mut plant = DemoPlant::new(vec![(rfid, parts.device)])?;
    let info: Vec<SlaveInfo> = (plant.slaves().iter())
        .map(|s| SlaveInfo {
            layout: s.layout(),
            channels: s.channels.clone(),
        })
        .collect();
    let pcap = (args.pcap.as_deref())
        .map(|p| {
            PcapWriter::create(p, Duration::ZERO)
                .with_context(|| format!("cannot create {}", p.display()))
        })
        .transpose()?;
    let pcap = Rc::new(RefCell::new(pcap));
    let recorder = pcap.clone();
    plant.on_telegram(move |at, bytes| {
        if let Some(w) = recorder.borrow_mut().as_mut() {
            let _ = w.write_telegram(at, bytes);
        }
    });

    let mut view = View::new(args.json, Duration::from_millis(args.interval.max(10)));
    if !args.json && !args.plain && std::io::stdout().is_terminal() {
        view.open_terminal(bus_view("dpctl demo", BAUD, &info))?;
    }
    let start = tokio::time::Instant::now();
    let shutdown = common::shutdown();
    tokio::pin!(shutdown);
    loop {
        let wall = Instant::from_nanos(start.elapsed().as_nanos() as u64);
        let behind = plant.advance((!args.fast).then_some(wall));
        // Stop before the application changes outputs: the last status
        // then shows the inputs that answer the outputs shown.
        if args
            .cycles
            .is_some_and(|n| plant.master().cycle_stats().cycles >= n)
        {
            break;
        }
        for e in plant.step(|a| view.by_hand(a)) {
            view.event(&Line::new("pkw", &e, e.to_string()));
        }
        let (now, ramp) = (plant.now(), plant.ramp());
        let m = plant.master();
        for e in reader.step(m, now, ramp) {
            view.event(&e);
        }
        drain_events(m, &info, &mut view);
        view.status(m, &info, BAUD, now, false);
        if view.tick(m, now).is_break() {
            break;
        }
        if !args.fast {
            let pause = if behind {
                Duration::ZERO
            } else {
                profibus_plant::demo::STEP
            };
            tokio::select! {
                _ = &mut shutdown => break,
                _ = tokio::time::sleep(pause) => {}
            }
        } else if common::stop_requested() {
            break;
        }
    }
    view.close();
    let now = plant.now();
    let m = plant.master();
    drain_events(m, &info, &mut view);
    view.status(m, &info, BAUD, now, true);
    let summary = plant.summary();
    if args.json {
        crate::out::outln!("{}", common::json_line(&Line::new("summary", &summary, "")))?;
    } else {
        crate::out::outln!("{summary}")?;
    }
    if let Some(mut w) = pcap.borrow_mut().take() {
        w.flush()?;
    }
    Ok(())
}
