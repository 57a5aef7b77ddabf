//! `dpctl slave` against the DP master of the `profirust` crate
//! (crates.io), a second independent implementation, over a socat pty
//! pair. profirust sends Set_Prm, Chk_Cfg and Slave_Diag as SRD low
//! (pyprofibus uses SRD high), passes the token to itself and polls its
//! GAP; the slave must reach Data_Exchange and echo changing outputs.
//!
//! The parameters and configuration come from `crates/devices/gsd/DPCTL_GEN.GSD` through
//! this stack's GSD parser (profirust has no GSD parser of its own).
//!
//! profirust's own PHYs cannot open a pty: `LinuxRs485Phy` asserts that
//! even parity was accepted, which Linux ptys clear, and `SerialPortPhy`
//! needs libudev and unwraps a low-latency ioctl that ptys refuse. So the
//! test runs profirust's FDL station and DP master on [`PtyPhy`], a
//! non-blocking pty implementation of profirust's `ProfibusPhy` trait
//! that does what `LinuxRs485Phy` does minus the termios checks.
//!
//! Needs socat; fails when it is missing.

mod common;

use common::*;
use profibus::dp::config::gsd::{Gsd, ParseOptions};
use profirust::{dp, fdl, phy};
use std::io::{Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// profirust's `ProfibusPhy` on a non-blocking pty (see the module docs).
struct PtyPhy {
    file: std::fs::File,
    rx: Vec<u8>,
    rx_len: usize,
    /// Bytes of the telegram being sent, and how many were written.
    tx: Option<(Vec<u8>, usize)>,
}

impl PtyPhy {
    fn open(path: &std::path::Path) -> PtyPhy {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(nix::fcntl::OFlag::O_NONBLOCK.bits() | nix::fcntl::OFlag::O_NOCTTY.bits())
            .open(path)
            .expect("open the master's pty");
        PtyPhy {
            file,
            rx: vec![0; 512],
            rx_len: 0,
            tx: None,
        }
    }

    fn write_some(&mut self, buf: &[u8]) -> usize {
        match self.file.write(buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => 0,
            Err(e) => panic!("pty write: {e}"),
        }
    }
}

impl phy::ProfibusPhy for PtyPhy {
    fn poll_transmission(&mut self, _now: profirust::time::Instant) -> bool {
        let Some((buf, done)) = self.tx.take() else {
            return false;
        };
        if done < buf.len() {
            let n = self.write_some(&buf[done..]);
            self.tx = Some((buf, done + n));
            true
        } else {
            false
        }
    }

    fn transmit_data<F, R>(&mut self, _now: profirust::time::Instant, f: F) -> R
    where
        F: FnOnce(&mut [u8]) -> (usize, R),
    {
        assert!(self.tx.is_none(), "transmit_data() while transmitting");
        let mut buf = vec![0u8; 512];
        let (len, res) = f(&mut buf);
        if len > 0 {
            buf.truncate(len);
            let n = self.write_some(&buf);
            self.tx = Some((buf, n));
        }
        res
    }

    fn receive_data<F, R>(&mut self, _now: profirust::time::Instant, f: F) -> R
    where
        F: FnOnce(&[u8]) -> (usize, R),
    {
        assert!(self.tx.is_none(), "receive_data() while transmitting");
        match self.file.read(&mut self.rx[self.rx_len..]) {
            Ok(n) => self.rx_len += n,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(e) => panic!("pty read: {e}"),
        }
        let (drop, res) = f(&self.rx[..self.rx_len]);
        let drop = drop.min(self.rx_len);
        self.rx.copy_within(drop..self.rx_len, 0);
        self.rx_len -= drop;
        res
    }
}

#[test]
fn profirust_master_reaches_data_exchange_with_dpctl_slave() {
    let dir = TempDir::new("profirust");
    let (a, b) = (dir.path("master"), dir.path("slave"));
    let _socat = pty_pair(&a, &b);
    let gsd_path = repo().join("crates/devices/gsd/DPCTL_GEN.GSD");
    let gsd = Gsd::from_file(&gsd_path, ParseOptions::STRICT)
        .expect("DPCTL_GEN.GSD parses")
        .gsd;
    let module = "2 words in/out";
    let sel = gsd.select(&[module]).unwrap();
    let user_prm = gsd.user_prm_data(&sel, &[]).unwrap();
    let cfg = gsd.chk_cfg(&sel).unwrap();

    let mut slave = Proc::spawn(
        "dpctl slave",
        Command::new(dpctl())
            .args(["slave", "--port"])
            .arg(&b)
            .args(["--addr", "9", "--baud", "500000", "--gsd"])
            .arg(&gsd_path)
            .args(["--module", module, "--inputs", "echo", "--json"])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit()),
    );
    let mut slave_out = started(&mut slave, Duration::from_secs(10));

    // profirust's master, as its examples set it up for a USB-RS485
    // adapter: a long slot time and retries for a non-real-time OS.
    let baud = profirust::Baudrate::B500000;
    let mut dp_master = dp::DpMaster::new(vec![]);
    let options = dp::PeripheralOptions {
        ident_number: gsd.ident_number,
        user_parameters: Some(&user_prm),
        config: Some(&cfg),
        max_tsdr: gsd.max_tsdr(profibus::fdl::Baud::B500000).unwrap_or(100) as u16,
        fail_safe: false,
        ..Default::default()
    };
    let mut pi_i = [0u8; 4];
    let mut pi_q = [0u8; 4];
    let handle = dp_master.add(dp::Peripheral::new(
        9,
        options,
        &mut pi_i[..],
        &mut pi_q[..],
    ));
    let mut station = fdl::FdlActiveStation::new(
        fdl::ParametersBuilder::new(2, baud)
            .slot_bits(4000)
            .max_retry_limit(3)
            .watchdog_timeout(profirust::time::Duration::from_secs(2))
            .build_verified(&dp_master),
    );
    let mut phy = PtyPhy::open(&a);
    station.set_online();
    dp_master.enter_operate();

    let start = Instant::now();
    let mut configured = false;
    let mut sent: Option<[u8; 4]> = None;
    let mut echoed = 0u32;
    let mut n = 0u32;
    while echoed < 200 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no Data_Exchange with profirust after {:?} (configured: {configured}, \
             {echoed} echoes); slave said: {:?}",
            start.elapsed(),
            slave_out.1
        );
        station.poll(profirust::time::Instant::now(), &mut phy, &mut dp_master);
        let events = dp_master.take_last_events();
        if let Some((_, ev)) = events.peripheral {
            match ev {
                dp::PeripheralEvent::Configured => configured = true,
                dp::PeripheralEvent::ConfigError | dp::PeripheralEvent::ParameterError => {
                    panic!("profirust: {ev:?}; slave said: {:?}", slave_out.1)
                }
                _ => {}
            }
        }
        if events.cycle_completed {
            let p = dp_master.get_mut(handle);
            if p.is_running() {
                // The echo answers the outputs of the same exchange: the
                // value set one cycle ago was sent in this one.
                if let Some(s) = sent {
                    if p.pi_i() == s {
                        echoed += 1;
                    }
                }
                n += 1;
                let next = (n.wrapping_mul(0x0101_0101) ^ 0x5A00_00A5).to_be_bytes();
                p.pi_q_mut().copy_from_slice(&next);
                sent = Some(next);
            }
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    assert!(configured);

    let st = slave.terminate(Duration::from_secs(10));
    assert!(st.success(), "dpctl slave exited with {st}");
    let events = json_lines(slave_out.rest());
    let prm = events
        .iter()
        .find(|v| v["event"] == "prm_ok")
        .expect("Set_Prm accepted");
    assert_eq!(prm["master"], 2);
    assert_eq!(prm["watchdog_ms"], 2000);
    assert!(events
        .iter()
        .any(|v| v["event"] == "state" && v["to"] == "Data_Exch"));
    for bad in ["prm_fault", "cfg_fault", "watchdog"] {
        assert!(
            !events.iter().any(|v| v["event"] == bad),
            "slave reported {bad}: {events:?}"
        );
    }
    let stopped = events.iter().find(|v| v["event"] == "stopped").unwrap();
    assert!(stopped["data_exchanges"].as_u64().unwrap() >= 200);
}
