//! The bus side of the JX2-PROFI1: [`Device`] for the DP slave core.

use super::{DiagKind, ErrorNumber, Jx2};
use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{
    ClearReason, Device, DeviceEvent, DiagWriter, Dpv1Outcome, Features, IoLayout, OwnAddress,
    Reason, SlaveState, ERR_CLASS_ACCESS, ERR_CLASS_APPLICATION, ERR_WRITE_LENGTH,
};
use profibus_fdl::Instant;

/// Application error code "read error" (the DP-V1 answer to command 12).
pub const ERR_READ: u8 = 0;
/// Application error code "write error" (the answer to command 14).
pub const ERR_WRITE: u8 = 1;

/// User Prm bytes the module mirrors (1x242..1x263) after the 3 DP-V1
/// status bytes.
pub const MAX_USER_PRM: usize = 22;

impl Jx2 {
    fn output_words(&mut self, outputs: &[u8]) {
        let l = self.layout;
        for (i, w) in outputs.chunks_exact(2).enumerate() {
            *self.mem_mut(l.out_start + i as i32) = u16::from_be_bytes([w[0], w[1]]);
        }
        if self.cout_wanted {
            for i in 0..l.cout_words {
                let v = self.mem(l.out_start + l.cout_offset + i);
                *self.mem_mut(l.cout_start + i) = v;
            }
            self.cout_wanted = false;
            self.cout_received = true;
        }
    }

    fn area_bytes(&self, start: i32, out: &mut [u8]) {
        for (i, b) in out.chunks_mut(2).enumerate() {
            let w = self.mem(start + i as i32).to_be_bytes();
            b.copy_from_slice(&w[..b.len()]);
        }
    }
}

impl Device for Jx2 {
    fn ident_number(&self) -> u16 {
        super::IDENT
    }

    fn real_cfg(&self) -> &[u8] {
        &self.real_cfg
    }

    fn features(&self) -> Features {
        Features {
            dpv1: true,
            c1_read_write: true,
            max_diag_len: 32,
            ..Features::default()
        }
    }

    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        if prm.user_prm_data.len() > 3 + MAX_USER_PRM {
            return Err(format!(
                "{} bytes of User_Prm_Data, the module keeps 3 DP-V1 status bytes and {MAX_USER_PRM} user bytes",
                prm.user_prm_data.len()
            )
            .into());
        }
        let mut buf = [0u8; 64];
        let n = prm.emit(&mut buf).unwrap_or(0).min(32);
        self.prm = [0; 32];
        self.prm[..n].copy_from_slice(&buf[..n]);
        self.prm_len = n;
        Ok(())
    }

    fn prm_refused(&mut self, _now: Instant, reason: &Reason) {
        self.raise(ErrorNumber::Prm);
        self.events
            .note("jx2", format!("Set_Prm refused: {reason}"));
    }

    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        match self.check_cfg_bytes(cfg) {
            Ok((inputs, outputs)) => {
                let n = cfg.len().min(32);
                self.cfg = [0; 32];
                self.cfg[..n].copy_from_slice(&cfg[..n]);
                self.cfg_len = n;
                Ok(IoLayout { inputs, outputs })
            }
            Err(reason) => {
                self.raise(ErrorNumber::Cfg);
                Err(reason.to_string().into())
            }
        }
    }

    fn write_outputs(&mut self, _now: Instant, outputs: &[u8]) {
        self.output_words(outputs);
    }

    fn read_inputs(&mut self, _now: Instant, inputs: &mut [u8]) {
        let start = self.layout.in_start;
        self.area_bytes(start, inputs);
        if self.cin_copied {
            self.cin_copied = false;
            self.cin_sent = true;
        }
    }

    fn clear_outputs(&mut self, _now: Instant, _why: ClearReason) {
        let l = self.layout;
        if self.layout_ok {
            for i in 0..l.out_words {
                *self.mem_mut(l.out_start + i) = 0;
            }
        }
    }

    fn diagnosis(&mut self, _now: Instant, diag: &mut DiagWriter<'_>) {
        if let Some(p) = self.diag_pending.take() {
            self.diag_current = Some(p);
        }
        let Some(t) = self.diag_current else {
            return;
        };
        diag.block(&t.bytes[6..t.len]);
        match t.kind {
            DiagKind::Status => {}
            DiagKind::Extended => diag.set_ext_diag(),
            DiagKind::Static => diag.set_stat_diag(),
        }
    }

    fn take_new_diag(&mut self) -> bool {
        std::mem::take(&mut self.diag_new)
    }

    fn dpv1_read(&mut self, _now: Instant, slot: u8, index: u8, out: &mut [u8]) -> Dpv1Outcome {
        let n = out.len().min(2 * self.layout.dsr_words.max(0) as usize);
        self.dsr = super::Record {
            pending: true,
            answer: None,
            len: n as u8,
            slot,
            index,
        };
        self.last_request_read = true;
        self.acyclic_busy = false;
        Dpv1Outcome::Pending
    }

    fn dpv1_write(&mut self, _now: Instant, slot: u8, index: u8, data: &[u8]) -> Dpv1Outcome {
        let room = 2 * self.layout.dsw_words.max(0) as usize;
        if data.len() > room {
            self.events.note(
                "jx2",
                format!(
                    "data-record write of {} bytes refused: the area holds {room}",
                    data.len()
                ),
            );
            return Dpv1Outcome::write_error(ERR_CLASS_ACCESS, ERR_WRITE_LENGTH);
        }
        let start = self.layout.dsw_start;
        for (i, b) in data.chunks(2).enumerate() {
            let w = u16::from_be_bytes([b[0], b.get(1).copied().unwrap_or(0)]);
            *self.mem_mut(start + i as i32) = w;
        }
        self.dsw = super::Record {
            pending: true,
            answer: None,
            len: data.len() as u8,
            slot,
            index,
        };
        self.last_request_read = false;
        Dpv1Outcome::Pending
    }

    fn dpv1_poll(&mut self, _now: Instant, out: &mut [u8]) -> Dpv1Outcome {
        if self.last_request_read {
            match self.dsr.answer.take() {
                None => Dpv1Outcome::Pending,
                Some(true) => {
                    let n = (self.dsr.len as usize).min(out.len());
                    let start = self.layout.dsr_start;
                    self.area_bytes(start, &mut out[..n]);
                    self.acyclic_busy = false;
                    Dpv1Outcome::Done(n)
                }
                Some(false) => Dpv1Outcome::read_error(ERR_CLASS_APPLICATION, ERR_READ),
            }
        } else {
            match self.dsw.answer.take() {
                None => Dpv1Outcome::Pending,
                Some(true) => Dpv1Outcome::Done(self.dsw.len as usize),
                Some(false) => Dpv1Outcome::write_error(ERR_CLASS_APPLICATION, ERR_WRITE),
            }
        }
    }

    fn own_address(&self) -> OwnAddress {
        match self.station_address() {
            Some(a) => OwnAddress::Set(a),
            None => OwnAddress::NoneYet,
        }
    }

    fn take_restart(&mut self) -> bool {
        std::mem::take(&mut self.restart)
    }

    fn state_changed(&mut self, _now: Instant, state: SlaveState) {
        if self.dp_state == SlaveState::DataExch && state != SlaveState::DataExch {
            // The slave core dropped any data-record job.
            self.dsr = Default::default();
            self.dsw = Default::default();
            self.acyclic_busy = false;
        }
        self.dp_state = state;
    }

    fn poll_event(&mut self) -> Option<DeviceEvent> {
        self.events.pop()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.next_deadline()
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.settle(now);
    }
}
