//! An FMS exchange on a `dpctl bus`, heard by `dpctl sniff` (shared by
//! fms_sniff.rs and wireshark.rs): a `dpctl slave --device bk3000
//! --device-opt fms=mixed` (station 5; KL3102, KL4002, KL9010) answers,
//! `dpctl sniff --json --pcap` and `dpctl sniff --plain` listen, and the
//! test is the FMS client (station 3, LSAP 33 → the coupler's LSAP 40):
//! it writes each SRD request itself, built with the library's LLI and
//! FMS encoders, and waits for the answer before the next one.

// Each test binary uses a part.
#![allow(dead_code)]

use crate::common::{dpctl, started, Bus, Proc, TempDir};
use profibus::dp::fms::client::default_initiate;
use profibus::dp::fms::lli::{LliPdu, ABORT_USER};
use profibus::dp::fms::pdu::{FmsPdu, GetOdRequest, Request};
use profibus::fdl::{DataTelegram, FunctionCode, RequestKind, Telegram};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

/// The coupler's station address and FMS LSAP (KBL entry 1, mixed mode).
pub const SERVER: u8 = 5;
/// The coupler's LSAP of KBL entry 1.
pub const SERVER_LSAP: u8 = 40;
/// The client's station address and LSAP.
pub const CLIENT: u8 = 3;
/// The client's LSAP.
pub const CLIENT_LSAP: u8 = 33;

/// What the sniffers heard.
pub struct Capture {
    /// `dpctl sniff --json`, one line each.
    pub json: Vec<serde_json::Value>,
    /// `dpctl sniff --plain`, one line each.
    pub plain: Vec<String>,
    /// `dpctl sniff --pcap`.
    pub pcap: PathBuf,
    /// Keeps the capture file.
    _dir: TempDir,
}

/// The FMS client's end of the bus: SRD low requests with the FCB rule.
struct Client {
    line: crate::common::RawStation,
    fcb: Option<bool>,
}

impl Client {
    fn open(p: &Path) -> Client {
        Client {
            line: crate::common::RawStation::open(p),
            fcb: None,
        }
    }

    /// SRD low to the coupler's LSAP with `du`; the answer's data unit
    /// (empty for a short acknowledge or a response without data).
    fn srd(&mut self, du: &[u8]) -> Vec<u8> {
        let (fcb, fcv) = match self.fcb {
            None => (true, false),
            Some(b) => (!b, true),
        };
        self.fcb = Some(fcb);
        let fc = FunctionCode::Request {
            kind: RequestKind::SrdLow,
            fcb,
            fcv,
        };
        let t = DataTelegram::new(SERVER, CLIENT, fc, du)
            .with_saps(Some(SERVER_LSAP), Some(CLIENT_LSAP));
        let req = Telegram::Data(t).to_vec().unwrap();
        match self.line.exchange(&req, Duration::from_secs(10)) {
            Some((_, _, data)) => data,
            None => vec![],
        }
    }

    /// A confirmed FMS request; the answer's FMS PDU.
    fn confirmed(&mut self, invoke_id: u8, request: Request) -> FmsPdu {
        let du = FmsPdu::Request { invoke_id, request }.to_vec().unwrap();
        let answer = self.srd(&du);
        match LliPdu::parse(&answer) {
            Ok(LliPdu::Data(p)) => p,
            other => panic!("answer to invoke {invoke_id}: {answer:02X?} {other:?}"),
        }
    }
}

fn sniff(bus: &Bus, extra: &[&str]) -> Proc {
    let mut cmd = Command::new(dpctl());
    cmd.args(["sniff", "--baud", "1.5M"]).args(extra);
    // Each sniffer on its own link.
    let link = if extra.contains(&"--plain") { 3 } else { 1 };
    cmd.args(["--port", &bus.link_str(link)]);
    Proc::spawn_captured(cmd)
}

/// Runs the exchange and returns what the sniffers heard: Associate
/// (monitoring 2 s), Identify (invoke 1), Read 2020 (2), Write 2041 (3),
/// Read of object 9999 that does not exist (4), Get-OD of 2020 (5), a
/// garbled PDU (rejected), an empty poll, and Abort.
pub fn record() -> Capture {
    let dir = TempDir::new("fms-capture");
    let pcap = dir.path("fms.pcapng");
    let bus = Bus::start(4, &["--baud", "1.5M"]);
    let mut slave = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--device", "bk3000"])
            .args(["--terminals", "KL3102,KL4002,KL9010"])
            .args(["--device-opt", "fms=mixed", "--switch-ones", "5"])
            .args(["--baud", "1.5M", "--json", "--port", &bus.link_str(0)])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit()),
    );
    let _slave_out = started(&mut slave, Duration::from_secs(30));
    let json = sniff(&bus, &["--json", "--pcap", pcap.to_str().unwrap()]);
    let plain = sniff(&bus, &["--plain"]);
    let mut client = Client::open(&bus.link(2));
    bus.wait_connected(4);

    let associate = LliPdu::Associate {
        monitoring: Some(Duration::from_secs(2)),
        initiate: default_initiate(),
    };
    let answer = client.srd(&associate.to_vec().unwrap());
    assert!(
        matches!(LliPdu::parse(&answer), Ok(LliPdu::Associated(Ok(_)))),
        "Associate answered {answer:02X?}"
    );
    let read = |index| Request::Read {
        index,
        subindex: None,
    };
    for (invoke, request) in [
        (1, Request::Identify),
        (2, read(2020)),
        (
            3,
            Request::Write {
                index: 2041,
                subindex: None,
                data: vec![0x00, 0x20, 0x00],
            },
        ),
        (4, read(9999)),
        (
            5,
            Request::GetOd(GetOdRequest {
                long_form: false,
                from_index: false,
                index: 2020,
            }),
        ),
    ] {
        let answer = client.confirmed(invoke, request);
        assert_eq!(answer.invoke_id(), Some(invoke), "{answer}");
    }
    // A confirmed request of an unknown service: the server rejects it.
    let answer = client.srd(&[1, 6, 9]);
    assert!(
        matches!(
            LliPdu::parse(&answer),
            Ok(LliPdu::Data(FmsPdu::Reject { .. }))
        ),
        "{answer:02X?}"
    );
    client.srd(&[]);
    let abort = LliPdu::Abort {
        reason: ABORT_USER,
        detail: 0,
    };
    client.srd(&abort.to_vec().unwrap());

    // Both sniffers have heard the Abort (and its answer) once they
    // print it; then they stop and flush.
    json.wait_stdout("the Abort", 1, |l| l.contains(r#""lli":"abort""#));
    plain.wait_stdout("the Abort", 1, |l| l.contains("LLI Abort"));
    let json_out = json.stop();
    let plain_out = plain.stop();
    assert!(json_out.status.success(), "{}", json_out.stderr);
    assert!(plain_out.status.success(), "{}", plain_out.stderr);
    drop(client);
    drop(slave);
    bus.stop();
    Capture {
        json: crate::common::json_lines(json_out.stdout.lines()),
        plain: plain_out.stdout.lines().map(str::to_string).collect(),
        pcap,
        _dir: dir,
    }
}
