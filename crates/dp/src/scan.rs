//! Live list: which stations answer on the bus, and what they are.
//!
//! [`LiveListScan`] is the application of an FDL active station
//! ([`MasterApp`]): while its station holds the token it sends FDL Status
//! to every address 0..=126 (except its own) and then Slave_Diag to every
//! passive station that answered, to learn its DP ident number. The station
//! joins the token ring like any master, so a scan shares the bus with
//! running masters.

use crate::pdu::diag::SlaveDiag;
use crate::pdu::sap;
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

/// A row of the live list as programs print it: a station found, or the
/// scanner itself ([`LiveRow::scanner`]). Text: `  8  passive, DP slave
/// ident 0x1234, parameterised by master 2`. JSON (`serde` feature):
/// `address`, `type`, `self` (the scanner only), `ident` (`0x…`) and
/// `master` (`null`: not parameterised) where known.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LiveRow {
    /// The station.
    pub station: LiveStation,
    /// Whether it is the scanner.
    pub scanner: bool,
}

impl LiveRow {
    /// The scanner at `address` (active, in the ring).
    pub fn scanner(address: u8) -> LiveRow {
        let station = LiveStation {
            address,
            station: StationType::ActiveInRing,
            ident_number: None,
            master_address: None,
        };
        LiveRow {
            station,
            scanner: true,
        }
    }
}

impl From<LiveStation> for LiveRow {
    fn from(station: LiveStation) -> LiveRow {
        LiveRow {
            station,
            scanner: false,
        }
    }
}

impl std::fmt::Display for LiveRow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = &self.station;
        write!(f, "{:3}  {}", s.address, s.station.describe())?;
        if self.scanner {
            return f.write_str(" (this scanner)");
        }
        if s.station != StationType::Passive {
            return Ok(());
        }
        match (s.ident_number, s.master_address) {
            (Some(id), Some(255)) => write!(f, ", DP slave ident 0x{id:04X}, not parameterised"),
            (Some(id), Some(m)) => write!(
                f,
                ", DP slave ident 0x{id:04X}, parameterised by master {m}"
            ),
            _ => f.write_str(", no DP diagnosis"),
        }
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for LiveRow {
    fn serialize<S: serde::Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        #[derive(serde::Serialize)]
        struct Row {
            address: u8,
            #[serde(rename = "type")]
            kind: &'static str,
            #[serde(rename = "self", skip_serializing_if = "std::ops::Not::not")]
            this: bool,
            #[serde(skip_serializing_if = "Option::is_none")]
            ident: Option<String>,
            #[serde(skip_serializing_if = "Option::is_none")]
            master: Option<Option<u8>>,
        }
        let s = &self.station;
        Row {
            address: s.address,
            kind: s.station.describe(),
            this: self.scanner,
            ident: s.ident_number.map(|id| format!("0x{id:04X}")),
            // 255: no master (not parameterised).
            master: s.master_address.map(|m| (m != 255).then_some(m)),
        }
        .serialize(ser)
    }
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
                // FDL Status: answered with 6 characters.
                max_reply_len: None,
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
                    max_reply_len: Some(crate::pdu::diag::MAX_DIAG_LEN as u8),
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

#[cfg(test)]
mod tests {
    use super::{LiveRow, LiveStation, StationType};

    #[test]
    fn live_rows_in_words_and_json() {
        let slave = |master| {
            LiveRow::from(LiveStation {
                address: 8,
                station: StationType::Passive,
                ident_number: Some(0x1234),
                master_address: Some(master),
            })
        };
        assert_eq!(
            LiveRow::scanner(1).to_string(),
            "  1  active, in ring (this scanner)"
        );
        assert_eq!(
            slave(2).to_string(),
            "  8  passive, DP slave ident 0x1234, parameterised by master 2"
        );
        assert_eq!(
            slave(255).to_string(),
            "  8  passive, DP slave ident 0x1234, not parameterised"
        );
        #[cfg(feature = "serde")]
        {
            let json = |r: LiveRow| serde_json::to_value(r).unwrap().to_string();
            assert_eq!(
                json(LiveRow::scanner(1)),
                r#"{"address":1,"self":true,"type":"active, in ring"}"#
            );
            assert_eq!(
                json(slave(255)),
                r#"{"address":8,"ident":"0x1234","master":null,"type":"passive"}"#
            );
        }
    }
}
