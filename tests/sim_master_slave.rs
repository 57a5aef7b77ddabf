//! The DP master core against DP slave cores on the simulated bus
//! (virtual time): start-up to Data_Exchange, data both ways, a lost
//! slave re-parameterised after a restart, a configuration fault in words,
//! two masters with their own slaves on one bus.

use profibus::devices::generic::{GenericDevice, InputPattern};
use profibus::dp::master::{
    DpMaster, MasterConfig, MasterEvent, MasterOptions, SlaveParams, SlaveState,
};
use profibus::dp::slave::{DpSlave, Features};
use profibus::fdl::medium::MediumConfig;
use profibus::fdl::sim::{SimBus, StationId};
use profibus::fdl::station::active::{ActiveConfig, ActiveStation};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::{Baud, BusParams};
use std::time::Duration;

type Master = ActiveStation<DpMaster>;
type Slave = PassiveStation<DpSlave<GenericDevice>>;

const CFG: [u8; 2] = [0x11, 0x21]; // 2 bytes in, 2 bytes out

fn slave(addr: u8, params: BusParams, cfg: &[u8]) -> Slave {
    let dev = GenericDevice::new("test", 0x0DCE, cfg.to_vec(), Features::default())
        .with_inputs(InputPattern::Echo);
    PassiveStation::new(DpSlave::new(dev, addr), params)
}

fn master_cfg(addr: u8, params: BusParams, slaves: &[u8]) -> MasterConfig {
    MasterConfig {
        address: addr,
        params,
        slaves: slaves
            .iter()
            .map(|&a| {
                let mut p = SlaveParams::new(a, 0x0DCE, CFG.to_vec());
                p.watchdog = Some(Duration::from_millis(100));
                p
            })
            .collect(),
        options: MasterOptions::default(),
    }
}

struct Plant {
    bus: SimBus,
    master: StationId,
    slaves: Vec<StationId>,
    params: BusParams,
}

fn plant(slave_cfgs: &[(u8, &[u8])]) -> Plant {
    let params = BusParams::defaults(Baud::B1500000);
    let mut bus = SimBus::new(MediumConfig::paced(Baud::B1500000));
    let addrs: Vec<u8> = slave_cfgs.iter().map(|s| s.0).collect();
    let dp = DpMaster::new(&master_cfg(2, params, &addrs)).unwrap();
    let master = bus.add(ActiveStation::new(ActiveConfig::new(2, params), dp));
    let slaves = slave_cfgs
        .iter()
        .map(|&(a, cfg)| bus.add(slave(a, params, cfg)))
        .collect();
    Plant {
        bus,
        master,
        slaves,
        params,
    }
}

impl Plant {
    fn m(&mut self) -> &mut DpMaster {
        self.bus.station_mut::<Master>(self.master).app_mut()
    }
    fn all_in_data_exchange(&self) -> bool {
        let m = self.bus.station::<Master>(self.master).app();
        m.slave_addresses()
            .all(|a| m.slave_state(a) == Some(SlaveState::DataExchange))
    }
}

#[test]
fn three_slaves_reach_data_exchange_and_data_flows_both_ways() {
    let mut p = plant(&[(10, &CFG), (11, &CFG), (12, &CFG)]);
    assert!(p.bus.run_while(Duration::from_millis(500), |b| {
        let m = b.station::<Master>(0).app();
        m.slave_addresses()
            .all(|a| m.slave_state(a) == Some(SlaveState::DataExchange))
    }));
    for (i, a) in [10u8, 11, 12].into_iter().enumerate() {
        assert!(p.m().set_outputs(a, &[a, i as u8 + 0x40]));
    }
    p.bus.run_for(Duration::from_millis(20));
    for (i, a) in [10u8, 11, 12].into_iter().enumerate() {
        let s = p.bus.station::<Slave>(p.slaves[i]);
        assert_eq!(s.app().device().outputs(), &[a, i as u8 + 0x40]);
        // Echo: the inputs the master sees are the outputs it sent.
        assert_eq!(p.m().inputs(a), Some(&[a, i as u8 + 0x40][..]));
        assert_eq!(p.m().slave_stats(a).unwrap().errors, 0);
    }
    let c = p.m().cycle_stats();
    assert!(c.cycles > 10);
}

