//! The DP layer of a telegram, decoded: which DP service it carries and
//! what its data unit says (IEC 61158-6-3; the layouts are in the modules
//! of each service: [`crate::pdu::diag`], [`crate::pdu::prm`], [`crate::pdu::cfg`],
//! [`crate::pdu::control`], [`crate::pdu::dpv1`]).
//!
//! [`decode`] is sans-IO and stateless: a telegram, and for a response the
//! request it answers ([`Request`]), give a [`DpTelegram`] (serde-
//! serialisable with the feature `serde`). A response's DP meaning follows
//! from its request: a short acknowledge carries no addresses at all, a
//! Data_Exchange answer no SAPs, and some slaves answer other services
//! without SAPs too. [`Exchanges`] pairs them on a stream of telegrams: it
//! keeps the last request per master/slave pair (and the one a short
//! acknowledge can answer: the last request that expects a reply).
//!
//! Used by `dpctl sniff --json` (the `"dp"` object of each telegram).
//!
//! ```
//! use profibus_dp::pdu::decode::{Exchanges, Detail};
//! use profibus_fdl::Telegram;
//!
//! let mut ex = Exchanges::default();
//! // Master 2 asks slave 8 for its diagnosis (SD2, DSAP 60, SSAP 62) …
//! let req = [0x68, 0x05, 0x05, 0x68, 0x88, 0x82, 0x6D, 0x3C, 0x3E, 0xF1, 0x16];
//! let (t, _) = Telegram::parse(&req).unwrap();
//! assert_eq!(ex.decode(&t).unwrap().service, "Slave_Diag");
//! // … and slave 8 answers: Station_Not_Ready, Prm_Req, ident 0x0ED0.
//! let res = [
//!     0x68, 0x0B, 0x0B, 0x68, 0x82, 0x88, 0x08, 0x3E, 0x3C, //
//!     0x02, 0x05, 0x00, 0xFF, 0x0E, 0xD0, 0x70, 0x16,
//! ];
//! let (t, _) = Telegram::parse(&res).unwrap();
//! let dp = ex.decode(&t).unwrap();
//! let Some(Detail::SlaveDiag { status, ident_number, .. }) = dp.detail else { panic!() };
//! assert_eq!(status, ["Station_Not_Ready", "Prm_Req"]);
//! assert_eq!(ident_number, 0x0ED0);
//! ```

use crate::config::gsd::Gsd;
use crate::config::layout::{ModuleLayout, Span};
use crate::fms::decode::{self as fms_decode, FmsTelegram};
use crate::monitor::{Image, ImageDecoder, Reading};
use crate::pdu::alarm::{self, DiagBlock};
use crate::pdu::c2::{C2Pdu, InitiateRes};
use crate::pdu::cfg;
use crate::pdu::control::{ControlCommand, GlobalControl, SetSlaveAdd};
use crate::pdu::diag::{self, SlaveDiag, NO_MASTER};
use crate::pdu::dpv1::{self, Pdu};
use crate::pdu::im::{self, CallHeader, Im0};
use crate::pdu::prm::{Dpv1Status1, Dpv1Status2, PrmStationStatus, SetPrm};
use crate::pdu::sap;
use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus, Telegram};
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::sync::Arc;

/// What a decoder needs to know of a request to read its response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Request {
    /// The requester (a master).
    pub master: u8,
    /// The responder (a slave).
    pub slave: u8,
    /// Destination SAP (without the segment bit); `None`: Data_Exchange.
    pub dsap: Option<u8>,
    /// Source SAP (without the segment bit).
    pub ssap: Option<u8>,
}

impl Request {
    /// The request `d`, if it is one (a response gives `None`).
    pub fn of(d: &DataTelegram<'_>) -> Option<Request> {
        d.fc.is_request().then_some(Request {
            master: d.sa,
            slave: d.da,
            dsap: d.dsap.map(|s| s & 0x3F),
            ssap: d.ssap.map(|s| s & 0x3F),
        })
    }
}

/// One identifier of a Chk_Cfg or Get_Cfg, decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct CfgIdentifier {
    /// Its bytes.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub raw: Vec<u8>,
    /// In words (`2 words in+out`, `empty slot`, …).
    pub text: String,
    /// Input bytes.
    pub input_bytes: usize,
    /// Output bytes.
    pub output_bytes: usize,
}

/// One module's share of a process image.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct ModuleSlice {
    /// Slot, counted from 1 in configuration order.
    pub slot: usize,
    /// The module: its GSD name (bus file) or its identifier in words
    /// (learned from a Chk_Cfg).
    pub name: String,
    /// Its bytes.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub data: Vec<u8>,
}

/// A DP-V1 alarm block of a Slave_Diag response, with the field names of
/// the master's `alarm` event.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct AlarmInfo {
    /// Alarm type in one word (`diagnostic`, `process`, `pull`, `plug`,
    /// `status`, `update`, `manufacturer`, `reserved`).
    #[cfg_attr(feature = "serde", serde(rename = "type"))]
    pub alarm_type: &'static str,
    /// The type's code.
    pub type_code: u8,
    /// Slot number.
    pub slot: u8,
    /// `appears`, `disappears`, `disappears-still-faulty` or `none`.
    pub specifier: &'static str,
    /// Sequence number 0..=31.
    pub seq: u8,
    /// Add_Ack: the user must confirm beyond Alarm_Ack.
    pub add_ack: bool,
    /// Diagnostic_User_Data.
    #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
    pub data: Vec<u8>,
}

