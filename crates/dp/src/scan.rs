//! Live list: which stations answer on the bus, and what they are.
//!
//! [`LiveListScan`] is the application of an FDL active station
//! ([`MasterApp`]): while its station holds the token it sends FDL Status
//! to every address 0..=126 (except its own) and then Slave_Diag to every
//! passive station that answered, to learn its DP ident number. The station
//! joins the token ring like any master, so a scan shares the bus with
//! running masters. [`LiveListScan::with_config`] also reads each DP
//! slave's configuration (Get_Cfg, SAP 59), which a slave answers
//! whichever master owns it (IEC 61158-6-3: Get_Cfg and Slave_Diag are
//! not locked), and keeps the whole Slave_Diag answer
//! ([`LiveListScan::slave_data`]).
//!
//! [`ServiceRequests`] is the one-shot counterpart: a list of DP requests
//! to single slaves (Slave_Diag, Get_Cfg, Rd_Inp, Rd_Outp,
//! Set_Slave_Add, Global_Control), each answered or not, for the service
//! commands of a commissioning tool.

use crate::pdu::diag::SlaveDiag;
use crate::pdu::sap;
use profibus_fdl::station::active::{
    CycleResult, MasterApp, Outcome, Request, Service, TokenContext,
};
use profibus_fdl::time::Instant;
use profibus_fdl::wire::{ResponseStatus, StationType};
use std::collections::BTreeMap;

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

/// What a scan with [`LiveListScan::with_config`] read from one DP
/// slave besides its live-list row.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SlaveData {
    /// The whole Slave_Diag answer, if it answered one.
    pub diag: Option<Vec<u8>>,
    /// The Get_Cfg answer (its real configuration), if it answered one.
    pub cfg: Option<Vec<u8>>,
}

/// Which request of the scan is out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Asked {
    Status,
    Diag,
    Cfg,
}

/// The live-list scanner; see the module docs.
#[derive(Debug)]
pub struct LiveListScan {
    own: u8,
    next_status: u16,
    next_diag: usize,
    next_cfg: usize,
    read_cfg: bool,
    found: Vec<LiveStation>,
    data: BTreeMap<u8, SlaveData>,
    pending: Option<(u8, Asked)>,
    done: bool,
}

impl LiveListScan {
    /// A scan run by the station with address `own`.
    pub fn new(own: u8) -> Self {
        LiveListScan {
            own,
            next_status: 0,
            next_diag: 0,
            next_cfg: 0,
            read_cfg: false,
            found: Vec::with_capacity(127),
            data: BTreeMap::new(),
            pending: None,
            done: false,
        }
    }

    /// A scan that also reads each DP slave's Get_Cfg (after every
    /// Slave_Diag).
    pub fn with_config(own: u8) -> Self {
        LiveListScan {
            read_cfg: true,
            ..LiveListScan::new(own)
        }
    }

    /// The Slave_Diag and Get_Cfg answers of the DP slave at `address`.
    pub fn slave_data(&self, address: u8) -> Option<&SlaveData> {
        self.data.get(&address)
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
            self.pending = Some((a, Asked::Status));
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
                self.pending = Some((s.address, Asked::Diag));
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
        while self.read_cfg && self.next_cfg < self.found.len() {
            let s = self.found[self.next_cfg];
            self.next_cfg += 1;
            if s.ident_number.is_some() {
                self.pending = Some((s.address, Asked::Cfg));
                return Some(Request {
                    da: s.address,
                    service: Service::SrdHigh,
                    dsap: Some(sap::GET_CFG),
                    ssap: Some(sap::MASTER),
                    data: &[],
                    // Get_Cfg: up to 244 bytes of identifiers.
                    max_reply_len: Some(244),
                });
            }
        }
        self.done = true;
        None
    }

