//! The V controller's device control state machine, as the Omega board
//! passes it through: control word 1 in, status word 1 out.
//!
//! The manual lists only the **status** bits and their state names
//! (chapter 9.4, "V controller status word", L1333-1347: ready to switch
//! on, switched on, operation enabled, fault, voltage disabled, quick
//! stop, switch-on disabled, remote, setpoint reached) and says the
//! controller follows "the DRIVECOM principle" in velocity mode 1
//! (chapter 9.5, L1349-1353). The **control** bits and the transitions are
//! not in the manual: they are the DRIVECOM profile's (profile 21/22, the
//! same state machine IEC 61800-7-201 took over as CiA 402):
//!
//! | control word 1 bit | meaning |
//! |---|---|
//! | 0 | switch on |
//! | 1 | enable voltage (0 = command "disable voltage") |
//! | 2 | quick stop (0 = command "quick stop") |
//! | 3 | enable operation |
//! | 7 | fault reset (rising edge) |
//!
//! | command | bits 7,3,2,1,0 | transitions |
//! |---|---|---|
//! | shutdown | 0 x 1 1 0 | switch-on disabled, switched on, operation enabled → ready to switch on |
//! | switch on | 0 0 1 1 1 | ready to switch on → switched on; operation enabled → switched on |
//! | enable operation | 0 1 1 1 1 | switched on (or ready to switch on, via switched on) → operation enabled |
//! | disable voltage | 0 x x 0 x | any but fault → switch-on disabled |
//! | quick stop | 0 x 0 1 x | ready / switched on → switch-on disabled; operation enabled → quick stop active |
//! | fault reset | ↑ x x x x | fault → switch-on disabled |
//!
//! Choices where the profile leaves options: "quick stop active" is left
//! with "disable voltage" only (no transition back to operation enabled);
//! "not ready to switch on" and "fault reaction active" pass at once (the
//! emulated drive has no switch-on test and no braking time); status bit
//! 4 is set while control bit 1 is 1 (the manual: "Bit = 0: request
//! *Disable voltage* is present", L1339); bit 10 "setpoint reached" is set
//! in operation enabled (the actual values follow the setpoints at
//! once); bits 14/15 (freely configurable, P134/P135) stay 0.

use std::fmt;

/// Control word 1 bit 0: switch on.
pub const CW_SWITCH_ON: u16 = 1 << 0;
/// Control word 1 bit 1: enable voltage (0 = disable voltage).
pub const CW_ENABLE_VOLTAGE: u16 = 1 << 1;
/// Control word 1 bit 2: no quick stop (0 = quick stop).
pub const CW_QUICK_STOP: u16 = 1 << 2;
/// Control word 1 bit 3: enable operation.
pub const CW_ENABLE_OPERATION: u16 = 1 << 3;
/// Control word 1 bit 7: fault reset (rising edge).
pub const CW_FAULT_RESET: u16 = 1 << 7;

/// Status word 1 bit 0: ready to switch on (L1335).
pub const SW_READY: u16 = 1 << 0;
/// Status word 1 bit 1: switched on.
pub const SW_SWITCHED_ON: u16 = 1 << 1;
/// Status word 1 bit 2: operation enabled.
pub const SW_OPERATION_ENABLED: u16 = 1 << 2;
/// Status word 1 bit 3: fault.
pub const SW_FAULT: u16 = 1 << 3;
/// Status word 1 bit 4: voltage disabled (0 = "disable voltage" requested).
pub const SW_VOLTAGE: u16 = 1 << 4;
/// Status word 1 bit 5: quick stop (0 = quick stop active).
pub const SW_QUICK_STOP: u16 = 1 << 5;
/// Status word 1 bit 6: switch-on disabled.
pub const SW_SWITCH_ON_DISABLED: u16 = 1 << 6;
/// Status word 1 bit 9: remote (L1342).
pub const SW_REMOTE: u16 = 1 << 9;
/// Status word 1 bit 10: setpoint reached (L1343).
pub const SW_SETPOINT_REACHED: u16 = 1 << 10;

