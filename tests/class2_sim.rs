//! The class-2 master core against the DP slave core on the simulated
//! bus (virtual time), next to a class-1 master that keeps its slaves in
//! Data_Exchange: two connections to two slaves at once (I&M0 on one, a
//! record write and read on the other), an idle connection kept open by
//! Idle for several Send_Timeouts while one without Idle is aborted by
//! the slave (TO, in words), and the slaves never leave Data_Exchange.

use profibus::devices::generic::InputPattern;
use profibus::dp::class2::{
    Class2Config, Class2Event, Class2Master, ConnId, RecordAnswer, RecordOp,
};
use profibus::dp::config::gsd::{Gsd, ParseOptions};
use profibus::dp::master::{DpMaster, MasterEvent, SlaveState};
use profibus::dp::pdu::im::{CallHeader, Im0};
use profibus::fdl::sim::{SimBus, StationId};
use profibus::fdl::station::active::{ActiveConfig, ActiveStation};
use profibus::fdl::Baud;
use profibus_plant::{MasterStation, Plant};
use std::time::Duration;

type C2 = ActiveStation<Class2Master>;

/// The generic GSD with class 2 (2 connections).
fn gsd() -> Gsd {
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/devices/gsd/DPCTL_GEN.GSD"),
    )
    .unwrap()
    .replace(
        "C1_Response_Timeout=100",
        "C1_Response_Timeout=100\nC2_Read_Write_supp=1\nC2_Max_Data_Len=240\n\
         C2_Response_Timeout=300\nC2_Max_Count_Channels=2",
    );
    Gsd::parse(&text, ParseOptions::default()).unwrap().gsd
}

/// Master 2 with slaves 10 and 11 in Data_Exchange, and the class-2
/// master 3 (Send_Timeout 1 s) on the same line.
struct Line {
    bus: SimBus,
    master: StationId,
    c2: StationId,
}

impl Line {
    fn new(idle: Option<Duration>) -> Line {
        let gsd = gsd();
        let module = ["2 words in/out"];
        let s = Plant::builder()
            .baud(Baud::B1500000)
            .master(2)
            .generic(10, "a", &gsd, &module, InputPattern::Echo)
            .unwrap()
            .generic(11, "b", &gsd, &module, InputPattern::Echo)
            .unwrap()
            .stations()
            .unwrap();
        let mut bus = SimBus::new(s.medium);
        let master = bus.add(s.master);
        for (_, st) in s.slaves {
            bus.add(st);
        }
        let mut cfg = Class2Config::for_baud(Baud::B1500000);
        cfg.send_timeout = Duration::from_secs(1);
        cfg.idle_interval = idle;
        let c2 = bus.add(ActiveStation::new(
            ActiveConfig::new(3, s.params),
            Class2Master::new(cfg),
        ));
        let mut line = Line { bus, master, c2 };
        let dx = |l: &Line| {
            [10, 11]
                .iter()
                .all(|a| l.state(*a) == Some(SlaveState::DataExchange))
        };
        let end = line.bus.now() + Duration::from_secs(2);
        while !dx(&line) {
            assert!(line.bus.now() < end, "start-up");
            line.bus.run_for(Duration::from_millis(1));
        }
        while line.dp().poll_event().is_some() {}
        line
    }

    fn dp(&mut self) -> &mut DpMaster {
        self.bus.station_mut::<MasterStation>(self.master).app_mut()
    }

    fn state(&self, a: u8) -> Option<SlaveState> {
        self.bus
            .station::<MasterStation>(self.master)
            .app()
            .slave_state(a)
    }

    fn c2(&mut self) -> &mut Class2Master {
        self.bus.station_mut::<C2>(self.c2).app_mut()
    }

    fn now(&self) -> profibus::fdl::Instant {
        self.bus.now()
    }
}

/// Run for `d` in 1 ms steps, checking the class-2 timeouts, with the
/// class-1 master's slaves in Data_Exchange at every step; the class-2
/// events of that time.
fn run(line: &mut Line, d: Duration) -> Vec<Class2Event> {
    let end = line.now() + d;
    let mut events = Vec::new();
    while line.now() < end {
        line.bus.run_for(Duration::from_millis(1));
        let now = line.now();
        let m = line.c2();
        m.handle_time(now);
        events.extend(std::iter::from_fn(|| m.poll_event()));
        for a in [10, 11] {
            assert_eq!(
                line.state(a),
                Some(SlaveState::DataExchange),
                "slave {a} left Data_Exchange at {now:?}"
            );
        }
        while let Some(e) = line.dp().poll_event() {
            assert!(
                !matches!(
                    e,
                    MasterEvent::StateChanged { .. } | MasterEvent::Fault { .. }
                ),
                "{e:?}"
            );
        }
    }
    events
}