/// What the data unit of a DP telegram says, per service.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(feature = "serde", serde(untagged))]
pub enum Detail {
    /// A Slave_Diag response.
    SlaveDiag {
        /// The station status bits that are set, by their names in the
        /// standard (`Station_Not_Ready`, `Prm_Req`, …); empty: all clear.
        status: Vec<String>,
        /// Diag.Master_Add: the master that parameterised the slave
        /// (`None`: 255, none).
        master_address: Option<u8>,
        /// Ident_Number.
        ident_number: u16,
        /// The extended diagnosis blocks in words.
        ext_diag: Vec<String>,
        /// Bit 2 of Station_Status_2 (always 1 in a slave's diagnosis).
        valid: bool,
        /// The DP-V1 alarm blocks, when this capture saw the slave
        /// parameterised with DPV1_Enable (empty otherwise).
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Vec::is_empty"))]
        alarms: Vec<AlarmInfo>,
    },
    /// A Set_Prm request.
    SetPrm {
        /// Station_Status bits set (`Lock_Req`, `WD_On`, …).
        station_status: Vec<&'static str>,
        /// The watchdog time (`None`: WD_On clear). Counted in 1 ms when
        /// the first User_Prm_Data byte is a DPV1_Status_1 with
        /// DPV1_Enable and WD_Base_1ms, else in 10 ms.
        watchdog_ms: Option<u64>,
        /// min TSDR in bit times (0: keep).
        min_tsdr: u8,
        /// Ident_Number.
        ident_number: u16,
        /// Groups of Group_Ident (1..=8).
        groups: Vec<u8>,
        /// The bits set in DPV1_Status_1 and DPV1_Status_2, the first two
        /// User_Prm_Data bytes, when DPV1_Enable is set (`DPV1_Enable`,
        /// `WD_Base_1ms`, `Diagnostic_Alarm`, …; empty: a DP-V0
        /// Set_Prm, whose User_Prm_Data is the device's own).
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Vec::is_empty"))]
        dpv1_status: Vec<&'static str>,
        /// User_Prm_Data (for DP-V1 slaves starting with DPV1_Status_1..3).
        #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
        user_prm_data: Vec<u8>,
    },
    /// A Chk_Cfg request or a Get_Cfg response.
    Cfg {
        /// The identifiers, each decoded.
        identifiers: Vec<CfgIdentifier>,
        /// Input bytes in all.
        input_bytes: usize,
        /// Output bytes in all.
        output_bytes: usize,
        /// Why the rest could not be decoded.
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
        error: Option<String>,
    },
    /// Outputs: a Data_Exchange request, a Rd_Outp response.
    Outputs {
        /// The output bytes.
        #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
        outputs: Vec<u8>,
        /// The bytes split by module, when [`Exchanges`] knows the
        /// slave's modules (a bus file, or the Chk_Cfg seen on the wire).
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Vec::is_empty"))]
        modules: Vec<ModuleSlice>,
        /// The bytes as the named channels of the slave's device profile,
        /// when [`Exchanges`] has its decoder ([`Exchanges::set_decoder`]);
        /// JSON `{"NAME": value, …}`, as `dpctl monitor` names them.
        #[cfg_attr(
            feature = "serde",
            serde(
                skip_serializing_if = "Vec::is_empty",
                serialize_with = "crate::monitor::ser::readings"
            )
        )]
        channels: Vec<Reading>,
    },
    /// Inputs: a Data_Exchange or Rd_Inp response.
    Inputs {
        /// The input bytes.
        #[cfg_attr(feature = "serde", serde(serialize_with = "profibus_fdl::ser::hex"))]
        inputs: Vec<u8>,
        /// The slave has new diagnosis (response status DH or RDH).
        new_diag: bool,
        /// The bytes split by module (see [`Detail::Outputs`]).
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Vec::is_empty"))]
        modules: Vec<ModuleSlice>,
        /// The named channels (see [`Detail::Outputs`]).
        #[cfg_attr(
            feature = "serde",
            serde(
                skip_serializing_if = "Vec::is_empty",
                serialize_with = "crate::monitor::ser::readings"
            )
        )]
        channels: Vec<Reading>,
    },
    /// A Global_Control broadcast.
    GlobalControl {
        /// Control_Command bits set (`Clear_Data`, `Sync`, …).
        command: Vec<&'static str>,
        /// Groups of Group_Select (empty: every slave).
        groups: Vec<u8>,
    },
    /// A Set_Slave_Add request.
    SetSlaveAdd {
        /// The address the slave is to take.
        new_address: u8,
        /// Ident_Number.
        ident_number: u16,
        /// No further address change through the bus.
        no_add_chg: bool,
    },
    /// A DP-V1 PDU (MSAC_C1, MSAC_C2).
    Dpv1 {
        /// `Read`, `Write`, `Alarm_Ack`, `Data_Transport`, `Initiate`,
        /// `Abort`, `Idle`, `Error`, or `Poll` (an empty request that
        /// polls for the answer).
        pdu: &'static str,
        /// Slot.
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
        slot: Option<u8>,
        /// Index.
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
        index: Option<u8>,
        /// Length byte.
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
        length: Option<u8>,
        /// The data read or written.
        #[cfg_attr(
            feature = "serde",
            serde(
                skip_serializing_if = "Option::is_none",
                serialize_with = "profibus_fdl::ser::opt_hex"
            )
        )]
        data: Option<Vec<u8>>,
        /// A negative response in words.
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
        error: Option<String>,
        /// The PDU in words where there is more to say than the fields
        /// above: Initiate parameters, the RM's connection SAP, an
        /// Abort's instance and reason, an I&M call and its record.
        #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
        text: Option<String>,
    },
    /// The data unit does not decode as its service's.
    Malformed {
        /// Why.
        error: String,
    },
}

