//! Real masters' start-ups replayed to our DP slave configured as the real
//! device: the answers must be byte-identical to the real device's.
//!
//! The traces are public logs of pyprofibus talking to real slaves
//! (pyprofibus issue #7: a TI AM3359 PROFIBUS slave, ident 0x0CDA, at
//! address 2; issue #26: a Siemens ET 200S at address 5). Real slaves
//! answer a Slave_Diag of 6 bytes as SD2 with LE = 0x0B, not SD3.

use profibus::devices::generic::GenericDevice;
use profibus::dp::slave::{DpSlave, Features};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::station::Station;
use profibus::fdl::time::Instant;
use profibus::fdl::{Baud, BusParams};

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

/// Feed each request to the station and compare its answer.
fn replay(station: &mut impl Station, exchanges: &[(&str, &str)]) {
    let mut now = Instant::ZERO;
    for (request, want) in exchanges {
        now += std::time::Duration::from_millis(1);
        station.handle_rx(now, &hex(request));
        let due = station.poll_timeout().expect("an answer is due");
        station.handle_timeout(due);
        let got = station.poll_transmit(due).expect("an answer").to_vec();
        assert_eq!(got, hex(want), "answer to {request}");
        now = due;
    }
}

#[test]
fn ti_slave_start_up_answers_are_byte_identical() {
    let features = Features {
        sync: true,
        freeze: true,
        fail_safe: true,
        ..Features::default()
    };
    let dev = GenericDevice::new("TI AM3359 slave", 0x0CDA, vec![0x11, 0x21], features);
    let mut st = PassiveStation::new(DpSlave::new(dev, 2), BusParams::defaults(Baud::B19200));
    replay(
        &mut st,
        &[
            // FDL status from master 99.
            ("10 02 63 49 AE 16", "10 63 02 00 65 16"),
            // Slave_Diag: Station_Not_Ready, Prm_Req, no master, 0x0CDA.
            (
                "68 05 05 68 82 E3 6D 3C 3E 4C 16",
                "68 0B 0B 68 E3 82 08 3E 3C 02 05 00 FF 0C DA D3 16",
            ),
            // Set_Prm: acknowledged with SC.
            (
                "68 0F 0F 68 82 E3 5D 3D 3E B8 05 01 00 0C DA 01 40 00 00 22 16",
                "E5",
            ),
        ],
    );
}

#[test]
fn et200s_fdl_status_answer_is_byte_identical() {
    let dev = GenericDevice::new(
        "ET 200S",
        0x806A,
        vec![0x00, 0x10, 0x20],
        Features::default(),
    );
    let mut st = PassiveStation::new(DpSlave::new(dev, 5), BusParams::defaults(Baud::B19200));
    replay(&mut st, &[("10 05 02 49 50 16", "10 02 05 00 07 16")]);
}
