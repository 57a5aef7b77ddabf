//! The PKW client of the DP master against the BM4-O-PRO-01 and Omega
//! profiles on the simulated bus (virtual time, deterministic): the
//! handshake over real Data_Exchange cycles, and Cfg_Fault for a
//! configuration against the Omega's rules.

use profibus::devices::bm4::Bm4;
use profibus::devices::bm4::PKW as BM4;
use profibus::devices::omega::Omega;
use profibus::devices::omega::PKW as OMEGA;
use profibus::devices::pkw::client::{PkwAnswer, PkwClient, PkwError};
use profibus::devices::pkw::{Command, Reply};
use profibus::dp::master::{MasterEvent, SlaveParams, SlaveState};
use profibus_plant::Plant;
use std::time::Duration;

const BM4_ADDR: u8 = 6;
const OMEGA_ADDR: u8 = 25;

/// Master 2 with the BM4-O-PRO-01 (example variables) and an Omega
/// configured with `omega_cfg`, from the plant builder.
fn plant(omega_cfg: &[u8]) -> Plant {
    let t = profibus::devices::bm4::vars::VarTable::example();
    let bm4_cfg = [
        vec![0x73],
        t.identifier(0).to_vec(),
        t.identifier(3).to_vec(),
    ]
    .concat();
    let mut b = SlaveParams::new(BM4_ADDR, 0x0008, bm4_cfg);
    b.user_prm_data = vec![0; 3];
    let mut o = SlaveParams::new(OMEGA_ADDR, 0x00D0, omega_cfg.to_vec());
    o.user_prm_data = vec![0; 5];
    Plant::builder()
        .master(2)
        .slave_params(b, Box::new(Bm4::example(BM4_ADDR)))
        .slave_params(o, Box::new(Omega::with_defaults()))
        .build()
        .unwrap()
}

/// Run one PKW job on slave `addr`, 1 ms of bus time per step.
fn job(
    p: &mut Plant,
    client: &mut PkwClient,
    addr: u8,
    pnu: u16,
    cmd: Command,
) -> Result<PkwAnswer, PkwError> {
    client.start(p.now(), pnu, cmd).unwrap();
    let mut result = None;
    for _ in 0..2000 {
        p.run_for(Duration::from_millis(1));
        let now = p.now();
        let dp = p.master();
        let cycle = dp.slave_stats(addr).unwrap().data_exchanges;
        let inputs = dp.inputs(addr).unwrap().to_vec();
        let mut outputs = dp.outputs(addr).unwrap().to_vec();
        if let Some(r) = client.poll(now, cycle, &inputs, &mut outputs) {
            result = Some(r);
        }
        dp.set_outputs(addr, &outputs);
        if client.is_idle() {
            if let Some(r) = result.take() {
                return r;
            }
        }
    }
    panic!("the job did not end");
}

#[test]
fn pkw_jobs_over_the_simulated_bus() {
    let mut p = plant(&[0x73, 0x71, 0x51, 0x61]);
    assert!(p.run_while(Duration::from_millis(500), |m| {
        [BM4_ADDR, OMEGA_ADDR]
            .iter()
            .all(|&a| m.slave_state(a) == Some(SlaveState::DataExchange))
    }));
    let mut c = PkwClient::new(&BM4, Duration::from_millis(200));
    let a = job(&mut p, &mut c, BM4_ADDR, 4, Command::Read).unwrap();
    assert_eq!(a.response.to_string(), "2004 0000 0000 0BB8");
    let a = job(
        &mut p,
        &mut c,
        BM4_ADDR,
        2,
        Command::WriteDword(0x1234_5678),
    )
    .unwrap();
    assert_eq!(a.response.to_string(), "2002 0000 1234 5678");
    let e = job(&mut p, &mut c, BM4_ADDR, 9, Command::Read).unwrap_err();
    assert!(matches!(e, PkwError::Refused { code: 0x000B, .. }), "{e}");

    let mut c = PkwClient::new(&OMEGA, Duration::from_millis(200));
    let a = job(&mut p, &mut c, OMEGA_ADDR, 127, Command::WriteWord(4)).unwrap();
    assert_eq!(a.response.to_string(), "107F 0000 0000 0004");
    let a = job(&mut p, &mut c, OMEGA_ADDR, 126, Command::Describe(6)).unwrap();
    assert_eq!(a.reply, Reply::Element(0x000F));
    let a = job(
        &mut p,
        &mut c,
        OMEGA_ADDR,
        1000,
        Command::WriteDword(0x1234_5678),
    )
    .unwrap();
    assert_eq!(a.response.to_string(), "23E8 0000 1234 5678");
    let a = job(&mut p, &mut c, OMEGA_ADDR, 1000, Command::Read).unwrap();
    assert_eq!(a.reply, Reply::Dword(0x1234_5678));
    // Both slaves kept exchanging data throughout.
    let dp = p.master_ref();
    assert_eq!(dp.slave_stats(BM4_ADDR).unwrap().restarts, 0);
    assert_eq!(dp.slave_stats(OMEGA_ADDR).unwrap().restarts, 0);
}

#[test]
fn omega_configuration_against_the_rules_is_a_cfg_fault() {
    // Status / control module missing.
    let mut p = plant(&[0x73, 0x51, 0x61]);
    p.run_for(Duration::from_millis(300));
    let dp = p.master();
    assert_eq!(dp.slave_state(BM4_ADDR), Some(SlaveState::DataExchange));
    assert_ne!(dp.slave_state(OMEGA_ADDR), Some(SlaveState::DataExchange));
    let mut faults = vec![];
    while let Some(e) = dp.poll_event() {
        if let MasterEvent::Fault { address, reason } = e {
            faults.push((address, reason.to_string()));
        }
    }
    assert!(
        faults
            .iter()
            .any(|(a, r)| *a == OMEGA_ADDR && r.contains("Cfg_Fault")),
        "{faults:?}"
    );
}