/// A telegram's DP layer.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct DpTelegram {
    /// The DP service: `Data_Exchange`, `Slave_Diag`, `Set_Prm`,
    /// `Chk_Cfg`, `Get_Cfg`, `Global_Control`, `Set_Slave_Add`, `Rd_Inp`,
    /// `Rd_Outp`, `MSAC_C1`, `Alarm_Ack`, `MSAC_C2_Initiate`, `MSAC_C2`.
    pub service: &'static str,
    /// `request` or `response` (a short acknowledge is a response).
    pub direction: &'static str,
    /// The service's data, decoded (`None`: the data unit is empty, or a
    /// negative response).
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub detail: Option<Detail>,
}

fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn list(words: &[impl AsRef<str>], none: &str) -> String {
    if words.is_empty() {
        none.to_string()
    } else {
        words
            .iter()
            .map(AsRef::as_ref)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

fn group_list(g: &[u8]) -> String {
    g.iter().map(u8::to_string).collect::<Vec<_>>().join(",")
}

fn show_modules(
    f: &mut fmt::Formatter<'_>,
    modules: &[ModuleSlice],
    channels: &[Reading],
) -> fmt::Result {
    for m in modules {
        write!(f, "; {} {}: {}", m.slot, m.name, hex(&m.data))?;
    }
    if !channels.is_empty() {
        f.write_str(";")?;
        for c in channels {
            write!(f, " {c}")?;
        }
    }
    Ok(())
}

impl fmt::Display for DpTelegram {
    /// The DP layer in words, as `dpctl sniff` prints it after the
    /// telegram: `Set_Prm request: WD_On; watchdog 5000 ms; …`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}", self.service, self.direction)?;
        let Some(d) = &self.detail else {
            return Ok(());
        };
        f.write_str(": ")?;
        match d {
            Detail::SlaveDiag {
                status,
                master_address,
                ident_number,
                ext_diag,
                alarms,
                ..
            } => {
                write!(f, "{}; ident 0x{ident_number:04X}", list(status, "OK"))?;
                match master_address {
                    Some(m) => write!(f, "; master {m}")?,
                    None => f.write_str("; no master")?,
                }
                for e in ext_diag {
                    write!(f, "; {e}")?;
                }
                for a in alarms {
                    write!(
                        f,
                        "; {} alarm slot {} {} seq {}",
                        a.alarm_type, a.slot, a.specifier, a.seq
                    )?;
                }
                Ok(())
            }
            Detail::SetPrm {
                station_status,
                dpv1_status,
                watchdog_ms,
                min_tsdr,
                ident_number,
                groups,
                user_prm_data,
            } => {
                f.write_str(&list(station_status, "no status bits"))?;
                match watchdog_ms {
                    Some(w) => write!(f, "; watchdog {w} ms")?,
                    None => f.write_str("; watchdog off")?,
                }
                write!(f, "; min TSDR {min_tsdr}; ident 0x{ident_number:04X}")?;
                if !groups.is_empty() {
                    write!(f, "; groups {}", group_list(groups))?;
                }
                if !dpv1_status.is_empty() {
                    write!(f, "; DPV1 {}", list(dpv1_status, ""))?;
                }
                if !user_prm_data.is_empty() {
                    write!(f, "; user prm {}", hex(user_prm_data))?;
                }
                Ok(())
            }
            Detail::Cfg {
                identifiers,
                input_bytes,
                output_bytes,
                error,
            } => {
                let texts: Vec<String> = identifiers
                    .iter()
                    .map(|i| format!("{} ({})", i.text, hex(&i.raw)))
                    .collect();
                let n = |b: usize| {
                    if b == 1 {
                        "1 byte".into()
                    } else {
                        format!("{b} bytes")
                    }
                };
                write!(
                    f,
                    "{}; {} in, {} out",
                    list(&texts, "no modules"),
                    n(*input_bytes),
                    n(*output_bytes)
                )?;
                if let Some(e) = error {
                    write!(f, "; {e}")?;
                }
                Ok(())
            }
            Detail::Outputs {
                outputs,
                modules,
                channels,
            } => {
                write!(f, "outputs {}", hex(outputs))?;
                show_modules(f, modules, channels)
            }
            Detail::Inputs {
                inputs,
                new_diag,
                modules,
                channels,
            } => {
                write!(f, "inputs {}", hex(inputs))?;
                if *new_diag {
                    f.write_str(" (new diagnosis)")?;
                }
                show_modules(f, modules, channels)
            }
            Detail::GlobalControl { command, groups } => {
                f.write_str(&list(command, "no command"))?;
                if groups.is_empty() {
                    f.write_str("; all groups")
                } else {
                    write!(f, "; groups {}", group_list(groups))
                }
            }
            Detail::SetSlaveAdd {
                new_address,
                ident_number,
                no_add_chg,
            } => {
                write!(f, "new address {new_address}; ident 0x{ident_number:04X}")?;
                if *no_add_chg {
                    f.write_str("; No_Add_Chg")?;
                }
                Ok(())
            }
            Detail::Dpv1 {
                pdu,
                slot,
                index,
                length,
                data,
                error,
                text,
            } => {
                f.write_str(pdu)?;
                if let Some(s) = slot {
                    write!(f, " slot {s}")?;
                }
                if let Some(i) = index {
                    write!(f, " index {i}")?;
                }
                if let Some(l) = length {
                    write!(f, " length {l}")?;
                }
                if let Some(d) = data.as_ref().filter(|d| !d.is_empty()) {
                    write!(f, " data {}", hex(d))?;
                }
                if let Some(e) = error {
                    write!(f, "; {e}")?;
                }
                if let Some(t) = text {
                    write!(f, "; {t}")?;
                }
                Ok(())
            }
            Detail::Malformed { error } => write!(f, "malformed: {error}"),
        }
    }
}

/// The DP layer of `telegram`; `answers` is the request a response (or
/// short acknowledge) answers, when known. `None`: no DP telegram (a
/// token, FDL status and ident requests, other SAPs).
pub fn decode(telegram: &Telegram<'_>, answers: Option<&Request>) -> Option<DpTelegram> {
    decode_in(telegram, answers, false)
}

/// [`decode`], reading device-related diagnosis blocks as DP-V1 alarm
/// and status blocks when `dpv1` (the slave was seen parameterised with
/// DPV1_Enable).
fn decode_in(telegram: &Telegram<'_>, answers: Option<&Request>, dpv1: bool) -> Option<DpTelegram> {
    let d = match telegram {
        Telegram::Token { .. } => return None,
        Telegram::ShortAck => {
            let r = answers?;
            return Some(DpTelegram {
                service: service(r.dsap)?,
                direction: "response",
                detail: None,
            });
        }
        Telegram::Data(d) => d,
    };
    match d.fc {
        FunctionCode::Request { kind, .. } => request(d, kind),
        FunctionCode::Response { status, .. } => response(d, status, answers, dpv1),
    }
}

/// The DP service of a slave SAP (`None`: Data_Exchange).
fn service(sap: Option<u8>) -> Option<&'static str> {
    match sap {
        None => Some("Data_Exchange"),
        Some(s) => sap::name(s),
    }
}

