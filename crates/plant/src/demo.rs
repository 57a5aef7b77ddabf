//! The demo plant of `dpctl demo`: a DP master (station 1) and emulated
//! slaves of every profile on the simulated bus ([`Plant`]) at 1.5 Mbit/s,
//! with the PLC program that moves them.
//!
//! Sans-IO: the plant runs on virtual time only when told to
//! ([`DemoPlant::advance`]); [`DemoPlant::step`] runs one pass of the PLC program
//! (ramps and a speed profile on the outputs, the BM4's own PLC counting a
//! variable, rounds of PKW jobs on the BM4 and the Omega drive) and
//! returns the PKW jobs that ended. A program showing the plant reads the
//! master through [`DemoPlant::master`] and the slaves through
//! [`DemoPlant::slaves`].
//!
//! The slaves: a generic echo (3) and counter (4) device from
//! `DPCTL-GEN.gsd`, a Baumüller BM4-O-PRO-01 with the manual's example
//! variables (6), an Omega Drive-Line II (25), a Beckhoff BK3000 with a
//! mixed terminal strip (9), a JX2-PROFI1 whose PLC configured it and runs
//! a program (7), and whatever else the caller adds ([`DemoPlant::new`]).

use crate::{Plant, PlantError, PlantSlave};
use profibus_devices::channels::{ChannelMap, Value};
use profibus_devices::generic::InputPattern;
use profibus_devices::jx2::{self, script::Interpreter};
use profibus_devices::pkw::{self, client::PkwClient};
use profibus_devices::{gsd_files, BoxedDevice, ControlInbox};
use profibus_dp::config::gsd::GsdError;
use profibus_dp::master::{DpMaster, SlaveState};
use profibus_fdl::line::tap::{Tap, TapEvent};
use profibus_fdl::{Baud, Instant};
use std::cell::Cell;
use std::rc::Rc;
use std::time::Duration;

/// The plant's line rate.
pub const BAUD: Baud = Baud::B1500000;

/// Station address of the plant's master.
pub const MASTER_ADDRESS: u8 = 1;

/// Longest stretch of bus time one [`DemoPlant::advance`] runs.
pub const STEP: Duration = Duration::from_millis(20);

/// Station address of the BM4-O-PRO-01.
pub const BM4_ADDRESS: u8 = 6;

/// Station address of the Omega Drive-Line II.
pub const OMEGA_ADDRESS: u8 = 25;

/// Station address of the BK3000 (its rotary switches).
pub const BK3000_ADDRESS: u8 = 9;

/// Station address the JX2-PROFI1 gets from its PLC.
pub const JX2_ADDRESS: u8 = 7;

/// The BK3000's terminal strip: digital in and out, analog in and out.
const BK3000_STRIP: &str = "KL1104,KL2134,KL3102,KL4002,KL9010";

/// How the PLC configured its JX2-PROFI1 (module 2) before the plant
/// started: 4 input and 4 output words, station 7 (example 1 of the
/// manual with smaller counts).
const JX2_INIT: &str = "write 12102 4\nwrite 12103 4\nwrite 12107 7\n";

/// The JX2's PLC program, in the register line protocol.
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