/// A state of the device control state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DriveState {
    /// Switch-on disabled: where the drive starts and where a fault reset
    /// or "disable voltage" leads.
    SwitchOnDisabled,
    /// Ready to switch on.
    ReadyToSwitchOn,
    /// Switched on (power stage on, no torque).
    SwitchedOn,
    /// Operation enabled: the drive follows its setpoints.
    OperationEnabled,
    /// Quick stop active.
    QuickStopActive,
    /// Fault, with the controller's error number.
    Fault(u16),
}

impl DriveState {
    /// Bits 0-3, 5 and 6 of status word 1 in this state (DRIVECOM).
    pub fn status_bits(self) -> u16 {
        match self {
            DriveState::SwitchOnDisabled => SW_SWITCH_ON_DISABLED,
            DriveState::ReadyToSwitchOn => SW_QUICK_STOP | SW_READY,
            DriveState::SwitchedOn => SW_QUICK_STOP | SW_READY | SW_SWITCHED_ON,
            DriveState::OperationEnabled => {
                SW_QUICK_STOP | SW_READY | SW_SWITCHED_ON | SW_OPERATION_ENABLED
            }
            DriveState::QuickStopActive => SW_READY | SW_SWITCHED_ON | SW_OPERATION_ENABLED,
            DriveState::Fault(_) => SW_FAULT,
        }
    }
}

impl fmt::Display for DriveState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DriveState::SwitchOnDisabled => f.write_str("switch-on disabled"),
            DriveState::ReadyToSwitchOn => f.write_str("ready to switch on"),
            DriveState::SwitchedOn => f.write_str("switched on"),
            DriveState::OperationEnabled => f.write_str("operation enabled"),
            DriveState::QuickStopActive => f.write_str("quick stop active"),
            DriveState::Fault(code) => write!(f, "fault 16#{code:04X}"),
        }
    }
}

/// The state machine; see the module docs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceControl {
    state: DriveState,
    control: u16,
}

impl Default for DeviceControl {
    fn default() -> DeviceControl {
        DeviceControl::new()
    }
}

impl DeviceControl {
    /// A drive after power-on: switch-on disabled, control word 0.
    pub fn new() -> DeviceControl {
        DeviceControl {
            state: DriveState::SwitchOnDisabled,
            control: 0,
        }
    }

    /// The current state.
    pub fn state(&self) -> DriveState {
        self.state
    }

    /// The last control word 1.
    pub fn control_word(&self) -> u16 {
        self.control
    }

    /// Apply control word 1; returns the new state when it changed.
    pub fn on_control(&mut self, cw: u16) -> Option<DriveState> {
        let before = self.state;
        let edge = cw & CW_FAULT_RESET != 0 && self.control & CW_FAULT_RESET == 0;
        self.control = cw;
        if let DriveState::Fault(_) = self.state {
            if edge {
                self.state = DriveState::SwitchOnDisabled;
            }
        } else {
            // "Switch on + enable operation" from ready to switch on goes
            // through switched on (two steps); the loop ends at a fixed point.
            for _ in 0..3 {
                let next = step(self.state, cw);
                if next == self.state {
                    break;
                }
                self.state = next;
            }
        }
        (self.state != before).then_some(self.state)
    }

    /// A fault of the controller (error number `code`): the drive goes to
    /// "fault" whatever its state.
    pub fn fault(&mut self, code: u16) -> Option<DriveState> {
        let before = self.state;
        self.state = DriveState::Fault(code);
        (self.state != before).then_some(self.state)
    }

    /// Status word 1 without the remote bit.
    pub fn status_word(&self) -> u16 {
        let mut sw = self.state.status_bits();
        if self.control & CW_ENABLE_VOLTAGE != 0 {
            sw |= SW_VOLTAGE;
        }
        if self.state == DriveState::OperationEnabled {
            sw |= SW_SETPOINT_REACHED;
        }
        sw
    }

