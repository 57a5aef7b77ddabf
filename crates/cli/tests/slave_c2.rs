//! `dpctl slave` with a generic DP-V1 device that offers class 2
//! (MSAC_C2), driven byte by byte as a class-2 master from the other end
//! of a socat pty pair: Initiate on SAP 49, I&M0 from the GSD, I&M1
//! written, kept in `--state-dir` and read back after a restart. The
//! class-2 bytes are those of `shared/reference/dpv1-c2-im-alarms.md`.
//!
//! Needs socat; fails when it is missing.

mod common;

use common::*;
use profibus::fdl::{DataTelegram, FunctionCode, Telegram};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

/// A DP-V1 slave with class 2 (two channels), its identity for I&M0.
const GSD: &str = r#"#Profibus_DP
GSD_Revision=3
Vendor_Name="profibus-rs"
Model_Name="dpctl class-2 test slave"
Revision="1.0"
Ident_Number=0x0DCE
Protocol_Ident=0
Station_Type=0
Hardware_Release="3"
Software_Release="V1.2.3"
OrderNumber="DPCTL-C2-1"
9.6_supp=1
19.2_supp=1
187.5_supp=1
1.5M_supp=1
MaxTsdr_9.6=60
MaxTsdr_19.2=60
MaxTsdr_187.5=60
MaxTsdr_1.5M=150
Implementation_Type="software"
Min_Slave_Intervall=1
Max_Diag_Data_Len=32
Modular_Station=0
DPV1_Slave=1
C1_Read_Write_supp=1
C1_Max_Data_Len=240
C2_Read_Write_supp=1
C2_Max_Data_Len=240
C2_Response_Timeout=100
C2_Max_Count_Channels=2
Max_Initiate_PDU_Length=52
Max_User_Prm_Data_Len=3
Ext_User_Prm_Data_Const(0)=0x80,0x00,0x00
Module="2 words in/out" 0x71
EndModule
"#;

const ADDR: u8 = 5;
/// The reference's minimal Initiate.req (Send_Timeout 1 s).
const INITIATE: [u8; 20] = [
    0x57, 0x00, 0x00, 0x00, 0x00, 0x64, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x02,
    0x00, 0x00, 0x00, 0x00,
];

/// The class-2 master's end of the pty pair: SRD requests from station 2
/// with the FCB rule (first frame FCV 0, then alternating).
struct Master {
    line: RawStation,
    fcb: Option<bool>,
}

impl Master {
    fn open(p: &Path) -> Master {
        Master {
            line: RawStation::open(p),
            fcb: None,
        }
    }

    /// The next SRD (high) function code byte.
    fn fc(&mut self) -> u8 {
        let fc = match self.fcb {
            None => 0x6D,
            Some(true) => 0x5D,
            Some(false) => 0x7D,
        };
        self.fcb = Some(fc != 0x5D);
        fc
    }

    /// SRD from SSAP 50 to `dsap` with `data`; the answer's (DSAP, SSAP,
    /// data), or None for a short acknowledge.
    fn c2(&mut self, dsap: u8, data: &[u8]) -> Answer {
        let fc = self.fc();
        let t = DataTelegram::new(ADDR, 2, FunctionCode::from_byte(fc), data)
            .with_saps(Some(dsap), Some(50));
        let req = Telegram::Data(t).to_vec().unwrap();
        self.line.exchange(&req, Duration::from_secs(3))
    }

    /// Request, then one poll: the response.
    fn ask(&mut self, sap: u8, data: &[u8]) -> Vec<u8> {
        assert_eq!(self.c2(sap, data), None, "SC to {data:02X?}");
        let (_, _, d) = self.c2(sap, &[]).expect("the response on the poll");
        d
    }

    /// Initiate, RM reply, poll for Initiate.res: the connection SAP.
    fn initiate(&mut self) -> u8 {
        let (dsap, ssap, rm) = self.c2(49, &INITIATE).expect("RM reply");
        assert_eq!((dsap, ssap), (Some(50), Some(49)));
        assert_eq!(rm.len(), 4);
        assert_eq!(rm[0], 0x56, "RM reply {rm:02X?}");
        let sap = rm[1];
        let (_, _, res) = self.c2(sap, &[]).expect("Initiate.res");
        assert_eq!(
            res,
            [
                0x57, 0xF0, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x02, 0x00, 0x00,
                0x00, 0x00
            ]
        );
        sap
    }