    fn on_result(&mut self, _now: Instant, r: &CycleResult<'_>) {
        let Some((address, asked)) = self.pending.take() else {
            return;
        };
        match (asked, r.outcome) {
            (
                Asked::Cfg,
                Outcome::Response {
                    status: ResponseStatus::Dl | ResponseStatus::Dh,
                    data,
                    ..
                },
            ) => {
                self.data.entry(address).or_default().cfg = Some(data.to_vec());
            }
            (Asked::Status, Outcome::Response { station, .. }) => {
                self.found.push(LiveStation {
                    address,
                    station,
                    ident_number: None,
                    master_address: None,
                });
            }
            (
                Asked::Diag,
                Outcome::Response {
                    status: ResponseStatus::Dl | ResponseStatus::Dh,
                    data,
                    ..
                },
            ) => {
                if self.read_cfg && SlaveDiag::parse(data).is_ok() {
                    self.data.entry(address).or_default().diag = Some(data.to_vec());
                }
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

/// One DP request of a service command ([`ServiceRequests`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceRequest {
    /// Slave_Diag of a slave (any master may read it).
    SlaveDiag(u8),
    /// Get_Cfg: a slave's real configuration (any master may read it).
    GetCfg(u8),
    /// Rd_Inp: a slave's inputs (answered in Data_Exchange only).
    RdInp(u8),
    /// Rd_Outp: the outputs a slave's master last sent it (answered in
    /// Data_Exchange only).
    RdOutp(u8),
    /// Set_Slave_Add (a slave takes it in Wait_Prm only, and only with
    /// its own ident number).
    SetSlaveAdd {
        /// The slave's present address.
        slave: u8,
        /// The address it is to take.
        new_address: u8,
        /// Its ident number (it refuses any other).
        ident_number: u16,
        /// Forbid further changes of the address over the bus.
        no_add_chg: bool,
    },
    /// Global_Control to every slave (broadcast, never answered; a slave
    /// obeys only the master that parameterised it).
    GlobalControl(crate::pdu::control::GlobalControl),
}

impl ServiceRequest {
    /// The station the request goes to (127: broadcast).
    pub fn destination(&self) -> u8 {
        match *self {
            ServiceRequest::SlaveDiag(a)
            | ServiceRequest::GetCfg(a)
            | ServiceRequest::RdInp(a)
            | ServiceRequest::RdOutp(a) => a,
            ServiceRequest::SetSlaveAdd { slave, .. } => slave,
            ServiceRequest::GlobalControl(_) => profibus_fdl::wire::consts::BROADCAST,
        }
    }
}

/// How a [`ServiceRequest`] ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ServiceAnswer {
    /// The data unit of a positive answer.
    Data(Vec<u8>),
    /// A short acknowledge (Set_Slave_Add taken).
    Ack,
    /// A broadcast went out (no answer is given to one).
    Sent,
    /// The slave refused (RS: the service is not active now, e.g. Rd_Inp
    /// outside Data_Exchange or Set_Slave_Add outside Wait_Prm; RR, UE,
    /// NR: no resources, user error, no reply data).
    Refused(ResponseStatus),
    /// No valid answer after the retries.
    NoAnswer,
}

impl std::fmt::Display for ServiceAnswer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ServiceAnswer::Data(d) => write!(f, "{}", profibus_fdl::wire::Hex(d)),
            ServiceAnswer::Ack => f.write_str("acknowledged"),
            ServiceAnswer::Sent => f.write_str("sent (broadcast, not answered)"),
            ServiceAnswer::Refused(st) => write!(f, "refused ({})", st.mnemonic()),
            ServiceAnswer::NoAnswer => f.write_str("no answer"),
        }
    }
}

/// The application of an FDL active station that sends a list of
/// [`ServiceRequest`]s in turn, each once (with the FDL's retries), and
/// keeps how each ended; see the module docs.
#[derive(Debug)]
pub struct ServiceRequests {
    requests: Vec<ServiceRequest>,
    answers: Vec<ServiceAnswer>,
    buf: [u8; 8],
    out: bool,
}

impl ServiceRequests {
    /// The requests, to send in order.
    pub fn new(requests: Vec<ServiceRequest>) -> ServiceRequests {
        ServiceRequests {
            answers: Vec::with_capacity(requests.len()),
            requests,
            buf: [0; 8],
            out: false,
        }
    }

    /// Whether every request has ended.
    pub fn is_done(&self) -> bool {
        self.answers.len() == self.requests.len()
    }

    /// How the requests ended so far, in order.
    pub fn answers(&self) -> &[ServiceAnswer] {
        &self.answers
    }
}

impl MasterApp for ServiceRequests {
    fn poll_request(&mut self, _ctx: &TokenContext) -> Option<Request<'_>> {
        if self.out {
            return None;
        }
        let r = *self.requests.get(self.answers.len())?;
        self.out = true;
        let srd = |dsap: u8| (Service::SrdHigh, dsap, 0usize);
        let (service, dsap, n) = match r {
            ServiceRequest::SlaveDiag(_) => srd(sap::SLAVE_DIAG),
            ServiceRequest::GetCfg(_) => srd(sap::GET_CFG),
            ServiceRequest::RdInp(_) => srd(sap::RD_INP),
            ServiceRequest::RdOutp(_) => srd(sap::RD_OUTP),
            ServiceRequest::SetSlaveAdd {
                new_address,
                ident_number,
                no_add_chg,
                ..
            } => {
                let n = crate::pdu::control::SetSlaveAdd {
                    new_address,
                    ident_number,
                    no_add_chg,
                    rem_slave_data: &[],
                }
                .emit(&mut self.buf)
                .unwrap_or(0);
                (Service::SrdHigh, sap::SET_SLAVE_ADD, n)
            }
            ServiceRequest::GlobalControl(gc) => {
                self.buf[..2].copy_from_slice(&gc.to_bytes());
                (Service::SdnHigh, sap::GLOBAL_CONTROL, 2)
            }
        };
        Some(Request {
            da: r.destination(),
            service,
            dsap: Some(dsap),
            ssap: Some(sap::MASTER),
            data: &self.buf[..n],
            // Slave_Diag, Get_Cfg, Rd_Inp, Rd_Outp: at most 244 bytes.
            max_reply_len: Some(244),
        })
    }

    fn on_result(&mut self, _now: Instant, r: &CycleResult<'_>) {
        if !std::mem::replace(&mut self.out, false) {
            return;
        }
        let answer = match r.outcome {
            Outcome::Response {
                status: ResponseStatus::Dl | ResponseStatus::Dh,
                data,
                ..
            } => ServiceAnswer::Data(data.to_vec()),
            Outcome::Response { status, .. } => ServiceAnswer::Refused(status),
            Outcome::ShortAck => ServiceAnswer::Ack,
            Outcome::Sent => ServiceAnswer::Sent,
            Outcome::NoResponse => ServiceAnswer::NoAnswer,
        };
        self.answers.push(answer);
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