fn answers(events: &[Class2Event], conn: ConnId) -> Vec<RecordAnswer> {
    events
        .iter()
        .filter_map(|e| match e {
            Class2Event::Answer {
                conn: c, answer, ..
            } if *c == conn => Some(answer.clone()),
            _ => None,
        })
        .collect()
}

#[test]
fn two_connections_at_once_next_to_the_class_1_master() {
    let mut line = Line::new(None);
    let now = line.now();
    let m = line.c2();
    let a = m.connect(10, now);
    let b = m.connect(11, now);
    let call = CallHeader::im(0).bytes().to_vec();
    for op in [
        RecordOp::Write {
            slot: 0,
            index: 255,
            data: call,
        },
        RecordOp::Read {
            slot: 0,
            index: 255,
            length: 68,
        },
    ] {
        m.request(a, op).unwrap();
    }
    for op in [
        RecordOp::Write {
            slot: 1,
            index: 7,
            data: vec![0xCA, 0xFE],
        },
        RecordOp::Read {
            slot: 1,
            index: 7,
            length: 2,
        },
    ] {
        m.request(b, op).unwrap();
    }
    let events = run(&mut line, Duration::from_millis(500));
    let opened: Vec<u8> = events
        .iter()
        .filter_map(|e| match e {
            Class2Event::Opened { slave, .. } => Some(*slave),
            _ => None,
        })
        .collect();
    assert_eq!(opened.len(), 2, "{events:#?}");
    let a_answers = answers(&events, a);
    assert_eq!(a_answers.len(), 2, "{events:#?}");
    let RecordAnswer::Read(im) = &a_answers[1] else {
        panic!("{a_answers:?}");
    };
    let (h, record) = CallHeader::parse(im).unwrap();
    assert_eq!(h.im_number(), Some(0));
    assert_eq!(Im0::parse(record).unwrap().order_id(), "DPCTL-GEN");
    assert_eq!(
        answers(&events, b),
        vec![
            RecordAnswer::Written(2),
            RecordAnswer::Read(vec![0xCA, 0xFE])
        ]
    );
    let m = line.c2();
    m.close(a);
    m.close(b);
    let events = run(&mut line, Duration::from_millis(100));
    let closed: Vec<_> = events
        .iter()
        .filter_map(|e| match e {
            Class2Event::Closed { error, .. } => Some(error.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(closed, vec![None, None]);
    assert_eq!(line.c2().connections(), 0);
}

#[test]
fn idle_keeps_a_connection_open_for_many_send_timeouts() {
    let mut line = Line::new(None);
    let now = line.now();
    let a = line.c2().connect(10, now);
    let events = run(&mut line, Duration::from_secs(5));
    assert!(
        events
            .iter()
            .all(|e| !matches!(e, Class2Event::Closed { .. })),
        "{events:#?}"
    );
    assert!(line.c2().is_open(a));
    // Still usable.
    line.c2()
        .request(
            a,
            RecordOp::Read {
                slot: 0,
                index: 1,
                length: 1,
            },
        )
        .unwrap();
    let events = run(&mut line, Duration::from_millis(200));
    assert_eq!(answers(&events, a).len(), 1, "{events:#?}");
}

#[test]
fn without_idle_the_slave_drops_the_connection_after_send_timeout() {
    // Idle only after 10 s: the slave's Send_Timeout (1 s) runs out
    // first, and the next request meets a connection the slave dropped.
    let mut line = Line::new(Some(Duration::from_secs(10)));
    let now = line.now();
    let a = line.c2().connect(10, now);
    run(&mut line, Duration::from_secs(2));
    line.c2()
        .request(
            a,
            RecordOp::Read {
                slot: 0,
                index: 1,
                length: 1,
            },
        )
        .unwrap();
    let events = run(&mut line, Duration::from_secs(3));
    let closed = events.iter().find_map(|e| match e {
        Class2Event::Closed { error, .. } => Some(error.clone()),
        _ => None,
    });
    let e = closed.flatten().expect("closed with an error").to_string();
    assert_eq!(
        e,
        "slave 10 aborted the connection: aborted by MSAC_C2: connection timeout (TO)"
    );
}