fn request(d: &DataTelegram<'_>, kind: RequestKind) -> Option<DpTelegram> {
    if matches!(
        kind,
        RequestKind::FdlStatus | RequestKind::Ident | RequestKind::LsapStatus
    ) {
        return None;
    }
    let dsap = d.dsap.map(|s| s & 0x3F);
    if dsap.is_none() && d.ssap.is_some() {
        return None;
    }
    let service = service(dsap)?;
    let du = d.data;
    let detail = match dsap {
        None => Some(Detail::Outputs {
            outputs: du.to_vec(),
            modules: vec![],
            channels: vec![],
        }),
        Some(sap::SET_PRM) => Some(set_prm(du)),
        Some(sap::CHK_CFG) => Some(config(du)),
        Some(sap::GLOBAL_CONTROL) => Some(match GlobalControl::parse(du) {
            Ok(gc) => Detail::GlobalControl {
                command: control_names(gc.command),
                groups: groups(gc.group_select),
            },
            Err(e) => malformed(e),
        }),
        Some(sap::SET_SLAVE_ADD) => Some(match SetSlaveAdd::parse(du) {
            Ok(s) => Detail::SetSlaveAdd {
                new_address: s.new_address,
                ident_number: s.ident_number,
                no_add_chg: s.no_add_chg,
            },
            Err(e) => malformed(e),
        }),
        Some(s) if s <= sap::MSAC_C2_INITIATE => Some(c2_pdu(du, true)),
        Some(s) if s <= sap::MSAC_C1 => Some(dpv1_pdu(du, true)),
        _ if du.is_empty() => None,
        _ => Some(Detail::Malformed {
            error: format!("{service} request carries {} bytes, needs none", du.len()),
        }),
    };
    Some(DpTelegram {
        service,
        direction: "request",
        detail,
    })
}

fn response(
    d: &DataTelegram<'_>,
    status: ResponseStatus,
    answers: Option<&Request>,
    dpv1: bool,
) -> Option<DpTelegram> {
    let answers = answers.filter(|r| r.master == d.da && r.slave == d.sa);
    // The slave's SAP is the response's SSAP; a response without SAPs
    // answers the request's service (Data_Exchange when none is known).
    let sap = match (d.ssap, answers) {
        (Some(s), _) => Some(s & 0x3F),
        (None, Some(r)) => r.dsap,
        (None, None) => None,
    };
    let service = service(sap)?;
    let du = d.data;
    let detail = if status.is_negative() {
        None
    } else {
        match sap {
            None => Some(Detail::Inputs {
                inputs: du.to_vec(),
                new_diag: matches!(status, ResponseStatus::Dh | ResponseStatus::Rdh),
                modules: vec![],
                channels: vec![],
            }),
            Some(sap::SLAVE_DIAG) => Some(slave_diag(du, dpv1)),
            Some(sap::GET_CFG) => Some(config(du)),
            Some(sap::RD_INP) => Some(Detail::Inputs {
                inputs: du.to_vec(),
                new_diag: false,
                modules: vec![],
                channels: vec![],
            }),
            Some(sap::RD_OUTP) => Some(Detail::Outputs {
                outputs: du.to_vec(),
                modules: vec![],
                channels: vec![],
            }),
            Some(s) if s <= sap::MSAC_C2_INITIATE && !du.is_empty() => Some(c2_pdu(du, false)),
            Some(s) if s <= sap::MSAC_C1 && !du.is_empty() => Some(dpv1_pdu(du, false)),
            _ => None,
        }
    };
    Some(DpTelegram {
        service,
        direction: "response",
        detail,
    })
}

