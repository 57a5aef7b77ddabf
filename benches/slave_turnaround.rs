//! Slave turnaround: the time from reading the last byte of a
//! Data_Exchange request to writing the first byte of the response.
//!
//! Two measurements, each with p50 / p99 / p99.9 / max:
//!
//! 1. **in-process**: `PassiveStation<DpSlave<GenericDevice>>` fed the
//!    request bytes (`handle_rx`) until it hands out the response
//!    (`poll_transmit` at the min TSDR deadline, 11 bit times at
//!    12 Mbit/s), wall clock on one thread. This is the processing time.
//! 2. **socat pty pair**: the slave runs on the tokio driver on one end of
//!    a socat pty pair (nominal 12 Mbit/s), a master thread sends
//!    Data_Exchange requests on the other end and waits for each answer.
//!    A wrapper around the slave's port timestamps the read that
//!    completed the request and the write of the response. The master's
//!    round trip (through socat twice) is reported too, next to a raw
//!    pty echo round trip as the baseline.
//!
//! Run: `cargo bench -p profibus --bench slave_turnaround` (needs socat).
//! Environment: `TURNAROUND_CYCLES` (default 50000).

use profibus::devices::generic::{GenericDevice, InputPattern};
use profibus::dp::slave::{DpSlave, Features, SlaveState};
use profibus::fdl::station::passive::PassiveStation;
use profibus::fdl::station::Station;
use profibus::fdl::{Baud, BusParams, DataTelegram, FunctionCode, Instant, RequestKind, Telegram};
use profibus_io::driver::{self, Clock};
use profibus_io::transport::Port;
use std::io::{Read, Write};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

const IDENT: u16 = 0x0DCE;
/// 32 bytes in and 32 out: two in+out identifiers of 16 bytes.
const CFG: [u8; 2] = [0x3F, 0x3F];
const IO: usize = 32;
const ADDR: u8 = 8;
const MASTER: u8 = 2;

fn device() -> GenericDevice {
    GenericDevice::new("bench", IDENT, CFG.to_vec(), Features::default())
        .with_inputs(InputPattern::Echo)
}

fn telegram(fc: FunctionCode, saps: Option<(u8, u8)>, data: &[u8]) -> Vec<u8> {
    let mut b = vec![0u8; 300];
    let n = Telegram::Data(DataTelegram {
        da: ADDR,
        sa: MASTER,
        fc,
        dsap: saps.map(|s| s.0),
        ssap: saps.map(|s| s.1),
        data,
        format: None,
    })
    .emit(&mut b)
    .unwrap();
    b.truncate(n);
    b
}

fn srd(fcb: bool, fcv: bool) -> FunctionCode {
    FunctionCode::Request {
        kind: RequestKind::SrdHigh,
        fcb,
        fcv,
    }
}

/// Set_Prm (Lock, WD 10 s, min TSDR 11), Chk_Cfg, then `n` Data_Exchange
/// requests with changing outputs and toggling FCB.
fn requests(n: usize) -> (Vec<Vec<u8>>, Vec<Vec<u8>>) {
    let setup = vec![
        telegram(
            srd(true, false),
            Some((61, 62)),
            &[0x88, 100, 10, 11, (IDENT >> 8) as u8, IDENT as u8, 0],
        ),
        telegram(srd(false, true), Some((62, 62)), &CFG),
    ];
    let dx = (0..n)
        .map(|i| {
            let out: Vec<u8> = (0..IO).map(|k| (i + k) as u8).collect();
            telegram(srd(i % 2 == 0, true), None, &out)
        })
        .collect();
    (setup, dx)
}

fn percentiles(name: &str, mut ns: Vec<u64>) {
    ns.sort_unstable();
    let p = |q: f64| ns[((ns.len() as f64 * q) as usize).min(ns.len() - 1)] as f64 / 1000.0;
    println!(
        "{name:<44} n={:<7} p50 {:>7.2} µs  p99 {:>7.2} µs  p99.9 {:>7.2} µs  max {:>8.2} µs",
        ns.len(),
        p(0.50),
        p(0.99),
        p(0.999),
        *ns.last().unwrap() as f64 / 1000.0
    );
}

fn in_process(cycles: usize) {
    let params = BusParams::defaults(Baud::B12000000);
    let mut st = PassiveStation::new(DpSlave::new(device(), ADDR), params);
    let (setup, dx) = requests(cycles + 1000);
    let mut now = Instant::from_nanos(1_000_000);
    let step = Duration::from_micros(50);
    let exchange = |st: &mut PassiveStation<DpSlave<GenericDevice>>, req: &[u8], now: Instant| {
        let t0 = std::time::Instant::now();
        st.handle_rx(now, req);
        let due = st.poll_timeout().expect("a response is due");
        st.handle_timeout(due);
        let n = st.poll_transmit(due).map(|b| b.len()).unwrap_or(0);
        (t0.elapsed().as_nanos() as u64, n)
    };
    for r in &setup {
        exchange(&mut st, r, now);
        now += step;
    }
    assert_eq!(st.app().state(), SlaveState::DataExch);
    let mut samples = Vec::with_capacity(cycles);
    for (i, r) in dx.iter().enumerate() {
        let (ns, n) = exchange(&mut st, r, now);
        assert_eq!(n, IO + 9, "a Data_Exchange response");
        now += step;
        if i >= 1000 {
            samples.push(ns);
        }
    }
    percentiles("in-process (PassiveStation + DpSlave)", samples);
}

/// A port that timestamps the read completing a request and the first
/// write after it.
struct Timed<P> {
    inner: P,
    last_read: Option<std::time::Instant>,
    samples: Arc<Mutex<Vec<u64>>>,
}

