//! The slave handles Data_Exchange without allocating: a counting global
//! allocator watches 1000 cycles through the passive station (receive,
//! framing, the slave core, the device, the response) on this thread;
//! and the same for Read, poll and Idle on an open class-2 connection.

use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{expect_cfg, Device, DpSlave, Features, IoLayout, Reason, SlaveState};
use profibus_fdl::station::passive::PassiveStation;
use profibus_fdl::station::Station;
use profibus_fdl::{Baud, BusParams, DataTelegram, FunctionCode, Instant, RequestKind, Telegram};
use profibus_io::alloc_count::{self, Counting};
use std::time::Duration;

#[global_allocator]
static GLOBAL: Counting = Counting;

/// 244 bytes each way; inputs echo the outputs plus a counter.
struct Echo {
    out: [u8; 244],
    n: u8,
}

/// 7 × 32 + 2 × 10 = 244 bytes each way.
const CFG: [u8; 9] = [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x39, 0x39];

impl Device for Echo {
    fn ident_number(&self) -> u16 {
        0x0B0B
    }
    fn real_cfg(&self) -> &[u8] {
        &CFG
    }
    fn features(&self) -> Features {
        Features {
            sync: true,
            freeze: true,
            ..Features::default()
        }
    }
    fn check_prm(&mut self, _: &SetPrm<'_>) -> Result<(), Reason> {
        Ok(())
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        expect_cfg(&CFG, cfg)
    }
    fn write_outputs(&mut self, _: Instant, outputs: &[u8]) {
        self.out[..outputs.len()].copy_from_slice(outputs);
    }
    fn read_inputs(&mut self, _: Instant, inputs: &mut [u8]) {
        self.n = self.n.wrapping_add(1);
        let n = inputs.len();
        inputs.copy_from_slice(&self.out[..n]);
        inputs[0] = self.n;
    }
}

fn emit(buf: &mut [u8], da: u8, fc: FunctionCode, saps: Option<(u8, u8)>, data: &[u8]) -> usize {
    let (dsap, ssap) = saps.unzip();
    let t = DataTelegram::new(da, 2, fc, data).with_saps(dsap, ssap);
    Telegram::Data(t).emit(buf).unwrap()
}

fn exchange<D: Device>(
    st: &mut PassiveStation<DpSlave<D>>,
    now: &mut Instant,
    req: &[u8],
) -> usize {
    st.handle_rx(*now, req);
    let mut n = 0;
    while let Some(t) = st.poll_timeout() {
        if t > *now + Duration::from_millis(1) {
            break;
        }
        *now = t;
        st.handle_timeout(t);
        if let Some(b) = st.poll_transmit(t) {
            n = b.len();
            break;
        }
    }
    *now += Duration::from_micros(100);
    n
}

#[test]
fn data_exchange_does_not_allocate() {
    let mut st = PassiveStation::new(
        DpSlave::new(
            Echo {
                out: [0; 244],
                n: 0,
            },
            8,
        ),
        BusParams::defaults(Baud::B12000000),
    );
    let mut now = Instant::from_nanos(1_000_000);
    let mut buf = [0u8; 300];
    let srd = |fcb| FunctionCode::Request {
        kind: RequestKind::SrdHigh,
        fcb,
        fcv: true,
    };
    let n = emit(
        &mut buf,
        8,
        FunctionCode::Request {
            kind: RequestKind::SrdHigh,
            fcb: true,
            fcv: false,
        },
        Some((61, 62)),
        &[0xB8, 100, 1, 11, 0x0B, 0x0B, 0],
    );
    assert_eq!(exchange(&mut st, &mut now, &buf[..n]), 1);
    let n = emit(&mut buf, 8, srd(false), Some((62, 62)), &CFG);
    assert_eq!(exchange(&mut st, &mut now, &buf[..n]), 1);
    assert_eq!(
        st.app().state(),
        SlaveState::DataExch,
        "{:?}",
        std::iter::from_fn(|| st.app_mut().poll_event()).collect::<Vec<_>>()
    );
    while st.app_mut().poll_event().is_some() {}

    // Prepare the requests up front: outputs change every cycle, FCB
    // toggles, a Global_Control (Operate) follows every Data_Exchange.
    let mut reqs = vec![];
    for i in 0..1000u32 {
        let mut b = vec![0u8; 300];
        let outputs: Vec<u8> = (0..244).map(|k| (k as u32 + i) as u8).collect();
        let n = emit(&mut b, 8, srd(i % 2 == 0), None, &outputs);
        b.truncate(n);
        let mut g = vec![0u8; 32];
        let m = emit(
            &mut g,
            127,
            FunctionCode::request(RequestKind::SdnHigh),
            Some((58, 62)),
            &[0x00, 0x00],
        );
        g.truncate(m);
        reqs.push((b, g, outputs));
    }

    let (lens, allocations) = alloc_count::on_this_thread(|| {
        let mut lens = 0usize;
        for (dx, gc, _) in &reqs {
            lens += exchange(&mut st, &mut now, dx);
            exchange(&mut st, &mut now, gc);
        }
        lens
    });

    // The cycles really ran: 244 inputs in SD2 (244 + 9 bytes) each.
    assert_eq!(lens, 1000 * (244 + 9));
    assert_eq!(st.app().stats().data_exchanges, 1000);
    assert_eq!(st.app().outputs(), &reqs[999].2[..]);
    assert_eq!(allocations, 0, "allocations while handling Data_Exchange");
}

