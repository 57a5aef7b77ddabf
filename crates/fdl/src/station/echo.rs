//! [`Echo`]: a responder that answers every request with its own data
//! unit, a loopback station for tests, simulations and the bring-up of a
//! line.

use super::passive::{Reply, Responder};
#[allow(unused_imports)]
use crate::prelude::*;
use crate::time::Instant;
use crate::wire::{DataTelegram, ResponseStatus};

/// Answers every request to its address with the request's data unit
/// (status DL, the SAPs swapped) and counts the requests it executed.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Echo {
    /// The station address.
    pub address: u8,
    /// Requests executed (a repeated request, answered from the FCB
    /// store, is not executed again).
    pub executed: u32,
}

impl Echo {
    /// An echo station at `address`.
    pub fn new(address: u8) -> Echo {
        Echo {
            address,
            executed: 0,
        }
    }
}

impl Responder for Echo {
    fn address(&self) -> u8 {
        self.address
    }

    fn on_request(&mut self, _now: Instant, req: &DataTelegram<'_>, out: &mut [u8]) -> Reply {
        self.executed += 1;
        out[..req.data.len()].copy_from_slice(req.data);
        Reply::Data {
            status: ResponseStatus::Dl,
            dsap: req.ssap,
            ssap: req.dsap,
            len: req.data.len(),
        }
    }
}