fn malformed(e: impl fmt::Display) -> Detail {
    Detail::Malformed {
        error: e.to_string(),
    }
}

/// Group numbers (1..=8) of a Group_Ident / Group_Select byte.
fn groups(bits: u8) -> Vec<u8> {
    (0..8)
        .filter(|b| bits & (1 << b) != 0)
        .map(|b| b + 1)
        .collect()
}

fn control_names(c: ControlCommand) -> Vec<&'static str> {
    [
        (ControlCommand::CLEAR_DATA, "Clear_Data"),
        (ControlCommand::UNFREEZE, "Unfreeze"),
        (ControlCommand::FREEZE, "Freeze"),
        (ControlCommand::UNSYNC, "Unsync"),
        (ControlCommand::SYNC, "Sync"),
    ]
    .into_iter()
    .filter(|(f, _)| c.contains(*f))
    .map(|(_, n)| n)
    .collect()
}

fn set_prm(du: &[u8]) -> Detail {
    let p = match SetPrm::parse(du) {
        Ok(p) => p,
        Err(e) => return malformed(e),
    };
    let dpv1 = p
        .dpv1_status()
        .is_some_and(|(s1, _, _)| s1.contains(Dpv1Status1::DPV1_ENABLE));
    let station_status = [
        (PrmStationStatus::LOCK_REQ, "Lock_Req"),
        (PrmStationStatus::UNLOCK_REQ, "Unlock_Req"),
        (PrmStationStatus::SYNC_REQ, "Sync_Req"),
        (PrmStationStatus::FREEZE_REQ, "Freeze_Req"),
        (PrmStationStatus::WD_ON, "WD_On"),
    ]
    .into_iter()
    .filter(|(f, _)| p.station_status.contains(*f))
    .map(|(_, n)| n)
    .collect();
    let dpv1_status = match p.dpv1_status() {
        Some((s1, s2, _)) if dpv1 => dpv1_names(s1, s2),
        _ => vec![],
    };
    Detail::SetPrm {
        station_status,
        dpv1_status,
        watchdog_ms: p.watchdog(dpv1).map(|w| w.as_millis() as u64),
        min_tsdr: p.min_tsdr,
        ident_number: p.ident_number,
        groups: groups(p.group_ident),
        user_prm_data: p.user_prm_data.to_vec(),
    }
}

/// The bits set in DPV1_Status_1 and _2 by their names (IEC 61158-6-3,
/// Set_Prm DPV1_Status; reference dpv1-c2-im-alarms.md).
fn dpv1_names(s1: Dpv1Status1, s2: Dpv1Status2) -> Vec<&'static str> {
    let one = [
        (Dpv1Status1::DPV1_ENABLE, "DPV1_Enable"),
        (Dpv1Status1::FAIL_SAFE, "Fail_Safe"),
        (Dpv1Status1::PUBLISHER_ENABLE, "Publisher_Enable"),
        (Dpv1Status1::WD_BASE_1MS, "WD_Base_1ms"),
        (Dpv1Status1::DIS_STOP_CONTROL, "Dis_Stop_Control"),
        (Dpv1Status1::DIS_START_CONTROL, "Dis_Start_Control"),
    ];
    let two = [
        (Dpv1Status2::PULL_PLUG_ALARM, "Pull_Plug_Alarm"),
        (Dpv1Status2::PROCESS_ALARM, "Process_Alarm"),
        (Dpv1Status2::DIAGNOSTIC_ALARM, "Diagnostic_Alarm"),
        (Dpv1Status2::MANUFACTURER_ALARM, "Manufacturer_Alarm"),
        (Dpv1Status2::STATUS_ALARM, "Status_Alarm"),
        (Dpv1Status2::UPDATE_ALARM, "Update_Alarm"),
        (Dpv1Status2::CHECK_CFG_MODE, "Check_Cfg_Mode"),
    ];
    let a = one
        .into_iter()
        .filter(|(f, _)| s1.contains(*f))
        .map(|(_, n)| n);
    let b = two
        .into_iter()
        .filter(|(f, _)| s2.contains(*f))
        .map(|(_, n)| n);
    a.chain(b).collect()
}

fn config(du: &[u8]) -> Detail {
    let mut identifiers = vec![];
    let mut error = None;
    for id in cfg::identifiers(du) {
        match id {
            Ok(id) => identifiers.push(CfgIdentifier {
                raw: id.raw.to_vec(),
                text: id.to_string(),
                input_bytes: id.input_bytes(),
                output_bytes: id.output_bytes(),
            }),
            Err(e) => error = Some(e.to_string()),
        }
    }
    Detail::Cfg {
        input_bytes: identifiers.iter().map(|i| i.input_bytes).sum(),
        output_bytes: identifiers.iter().map(|i| i.output_bytes).sum(),
        identifiers,
        error,
    }
}

