//! Global_Control (DSAP 58) and Set_Slave_Add (DSAP 55) data units (IEC 61158-6-3).

bitflags::bitflags! {
    /// Control_Command byte of Global_Control.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub struct ControlCommand: u8 {
        /// Clear_Data: the master is in the clear state; outputs go to
        /// their safe state.
        const CLEAR_DATA = 0x02;
        /// Unfreeze: inputs follow the process again.
        const UNFREEZE = 0x04;
        /// Freeze: latch the inputs now; Data_Exchange returns the frozen
        /// values until the next Freeze or Unfreeze.
        const FREEZE = 0x08;
        /// Unsync: outputs are applied as they arrive again.
        const UNSYNC = 0x10;
        /// Sync: apply the last received outputs now and hold them until
        /// the next Sync or Unsync.
        const SYNC = 0x20;
    }
}

/// A Global_Control data unit: `Control_Command, Group_Select`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GlobalControl {
    /// The command bits.
    pub command: ControlCommand,
    /// Groups addressed; 0 = every slave.
    pub group_select: u8,
}

/// A data unit of the wrong length.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
#[error("{service} needs {expected} bytes, got {got}")]
pub struct LengthError {
    /// The service.
    pub service: &'static str,
    /// Expected length (minimum for Set_Slave_Add).
    pub expected: usize,
    /// Received length.
    pub got: usize,
}

impl GlobalControl {
    /// Decode the 2-byte data unit.
    pub fn parse(du: &[u8]) -> Result<GlobalControl, LengthError> {
        match du {
            [c, g] => Ok(GlobalControl {
                command: ControlCommand::from_bits_retain(*c),
                group_select: *g,
            }),
            _ => Err(LengthError {
                service: "Global_Control",
                expected: 2,
                got: du.len(),
            }),
        }
    }

    /// Encode.
    pub fn to_bytes(&self) -> [u8; 2] {
        [self.command.bits(), self.group_select]
    }

    /// Whether a slave with `group_ident` is addressed.
    pub fn addresses(&self, group_ident: u8) -> bool {
        self.group_select == 0 || self.group_select & group_ident != 0
    }
}

/// A Set_Slave_Add data unit:
/// `New_Slave_Address, Ident_Number (2), No_Add_Chg [, Rem_Slave_Data…]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SetSlaveAdd<'a> {
    /// The address the slave is to take (0..=125).
    pub new_address: u8,
    /// Must equal the slave's ident number.
    pub ident_number: u16,
    /// Forbid further changes of the address through the bus.
    pub no_add_chg: bool,
    /// Optional manufacturer data stored with the address.
    pub rem_slave_data: &'a [u8],
}

impl<'a> SetSlaveAdd<'a> {
    /// Decode.
    pub fn parse(du: &'a [u8]) -> Result<SetSlaveAdd<'a>, LengthError> {
        if du.len() < 4 {
            return Err(LengthError {
                service: "Set_Slave_Add",
                expected: 4,
                got: du.len(),
            });
        }
        Ok(SetSlaveAdd {
            new_address: du[0],
            ident_number: u16::from_be_bytes([du[1], du[2]]),
            no_add_chg: du[3] != 0,
            rem_slave_data: &du[4..],
        })
    }

    /// Encode into `buf`; returns the length or `None` when too small.
    pub fn emit(&self, buf: &mut [u8]) -> Option<usize> {
        let n = 4 + self.rem_slave_data.len();
        if buf.len() < n {
            return None;
        }
        let id = self.ident_number.to_be_bytes();
        buf[..4].copy_from_slice(&[self.new_address, id[0], id[1], self.no_add_chg as u8]);
        buf[4..n].copy_from_slice(self.rem_slave_data);
        Some(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn global_control_groups() {
        let g = GlobalControl::parse(&[0x28, 0x03]).unwrap();
        assert!(g
            .command
            .contains(ControlCommand::SYNC | ControlCommand::FREEZE));
        assert!(g.addresses(0x02));
        assert!(!g.addresses(0x04));
        assert!(GlobalControl::parse(&[0x28, 0]).unwrap().addresses(0));
        assert!(GlobalControl::parse(&[1]).is_err());
        assert_eq!(g.to_bytes(), [0x28, 0x03]);
    }

    #[test]
    fn set_slave_add() {
        let s = SetSlaveAdd::parse(&[7, 0x00, 0x08, 1, 0xAA]).unwrap();
        assert_eq!((s.new_address, s.ident_number, s.no_add_chg), (7, 8, true));
        let mut b = [0u8; 8];
        assert_eq!(s.emit(&mut b), Some(5));
        assert_eq!(b[..5], [7, 0, 8, 1, 0xAA]);
        assert!(SetSlaveAdd::parse(&[1, 2, 3]).is_err());
    }
}