    /// I&M`n` through the call header: select, then read 68 bytes.
    fn read_im(&mut self, sap: u8, n: u8) -> Vec<u8> {
        let select = [0x5F, 0x00, 0xFF, 0x04, 0x08, 0x00, 0xFD, 0xE8 + n];
        assert_eq!(self.ask(sap, &select), [0x5F, 0x00, 0xFF, 0x04]);
        let res = self.ask(sap, &[0x5E, 0x00, 0xFF, 0x44]);
        assert_eq!(
            res[..8],
            [0x5E, 0x00, 0xFF, 0x44, 0x08, 0x00, 0xFD, 0xE8 + n]
        );
        res[8..].to_vec()
    }
}

fn start_slave(port: &Path, gsd: &Path, state: &Path) -> (Proc, Lines) {
    let mut p = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--port"])
            .arg(port)
            .arg("--gsd")
            .arg(gsd)
            // 1.5 Mbit/s (nominal on a pty): the minimum Send_Timeout is 1 s.
            .args(["--addr", "5", "--baud", "1.5M", "--json", "--state-dir"])
            .arg(state)
            .args(["--device-opt", "serial_number=SN-0042"])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit()),
    );
    let lines = started(&mut p, Duration::from_secs(10));
    (p, lines)
}

#[test]
fn class2_i_and_m1_is_kept_across_a_restart() {
    let dir = TempDir::new("slave-c2");
    let (a, b) = (dir.path("m"), dir.path("s"));
    let _socat = pty_pair(&a, &b);
    let gsd = dir.path("C2.GSD");
    std::fs::write(&gsd, GSD).unwrap();
    let state = dir.path("state");
    let (mut slave, mut out) = start_slave(&b, &gsd, &state);
    let mut m = Master::open(&a);

    // Class 2 before any Set_Prm: the slave stays in Wait_Prm.
    let sap = m.initiate();
    assert_eq!(sap, 48, "highest SAP first");
    assert!(
        out.wait_for("\"event\":\"c2_open\"", Duration::from_secs(3)),
        "{:?}",
        out.1
    );

    // I&M0 from the GSD and the options.
    let im0 = m.read_im(sap, 0);
    assert_eq!(&im0[0..10], b"profibus-r", "Vendor_Name in the header");
    assert_eq!(im0[10..12], [0, 0], "MANUFACTURER_ID: not given");
    assert_eq!(&im0[12..32], b"DPCTL-C2-1          ");
    assert_eq!(&im0[32..48], b"SN-0042         ");
    assert_eq!(im0[48..50], [0, 3], "Hardware_Release 3");
    assert_eq!(im0[50..54], [b'V', 1, 2, 3], "Software_Release V1.2.3");
    assert_eq!(im0[62..64], [0x00, 0x1E], "IM_SUPPORTED: I&M1..I&M4");

    // Write I&M1 (TAG_FUNCTION, TAG_LOCATION); it is saved.
    let mut im1 = [b' '; 64];
    im1[10..19].copy_from_slice(b"FEED PUMP");
    im1[42..49].copy_from_slice(b"HALL 3B");
    let write = [&[0x5F, 0x00, 0xFF, 0x44, 0x08, 0x00, 0xFD, 0xE9][..], &im1].concat();
    assert_eq!(m.ask(sap, &write), [0x5F, 0x00, 0xFF, 0x44]);
    assert!(
        out.wait_for("state saved to", Duration::from_secs(3)),
        "{:?}",
        out.1
    );
    assert_eq!(m.read_im(sap, 1), im1);
    // Idle, then Abort closes the connection; its SAP is then inactive.
    assert_eq!(
        m.c2(sap, &[0x48, 0x00]).map(|a| a.2),
        Some(vec![0x48, 0x00])
    );
    assert_eq!(m.c2(sap, &[0x58, 0x00, 0x20, 0x00]), None);
    assert!(out.wait_for("\"event\":\"c2_closed\"", Duration::from_secs(3)));
    assert!(slave.terminate(Duration::from_secs(10)).success());
    let kept = std::fs::read_to_string(state.join("im.toml")).unwrap();
    assert!(kept.contains("im1 = \""), "{kept}");

    // Restarted: I&M1 is still there.
    let (mut slave, _out) = start_slave(&b, &gsd, &state);
    m.fcb = None;
    let sap = m.initiate();
    assert_eq!(m.read_im(sap, 1), im1);
    assert_eq!(m.read_im(sap, 2), [b' '; 64], "I&M2 never written");
    assert!(slave.terminate(Duration::from_secs(10)).success());
}