/// Why the plant cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// The plant's builder refused a slave or the master.
    #[error(transparent)]
    Plant(#[from] PlantError),
    /// A shipped GSD file does not parse.
    #[error(transparent)]
    Gsd(#[from] GsdError),
    /// The JX2 PLC's script does not parse.
    #[error(transparent)]
    Script(#[from] jx2::script::ParseError),
    /// The JX2 module number is invalid.
    #[error(transparent)]
    ModuleNumber(#[from] jx2::BadModuleNumber),
    /// The JX2 PLC did not configure its module.
    #[error("the demo PLC did not configure its JX2-PROFI1")]
    Jx2NotConfigured,
}

/// The whole plant: see the module docs.
pub struct DemoPlant {
    plant: Plant,
    telegrams: Rc<Cell<u64>>,
    /// Commands for the BM4's own PLC program.
    bm4: ControlInbox,
    /// The channels the PLC program writes by name: the Omega's and the
    /// BM4's.
    channels: [Option<ChannelMap>; 2],
    ramp: u16,
    next_output: Instant,
    pkw: [DemoPkw; 2],
}

impl DemoPlant {
    /// The plant with its own slaves, then `extra` (a slave and its
    /// device each), on a line paced at [`BAUD`].
    pub fn new(extra: Vec<(PlantSlave, BoxedDevice)>) -> Result<DemoPlant, DemoError> {
        let bm4 = ControlInbox::new();
        let mut builder = own_slaves(bm4.clone())?;
        for (slave, device) in extra {
            builder = builder.slave(slave, device);
        }
        let plant = builder.build()?;
        let channels = [OMEGA_ADDRESS, BM4_ADDRESS].map(|a| {
            let s = plant.slaves().iter().find(|s| s.address == a)?;
            s.channels.clone()
        });
        let mut plant = DemoPlant {
            plant,
            channels,
            telegrams: Rc::new(Cell::new(0)),
            bm4,
            ramp: 0,
            next_output: Instant::ZERO,
            pkw: [
                DemoPkw::new(BM4_ADDRESS, &profibus_devices::bm4::PKW, &BM4_JOBS),
                DemoPkw::new(OMEGA_ADDRESS, &profibus_devices::omega::PKW, &OMEGA_JOBS),
            ],
        };
        plant.on_telegram(|_, _| {});
        Ok(plant)
    }

    /// Hand every valid telegram on the line (with its time) to `f`, e.g.
    /// a pcap writer; [`DemoPlant::telegrams`] counts them either way.
    pub fn on_telegram(&mut self, mut f: impl FnMut(Instant, &[u8]) + 'static) {
        let count = self.telegrams.clone();
        let mut tap = Tap::new();
        self.plant.bus().set_tap(Box::new(move |at, _from, bytes| {
            tap.push(at, bytes);
            while let Some(ev) = tap.poll() {
                if let TapEvent::Telegram { at, bytes } = ev {
                    count.set(count.get() + 1);
                    f(at, &bytes);
                }
            }
        }));
    }

    /// The slaves, in bus order.
    pub fn slaves(&self) -> &[PlantSlave] {
        self.plant.slaves()
    }

    /// The master's DP application.
    pub fn master(&mut self) -> &mut DpMaster {
        self.plant.master()
    }

    /// Virtual time of the bus.
    pub fn now(&self) -> Instant {
        self.plant.now()
    }

    /// Valid telegrams seen on the line so far.
    pub fn telegrams(&self) -> u64 {
        self.telegrams.get()
    }

    /// The PLC program's step counter (one step every 100 ms of bus
    /// time); other programs on the plant may follow it.
    pub fn ramp(&self) -> u16 {
        self.ramp
    }

    /// Run the bus up to `wall` (the wall clock since the start, or
    /// `None` to run as fast as possible), at most [`STEP`] at a time:
    /// a machine too slow for the clock falls behind it, but the plant
    /// goes on. Returns whether the bus is behind `wall`.
    pub fn advance(&mut self, wall: Option<Instant>) -> bool {
        let step = self.plant.now() + STEP;
        self.plant.run_until(wall.map_or(step, |w| w.min(step)));
        wall.is_some_and(|w| self.plant.now() < w)
    }

    /// One pass of the PLC program at the bus's time: new outputs every
    /// 100 ms, except for the slaves `by_hand` names (a person writes
    /// theirs), and the PKW jobs. Returns the PKW jobs that ended.
    pub fn step(&mut self, by_hand: impl Fn(u8) -> bool) -> Vec<PkwDone> {
        let now = self.plant.now();
        let m = self.plant.master();
        if now >= self.next_output {
            self.next_output = now + Duration::from_millis(100);
            self.ramp = self.ramp.wrapping_add(1);
            let ramp = self.ramp;
            let r = ramp.to_be_bytes();
            // BK3000: a 0..10 V ramp on KL4002 channel 1, a walking bit
            // on the KL2134.
            let v = (((ramp % 100) as u32 * 32767 / 100) as u16).to_be_bytes();
            for (a, data) in [
                (3, &[r[0], r[1], !r[0], !r[1]][..]),
                (4, &[0, 0, r[0], r[1]]),
                (JX2_ADDRESS, &[r[0], r[1], 0, 0, 0, 0, 0, 0]),
                (BK3000_ADDRESS, &[v[0], v[1], 0, 0, 1 << (ramp % 4)]),
            ] {
                if !by_hand(a) {
                    m.set_outputs(a, data);
                }
            }
            let [omega, bm4] = &self.channels;
            // Omega: a speed profile up to 3000 and back in 20 s; the
            // drive's actual value follows the setpoint.
            let speed = 3000 - (i64::from(ramp % 200) - 100).abs() * 30;
            if !by_hand(OMEGA_ADDRESS) {
                let v = [("setpoint1", Value::Int(speed))];
                write_channels(m, OMEGA_ADDRESS, omega.as_ref(), &v);
            }
            // BM4: the master writes u_MyWriteVar2; the b maXX PLC's own
            // program counts ud_MyReadVar1.
            if !by_hand(BM4_ADDRESS) {
                let v = [("u_MyWriteVar2", Value::Int(i64::from(ramp % 1000)))];
                write_channels(m, BM4_ADDRESS, bm4.as_ref(), &v);
            }
            self.bm4
                .push(format!("set ud_MyReadVar1 {}", u32::from(ramp) * 7));
        }
        let ramp = self.ramp;
        self.pkw
            .iter_mut()
            .filter_map(|p| p.step(m, now, ramp))
            .collect()
    }

    /// The plant's numbers so far.
    pub fn summary(&mut self) -> PlantSummary {
        let now = self.now();
        let telegrams = self.telegrams();
        let addresses: Vec<u8> = self.slaves().iter().map(|s| s.address).collect();
        let m = self.master();
        let c = m.cycle_stats();
        let inputs = addresses
            .iter()
            .map(|&a| {
                let hex = profibus_fdl::wire::Hex(m.inputs(a).unwrap_or(&[])).to_string();
                (a.to_string(), hex)
            })
            .collect();
        PlantSummary {
            cycles: c.cycles,
            bus_time_s: now,
            telegrams,
            inputs,
            cycle_min_us: c.min_ns / 1000,
            cycle_avg_us: c.avg().as_micros() as u64,
            cycle_max_us: c.max_ns / 1000,
        }
    }
}

/// What the plant did: the last line of `dpctl demo`.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct PlantSummary {
    /// Poll cycles of the master.
    pub cycles: u64,
    /// Bus time.
    pub bus_time_s: Instant,
    /// Valid telegrams on the line.
    pub telegrams: u64,
    /// Each slave's input image (hex), by station address.
    pub inputs: std::collections::BTreeMap<String, String>,
    /// Shortest poll cycle (µs).
    #[cfg_attr(feature = "serde", serde(skip))]
    pub cycle_min_us: u64,
    /// Mean poll cycle (µs).
    #[cfg_attr(feature = "serde", serde(skip))]
    pub cycle_avg_us: u64,
    /// Longest poll cycle (µs).
    #[cfg_attr(feature = "serde", serde(skip))]
    pub cycle_max_us: u64,
}

impl std::fmt::Display for PlantSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "demo: {} cycles in {:.3} s of bus time, cycle min/avg/max {}/{}/{} µs, {} telegrams on the line",
            self.cycles,
            self.bus_time_s.as_nanos() as f64 / 1e9,
            self.cycle_min_us,
            self.cycle_avg_us,
            self.cycle_max_us,
            self.telegrams
        )
    }
}