fn slave_diag(du: &[u8], dpv1: bool) -> Detail {
    let d = match SlaveDiag::parse(du) {
        Ok(d) => d,
        Err(e) => return malformed(e),
    };
    // `status_words` names each bit that is set, one word per bit.
    let words = d.status_words();
    let status = words
        .split(", ")
        .filter(|w| *w != "OK")
        .map(String::from)
        .collect();
    Detail::SlaveDiag {
        status,
        master_address: (d.master_address != NO_MASTER).then_some(d.master_address),
        ident_number: d.ident_number,
        ext_diag: diag::ext_blocks(d.ext_diag)
            .map(|b| b.describe(dpv1))
            .collect(),
        valid: d.is_valid(),
        alarms: if dpv1 {
            alarm::dpv1_blocks(d.ext_diag)
                .filter_map(|b| match b {
                    DiagBlock::Alarm(a) => Some(AlarmInfo {
                        alarm_type: a.alarm_type.word(),
                        type_code: a.alarm_type.code(),
                        slot: a.slot,
                        specifier: a.specifier.change.word(),
                        seq: a.specifier.seq,
                        add_ack: a.specifier.add_ack,
                        data: a.data.to_vec(),
                    }),
                    DiagBlock::Status(_) => None,
                })
                .collect()
        } else {
            vec![]
        },
    }
}

/// A DP-V1 PDU (function numbers: IEC 61158-6-3; /work/shared/reference
/// dpv1-c2-im-alarms.md §4.3). An empty request polls for the answer.
fn dpv1_pdu(du: &[u8], request: bool) -> Detail {
    let pdu = |pdu, slot, index, length, data: Option<&[u8]>, error| Detail::Dpv1 {
        pdu,
        slot,
        index,
        length,
        text: im_text(index, data),
        data: data.map(<[u8]>::to_vec),
        error,
    };
    let Some(&f) = du.first() else {
        return pdu("Poll", None, None, None, None, None);
    };
    let parsed = if request {
        Pdu::parse_request(du)
    } else {
        Pdu::parse_response(du)
    };
    let len = |x: &[u8]| Some(x.len().min(255) as u8);
    match parsed {
        Ok(Pdu::ReadReq {
            slot,
            index,
            length,
        }) => pdu("Read", Some(slot), Some(index), Some(length), None, None),
        Ok(Pdu::ReadRes { slot, index, data }) => {
            pdu("Read", Some(slot), Some(index), len(data), Some(data), None)
        }
        Ok(Pdu::WriteReq { slot, index, data }) => pdu(
            "Write",
            Some(slot),
            Some(index),
            len(data),
            Some(data),
            None,
        ),
        Ok(Pdu::WriteRes {
            slot,
            index,
            length,
        }) => pdu("Write", Some(slot), Some(index), Some(length), None, None),
        Ok(Pdu::AlarmAck { slot, .. }) => pdu("Alarm_Ack", Some(slot), None, None, None, None),
        Ok(Pdu::Error(e)) => pdu("Error", None, None, None, None, Some(e.describe())),
        Err(e) => {
            let name = match f & 0x7F {
                dpv1::FN_IDLE => "Idle",
                0x51 => "Data_Transport",
                0x56 => "Resource_Manager",
                0x57 => "Initiate",
                0x58 => "Abort",
                _ => return malformed(e),
            };
            let error = (f & 0x80 != 0).then(|| format!("negative response 0x{f:02X}"));
            pdu(name, None, None, None, None, error)
        }
    }
}

/// Words for an I&M call on index 255: the record selected, and I&M0's
/// identity or I&M1..4's fields when the data carry the record.
fn im_text(index: Option<u8>, data: Option<&[u8]>) -> Option<String> {
    if index != Some(im::CALL_INDEX) {
        return None;
    }
    let (h, rest) = CallHeader::parse(data?).ok()?;
    let Some(n) = h.im_number() else {
        return Some(format!("call FI_Index {}", h.fi_index));
    };
    let mut s = format!("I&M{n} call");
    if rest.len() == im::RECORD_LEN {
        if n == 0 {
            if let Ok(r) = Im0::parse(rest) {
                s.push_str(&format!(
                    ": manufacturer {}, order {:?}, serial {:?}, hardware {}, software {}, {}",
                    r.manufacturer_id,
                    r.order_id(),
                    r.serial_number(),
                    r.hardware_revision,
                    r.software_revision,
                    r.im_supported.describe()
                ));
            }
        } else if let Ok(r) = im::ImRecord::parse(n, rest) {
            for (name, value) in r.fields() {
                s.push_str(&format!(", {name} {value:?}"));
            }
        }
    }
    Some(s)
}

