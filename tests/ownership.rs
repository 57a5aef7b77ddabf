//! Ownership and addressing on the simulated bus, with real masters and
//! slave cores: a slave locked by one master cannot be parameterised,
//! configured or written by another (neither a polite DP master nor a
//! rogue one that sends the requests anyway), and another master's
//! Clear_Data broadcast leaves it alone; Global_Control to 127 reaches
//! the slaves of the selected groups and is never answered; Set_Slave_Add
//! is refused after No_Add_Chg.
//!
//! The slave core's unit tests check each rule on single telegrams
//! (`crates/dp/src/slave/tests.rs`); these check them end to end through
//! the FDL stations, the token ring and the DP master.

use profibus::devices::generic::{GenericDevice, InputPattern};
use profibus::dp::master::{
    DpMaster, Job, JobResult, MasterConfig, MasterEvent, MasterOptions, OperatingState,
    SlaveParams, SlaveState,
};
use profibus::dp::pdu::control::ControlCommand;
use profibus::dp::slave::{DpSlave, Features, SlaveEvent, SlaveState as SlaveCoreState};
use profibus::fdl::line::medium::MediumConfig;
use profibus::fdl::line::tap::{Tap, TapEvent};
use profibus::fdl::sim::{SimBus, StationId};
use profibus::fdl::station::active::{
    ActiveConfig, ActiveStation, CycleResult, MasterApp, Outcome, Request, Service, TokenContext,
};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::wire::{FunctionCode, ResponseStatus, Telegram};
use profibus::fdl::{Baud, BusParams, Instant};
use std::cell::RefCell;
use std::rc::Rc;
use std::time::Duration;

type Master = ActiveStation<DpMaster>;
type Slave = PassiveStation<DpSlave<GenericDevice>>;

const IDENT: u16 = 0x0DCE;
/// 2 bytes in, 2 bytes out.
const CFG: [u8; 2] = [0x11, 0x21];
const BAUD: Baud = Baud::B1500000;

fn params() -> BusParams {
    BusParams::defaults(BAUD)
}

fn slave(address: u8, features: Features) -> Slave {
    let dev =
        GenericDevice::new("test", IDENT, CFG.to_vec(), features).with_inputs(InputPattern::Echo);
    PassiveStation::new(DpSlave::new(dev, address), params())
}

fn slave_params(address: u8) -> SlaveParams {
    let mut p = SlaveParams::new(address, IDENT, CFG.to_vec());
    p.watchdog = Some(Duration::from_millis(100));
    p
}

fn master(address: u8, slaves: Vec<SlaveParams>) -> Master {
    let cfg = MasterConfig {
        address,
        params: params(),
        slaves,
        options: MasterOptions::default(),
    };
    ActiveStation::new(
        ActiveConfig::new(address, params()),
        DpMaster::new(&cfg).unwrap(),
    )
}

fn dp(bus: &mut SimBus, id: StationId) -> &mut DpMaster {
    bus.station_mut::<Master>(id).app_mut()
}

fn core(bus: &mut SimBus, id: StationId) -> &mut DpSlave<GenericDevice> {
    bus.station_mut::<Slave>(id).app_mut()
}

fn events(bus: &mut SimBus, id: StationId) -> Vec<MasterEvent> {
    std::iter::from_fn(|| dp(bus, id).poll_event()).collect()
}

fn slave_events(bus: &mut SimBus, id: StationId) -> Vec<SlaveEvent> {
    std::iter::from_fn(|| core(bus, id).poll_event()).collect()
}

fn in_dx(bus: &SimBus, m: StationId, address: u8) -> bool {
    bus.station::<Master>(m).app().slave_state(address) == Some(SlaveState::DataExchange)
}

/// Left Data_Exchange (for the master) in these events?
fn left_dx(ev: &[MasterEvent], address: u8) -> bool {
    ev.iter().any(|e| {
        matches!(e, MasterEvent::StateChanged { address: a, from: SlaveState::DataExchange, .. } if *a == address)
    })
}