/// The plant's own slaves; `bm4` takes the commands of the
/// BM4-O-PRO-01's own PLC program.
fn own_slaves(bm4: ControlInbox) -> Result<crate::PlantBuilder, DemoError> {
    let gen = gsd_files::parse(gsd_files::DPCTL_GEN)?;
    let echo = ["2 words in/out", "8 bytes in consistent"];
    let strip = format!("terminals={BK3000_STRIP}");
    let jx2 = PlantSlave {
        address: JX2_ADDRESS,
        name: "JX2-PROFI1 (jx2)".into(),
        gsd: Some(gsd_files::parse(jx2::GSD)?),
        modules: vec!["INPUT : 4 words".into(), "OUTPUT : 4 words".into()],
        channels: None,
        profile: Some(jx2::profile::NAME),
    };
    let b = Plant::builder()
        .baud(BAUD)
        .master(MASTER_ADDRESS)
        .watchdog(Duration::from_millis(200))
        .generic(3, "echo (generic)", &gen, &echo, InputPattern::Echo)?
        .generic(
            4,
            "counter (generic)",
            &gen,
            &["2 words in/out"],
            InputPattern::Counter,
        )?
        // Baumüller BM4-O-PRO-01 with the manual's example variables and
        // its generated GSD; PKW module first.
        .profile(
            BM4_ADDRESS,
            "BM4-O-PRO-01 (bm4)",
            "bm4",
            &[
                "example=true",
                r#"variables=["ud_MyReadVar1", "u_MyWriteVar2"]"#,
            ],
            Some(bm4),
        )?
        // Omega Drive-Line II: PKW, status / control, 2 values each way.
        .profile(
            OMEGA_ADDRESS,
            "Omega Drive-Line II (omega)",
            "omega",
            &["drive-enable=auto"],
            None,
        )?
        // Beckhoff BK3000 with a mixed terminal strip, from its rotary
        // switches (station 9).
        .profile(
            BK3000_ADDRESS,
            "BK3000 bus coupler (bk3000)",
            "bk3000",
            &[&strip, "switch-ones=9"],
            None,
        )?
        .slave(jx2, Box::new(jx2_plc()?));
    Ok(b)
}

