//! The master side of the PKW channel: [`PkwClient`] runs one job at a
//! time over the process images of a slave in Data_Exchange.
//!
//! The client is fed with the slave's input image, its output image (to
//! write into) and the count of completed Data_Exchange cycles of that
//! slave, which tells it that what it wrote has been sent. A change is
//! taken as sent once the count has grown by 2 (the cycle in flight when
//! the change was made may still have carried the old words). Steps:
//!
//! 1. **Prepare**: PKE = 0 with the job's IND and PWE; wait until they are
//!    sent and the slave answers PKE = 0 (so no earlier response is taken
//!    for this job's).
//! 2. **Request**: write PKE; wait for a response with an AK other than 0
//!    and the job's PNU in a cycle after the request was sent.
//! 3. **Reset**: PKW words back to 0; the client is idle again once that
//!    was sent.
//!
//! The PKW words are the first 8 bytes of both images (both devices put
//! the PKW module first).

use super::{Command, Dialect, Pkw, Reply, PKW_LEN};
use profibus_dp::master::{DpMaster, SlaveHandle};
use profibus_fdl::Instant;
use std::time::Duration;

/// Cycles after a change before it counts as sent.
const SENT_AFTER: u64 = 2;

/// Why a PKW job failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PkwError {
    /// The slave answered "cannot execute" (AK 7) with this error number.
    #[error("the slave cannot execute the command: error 0x{code:04X} ({text})")]
    Refused {
        /// Error number (PWE2).
        code: u16,
        /// Its meaning in the device's dialect.
        text: &'static str,
    },
    /// No response within the timeout.
    #[error("{}", timeout_text(*after, *reached_request))]
    Timeout {
        /// The timeout.
        after: Duration,
        /// Whether the slave acknowledged the reset (PKE = 0) before.
        reached_request: bool,
    },
    /// A response code the dialect does not define.
    #[error("undefined PKW response {0}")]
    BadResponse(Pkw),
}

fn timeout_text(after: Duration, reached_request: bool) -> String {
    if reached_request {
        format!("no PKW response within {} ms", after.as_millis())
    } else {
        format!(
            "the slave did not clear its PKW response within {} ms (is the PKW module configured?)",
            after.as_millis()
        )
    }
}

/// Why a job cannot start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum StartError {
    /// A job is running or its reset not yet sent.
    #[error("a PKW job is still running")]
    Busy,
    /// The dialect has no command code for this.
    #[error("the device's PKW channel has no command for that")]
    Unsupported,
    /// The parameter number does not fit 11 bits.
    #[error("parameter number {0} is above 2047")]
    BadPnu(u16),
}

/// A finished job: the request and response words and the value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PkwAnswer {
    /// The request words sent.
    pub request: Pkw,
    /// The response words received.
    pub response: Pkw,
    /// The decoded value.
    pub reply: Reply,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Idle,
    Prepare { req: Pkw, written: Option<u64> },
    Request { req: Pkw, written: Option<u64> },
    Reset { written: Option<u64> },
}

/// The master side of the PKW handshake; see the module docs.
#[derive(Debug, Clone)]
pub struct PkwClient {
    dialect: &'static Dialect,
    timeout: Duration,
    state: State,
    started: Instant,
}

impl PkwClient {
    /// An idle client speaking `dialect`, giving up a job after `timeout`.
    pub fn new(dialect: &'static Dialect, timeout: Duration) -> PkwClient {
        PkwClient {
            dialect,
            timeout,
            state: State::Idle,
            started: Instant::ZERO,
        }
    }

