//! [`ScriptedJx2`]: the module with its PLC program running inside the
//! device, for the registry (`--device-opt script=FILE`, a bus file) and
//! `dpctl demo`. Register commands also come from a control inbox.

use super::script::{Interpreter, Progress};
use super::Plc;
use crate::kit::INBOX_PERIOD;
use crate::profile::ControlInbox;
use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{
    ClearReason, Device, DeviceEvent, DiagWriter, Dpv1Outcome, Features, IoLayout, OwnAddress,
    Reason, SlaveState,
};
use profibus_fdl::Instant;
use std::collections::VecDeque;

/// A [`Plc`] whose program ([`Interpreter`]) runs at every bus event and
/// timeout. Replies to inbox commands, and the program's failed commands
/// and reads, become device events (kind `jx2`, the JSON reply as text).
#[derive(Debug)]
pub struct ScriptedJx2 {
    plc: Plc,
    program: Interpreter,
    inbox: Option<(ControlInbox, Interpreter)>,
    wake: Option<Instant>,
    next_inbox: Instant,
    replies: VecDeque<DeviceEvent>,
}

impl ScriptedJx2 {
    /// Run `program` on `plc`; `inbox` lines are register commands too.
    pub fn new(plc: Plc, program: Interpreter, inbox: Option<ControlInbox>) -> ScriptedJx2 {
        ScriptedJx2 {
            plc,
            program,
            inbox: inbox.map(|i| (i, Interpreter::new())),
            wake: Some(Instant::ZERO),
            next_inbox: Instant::ZERO,
            replies: VecDeque::new(),
        }
    }

    /// The PLC.
    pub fn plc(&self) -> &Plc {
        &self.plc
    }

    fn step(&mut self, now: Instant) {
        self.plc.module.settle(now);
        let mut wake: Option<Instant> = None;
        let mut merge = |p: Progress| match p {
            Progress::Idle => {}
            Progress::Waiting(t) => wake = Some(wake.map_or(t, |w: Instant| w.min(t))),
            Progress::Busy => wake = Some(now),
        };
        merge(self.program.run(&mut self.plc, now));
        while let Some(r) = self.program.take_reply() {
            let notable = !r.ok || matches!(r.cmd, Some("read" | "status"));
            if notable && self.replies.len() < 256 {
                self.replies.push_back(DeviceEvent {
                    kind: "jx2",
                    text: r.to_string(),
                });
            }
        }
        if let Some((inbox, it)) = &mut self.inbox {
            if now >= self.next_inbox {
                self.next_inbox = now + INBOX_PERIOD;
                while let Some(l) = inbox.take() {
                    it.push(&l);
                }
            }
            merge(it.run(&mut self.plc, now));
            while let Some(r) = it.take_reply() {
                self.replies.push_back(DeviceEvent {
                    kind: "jx2",
                    text: r.to_string(),
                });
            }
            wake = Some(wake.map_or(self.next_inbox, |w| w.min(self.next_inbox)));
        }
        self.wake = wake;
    }
}

impl Device for ScriptedJx2 {
    fn ident_number(&self) -> u16 {
        super::IDENT
    }
    fn real_cfg(&self) -> &[u8] {
        self.plc.module.real_cfg()
    }
    fn features(&self) -> Features {
        self.plc.module.features()
    }
    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        self.plc.module.check_prm(prm)
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        self.plc.module.check_cfg(cfg)
    }
    fn write_outputs(&mut self, now: Instant, outputs: &[u8]) {
        self.plc.module.write_outputs(now, outputs);
        self.step(now);
    }
    fn read_inputs(&mut self, now: Instant, inputs: &mut [u8]) {
        self.plc.module.read_inputs(now, inputs);
    }
    fn clear_outputs(&mut self, now: Instant, why: ClearReason) {
        self.plc.module.clear_outputs(now, why);
    }
    fn diagnosis(&mut self, now: Instant, diag: &mut DiagWriter<'_>) {
        self.plc.module.diagnosis(now, diag);
        self.step(now);
    }
    fn take_new_diag(&mut self) -> bool {
        self.plc.module.take_new_diag()
    }
    fn dpv1_read(&mut self, now: Instant, slot: u8, index: u8, out: &mut [u8]) -> Dpv1Outcome {
        let r = self.plc.module.dpv1_read(now, slot, index, out);
        self.step(now);
        r
    }
    fn dpv1_write(&mut self, now: Instant, slot: u8, index: u8, data: &[u8]) -> Dpv1Outcome {
        let r = self.plc.module.dpv1_write(now, slot, index, data);
        self.step(now);
        r
    }
    fn dpv1_poll(&mut self, now: Instant, out: &mut [u8]) -> Dpv1Outcome {
        self.plc.module.dpv1_poll(now, out)
    }
    fn own_address(&self) -> OwnAddress {
        self.plc.module.own_address()
    }
    fn take_restart(&mut self) -> bool {
        self.plc.module.take_restart()
    }
    fn state_changed(&mut self, now: Instant, state: SlaveState) {
        self.plc.module.state_changed(now, state);
        self.step(now);
    }
    fn prm_refused(&mut self, now: Instant, reason: &Reason) {
        self.plc.module.prm_refused(now, reason);
    }
    fn poll_event(&mut self) -> Option<DeviceEvent> {
        self.plc
            .module
            .poll_event()
            .or_else(|| self.replies.pop_front())
    }
    fn poll_timeout(&self) -> Option<Instant> {
        match (self.wake, self.plc.module.next_deadline()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
    fn handle_timeout(&mut self, now: Instant) {
        self.step(now);
    }
}
