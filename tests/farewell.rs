//! The clean stop of a DP master (`profibus_dp::master::Farewell`, what
//! `dpctl master` and `dpctl gateway` do on SIGTERM and Ctrl-C) on the
//! simulated bus with real slave cores: the slaves see Global_Control
//! with Clear_Data and get zero outputs within a cycle or so, long
//! before their watchdog would; the master falls silent without the
//! token, so the other master of the ring keeps its slaves in
//! Data_Exchange without a token claim.

use profibus::devices::generic::{GenericDevice, InputPattern};
use profibus::dp::master::{
    DpMaster, Farewell, MasterConfig, MasterOptions, SlaveParams, SlaveState, FAREWELL_LIMIT,
};
use profibus::dp::pdu::control::ControlCommand;
use profibus::dp::slave::{DpSlave, Features, SlaveEvent};
use profibus::fdl::line::medium::MediumConfig;
use profibus::fdl::sim::{SimBus, StationId};
use profibus::fdl::station::active::{ActiveConfig, ActiveStation};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::{Baud, BusParams};
use std::time::Duration;

type Master = ActiveStation<DpMaster>;
type Slave = PassiveStation<DpSlave<GenericDevice>>;

const IDENT: u16 = 0x0DCE;
const CFG: [u8; 2] = [0x11, 0x21];
const BAUD: Baud = Baud::B1500000;
/// The slaves' watchdog: what they would wait without the Clear.
const WATCHDOG: Duration = Duration::from_millis(500);

fn slave(address: u8) -> Slave {
    let dev = GenericDevice::new("test", IDENT, CFG.to_vec(), Features::default())
        .with_inputs(InputPattern::Echo);
    PassiveStation::new(DpSlave::new(dev, address), BusParams::defaults(BAUD))
}

fn master(address: u8, slaves: &[u8]) -> Master {
    let slaves = slaves
        .iter()
        .map(|&a| {
            let mut p = SlaveParams::new(a, IDENT, CFG.to_vec());
            p.watchdog = Some(WATCHDOG);
            p
        })
        .collect();
    let cfg = MasterConfig {
        address,
        params: BusParams::defaults(BAUD),
        slaves,
        options: MasterOptions::default(),
    };
    ActiveStation::new(
        ActiveConfig::new(address, BusParams::defaults(BAUD)),
        DpMaster::new(&cfg).unwrap(),
    )
}

fn dp(bus: &mut SimBus, id: StationId) -> &mut DpMaster {
    bus.station_mut::<Master>(id).app_mut()
}

fn in_dx(bus: &SimBus, m: StationId, address: u8) -> bool {
    bus.station::<Master>(m).app().slave_state(address) == Some(SlaveState::DataExchange)
}

/// Run in 100 µs steps until `cond` (at most `limit`).
fn run_until(bus: &mut SimBus, limit: Duration, mut cond: impl FnMut(&mut SimBus) -> bool) -> bool {
    let end = bus.now() + limit;
    while bus.now() < end {
        bus.run_for(Duration::from_micros(100));
        if cond(bus) {
            return true;
        }
    }
    false
}

fn slave_events(bus: &mut SimBus, id: StationId) -> Vec<SlaveEvent> {
    std::iter::from_fn(|| bus.station_mut::<Slave>(id).app_mut().poll_event()).collect()
}

/// Masters 1 (slaves 5, 6) and 2 (slave 7) in one ring; master 1 says
/// farewell. Its slaves see Clear_Data and zero outputs within a few
/// ms; it stops without the token; master 2's slave never leaves
/// Data_Exchange and master 2 claims no token.
#[test]
fn a_master_that_says_farewell_clears_its_slaves_and_leaves_without_the_token() {
    let mut bus = SimBus::new(MediumConfig::paced(BAUD));
    let a = bus.add(master(1, &[5, 6]));
    let b = bus.add(master(2, &[7]));
    let s: Vec<StationId> = [5, 6, 7].into_iter().map(|n| bus.add(slave(n))).collect();
    assert!(run_until(&mut bus, Duration::from_secs(2), |bus| {
        in_dx(bus, a, 5) && in_dx(bus, a, 6) && in_dx(bus, b, 7)
    }));
    dp(&mut bus, a).set_outputs(5, &[0x11, 0x22]);
    dp(&mut bus, a).set_outputs(6, &[0x33, 0x44]);
    dp(&mut bus, b).set_outputs(7, &[0x55, 0x66]);
    assert!(run_until(&mut bus, Duration::from_secs(1), |bus| {
        bus.station::<Slave>(s[0]).app().outputs() == [0x11, 0x22]
            && bus.station::<Slave>(s[1]).app().outputs() == [0x33, 0x44]
            && bus.station::<Slave>(s[2]).app().outputs() == [0x55, 0x66]
    }));
    for &id in &s {
        slave_events(&mut bus, id);
    }
    let claims = bus.station::<Master>(b).stats();

    let began = bus.now();
    let farewell = Farewell::begin(dp(&mut bus, a), began);
    let done = |bus: &mut SimBus, f: &Farewell| {
        let st = bus.station::<Master>(a);
        let alone = st.next_station() == 1;
        f.done(st.app(), st.ring_state(), alone, bus.now())
    };
    assert!(!done(&mut bus, &farewell), "not before the Clear is sent");
    assert!(run_until(&mut bus, FAREWELL_LIMIT, |bus| done(
        bus, &farewell
    )));
    let took = bus.now() - began;
    assert!(!farewell.timed_out(bus.now()), "took {took:?}");
    assert!(took < Duration::from_millis(50), "took {took:?}");
    let st = bus.station::<Master>(a);
    assert!(
        !matches!(
            st.ring_state(),
            profibus::fdl::station::active::RingState::UseToken
                | profibus::fdl::station::active::RingState::CheckTokenPass
        ),
        "{:?}",
        st.ring_state()
    );
    // Master 1's slaves: Clear_Data from master 1, zero outputs, now.
    for &id in &s[..2] {
        let ev = slave_events(&mut bus, id);
        assert!(
            ev.iter().any(|e| matches!(e, SlaveEvent::GlobalControl { master: 1, command, .. } if command.contains(ControlCommand::CLEAR_DATA))),
            "{ev:?}"
        );
        assert_eq!(bus.station::<Slave>(id).app().outputs(), [0, 0]);
    }

    // Master 1 falls silent (removed from the line) without the token:
    // master 2 goes on; its slave keeps its outputs and Data_Exchange.
    bus.set_online(a, false);
    let cycles = dp(&mut bus, b).cycle_stats().cycles;
    assert!(run_until(&mut bus, 2 * WATCHDOG, |bus| {
        bus.station::<Master>(b).app().cycle_stats().cycles > cycles + 200
    }));
    assert!(in_dx(&bus, b, 7));
    assert_eq!(bus.station::<Slave>(s[2]).app().outputs(), [0x55, 0x66]);
    let after = bus.station::<Master>(b).stats();
    assert_eq!(after.claims, claims.claims, "master 2 claimed a token");
}
