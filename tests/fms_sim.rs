//! PROFIBUS-FMS beside DP on the simulated bus (issue 35's checks at the
//! core level): a BK3000 with KL3102 and KL4002 in mixed mode
//! (`fms=mixed`) in Data_Exchange with a class-1 master while an FMS
//! client (an active station with `FmsMaster`) reads a channel object —
//! status byte plus the value the master's Data_Exchange carries —,
//! writes an output channel object, reads the object dictionary, Status
//! and Identify; the slave never leaves Data_Exchange. A coupler in DP-only
//! mode refuses the connection.

use profibus::dp::fms::client::{FmsMaster, FmsRun, FmsRunError};
use profibus::dp::fms::pdu::{GetOdRequest, Request, Response};
use profibus::dp::master::SlaveState;
use profibus::fdl::sim::{SimBus, StationId};
use profibus::fdl::station::active::{ActiveConfig, ActiveStation};
use profibus::fdl::Baud;
use profibus_devices::bk3000::master::Bk3000Master;
use profibus_plant::{MasterStation, Plant};
use std::collections::BTreeSet;
use std::time::Duration;

const STRIP: &str = "KL3102,KL4002,KL9010";

struct Line {
    bus: SimBus,
    master: StationId,
    fms: StationId,
}

fn line(mode: &str, requests: Vec<Request>) -> (Line, FmsRun) {
    let terminals = format!("terminals={STRIP}");
    let fms = format!("fms={mode}");
    let s = Plant::builder()
        .baud(Baud::B1500000)
        .master(2)
        .profile(5, "bk", "bk3000", &[&terminals, &fms], None)
        .unwrap()
        .stations()
        .unwrap();
    let mut bus = SimBus::new(s.medium);
    let master = bus.add(s.master);
    for (_, st) in s.slaves {
        bus.add(st);
    }
    let fms = bus.add(ActiveStation::new(
        ActiveConfig::new(3, s.params),
        FmsMaster::new(5, 40, Some(Duration::from_millis(500))),
    ));
    let mut l = Line { bus, master, fms };
    let end = l.bus.now() + Duration::from_secs(3);
    while l.state() != Some(SlaveState::DataExchange) {
        assert!(l.bus.now() < end, "start-up");
        l.bus.run_for(Duration::from_millis(1));
    }
    (l, FmsRun::new(requests))
}

impl Line {
    fn state(&self) -> Option<SlaveState> {
        self.bus
            .station::<MasterStation>(self.master)
            .app()
            .slave_state(5)
    }

    fn inputs(&self) -> Vec<u8> {
        let m = self.bus.station::<MasterStation>(self.master).app();
        m.inputs(5).unwrap_or_default().to_vec()
    }

    /// Runs `run` to its end; every input image the master saw.
    fn run(&mut self, run: &mut FmsRun) -> Vec<Vec<u8>> {
        let mut seen = vec![self.inputs()];
        let end = self.bus.now() + Duration::from_secs(10);
        loop {
            // Steps shorter than a Data_Exchange cycle: the master's input
            // image after every cycle.
            self.bus.run_for(Duration::from_micros(50));
            let now = self.bus.now();
            let st = self.bus.station_mut::<ActiveStation<FmsMaster>>(self.fms);
            // The connection's timers start once the station is in the ring.
            if st.stats().tokens == 0 {
                assert!(now < end, "the FMS station never got the token");
                continue;
            }
            run.tick(st.app_mut(), now);
            let queued = st.app_mut().lli().has_queued();
            seen.push(self.inputs());
            assert_eq!(self.state(), Some(SlaveState::DataExchange));
            if run.is_done() && !queued {
                break;
            }
            assert!(now < end, "FMS run did not end: {run:?}");
        }
        seen
    }
}

#[test]
fn fms_reads_and_writes_channel_objects_while_data_exchange_goes_on() {
    let reqs = vec![
        Request::Status,
        Request::Identify,
        Request::Read {
            index: 2020,
            subindex: None,
        },
        Request::Write {
            index: 2041,
            subindex: None,
            data: vec![0, 0x20, 0x00],
        },
        Request::GetOd(GetOdRequest {
            long_form: true,
            from_index: true,
            index: 2000,
        }),
    ];
    let (mut l, mut run) = line("mixed", reqs);
    let seen = l.run(&mut run);
    assert_eq!(run.error, None, "{run:?}");
    assert_eq!(run.results.len(), 5, "{run:?}");
    let m = Bk3000Master::from_names(&STRIP.split(',').collect::<Vec<_>>()).unwrap();
    let value = m
        .image()
        .entries
        .iter()
        .find(|e| e.name == "1.KL3102.1")
        .unwrap();
    let carried: BTreeSet<Vec<u8>> = seen
        .iter()
        .filter(|i| i.len() >= value.byte + 2)
        .map(|i| i[value.byte..value.byte + 2].to_vec())
        .collect();
    match &run.results[2].1 {
        Ok(Response::Read(v)) => {
            assert_eq!(v.len(), 3, "status byte and a word: {v:02X?}");
            assert!(
                carried.contains(&v[1..]),
                "{v:02X?} not among the values Data_Exchange carried: {carried:02X?}"
            );
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(run.results[3].1, Ok(Response::Write));
    match &run.results[4].1 {
        Ok(Response::GetOd { descriptions, .. }) => {
            let idx: Vec<u16> = descriptions
                .iter()
                .map(|d| u16::from_be_bytes([d[0], d[1]]))
                .collect();
            assert!(idx.contains(&2020) && idx.contains(&2041), "{idx:?}");
        }
        other => panic!("{other:?}"),
    }
    match &run.results[1].1 {
        Ok(Response::Identify(i)) => assert_eq!(i.model, "BK3000"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_coupler_in_dp_mode_has_no_fms() {
    let (mut l, mut run) = line("dp", vec![Request::Identify]);
    l.run(&mut run);
    let e = run.error.clone().expect("an error");
    assert!(
        matches!(e, FmsRunError::NotServer { lsap: 40, .. }),
        "{e:?}"
    );
    assert_eq!(
        e.to_string(),
        "the station answered RS (SAP not activated): it serves no FMS connection on LSAP 40"
    );
    assert!(run.results.is_empty());
}
