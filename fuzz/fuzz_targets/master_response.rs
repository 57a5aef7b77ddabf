//! The DP master's response handler through its FDL active station: every
//! request the master sends gets the reply the input chooses (silence, SC,
//! a response telegram with any status, SAPs and data, a plausible slave
//! reply, raw bytes) after any delay, and the input may submit acyclic
//! jobs (diagnosis, Get_Cfg, Rd_Inp/Outp, Set_Slave_Add, DP-V1 read and
//! write). Checks: no panic; time always advances (no deadline stays due
//! without progress); the master never sends a telegram that does not
//! parse; images keep their configured lengths; diagnosis texts of
//! whatever the master stored never panic.
//!
//! Records: `mode, delay, len, body[len]`, one per request that expects a
//! reply. `mode % 8`: 0 silence, 1 SC, 2 response `fc = body[0]`, SAPs
//! swapped, data `body[1..]`, 3 as 2 with SAPs `body[1]`/`body[2]`, 4 a
//! plausible reply (diagnosis "ready", SC, inputs of the right length
//! from `body`), 5 raw bytes, 6 garbage then the plausible reply, 7 the
//! plausible reply twice. `mode & 0x80`: first submit the job that
//! `body[0..]` describes.
//!
//! Run: `cd fuzz && cargo +nightly fuzz run master_response`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::master::{DpMaster, Job, MasterConfig, MasterOptions, SlaveParams};
use profibus_dp::pdu::sap;
use profibus_fdl::station::active::{ActiveConfig, ActiveStation};
use profibus_fdl::station::Station;
use profibus_fdl::wire::Telegram;
use profibus_fdl::{
    Baud, BusParams, DataTelegram, FunctionCode, Instant, ResponseStatus, StationType,
};
use std::sync::OnceLock;
use std::time::Duration;

const ME: u8 = 2;

fn config() -> MasterConfig {
    let mut params = BusParams::defaults(Baud::B1500000);
    params.hsa = 4;
    let a = SlaveParams::new(8, 0x0DCE, vec![0x11, 0x21]);
    let mut b = SlaveParams::new(9, 0x0008, vec![0x42, 0xC1, 0x02, 0x04]);
    b.dpv1 = true;
    b.user_prm_data = vec![0x80, 0x00, 0x00, 0x05];
    b.watchdog = Some(Duration::from_millis(20));
    let mut c = SlaveParams::new(10, 0x0DC4, vec![0xBF, 0x9F]);
    c.fail_safe = true;
    c.sync = true;
    c.freeze = true;
    c.group = 1;
    MasterConfig {
        address: ME,
        params,
        slaves: vec![a, b, c],
        options: MasterOptions::default(),
    }
}

/// Input bytes of the slave at `addr` in `config` (0 for others).
fn input_len(addr: u8) -> usize {
    static LENS: OnceLock<Vec<(u8, usize)>> = OnceLock::new();
    LENS.get_or_init(|| {
        config()
            .slaves
            .iter()
            .map(|s| (s.address, s.io_lengths().unwrap().0))
            .collect()
    })
    .iter()
    .find(|(a, _)| *a == addr)
    .map_or(0, |(_, n)| *n)
}

fn ident(addr: u8) -> u16 {
    match addr {
        8 => 0x0DCE,
        9 => 0x0008,
        _ => 0x0DC4,
    }
}

/// What a healthy slave answers to `req`.
fn plausible(req: &DataTelegram<'_>, body: &[u8], out: &mut [u8]) -> usize {
    let resp = |dsap, ssap, data: &[u8], out: &mut [u8]| {
        Telegram::Data(DataTelegram {
            da: req.sa,
            sa: req.da,
            fc: FunctionCode::Response {
                status: ResponseStatus::Dl,
                station: StationType::Passive,
            },
            dsap,
            ssap,
            data,
            format: None,
        })
        .emit(out)
        .unwrap_or(0)
    };
    match req.dsap {
        Some(sap::SLAVE_DIAG) => {
            let id = ident(req.da);
            let st1 = body.first().copied().unwrap_or(0) & 0x0A;
            let mut d = vec![st1, 0x0C, 0x00, ME, (id >> 8) as u8, id as u8];
            d.extend(body.iter().skip(1).take(8));
            resp(req.ssap, req.dsap, &d, out)
        }
        Some(sap::MSAC_C1) => {
            let mut d = req.data.get(..4).unwrap_or(req.data).to_vec();
            if let Some(&n) = d.get(3) {
                d.extend(body.iter().cycle().take(n as usize));
            }
            resp(req.ssap, req.dsap, &d[..d.len().min(244)], out)
        }
        Some(sap::GET_CFG) | Some(sap::RD_INP) | Some(sap::RD_OUTP) | None
            if req.data.len() < 250 =>
        {
            let n = if req.dsap.is_none() {
                input_len(req.da)
            } else {
                body.len().min(32)
            };
            let d: Vec<u8> = body.iter().copied().cycle().take(n).collect();
            let d = if d.len() < n { vec![0; n] } else { d };
            resp(req.ssap, req.dsap, &d, out)
        }
        _ => Telegram::ShortAck.emit(out).unwrap_or(0),
    }
}