/// A master that ignores the lock: from `start` on it sends Slave_Diag,
/// Set_Prm, Chk_Cfg and Data_Exchange to `target` and records what came
/// back.
struct Rogue {
    target: u8,
    start: Instant,
    script: Vec<(&'static str, Option<u8>, Vec<u8>)>,
    next: usize,
    results: Vec<(&'static str, String, Vec<u8>)>,
}

impl MasterApp for Rogue {
    fn poll_request(&mut self, ctx: &TokenContext) -> Option<Request<'_>> {
        if ctx.now < self.start || ctx.cycles > 0 {
            return None;
        }
        let (_, dsap, data) = self.script.get(self.next)?;
        Some(Request {
            da: self.target,
            service: Service::SrdHigh,
            dsap: *dsap,
            ssap: dsap.map(|_| 62),
            data,
            max_reply_len: None,
        })
    }

    fn on_result(&mut self, _now: Instant, r: &CycleResult<'_>) {
        let (name, _, _) = self.script[self.next];
        self.next += 1;
        let (outcome, data) = match r.outcome {
            Outcome::Response { status, data, .. } => (format!("{status:?}"), data.to_vec()),
            Outcome::ShortAck => ("SC".into(), vec![]),
            Outcome::Sent => ("sent".into(), vec![]),
            Outcome::NoResponse => ("no response".into(), vec![]),
        };
        self.results.push((name, outcome, data));
    }
}

/// Run until `cond` holds (at most `limit` of bus time), draining the
/// events of masters `ms` into `log`.
fn run_until(
    bus: &mut SimBus,
    ms: &[StationId],
    log: &mut Vec<(StationId, MasterEvent)>,
    limit: Duration,
    mut cond: impl FnMut(&mut SimBus) -> bool,
) -> bool {
    let end = bus.now() + limit;
    while bus.now() < end {
        bus.run_for(Duration::from_millis(1));
        for &m in ms {
            log.extend(events(bus, m).into_iter().map(|e| (m, e)));
        }
        if cond(bus) {
            return true;
        }
    }
    false
}

#[test]
fn a_rogue_master_cannot_parameterise_configure_or_write_a_locked_slave() {
    let mut bus = SimBus::new(MediumConfig::paced(BAUD));
    let owner = bus.add(master(1, vec![slave_params(5)]));
    let start = Instant::ZERO + Duration::from_millis(300);
    let prm = slave_params(5).set_prm(); // Lock_Req + WD_On, same ident
    let rogue = bus.add(ActiveStation::new(
        ActiveConfig::new(2, params()),
        Rogue {
            target: 5,
            start,
            script: vec![
                ("Slave_Diag", Some(60), vec![]),
                ("Set_Prm", Some(61), prm),
                ("Chk_Cfg", Some(62), CFG.to_vec()),
                ("Data_Exchange", None, vec![0xEE, 0xEE]),
                ("Slave_Diag", Some(60), vec![]),
            ],
            next: 0,
            results: vec![],
        },
    ));
    let s = bus.add(slave(5, Features::default()));
    let mut log = vec![];
    assert!(run_until(
        &mut bus,
        &[owner],
        &mut log,
        Duration::from_millis(250),
        |b| { in_dx(b, owner, 5) }
    ));
    assert!(dp(&mut bus, owner).set_outputs(5, &[0x12, 0x34]));
    let prm_before = core(&mut bus, s).stats().prm_accepted;
    slave_events(&mut bus, s);
    assert!(bus.now() < start, "the owner took too long: {}", bus.now());
    assert!(run_until(
        &mut bus,
        &[owner],
        &mut log,
        Duration::from_secs(2),
        |b| { b.station::<ActiveStation<Rogue>>(rogue).app().results.len() == 5 }
    ));
    // Let the owner run a few more cycles.
    let cycles = dp(&mut bus, owner).cycle_stats().cycles;
    assert!(run_until(
        &mut bus,
        &[owner],
        &mut log,
        Duration::from_secs(1),
        |b| { b.station::<Master>(owner).app().cycle_stats().cycles > cycles + 10 }
    ));

    let results = bus
        .station::<ActiveStation<Rogue>>(rogue)
        .app()
        .results
        .clone();
    let outcome: Vec<(&str, &str)> = results.iter().map(|(n, o, _)| (*n, o.as_str())).collect();
    assert_eq!(
        outcome,
        [
            ("Slave_Diag", "Dl"),
            ("Set_Prm", "SC"),
            ("Chk_Cfg", "SC"),
            ("Data_Exchange", "Rs"),
            ("Slave_Diag", "Dl"),
        ],
        "{results:?}"
    );
    // The diagnosis names the owner (Master_Add, byte 3) both times.
    assert_eq!(results[0].2[3], 1);
    assert_eq!(results[4].2[3], 1);
    // The slave is still the owner's, with the owner's outputs, and the
    // owner never lost it.
    let core = core(&mut bus, s);
    assert_eq!(core.master(), Some(1));
    assert_eq!(core.state(), SlaveCoreState::DataExch);
    assert_eq!(core.outputs(), [0x12, 0x34]);
    assert_eq!(core.stats().prm_accepted, prm_before);
    let refused: Vec<&'static str> = std::iter::from_fn(|| core.poll_event())
        .filter_map(|e| match e {
            SlaveEvent::Refused {
                master: 2, service, ..
            } => Some(service.as_str()),
            _ => None,
        })
        .collect();
    assert_eq!(refused.len(), 3, "{refused:?}");
    assert!(!left_dx(
        &log.iter().map(|(_, e)| e.clone()).collect::<Vec<_>>(),
        5
    ));
}

#[test]
fn a_second_dp_master_sees_the_slave_locked_and_leaves_it_alone() {
    let mut bus = SimBus::new(MediumConfig::paced(BAUD));
    let a = bus.add(master(1, vec![slave_params(5)]));
    let b = bus.add(master(2, vec![slave_params(5)]));
    bus.set_online(b, false);
    let s = bus.add(slave(5, Features::default()));
    let mut log = vec![];
    assert!(run_until(
        &mut bus,
        &[a],
        &mut log,
        Duration::from_secs(1),
        |bus| { in_dx(bus, a, 5) }
    ));
    dp(&mut bus, a).set_outputs(5, &[0x56, 0x78]);
    let prm_before = core(&mut bus, s).stats().prm_accepted;
    // Master 2 is switched on with the same slave in its configuration.
    let now = bus.now();
    bus.station_mut::<Master>(b).restart(now);
    bus.set_online(b, true);
    assert!(
        run_until(&mut bus, &[a, b], &mut log, Duration::from_secs(3), |bus| {
            bus.station::<Master>(b).app().slave_state(5) == Some(SlaveState::Locked)
        }),
        "{log:?}"
    );
    let cycles = dp(&mut bus, a).cycle_stats().cycles;
    assert!(run_until(
        &mut bus,
        &[a, b],
        &mut log,
        Duration::from_secs(2),
        |bus| { bus.station::<Master>(a).app().cycle_stats().cycles > cycles + 20 }
    ));
    assert_eq!(dp(&mut bus, b).slave_state(5), Some(SlaveState::Locked));
    let ev_a: Vec<MasterEvent> = log
        .iter()
        .filter(|(m, _)| *m == a)
        .map(|(_, e)| e.clone())
        .collect();
    assert!(!left_dx(&ev_a, 5), "{ev_a:?}");
    let core = core(&mut bus, s);
    assert_eq!(core.master(), Some(1));
    assert_eq!(core.outputs(), [0x56, 0x78]);
    // Master 2 never sent a Set_Prm the slave took.
    assert_eq!(core.stats().prm_accepted, prm_before);
}

#[test]
fn clear_data_from_another_master_leaves_a_locked_slave_alone() {
    let mut bus = SimBus::new(MediumConfig::paced(BAUD));
    let a = bus.add(master(1, vec![slave_params(5)]));
    let b = bus.add(master(2, vec![slave_params(6)]));
    let s5 = bus.add(slave(5, Features::default()));
    let s6 = bus.add(slave(6, Features::default()));
    let mut log = vec![];
    assert!(run_until(
        &mut bus,
        &[a, b],
        &mut log,
        Duration::from_secs(1),
        |bus| { in_dx(bus, a, 5) && in_dx(bus, b, 6) }
    ));
    dp(&mut bus, a).set_outputs(5, &[0x11, 0x22]);
    dp(&mut bus, b).set_outputs(6, &[0x33, 0x44]);
    assert!(run_until(
        &mut bus,
        &[a, b],
        &mut log,
        Duration::from_secs(1),
        |bus| {
            bus.station::<Slave>(s6).app().outputs() == [0x33, 0x44]
                && bus.station::<Slave>(s5).app().outputs() == [0x11, 0x22]
        }
    ));
    slave_events(&mut bus, s5);
    slave_events(&mut bus, s6);
    // Master 2 goes to Clear: Clear_Data to every station (127).
    dp(&mut bus, b).set_operating_state(OperatingState::Clear);
    assert!(run_until(
        &mut bus,
        &[a, b],
        &mut log,
        Duration::from_secs(1),
        |bus| { bus.station::<Slave>(s6).app().outputs() == [0, 0] }
    ));
    let cycles = dp(&mut bus, a).cycle_stats().cycles;
    assert!(run_until(
        &mut bus,
        &[a, b],
        &mut log,
        Duration::from_secs(1),
        |bus| { bus.station::<Master>(a).app().cycle_stats().cycles > cycles + 20 }
    ));
    let e6 = slave_events(&mut bus, s6);
    assert!(e6.iter().any(|e| matches!(e, SlaveEvent::GlobalControl { master: 2, command, .. } if command.contains(ControlCommand::CLEAR_DATA))), "{e6:?}");
    let e5 = slave_events(&mut bus, s5);
    assert!(
        !e5.iter().any(|e| matches!(
            e,
            SlaveEvent::GlobalControl { .. } | SlaveEvent::OutputsCleared { .. }
        )),
        "{e5:?}"
    );
    assert_eq!(bus.station::<Slave>(s5).app().outputs(), [0x11, 0x22]);
}

#[test]
fn global_control_to_127_reaches_the_selected_groups_and_is_never_answered() {
    let mut bus = SimBus::new(MediumConfig::paced(BAUD));
    let features = Features {
        freeze: true,
        sync: true,
        ..Features::default()
    };
    // Slaves 5 and 7 in group 1, slave 6 in group 2; all in freeze mode.
    let sp = |a: u8, group: u8| {
        let mut p = slave_params(a);
        p.group = group;
        p.freeze = true;
        p
    };
    let m = bus.add(master(1, vec![sp(5, 0b01), sp(6, 0b10), sp(7, 0b01)]));
    let slaves: Vec<StationId> = [5, 6, 7]
        .iter()
        .map(|&a| bus.add(slave(a, features)))
        .collect();
    // Every telegram on the line, in order.
    let seen = Rc::new(RefCell::new(Vec::<Vec<u8>>::new()));
    {
        let seen = seen.clone();
        let mut tap = Tap::new();
        bus.set_tap(Box::new(move |at, _from, bytes| {
            tap.push(at, bytes);
            while let Some(ev) = tap.poll() {
                if let TapEvent::Telegram { bytes, .. } = ev {
                    seen.borrow_mut().push(bytes);
                }
            }
        }));
    }
    let mut log = vec![];
    assert!(run_until(
        &mut bus,
        &[m],
        &mut log,
        Duration::from_secs(1),
        |bus| { [5, 6, 7].iter().all(|&a| in_dx(bus, m, a)) }
    ));
    for &s in &slaves {
        slave_events(&mut bus, s);
    }
    // Freeze group 1.
    assert!(dp(&mut bus, m).global_control(ControlCommand::FREEZE, 0b01));
    let frozen = |bus: &mut SimBus, s: StationId| {
        slave_events(bus, s).into_iter().any(|e| {
            matches!(e, SlaveEvent::GlobalControl { master: 1, command, group_select: 0b01 } if command.contains(ControlCommand::FREEZE))
        })
    };
    let mut got = [false; 3];
    assert!(run_until(
        &mut bus,
        &[m],
        &mut log,
        Duration::from_secs(1),
        |bus| {
            for (i, &s) in slaves.iter().enumerate() {
                got[i] |= frozen(bus, s);
            }
            got[0] && got[2]
        }
    ));
    let cycles = dp(&mut bus, m).cycle_stats().cycles;
    assert!(run_until(
        &mut bus,
        &[m],
        &mut log,
        Duration::from_secs(1),
        |bus| { bus.station::<Master>(m).app().cycle_stats().cycles > cycles + 10 }
    ));
    got[1] |= frozen(&mut bus, slaves[1]);
    assert_eq!(
        got,
        [true, false, true],
        "group 2 must not act on a group-1 command"
    );
    // The broadcasts went to 127 and nobody answered them: the telegram
    // after each one is a request or a token, never a response.
    let seen = seen.borrow();
    let mut broadcasts = 0;
    for w in seen.windows(2) {
        let Ok((Telegram::Data(d), _)) = Telegram::parse(&w[0]) else {
            continue;
        };
        if d.da != 127 {
            continue;
        }
        broadcasts += 1;
        assert_eq!(d.dsap, Some(58), "Global_Control SAP");
        match Telegram::parse(&w[1]) {
            Ok((Telegram::Data(n), _)) => assert!(
                matches!(n.fc, FunctionCode::Request { .. }),
                "a station answered a broadcast: {:02X?}",
                w[1]
            ),
            Ok((Telegram::ShortAck, _)) => panic!("a short ack after a broadcast"),
            _ => {}
        }
    }
    assert!(broadcasts >= 1);
}

/// Commission a slave that starts at 126: Set_Slave_Add to 10 (with
/// `no_add_chg`), then try to move it on to 11.
fn commission(no_add_chg: bool) -> (JobResult, JobResult, u8) {
    let mut bus = SimBus::new(MediumConfig::paced(BAUD));
    let m = bus.add(master(1, vec![]));
    let features = Features {
        set_slave_add: true,
        ..Features::default()
    };
    let s = bus.add(slave(126, features));
    let mut log = vec![];
    let mut job = |bus: &mut SimBus, address: u8, new_address: u8, no_add_chg: bool| {
        let id = dp(bus, m)
            .submit(Job::SetSlaveAdd {
                address,
                new_address,
                ident_number: IDENT,
                no_add_chg,
            })
            .unwrap();
        let mut result = None;
        assert!(run_until(
            bus,
            &[m],
            &mut log,
            Duration::from_secs(2),
            |bus| {
                result = dp(bus, m).take_result(id);
                result.is_some()
            }
        ));
        result.unwrap()
    };
    let first = job(&mut bus, 126, 10, no_add_chg);
    let second = job(&mut bus, 10, 11, false);
    let address =
        profibus::fdl::station::passive::Responder::address(bus.station::<Slave>(s).app());
    let _ = slave_events(&mut bus, s);
    (first, second, address)
}

#[test]
fn set_slave_add_is_refused_after_no_add_chg() {
    // Without No_Add_Chg the address may be changed again …
    let (first, second, address) = commission(false);
    assert_eq!(
        (first, second, address),
        (JobResult::Done, JobResult::Done, 11)
    );
    // … with it, the second change is refused and the address stays.
    let (first, second, address) = commission(true);
    assert_eq!(first, JobResult::Done);
    assert_eq!(second, JobResult::Refused(ResponseStatus::Rs));
    assert_eq!(address, 10);
}