    /// The dialect.
    pub fn dialect(&self) -> &'static Dialect {
        self.dialect
    }

    /// No job is running and the last reset was sent.
    pub fn is_idle(&self) -> bool {
        self.state == State::Idle
    }

    /// Start `cmd` on parameter `pnu`.
    pub fn start(&mut self, now: Instant, pnu: u16, cmd: Command) -> Result<(), StartError> {
        if !self.is_idle() {
            return Err(StartError::Busy);
        }
        if pnu > 0x7FF {
            return Err(StartError::BadPnu(pnu));
        }
        if matches!(cmd, Command::Unsupported(_)) {
            return Err(StartError::Unsupported);
        }
        let req = self
            .dialect
            .request(pnu, cmd)
            .ok_or(StartError::Unsupported)?;
        self.state = State::Prepare { req, written: None };
        self.started = now;
        Ok(())
    }

    /// Drive the handshake: `cycle` is the slave's count of completed
    /// Data_Exchange cycles, `inputs`/`outputs` its process images (the
    /// PKW words are their first 8 bytes). Returns the job's result once.
    pub fn poll(
        &mut self,
        now: Instant,
        cycle: u64,
        inputs: &[u8],
        outputs: &mut [u8],
    ) -> Option<Result<PkwAnswer, PkwError>> {
        if outputs.len() < PKW_LEN {
            return None;
        }
        let sent = |w: Option<u64>| w.is_some_and(|c| cycle >= c + SENT_AFTER);
        let resp = Pkw::parse(inputs);
        let timed_out = now.saturating_duration_since(self.started) >= self.timeout;
        match self.state {
            State::Idle => None,
            State::Prepare { req, written } => {
                let prep = Pkw { pke: 0, ..req };
                prep.emit(outputs);
                let written = written.or(Some(cycle));
                if sent(written) && resp.is_some_and(|r| r.pke == 0) {
                    req.emit(outputs);
                    self.state = State::Request {
                        req,
                        written: Some(cycle),
                    };
                } else if timed_out {
                    return Some(Err(self.fail(cycle, outputs, false)));
                } else {
                    self.state = State::Prepare { req, written };
                }
                None
            }
            State::Request { req, written } => {
                req.emit(outputs);
                if let Some(r) = resp.filter(|r| sent(written) && r.pke != 0) {
                    if r.pnu() == req.pnu() {
                        Pkw::ZERO.emit(outputs);
                        self.state = State::Reset {
                            written: Some(cycle),
                        };
                        return Some(match self.dialect.decode_response(&r) {
                            Some(Ok(reply)) => Ok(PkwAnswer {
                                request: req,
                                response: r,
                                reply,
                            }),
                            Some(Err(code)) => Err(PkwError::Refused {
                                code,
                                text: self.dialect.error_text(code),
                            }),
                            None => Err(PkwError::BadResponse(r)),
                        });
                    }
                }
                if timed_out {
                    return Some(Err(self.fail(cycle, outputs, true)));
                }
                None
            }
            State::Reset { written } => {
                Pkw::ZERO.emit(outputs);
                if sent(written) {
                    self.state = State::Idle;
                }
                None
            }
        }
    }

    /// [`PkwClient::poll`] on slave `h` of `master`, in place: its input
    /// image is read and its output image written where the master keeps
    /// them (no copies, no allocation). Polls in every state, so a job
    /// times out while the slave is away from Data_Exchange.
    pub fn drive(
        &mut self,
        now: Instant,
        master: &mut DpMaster,
        h: SlaveHandle,
    ) -> Option<Result<PkwAnswer, PkwError>> {
        let io = master.io_mut(h);
        self.poll(now, io.stats.data_exchanges, io.inputs, io.outputs)
    }

    fn fail(&mut self, cycle: u64, outputs: &mut [u8], reached_request: bool) -> PkwError {
        Pkw::ZERO.emit(outputs);
        self.state = State::Reset {
            written: Some(cycle),
        };
        PkwError::Timeout {
            after: self.timeout,
            reached_request,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{DESCRIBE as OMEGA, ELEMENTS as BM4};
    use super::super::{PkwEngine, PkwServer};
    use super::*;

    /// Dword parameter 4 = 3000; word parameter 5 writable.
    struct Table(u16);
    impl PkwServer for Table {
        fn execute(&mut self, _: Instant, pnu: u16, _: u16, cmd: Command) -> Result<Reply, u16> {
            match (pnu, cmd) {
                (4, Command::Read) => Ok(Reply::Dword(3000)),
                (5, Command::WriteWord(v)) => {
                    self.0 = v;
                    Ok(Reply::Word(v))
                }
                _ => Err(0x0B),
            }
        }
    }

    /// Run client and engine against each other, one Data_Exchange per
    /// ms (outputs sent, then the inputs of that cycle answered).
    fn run(
        dialect: &'static Dialect,
        delay: Duration,
        pnu: u16,
        cmd: Command,
        t: &mut Table,
    ) -> (Result<PkwAnswer, PkwError>, u64) {
        let mut c = PkwClient::new(dialect, Duration::from_millis(200));
        let mut e = PkwEngine::new(dialect, delay);
        let (mut inp, mut out) = ([0u8; 8], [0u8; 8]);
        let mut now = Instant::ZERO;
        c.start(now, pnu, cmd).unwrap();
        assert_eq!(c.start(now, pnu, cmd), Err(StartError::Busy));
        let mut result = None;
        for cycle in 0..1000u64 {
            if let Some(r) = c.poll(now, cycle, &inp, &mut out) {
                result = Some((r, cycle));
            }
            if result.is_some() && c.is_idle() {
                break;
            }
            // The Data_Exchange of this cycle.
            now += Duration::from_millis(1);
            e.on_request(now, Pkw::parse(&out).unwrap(), t);
            e.response(now).emit(&mut inp);
        }
        assert!(c.is_idle());
        assert_eq!(out, [0; 8], "reset at the end");
        result.expect("a result")
    }

    #[test]
    fn read_and_write_through_the_engine() {
        let mut t = Table(0);
        let (r, _) = run(&BM4, Duration::ZERO, 4, Command::Read, &mut t);
        let a = r.unwrap();
        assert_eq!(a.request.to_string(), "1004 0000 0000 0000");
        assert_eq!(a.response.to_string(), "2004 0000 0000 0BB8");
        assert_eq!(a.reply, Reply::Dword(3000));
        let (r, _) = run(
            &OMEGA,
            Duration::from_millis(7),
            5,
            Command::WriteWord(4),
            &mut t,
        );
        assert_eq!(r.unwrap().reply, Reply::Word(4));
        assert_eq!(t.0, 4);
        let (r, _) = run(&BM4, Duration::ZERO, 9, Command::Read, &mut t);
        assert_eq!(
            r.unwrap_err(),
            PkwError::Refused {
                code: 0x0B,
                text: BM4.error_text(0x0B)
            }
        );
    }

    #[test]
    fn timeout_when_nobody_answers() {
        let mut c = PkwClient::new(&OMEGA, Duration::from_millis(50));
        let (inp, mut out) = ([0u8; 8], [0u8; 8]);
        c.start(Instant::ZERO, 1, Command::Read).unwrap();
        let mut res = None;
        for cycle in 0..100u64 {
            let now = Instant::ZERO + Duration::from_millis(cycle);
            if let Some(r) = c.poll(now, cycle, &inp, &mut out) {
                res = Some(r);
                break;
            }
        }
        let e = res.unwrap().unwrap_err();
        assert!(matches!(
            e,
            PkwError::Timeout {
                reached_request: true,
                ..
            }
        ));
        assert!(e.to_string().contains("no PKW response within 50 ms"));
        assert_eq!(
            c.start(Instant::ZERO, 1, Command::Describe(1)),
            Err(StartError::Busy)
        );
        let mut b = PkwClient::new(&BM4, Duration::from_millis(50));
        assert_eq!(
            b.start(Instant::ZERO, 1, Command::Describe(1)),
            Err(StartError::Unsupported)
        );
        assert_eq!(
            b.start(Instant::ZERO, 2048, Command::Read),
            Err(StartError::BadPnu(2048))
        );
    }

    #[test]
    fn a_stale_response_is_not_taken() {
        // The slave still shows the response of an earlier job for the
        // same PNU: the client waits until it is cleared.
        let mut c = PkwClient::new(&BM4, Duration::from_millis(500));
        let stale = Pkw::new(2, 4, 0, 1);
        let mut inp = [0u8; 8];
        stale.emit(&mut inp);
        let mut out = [0u8; 8];
        c.start(Instant::ZERO, 4, Command::Read).unwrap();
        for cycle in 0..10 {
            assert_eq!(c.poll(Instant::ZERO, cycle, &inp, &mut out), None);
            assert_eq!(Pkw::parse(&out).unwrap().pke, 0, "still preparing");
        }
    }
}