/// A DP-V1 device with class 2: one 16-byte record, no process data.
struct Records {
    record: [u8; 16],
}

impl Device for Records {
    fn ident_number(&self) -> u16 {
        0x0B0C
    }
    fn real_cfg(&self) -> &[u8] {
        &[]
    }
    fn features(&self) -> Features {
        Features {
            dpv1: true,
            c2_read_write: true,
            c2_max_count_channels: 1,
            ..Features::default()
        }
    }
    fn check_prm(&mut self, _: &SetPrm<'_>) -> Result<(), Reason> {
        Ok(())
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        expect_cfg(&[], cfg)
    }
    fn write_outputs(&mut self, _: Instant, _: &[u8]) {}
    fn read_inputs(&mut self, _: Instant, _: &mut [u8]) {}
    fn dpv1_read(
        &mut self,
        _: Instant,
        _slot: u8,
        _index: u8,
        out: &mut [u8],
    ) -> profibus_dp::slave::Dpv1Outcome {
        let n = out.len().min(16);
        out[..n].copy_from_slice(&self.record[..n]);
        self.record[0] = self.record[0].wrapping_add(1);
        profibus_dp::slave::Dpv1Outcome::Done(n)
    }
}

#[test]
fn class2_reads_and_idles_do_not_allocate() {
    let mut st = PassiveStation::new(
        DpSlave::new(Records { record: [7; 16] }, 8),
        BusParams::defaults(Baud::B12000000),
    );
    let mut now = Instant::from_nanos(1_000_000);
    let mut buf = [0u8; 300];
    let mut fcb = false;
    let mut srd = || {
        fcb = !fcb;
        FunctionCode::Request {
            kind: RequestKind::SrdHigh,
            fcb,
            fcv: true,
        }
    };
    // Initiate (Send_Timeout 1 s) and the poll for Initiate.res.
    let initiate = [
        0x57, 0, 0, 0, 0x00, 0x64, 0x01, 0, 0, 0, 0, 0, 0, 2, 0, 2, 0, 0, 0, 0,
    ];
    let n = emit(&mut buf, 8, srd(), Some((49, 50)), &initiate);
    assert_eq!(exchange(&mut st, &mut now, &buf[..n]), 11 + 4, "RM reply");
    let n = emit(&mut buf, 8, srd(), Some((48, 50)), &[]);
    assert_eq!(
        exchange(&mut st, &mut now, &buf[..n]),
        11 + 16,
        "Initiate.res"
    );
    while st.app_mut().poll_event().is_some() {}

    // Read, poll, Idle: 500 rounds, prepared up front.
    let mut reqs = vec![];
    for _ in 0..500 {
        for data in [&[0x5E, 1, 2, 16][..], &[], &[0x48, 0x00]] {
            let mut b = vec![0u8; 64];
            let n = emit(&mut b, 8, srd(), Some((48, 50)), data);
            b.truncate(n);
            reqs.push(b);
        }
    }
    let (lens, allocations) = alloc_count::on_this_thread(|| {
        reqs.iter()
            .map(|r| exchange(&mut st, &mut now, r))
            .sum::<usize>()
    });
    // Per round (SD2 with SAPs: 11 bytes around the data unit): SC (1),
    // the Read.res (11 + 4 + 16), Idle (11 + 2).
    assert_eq!(lens, 500 * (1 + 31 + 13));
    assert_eq!(st.app().c2_connections().count(), 1);
    assert_eq!(allocations, 0, "allocations on a class-2 connection");
}
