//! Live list: which stations answer on the bus, and what they are.
//!
//! [`LiveListScan`] is the application of an FDL active station
//! ([`MasterApp`]): while its station holds the token it sends FDL Status
//! to every address 0..=126 (except its own) and then Slave_Diag to every
//! passive station that answered, to learn its DP ident number. The station
//! joins the token ring like any master, so a scan shares the bus with
//! running masters.

use crate::diag::SlaveDiag;
use crate::sap;
use profibus_fdl::station::active::{
    CycleResult, MasterApp, Outcome, Request, Service, TokenContext,
};
use profibus_fdl::time::Instant;
use profibus_fdl::wire::{ResponseStatus, StationType};

/// What the scan learnt about one address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LiveStation {
    /// Station address.
    pub address: u8,
    /// Station type from the FDL Status answer.
    pub station: StationType,
    /// For passive stations that answered Slave_Diag: the DP ident number.
    pub ident_number: Option<u16>,
    /// For DP slaves: the master that parameterised it (255 = none).
    pub master_address: Option<u8>,
}

/// The live-list scanner; see the module docs.
#[derive(Debug)]
pub struct LiveListScan {
    own: u8,
    next_status: u16,
    next_diag: usize,
    found: Vec<LiveStation>,
    pending: Option<(u8, bool)>,
    done: bool,
}

impl LiveListScan {
    /// A scan run by the station with address `own`.
    pub fn new(own: u8) -> Self {
        LiveListScan {
            own,
            next_status: 0,
            next_diag: 0,
            found: Vec::with_capacity(127),
            pending: None,
            done: false,
        }
    }

    /// Whether every address was asked.
    pub fn is_done(&self) -> bool {
        self.done
    }

    /// Stations found so far, by address.
    pub fn stations(&self) -> &[LiveStation] {
        &self.found
    }
}

impl MasterApp for LiveListScan {
    fn poll_request(&mut self, _ctx: &TokenContext) -> Option<Request<'_>> {
        while self.next_status <= 126 {
            let a = self.next_status as u8;
            self.next_status += 1;
            if a == self.own {
                continue;
            }
            self.pending = Some((a, false));
            return Some(Request {
                da: a,
                service: Service::FdlStatus,
                dsap: None,
                ssap: None,
                data: &[],
            });
        }
        while self.next_diag < self.found.len() {
            let s = self.found[self.next_diag];
            self.next_diag += 1;
            if s.station == StationType::Passive {
                self.pending = Some((s.address, true));
                return Some(Request {
                    da: s.address,
                    service: Service::SrdHigh,
                    dsap: Some(sap::SLAVE_DIAG),
                    ssap: Some(sap::MASTER),
                    data: &[],
                });
            }
        }
        self.done = true;
        None
    }

    fn on_result(&mut self, _now: Instant, r: &CycleResult<'_>) {
        let Some((address, diag)) = self.pending.take() else {
            return;
        };
        match (diag, r.outcome) {
            (false, Outcome::Response { station, .. }) => {
                self.found.push(LiveStation {
                    address,
                    station,
                    ident_number: None,
                    master_address: None,
                });
            }
            (
                true,
                Outcome::Response {
                    status: ResponseStatus::Dl | ResponseStatus::Dh,
                    data,
                    ..
                },
            ) => {
                if let (Ok(d), Some(s)) = (
                    SlaveDiag::parse(data),
                    self.found.iter_mut().find(|s| s.address == address),
                ) {
                    s.ident_number = Some(d.ident_number);
                    s.master_address = Some(d.master_address);
                }
            }
            _ => {}
        }
    }
}