impl<P: AsyncRead + Unpin> AsyncRead for Timed<P> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        let r = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(r, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.last_read = Some(std::time::Instant::now());
        }
        r
    }
}

impl<P: driver::Waitable> driver::Waitable for Timed<P> {
    fn wait_fd(&self) -> Option<std::os::fd::BorrowedFd<'_>> {
        self.inner.wait_fd()
    }
}

impl<P: AsyncWrite + Unpin> AsyncWrite for Timed<P> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        if let Some(t) = self.last_read.take() {
            let ns = t.elapsed().as_nanos() as u64;
            if let Ok(mut s) = self.samples.try_lock() {
                if s.len() < s.capacity() {
                    s.push(ns);
                }
            }
        }
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }
    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

struct Socat(std::process::Child);

impl Drop for Socat {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn socat(a: &Path, b: &Path) -> Socat {
    let child = Socat(
        Command::new("socat")
            .arg(format!("pty,raw,echo=0,link={}", a.display()))
            .arg(format!("pty,raw,echo=0,link={}", b.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("socat is needed for this benchmark (scripts/setup-test-env installs it)"),
    );
    for _ in 0..500 {
        if a.exists() && b.exists() {
            return child;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("socat made no pty pair");
}

fn open_raw(path: &Path) -> std::fs::File {
    // The far end of the pair: raw via socat's options; blocking I/O.
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .expect("open pty")
}

/// Read one complete telegram (SC, SD1, SD2, SD3) from a blocking file.
fn read_telegram(f: &mut std::fs::File, buf: &mut [u8]) -> usize {
    let mut n = 0;
    loop {
        n += f.read(&mut buf[n..]).expect("read");
        if let Ok(len) = profibus::fdl::wire::frame_len(&buf[..n]) {
            if n >= len {
                return len;
            }
        }
    }
}

fn over_socat(cycles: usize, dir: &Path) {
    let (a, b) = (dir.join("master"), dir.join("slave"));
    let _socat = socat(&a, &b);
    let samples = Arc::new(Mutex::new(Vec::with_capacity(cycles + 2000)));
    let slave_samples = samples.clone();
    let slave_path = b.clone();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let slave = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async move {
            let port = Port::open(slave_path.to_str().unwrap(), Baud::B12000000).unwrap();
            let mut port = Timed {
                inner: port,
                last_read: None,
                samples: slave_samples,
            };
            let mut st = PassiveStation::new(
                DpSlave::new(device(), ADDR),
                BusParams::defaults(Baud::B12000000),
            );
            let _ = driver::run(
                &mut st,
                &mut port,
                Clock::start(),
                async {
                    let _ = stop_rx.await;
                },
                |_, _| ControlFlow::Continue(()),
            )
            .await;
            st.app().stats().data_exchanges
        })
    });
    std::thread::sleep(Duration::from_millis(200));
    let mut m = open_raw(&a);
    let (setup, dx) = requests(cycles + 1000);
    let mut buf = [0u8; 512];
    for r in &setup {
        m.write_all(r).unwrap();
        assert_eq!(read_telegram(&mut m, &mut buf), 1, "SC");
    }
    let mut rtt = Vec::with_capacity(cycles);
    for (i, r) in dx.iter().enumerate() {
        let t0 = std::time::Instant::now();
        m.write_all(r).unwrap();
        let n = read_telegram(&mut m, &mut buf);
        let ns = t0.elapsed().as_nanos() as u64;
        assert_eq!(n, IO + 9);
        assert_eq!(&buf[7..7 + IO], &r[7..7 + IO], "echo");
        if i >= 1000 {
            rtt.push(ns);
        }
    }
    let _ = stop_tx.send(());
    let dxs = slave.join().unwrap();
    assert!(dxs as usize >= cycles);
    let mut s = samples.lock().unwrap().clone();
    // Drop the set-up and warm-up exchanges.
    s.drain(..(1000 + 2).min(s.len()));
    percentiles("socat pty, slave read→write (12M nominal)", s);
    percentiles("socat pty, master round trip", rtt);
}

fn raw_pty_echo(cycles: usize, dir: &Path) {
    let (a, b) = (dir.join("echo-a"), dir.join("echo-b"));
    let _socat = socat(&a, &b);
    let mut far = open_raw(&b);
    let echo = std::thread::spawn(move || {
        let mut buf = [0u8; 512];
        loop {
            match far.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => {
                    if buf[..n].contains(&0xFF) {
                        break;
                    }
                    far.write_all(&buf[..n]).unwrap();
                }
            }
        }
    });
    let mut m = open_raw(&a);
    let msg = [0x42u8; IO + 9];
    let mut buf = [0u8; 512];
    let mut rtt = Vec::with_capacity(cycles);
    for i in 0..cycles + 1000 {
        let t0 = std::time::Instant::now();
        m.write_all(&msg).unwrap();
        let mut n = 0;
        while n < msg.len() {
            n += m.read(&mut buf[n..]).unwrap();
        }
        if i >= 1000 {
            rtt.push(t0.elapsed().as_nanos() as u64);
        }
    }
    m.write_all(&[0xFF]).unwrap();
    let _ = echo.join();
    percentiles("socat pty, raw echo round trip (baseline)", rtt);
}

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --benches` runs it as a
    // quick smoke test with a few cycles.
    let quick = !std::env::args().any(|a| a == "--bench");
    let cycles: usize = std::env::var("TURNAROUND_CYCLES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(if quick { 2000 } else { 50_000 });
    let tmp = tempfile::tempdir().unwrap();
    let dir: PathBuf = tmp.path().to_path_buf();
    println!("slave turnaround, {cycles} Data_Exchange cycles, {IO} bytes each way");
    in_process(cycles * 4);
    over_socat(cycles, &dir);
    raw_pty_echo(cycles, &dir);
}