#[test]
fn a_restarted_slave_is_parameterised_again_while_others_keep_cycling() {
    let mut p = plant(&[(10, &CFG), (11, &CFG)]);
    assert!(p.bus.run_while(Duration::from_millis(500), |b| {
        let m = b.station::<Master>(0).app();
        m.slave_addresses()
            .all(|a| m.slave_state(a) == Some(SlaveState::DataExchange))
    }));
    // Pull slave 11's plug.
    p.bus.set_online(p.slaves[1], false);
    let before = p.m().slave_stats(10).unwrap().data_exchanges;
    p.bus.run_for(Duration::from_millis(200));
    assert_eq!(p.m().slave_state(11), Some(SlaveState::Offline));
    assert!(p.m().slave_stats(10).unwrap().data_exchanges > before + 50);
    // Power it up again, fresh.
    let params = p.params;
    p.bus.replace(p.slaves[1], slave(11, params, &CFG));
    p.bus.set_online(p.slaves[1], true);
    assert!(p.bus.run_while(Duration::from_millis(500), |b| b
        .station::<Master>(0)
        .app()
        .slave_state(11)
        == Some(SlaveState::DataExchange)));
    let mut saw = vec![];
    while let Some(e) = p.m().poll_event() {
        if let MasterEvent::StateChanged {
            address: 11, to, ..
        } = e
        {
            saw.push(to);
        }
    }
    assert!(saw.ends_with(&[
        SlaveState::SetPrm,
        SlaveState::ChkCfg,
        SlaveState::CheckDiag,
        SlaveState::DataExchange
    ]));
    assert!(p.all_in_data_exchange());
}

#[test]
fn wrong_configuration_shows_cfg_fault_in_words() {
    // The slave expects 4 bytes in/out; the master configures 2/2.
    let mut p = plant(&[(10, &[0x13, 0x23])]);
    p.bus.run_for(Duration::from_millis(200));
    let mut faults = vec![];
    while let Some(e) = p.m().poll_event() {
        if let MasterEvent::Fault { reason, .. } = e {
            faults.push(reason.to_string());
        }
    }
    assert!(!faults.is_empty());
    assert!(faults[0].contains("Cfg_Fault"), "{faults:?}");
    assert_ne!(p.m().slave_state(10), Some(SlaveState::DataExchange));
}

#[test]
fn two_masters_each_with_their_own_slaves() {
    let params = BusParams::defaults(Baud::B1500000);
    let mut bus = SimBus::new(MediumConfig::paced(Baud::B1500000));
    let m1 = bus.add(ActiveStation::new(
        ActiveConfig::new(2, params),
        DpMaster::new(&master_cfg(2, params, &[10, 11])).unwrap(),
    ));
    let m2 = bus.add(ActiveStation::new(
        ActiveConfig::new(3, params),
        DpMaster::new(&master_cfg(3, params, &[20])).unwrap(),
    ));
    for a in [10, 11, 20] {
        bus.add(slave(a, params, &CFG));
    }
    assert!(bus.run_while(Duration::from_secs(2), |b| {
        [m1, m2].iter().all(|&m| {
            let d = b.station::<Master>(m).app();
            d.slave_addresses()
                .all(|a| d.slave_state(a) == Some(SlaveState::DataExchange))
        })
    }));
    let c1 = bus.station::<Master>(m1).app().cycle_stats().cycles;
    let c2 = bus.station::<Master>(m2).app().cycle_stats().cycles;
    bus.run_for(Duration::from_millis(100));
    assert!(bus.station::<Master>(m1).app().cycle_stats().cycles > c1 + 20);
    assert!(bus.station::<Master>(m2).app().cycle_stats().cycles > c2 + 20);
    assert!(bus.station::<Master>(m1).stats().tokens > 20);
    assert!(bus.station::<Master>(m2).stats().tokens > 20);
}