/// The JX2-PROFI1: configured and initialised by its PLC, the PLC's
/// program running.
fn jx2_plc() -> Result<jx2::ScriptedJx2, DemoError> {
    let mut plc = jx2::Plc::new(2)?;
    let mut init = Interpreter::script(JX2_INIT)?;
    init.run(&mut plc, Instant::ZERO);
    // The PLC was switched on before the plant: initialisation is over.
    plc.module.settle(Instant::ZERO + jx2::INIT_TIME);
    if plc.module.station_address() != Some(JX2_ADDRESS) {
        return Err(DemoError::Jx2NotConfigured);
    }
    let program = Interpreter::script(JX2_PROGRAM)?;
    Ok(jx2::ScriptedJx2::new(plc, program, None))
}

/// Write named output channels of the slave at `address` (all or none).
fn write_channels(m: &mut DpMaster, address: u8, map: Option<&ChannelMap>, v: &[(&str, Value)]) {
    if let (Some(map), Some(h)) = (map, m.handle(address)) {
        if let Err(e) = map.write_outputs(v.iter().copied(), m.outputs_mut(h)) {
            tracing::warn!("demo: slave {address}: {e}");
        }
    }
}

/// A PKW job of the plant that ended (the `pkw` event of `dpctl demo`).
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct PkwDone {
    /// Station address of the slave.
    pub slave: u8,
    /// Parameter number.
    pub pnu: u16,
    /// What the parameter is.
    pub name: &'static str,
    /// The value read or written back.
    pub value: Option<u32>,
    /// Why the job failed.
    pub error: Option<String>,
    /// The request and response words, in words.
    #[cfg_attr(feature = "serde", serde(skip))]
    pub words: String,
}

impl std::fmt::Display for PkwDone {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (slave, name, pnu) = (self.slave, self.name, self.pnu);
        match (&self.error, self.value) {
            (Some(e), _) => write!(f, "pkw slave {slave}: {name} (PNU {pnu}) failed: {e}"),
            (None, v) => {
                let v = v.unwrap_or(0);
                let words = &self.words;
                write!(
                    f,
                    "pkw slave {slave}: {name} (PNU {pnu}) → {v} (0x{v:X})  [{words}]"
                )
            }
        }
    }
}

/// A PKW job of the plant: (PNU, command from the ramp, what it is).
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

    fn step(&mut self, m: &mut DpMaster, now: Instant, ramp: u16) -> Option<PkwDone> {
        let h = m.handle(self.address)?;
        if m.slave(h).state != SlaveState::DataExchange {
            return None;
        }
        let report = self.client.drive(now, m, h).map(|r| {
            let (pnu, _, name) = self.jobs[(self.next + self.jobs.len() - 1) % self.jobs.len()];
            self.due = now + Duration::from_millis(300);
            PkwDone {
                slave: self.address,
                pnu,
                name,
                value: r.as_ref().ok().map(|a| a.reply.value()),
                error: r.as_ref().err().map(|e| e.to_string()),
                words: r
                    .as_ref()
                    .map(|a| format!("request {} / response {}", a.request, a.response))
                    .unwrap_or_default(),
            }
        });
        if self.client.is_idle() && now >= self.due {
            let (pnu, cmd, _) = self.jobs[self.next];
            self.next = (self.next + 1) % self.jobs.len();
            let _ = self.client.start(now, pnu, cmd(ramp));
        }
        report
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plant_exchanges_data_moves_its_outputs_and_runs_pkw_jobs() {
        let mut plant = DemoPlant::new(vec![]).unwrap();
        let addresses: Vec<u8> = plant.slaves().iter().map(|s| s.address).collect();
        assert_eq!(
            addresses,
            [
                3,
                4,
                BM4_ADDRESS,
                OMEGA_ADDRESS,
                BK3000_ADDRESS,
                JX2_ADDRESS
            ]
        );
        let mut pkw = vec![];
        while plant.now() < Instant::ZERO + Duration::from_secs(3) {
            plant.advance(None);
            pkw.extend(plant.step(|a| a == 4));
        }
        let m = plant.master();
        for a in addresses {
            assert_eq!(
                m.slave_state(a),
                Some(SlaveState::DataExchange),
                "slave {a}"
            );
        }
        // The echo device answers the ramp; the counter, written by hand,
        // keeps its zero outputs.
        let echo = m.inputs(3).unwrap().to_vec();
        assert_ne!(echo[..4], [0, 0, 0, 0]);
        assert_eq!(m.outputs(4).unwrap(), &[0, 0, 0, 0]);
        // Both drives answered PKW jobs without errors.
        for a in [BM4_ADDRESS, OMEGA_ADDRESS] {
            assert!(
                pkw.iter().any(|p| p.slave == a && p.error.is_none()),
                "no PKW answer from {a}: {pkw:?}"
            );
        }
        let s = plant.summary();
        assert!(s.cycles > 100 && s.telegrams > s.cycles, "{s}");
        assert_eq!(s.inputs.len(), 6);
        assert!(s.to_string().starts_with("demo: "));
    }
}
