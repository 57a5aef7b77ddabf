//! The PLC around the module ([`Plc`]: its own registers plus the
//! module's `1xzzz`) and [`SharedJx2`], one PLC shared by the bus side and
//! the register clients (stdin, a control socket, a script).

use super::{Jx2, WriteEffect};
use profibus_dp::pdu::prm::SetPrm;
use profibus_dp::slave::{
    ClearReason, Device, DeviceEvent, DiagWriter, Dpv1Outcome, Features, IoLayout, OwnAddress,
    Reason, SlaveState,
};
use profibus_fdl::Instant;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

/// A Jetter PLC with one JX2-PROFI1 as module `module_number`: register
/// numbers `1xzzz` (x = module number, zzz = 100..=999) go to the module,
/// every other number is a plain PLC register (initially 0).
#[derive(Debug, Clone)]
pub struct Plc {
    module_number: u8,
    /// The module.
    pub module: Jx2,
    memory: BTreeMap<u32, i32>,
}

/// A module number outside 1..=9.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("module number {0} is outside 1..=9")]
pub struct BadModuleNumber(pub u32);

impl Plc {
    /// A PLC with a fresh module at `module_number` (1..=9; the manual's
    /// examples use 2: registers 12100…).
    pub fn new(module_number: u32) -> Result<Plc, BadModuleNumber> {
        if !(1..=9).contains(&module_number) {
            return Err(BadModuleNumber(module_number));
        }
        Ok(Plc {
            module_number: module_number as u8,
            module: Jx2::new(),
            memory: BTreeMap::new(),
        })
    }

    /// The module number.
    pub fn module_number(&self) -> u8 {
        self.module_number
    }

    /// The register number of the module's register `zzz`.
    pub fn module_register(&self, z: u16) -> u32 {
        10_000 + 1_000 * self.module_number as u32 + z as u32
    }

    /// The module register `zzz` a register number names, if any.
    pub fn local(&self, reg: u32) -> Option<u16> {
        let base = 10_000 + 1_000 * self.module_number as u32;
        (base + 100..=base + 999)
            .contains(&reg)
            .then(|| (reg - base) as u16)
    }

    /// Read a register.
    pub fn read(&mut self, now: Instant, reg: u32) -> i32 {
        match self.local(reg) {
            Some(z) => self.module.read(now, z),
            None => self.memory.get(&reg).copied().unwrap_or(0),
        }
    }

    /// Write a register.
    pub fn write(&mut self, now: Instant, reg: u32, value: i64) -> WriteEffect {
        match self.local(reg) {
            Some(z) => self.module.write(now, z, value),
            None => {
                self.memory.insert(reg, value as i32);
                WriteEffect::Applied
            }
        }
    }
}

/// How often a [`SharedJx2`] on the bus looks at the time (BUSY ends, the
/// station joins the bus) when nothing else wakes it.
pub const SHARED_TICK: Duration = Duration::from_millis(10);

/// One [`Plc`] shared between the slave core (this type is its
/// [`Device`]) and register clients ([`SharedJx2::lock`]). Clones share
/// the PLC. `on_change` is called after every bus event that may have
/// changed a register (for clients waiting on a bit).
#[derive(Clone)]
pub struct SharedJx2 {
    inner: Arc<Mutex<Plc>>,
    on_change: Option<Arc<dyn Fn() + Send + Sync>>,
    real_cfg: Vec<u8>,
    next_tick: Instant,
}

impl std::fmt::Debug for SharedJx2 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SharedJx2")
            .field("real_cfg", &self.real_cfg)
            .finish_non_exhaustive()
    }
}

impl SharedJx2 {
    /// Share `plc`.
    pub fn new(plc: Plc) -> SharedJx2 {
        let real_cfg = plc.module.real_cfg.clone();
        SharedJx2 {
            inner: Arc::new(Mutex::new(plc)),
            on_change: None,
            real_cfg,
            next_tick: Instant::ZERO,
        }
    }

    /// Call `f` after bus events (e.g. to wake clients waiting on a bit).
    pub fn with_on_change(mut self, f: impl Fn() + Send + Sync + 'static) -> SharedJx2 {
        self.on_change = Some(Arc::new(f));
        self
    }

    /// The PLC, locked.
    pub fn lock(&self) -> MutexGuard<'_, Plc> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn with<T>(&self, f: impl FnOnce(&mut Jx2) -> T) -> T {
        let r = f(&mut self.lock().module);
        if let Some(n) = &self.on_change {
            n();
        }
        r
    }

    fn refresh_cfg(&mut self) {
        let g = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        if g.module.real_cfg != self.real_cfg {
            self.real_cfg = g.module.real_cfg.clone();
        }
    }
}

impl Device for SharedJx2 {
    fn ident_number(&self) -> u16 {
        super::IDENT
    }
    fn real_cfg(&self) -> &[u8] {
        &self.real_cfg
    }
    fn features(&self) -> Features {
        self.lock().module.features()
    }
    fn check_prm(&mut self, prm: &SetPrm<'_>) -> Result<(), Reason> {
        self.with(|m| m.check_prm(prm))
    }
    fn check_cfg(&mut self, cfg: &[u8]) -> Result<IoLayout, Reason> {
        self.refresh_cfg();
        self.with(|m| m.check_cfg(cfg))
    }
    fn write_outputs(&mut self, now: Instant, outputs: &[u8]) {
        self.with(|m| m.write_outputs(now, outputs))
    }
    fn read_inputs(&mut self, now: Instant, inputs: &mut [u8]) {
        self.with(|m| m.read_inputs(now, inputs))
    }
    fn clear_outputs(&mut self, now: Instant, why: ClearReason) {
        self.with(|m| m.clear_outputs(now, why))
    }
    fn diagnosis(&mut self, now: Instant, diag: &mut DiagWriter<'_>) {
        self.with(|m| m.diagnosis(now, diag))
    }
    fn take_new_diag(&mut self) -> bool {
        self.lock().module.take_new_diag()
    }
    fn dpv1_read(&mut self, now: Instant, slot: u8, index: u8, out: &mut [u8]) -> Dpv1Outcome {
        self.with(|m| m.dpv1_read(now, slot, index, out))
    }
    fn dpv1_write(&mut self, now: Instant, slot: u8, index: u8, data: &[u8]) -> Dpv1Outcome {
        self.with(|m| m.dpv1_write(now, slot, index, data))
    }
    fn dpv1_poll(&mut self, now: Instant, out: &mut [u8]) -> Dpv1Outcome {
        self.with(|m| m.dpv1_poll(now, out))
    }
    fn own_address(&self) -> OwnAddress {
        self.lock().module.own_address()
    }
    fn take_restart(&mut self) -> bool {
        self.refresh_cfg();
        self.lock().module.take_restart()
    }
    fn state_changed(&mut self, now: Instant, state: SlaveState) {
        self.with(|m| m.state_changed(now, state))
    }
    fn prm_refused(&mut self, now: Instant, reason: &Reason) {
        self.with(|m| m.prm_refused(now, reason))
    }
    fn poll_event(&mut self) -> Option<DeviceEvent> {
        self.lock().module.poll_event()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        Some(self.next_tick)
    }
    fn handle_timeout(&mut self, now: Instant) {
        self.next_tick = now + SHARED_TICK;
        self.with(|m| m.settle(now))
    }
}