    /// Whether the drive follows its setpoints.
    pub fn operation_enabled(&self) -> bool {
        self.state == DriveState::OperationEnabled
    }
}

/// One transition of the DRIVECOM state machine for control word `cw`.
fn step(state: DriveState, cw: u16) -> DriveState {
    use DriveState::*;
    let disable_voltage = cw & CW_ENABLE_VOLTAGE == 0;
    let quick_stop = !disable_voltage && cw & CW_QUICK_STOP == 0;
    let shutdown = cw & 0x87 == 0x06;
    let switch_on = cw & 0x8F == 0x07;
    let enable = cw & 0x8F == 0x0F;
    match state {
        Fault(_) => state,
        _ if disable_voltage => SwitchOnDisabled,
        QuickStopActive => QuickStopActive,
        OperationEnabled if quick_stop => QuickStopActive,
        _ if quick_stop => SwitchOnDisabled,
        SwitchOnDisabled if shutdown => ReadyToSwitchOn,
        SwitchedOn | OperationEnabled if shutdown => ReadyToSwitchOn,
        ReadyToSwitchOn if switch_on || enable => SwitchedOn,
        OperationEnabled if switch_on => SwitchedOn,
        SwitchedOn if enable => OperationEnabled,
        _ => state,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enable_sequence_and_status_words() {
        let mut d = DeviceControl::new();
        assert_eq!(d.status_word(), 0x0040, "switch-on disabled");
        // Shutdown 0x06, switch on 0x07, enable operation 0x0F.
        assert_eq!(d.on_control(0x06), Some(DriveState::ReadyToSwitchOn));
        assert_eq!(d.status_word(), 0x0031);
        assert_eq!(d.on_control(0x07), Some(DriveState::SwitchedOn));
        assert_eq!(d.status_word(), 0x0033);
        assert_eq!(d.on_control(0x0F), Some(DriveState::OperationEnabled));
        assert_eq!(d.status_word(), 0x0437);
        assert_eq!(d.on_control(0x0F), None);
        // Disable operation, then quick stop from operation enabled.
        assert_eq!(d.on_control(0x07), Some(DriveState::SwitchedOn));
        d.on_control(0x0F);
        assert_eq!(d.on_control(0x0B), Some(DriveState::QuickStopActive));
        assert_eq!(d.status_word(), 0x0017, "bit 5 = 0: quick stop");
        assert_eq!(d.on_control(0x0F), None, "left by disable voltage only");
        assert_eq!(d.on_control(0x00), Some(DriveState::SwitchOnDisabled));
        // Ready → operation enabled in one telegram (3 + 4).
        d.on_control(0x06);
        assert_eq!(d.on_control(0x0F), Some(DriveState::OperationEnabled));
        // Without shutdown first nothing happens.
        let mut d = DeviceControl::new();
        assert_eq!(d.on_control(0x0F), None);
        assert_eq!(d.on_control(0x07), None);
    }

    #[test]
    fn fault_and_fault_reset_edge() {
        let mut d = DeviceControl::new();
        d.on_control(0x06);
        d.on_control(0x0F);
        assert_eq!(d.fault(3), Some(DriveState::Fault(3)));
        assert_eq!(d.status_word() & 0x4F, SW_FAULT);
        assert_eq!(d.on_control(0x06), None, "no reset without bit 7");
        assert_eq!(d.on_control(0x86), Some(DriveState::SwitchOnDisabled));
        // The edge, not the level: holding bit 7 does not reset a new fault.
        d.fault(4);
        assert_eq!(d.on_control(0x86), None);
        d.on_control(0x06);
        assert_eq!(d.on_control(0x86), Some(DriveState::SwitchOnDisabled));
        assert_eq!(d.on_control(0x06), Some(DriveState::ReadyToSwitchOn));
    }
}