/// A class-2 (MSAC_C2) PDU on SAPs 0..=49 (`profibus_dp::pdu::c2`). An
/// empty request polls for the answer.
fn c2_pdu(du: &[u8], request: bool) -> Detail {
    let pdu =
        |pdu, slot, index, length, data: Option<&[u8]>, error, text: Option<String>| Detail::Dpv1 {
            pdu,
            slot,
            index,
            length,
            text: text.or_else(|| im_text(index, data)),
            data: data.map(<[u8]>::to_vec),
            error,
        };
    if du.is_empty() {
        return pdu("Poll", None, None, None, None, None, None);
    }
    let parsed = if request {
        C2Pdu::parse_request(du)
    } else {
        C2Pdu::parse_response(du)
    };
    let len = |x: &[u8]| Some(x.len().min(255) as u8);
    let init = |r: &InitiateRes<'_>| {
        format!(
            "Max_Len_Data_Unit {}, features 0x{:02X}{:02X}, profile 0x{:04X}",
            r.max_len_data_unit,
            r.features_supported_1,
            r.features_supported_2,
            r.profile_ident_number
        )
    };
    match parsed {
        Ok(C2Pdu::InitiateReq(r)) => pdu(
            "Initiate",
            None,
            None,
            None,
            None,
            None,
            Some(format!(
                "Send_Timeout {} ms, features 0x{:02X}{:02X}, profile 0x{:04X}",
                u32::from(r.send_timeout) * 10,
                r.features_supported_1,
                r.features_supported_2,
                r.profile_ident_number
            )),
        ),
        Ok(C2Pdu::InitiateRes(r)) => pdu("Initiate", None, None, None, None, None, Some(init(&r))),
        Ok(C2Pdu::Rm(r)) => pdu(
            "Resource_Manager",
            None,
            None,
            None,
            None,
            None,
            Some(format!(
                "connection SAP {}, Poll_Timeout {}",
                r.sap, r.poll_timeout
            )),
        ),
        Ok(C2Pdu::ReadReq {
            slot,
            index,
            length,
        }) => pdu(
            "Read",
            Some(slot),
            Some(index),
            Some(length),
            None,
            None,
            None,
        ),
        Ok(C2Pdu::ReadRes { slot, index, data }) => pdu(
            "Read",
            Some(slot),
            Some(index),
            len(data),
            Some(data),
            None,
            None,
        ),
        Ok(C2Pdu::WriteReq { slot, index, data }) => pdu(
            "Write",
            Some(slot),
            Some(index),
            len(data),
            Some(data),
            None,
            None,
        ),
        Ok(C2Pdu::WriteRes {
            slot,
            index,
            length,
        }) => pdu(
            "Write",
            Some(slot),
            Some(index),
            Some(length),
            None,
            None,
            None,
        ),
        Ok(C2Pdu::DataTransportReq { slot, index, data })
        | Ok(C2Pdu::DataTransportRes { slot, index, data }) => pdu(
            "Data_Transport",
            Some(slot),
            Some(index),
            len(data),
            Some(data),
            None,
            None,
        ),
        Ok(C2Pdu::Idle) => pdu("Idle", None, None, None, None, None, None),
        Ok(C2Pdu::Abort(a)) => pdu("Abort", None, None, None, None, None, Some(a.describe())),
        Ok(C2Pdu::Error(e)) => pdu("Error", None, None, None, None, Some(e.describe()), None),
        Err(e) => malformed(e),
    }
}

/// A telegram's layer above FDL, as [`Exchanges::decode_layer`] tells
/// it.
#[derive(Debug, Clone, PartialEq)]
pub enum Layer {
    /// A DP or DP-V1 telegram.
    Dp(DpTelegram),
    /// A telegram of an FMS connection: its LLI and FMS PDUs
    /// ([`crate::fms::decode`]).
    Fms(Box<FmsTelegram>),
}

/// Pairs responses with their requests on a stream of telegrams (see the
/// module docs) and decodes each.
#[derive(Debug, Default, Clone)]
pub struct Exchanges {
    /// The last request per (master, slave).
    last: BTreeMap<(u8, u8), Request>,
    /// The request a short acknowledge would answer now.
    pending: Option<Request>,
    /// Slaves last parameterised with DPV1_Enable (their device-related
    /// diagnosis blocks are alarm and status blocks).
    dpv1: BTreeSet<u8>,
    /// GSD files by slave address (a bus file).
    gsd_of: BTreeMap<u8, Gsd>,
    /// GSD files by ident number (a GSD library).
    gsd_by_ident: BTreeMap<u16, Gsd>,
    /// Module layouts by slave address, and whether configured (a bus
    /// file: kept) or learned from the last Chk_Cfg.
    layouts: BTreeMap<u8, (Vec<ModuleLayout>, bool)>,
    /// Named channels by slave address (device profiles of a bus file).
    decoders: BTreeMap<u8, Arc<dyn ImageDecoder>>,
    /// The FMS connections of the stream.
    fms: fms_decode::FmsStream,
}

impl Exchanges {
    /// Knows the slave at `address` from a bus file: its GSD (diagnosis
    /// texts) and its modules (Data_Exchange data split by module).
    pub fn set_slave(&mut self, address: u8, gsd: Option<Gsd>, modules: Vec<ModuleLayout>) {
        if let Some(g) = gsd {
            self.gsd_of.insert(address, g);
        }
        if !modules.is_empty() {
            self.layouts.insert(address, (modules, true));
        }
    }

    /// Names the channels of the slave at `address` with `decoder` (a
    /// device profile's, `profibus_devices::channels::ChannelMap`, the
    /// one `dpctl monitor` decodes with): its Data_Exchange, Rd_Inp and
    /// Rd_Outp data get [`Detail::Inputs`]'s and [`Detail::Outputs`]'
    /// `channels`.
    pub fn set_decoder(&mut self, address: u8, decoder: Box<dyn ImageDecoder>) {
        self.decoders.insert(address, Arc::from(decoder));
    }

    /// Knows `gsd`: a slave with its ident number gets its diagnosis
    /// texts (unless a bus file gave the slave another GSD).
    pub fn add_gsd(&mut self, gsd: Gsd) {
        self.gsd_by_ident.entry(gsd.ident_number).or_insert(gsd);
    }