fn job(body: &[u8]) -> Option<Job> {
    let [k, a, x, y, rest @ ..] = body else {
        return None;
    };
    let address = 8 + a % 4;
    Some(match k % 7 {
        0 => Job::ReadDiag { address },
        1 => Job::GetCfg { address },
        2 => Job::RdInp { address },
        3 => Job::RdOutp { address },
        4 => Job::SetSlaveAdd {
            address,
            new_address: *x,
            ident_number: ident(address),
            no_add_chg: y & 1 != 0,
        },
        5 => Job::Dpv1Read {
            address,
            slot: *x,
            index: *y,
            length: rest.first().copied().unwrap_or(4),
        },
        _ => Job::Dpv1Write {
            address,
            slot: *x,
            index: *y,
            data: rest.to_vec(),
        },
    })
}

fuzz_target!(|data: &[u8]| {
    let cfg = config();
    let mut st = ActiveStation::new(
        ActiveConfig::new(ME, cfg.params),
        DpMaster::new(&cfg).unwrap(),
    );
    let mut now = Instant::ZERO;
    let mut rest = data;
    let mut out = [0u8; 600];
    let mut stuck = 0u32;
    let mut steps = 0u32;
    loop {
        steps += 1;
        if steps > 20_000 {
            break;
        }
        // Everything the station wants to send now.
        let mut reply: Option<(Duration, Vec<u8>)> = None;
        while let Some(bytes) = st.poll_transmit(now) {
            let (tel, n) = Telegram::parse(bytes).expect("the master sends valid telegrams");
            assert_eq!(n, bytes.len(), "one telegram per transmission");
            let Telegram::Data(req) = tel else { continue };
            let FunctionCode::Request { kind, .. } = req.fc else {
                panic!("the master sent a response {req:?}");
            };
            if req.da == 127 || !kind.expects_reply() || req.da == ME {
                continue;
            }
            let [mode, delay, len, tail @ ..] = rest else {
                // Input used up: silence from now on.
                continue;
            };
            let n = (*len as usize).min(tail.len());
            let (body, tail) = tail.split_at(n);
            rest = tail;
            let mut bytes = Vec::new();
            let mut tel = |t: Telegram<'_>, bytes: &mut Vec<u8>| {
                let m = t.emit(&mut out).unwrap_or(0);
                bytes.extend_from_slice(&out[..m]);
            };
            let good = |bytes: &mut Vec<u8>| {
                let mut o = [0u8; 600];
                let m = plausible(&req, body, &mut o);
                bytes.extend_from_slice(&o[..m]);
            };
            match mode % 8 {
                0 => {}
                1 => tel(Telegram::ShortAck, &mut bytes),
                2 | 3 => {
                    let (fc, saps, data) = match (mode % 8, body) {
                        (2, [fc, d @ ..]) => (*fc, (req.ssap, req.dsap), d),
                        (3, [fc, s1, s2, d @ ..]) => (
                            *fc,
                            (
                                (*s1 != 0xFF).then_some(*s1 & 0x3F),
                                (*s2 != 0xFF).then_some(*s2 & 0x3F),
                            ),
                            d,
                        ),
                        _ => (0x08, (req.ssap, req.dsap), &[][..]),
                    };
                    let data = &data[..data.len().min(244)];
                    tel(
                        Telegram::Data(DataTelegram {
                            da: req.sa,
                            sa: req.da,
                            fc: FunctionCode::from_byte(fc & 0x3F),
                            dsap: saps.0,
                            ssap: saps.1,
                            data,
                            format: None,
                        }),
                        &mut bytes,
                    );
                }
                4 => good(&mut bytes),
                5 => bytes.extend_from_slice(body),
                6 => {
                    bytes.extend_from_slice(&body[..body.len().min(3)]);
                    good(&mut bytes);
                }
                _ => {
                    good(&mut bytes);
                    good(&mut bytes);
                }
            }
            if mode & 0x80 != 0 {
                if let Some(j) = job(body) {
                    let _ = st.app_mut().submit(j);
                }
            }
            reply = Some((Duration::from_micros(*delay as u64 * 4), bytes));
        }
        if let Some((delay, bytes)) = reply {
            now += delay;
            if st.poll_timeout().is_some_and(|t| t <= now) {
                st.handle_timeout(now);
            }
            if !bytes.is_empty() {
                st.handle_rx(now, &bytes);
            }
            continue;
        }
        if rest.len() < 3 {
            break;
        }
        // Nothing to send: on to the next deadline.
        let Some(t) = st.poll_timeout() else { break };
        if t <= now {
            stuck += 1;
            assert!(stuck < 100, "deadline {t} stays due at {now}");
        } else {
            stuck = 0;
        }
        now = now.max(t);
        st.handle_timeout(now);
    }
    let m = st.app_mut();
    for a in [8u8, 9, 10] {
        let Some(h) = m.handle(a) else { continue };
        let v = m.slave(h);
        assert!(
            v.inputs.len() <= input_len(a),
            "inputs of {a}: {:?}",
            v.inputs
        );
        assert_eq!(
            v.outputs.len(),
            m.slave_params(a).unwrap().io_lengths().unwrap().1
        );
        if let Some(d) = m.diag(a) {
            let _ = profibus_dp::pdu::diag::describe(d, None, a == 9);
        }
    }
    while m.poll_event().is_some() {}
});