    /// The layer of the next telegram of the stream: FMS on a
    /// connection SAP (0..=48, which DP-V1 leaves to MSAC_C2 and FMS
    /// shares) when its data unit starts with an LLI or FMS type octet
    /// ([`crate::fms::decode::starts_lli_pdu`]), or carries no data on a
    /// connection seen carrying FMS (a poll, a short acknowledge); else
    /// the DP layer ([`Exchanges::decode`]).
    pub fn decode_layer(&mut self, telegram: &Telegram<'_>) -> Option<Layer> {
        let fms = self.fms_of(telegram);
        let dp = self.decode(telegram);
        match fms {
            Some(f) => Some(Layer::Fms(Box::new(f))),
            None => dp.map(Layer::Dp),
        }
    }

    /// The FMS layer of `telegram` (before [`Exchanges::decode`] moves
    /// on to it): [`fms_decode::FmsStream`], the one rule.
    fn fms_of(&mut self, telegram: &Telegram<'_>) -> Option<FmsTelegram> {
        self.fms.telegram(telegram).map(|(_, f)| f)
    }

    /// The DP layer of the next telegram of the stream, with what is
    /// known of the slave: module names, GSD diagnosis texts.
    pub fn decode(&mut self, telegram: &Telegram<'_>) -> Option<DpTelegram> {
        let mut dp = self.decode_plain(telegram)?;
        let Telegram::Data(d) = telegram else {
            return Some(dp);
        };
        let slave = if d.fc.is_request() { d.da } else { d.sa };
        match &mut dp.detail {
            Some(Detail::Cfg { identifiers, .. })
                if dp.service == "Chk_Cfg"
                    && dp.direction == "request"
                    && !self.layouts.get(&slave).is_some_and(|l| l.1) =>
            {
                let (mut i, mut o) = (0, 0);
                let learned = identifiers
                    .iter()
                    .map(|id| {
                        let m = ModuleLayout {
                            name: id.text.clone(),
                            inputs: Span {
                                offset: i,
                                len: id.input_bytes,
                            },
                            outputs: Span {
                                offset: o,
                                len: id.output_bytes,
                            },
                        };
                        i += id.input_bytes;
                        o += id.output_bytes;
                        m
                    })
                    .collect();
                self.layouts.insert(slave, (learned, false));
            }
            Some(Detail::Outputs {
                outputs,
                modules,
                channels,
            }) => {
                *modules = self.split(slave, outputs, |m| m.outputs);
                *channels = self.readings(slave, Image::Outputs, outputs);
            }
            Some(Detail::Inputs {
                inputs,
                modules,
                channels,
                ..
            }) => {
                *modules = self.split(slave, inputs, |m| m.inputs);
                *channels = self.readings(slave, Image::Inputs, inputs);
            }
            Some(Detail::SlaveDiag {
                ext_diag,
                ident_number,
                ..
            }) => {
                let gsd = (self.gsd_of.get(&slave)).or_else(|| self.gsd_by_ident.get(ident_number));
                if let (Some(g), Ok(diag)) = (gsd, SlaveDiag::parse(d.data)) {
                    *ext_diag = diag::ext_words(diag.ext_diag, Some(g), self.dpv1.contains(&slave));
                }
            }
            _ => {}
        }
        Some(dp)
    }

    /// `bytes` as the named channels of `slave`; empty without a decoder.
    fn readings(&self, slave: u8, image: Image, bytes: &[u8]) -> Vec<Reading> {
        (self.decoders.get(&slave)).map_or(vec![], |d| d.decode(image, bytes))
    }

    /// `image` split by the modules known of `slave` (`span` picks the
    /// image's span); empty when none are known.
    fn split(
        &self,
        slave: u8,
        image: &[u8],
        span: impl Fn(&ModuleLayout) -> Span,
    ) -> Vec<ModuleSlice> {
        let Some((modules, _)) = self.layouts.get(&slave) else {
            return vec![];
        };
        modules
            .iter()
            .enumerate()
            .filter(|(_, m)| span(m).len > 0)
            .map(|(n, m)| ModuleSlice {
                slot: n + 1,
                name: m.name.clone(),
                data: span(m).of(image).to_vec(),
            })
            .collect()
    }

    fn decode_plain(&mut self, telegram: &Telegram<'_>) -> Option<DpTelegram> {
        match telegram {
            Telegram::Token { .. } => {
                self.pending = None;
                None
            }
            Telegram::ShortAck => decode(telegram, self.pending.take().as_ref()),
            Telegram::Data(d) => match (Request::of(d), d.fc) {
                (Some(r), FunctionCode::Request { kind, .. }) => {
                    self.pending = (kind.expects_reply() && !d.is_broadcast()).then_some(r);
                    if self.pending.is_some() {
                        self.last.insert((r.master, r.slave), r);
                    }
                    if r.dsap == Some(sap::SET_PRM) {
                        let dpv1 = SetPrm::parse(d.data).ok().and_then(|p| p.dpv1_status());
                        if dpv1.is_some_and(|(s1, _, _)| s1.contains(Dpv1Status1::DPV1_ENABLE)) {
                            self.dpv1.insert(r.slave);
                        } else {
                            self.dpv1.remove(&r.slave);
                        }
                    }
                    decode(telegram, None)
                }
                _ => {
                    self.pending = None;
                    let r = self.last.get(&(d.da, d.sa)).copied();
                    decode_in(telegram, r.as_ref(), self.dpv1.contains(&d.sa))
                }
            },
        }
    }
}

#[cfg(test)]
mod tests;
