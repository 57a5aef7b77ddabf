//! The JSON payloads of the plain topics, as typed [`Serialize`] values
//! built from the library's types: the master's [`OperatingState`] and
//! [`SlaveState`], the slave's Slave_Diag decoded by [`SlaveDiag`], the
//! images decoded by the device profile's or GSD's [`ChannelValues`]
//! (with the units of scaled channels). Field names and meaning: the
//! topic table of `docs/gateway.md` in the repository.

use crate::settings::SafeState;
use profibus_devices::channels::ChannelValues;
use profibus_dp::master::{AlarmReport, OperatingState, SlaveState};
use profibus_dp::pdu::diag::SlaveDiag;
use serde::{Serialize, Serializer};

/// Lower-case hex of bytes without separators, as the payloads carry
/// images (`"00ab"`).
pub fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

fn ser_hex<S: Serializer>(bytes: &[u8], s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&hex(bytes))
}

impl Serialize for SafeState {
    /// [`SafeState::as_str`].
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

/// `<prefix>/<bus>/status` (retained): `{"state": "online", …}`, or the
/// last will's `{"state": "offline"}`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum Status {
    /// The gateway is connected.
    Online {
        /// The master's operating state (`operate`, `clear`, `stop`).
        master: OperatingState,
        /// Wall-clock time, ms since the Unix epoch.
        ts: u64,
        /// The configured slaves' addresses.
        slaves: Vec<u8>,
        /// The addresses `[mqtt] writable` lists.
        writable: Vec<u8>,
        /// After an outage that reached `outputs_timeout`: what was done.
        #[serde(skip_serializing_if = "Option::is_none")]
        outputs_timeout: Option<OutputsTimeout>,
    },
    /// The last will (or a clean stop).
    Offline,
}

/// The safe state applied in the last broker outage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct OutputsTimeout {
    /// `[mqtt] safe_state`.
    pub safe_state: SafeState,
    /// When it was applied (ms since the Unix epoch).
    pub at: u64,
}

/// `<addr>/state` (retained): the slave's state in the master.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SlaveStatePayload<'a> {
    /// Station address.
    pub address: u8,
    /// Name from the bus file.
    pub name: &'a str,
    /// The master's state of the slave ([`SlaveState::name`]).
    pub state: SlaveState,
    /// The last parameterisation/configuration fault, in words.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fault: Option<&'a str>,
    /// Wall-clock time, ms since the Unix epoch.
    pub ts: u64,
    /// The master's poll cycle counter.
    pub cycle: u64,
}

/// `<addr>/inputs` and `<addr>/outputs` (retained): a process image.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImagePayload<'a> {
    /// Station address.
    pub address: u8,
    /// The image, lower-case hex.
    #[serde(serialize_with = "ser_hex")]
    pub hex: &'a [u8],
    /// Named channels of a profiled or GSD-module slave,
    /// `{"name": value}` (scaled channels in their unit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub values: Option<ChannelValues>,
    /// The units of the scaled channels among `values`, `{"name": "V"}`
    /// (absent when none is scaled).
    #[serde(skip_serializing_if = "Units::is_empty")]
    pub units: Units,
    /// Wall-clock time, ms since the Unix epoch.
    pub ts: u64,
    /// The master's poll cycle counter.
    pub cycle: u64,
}

impl<'a> ImagePayload<'a> {
    /// The payload of `image`, decoded as `values` when the slave has
    /// named channels.
    pub fn new(
        address: u8,
        image: &'a [u8],
        values: Option<ChannelValues>,
        ts: u64,
        cycle: u64,
    ) -> Self {
        let units = Units(
            values
                .iter()
                .flat_map(|v| &v.0)
                .filter_map(|n| Some((n.name.clone(), n.unit.clone()?)))
                .collect(),
        );
        ImagePayload {
            address,
            hex: image,
            values,
            units,
            ts,
            cycle,
        }
    }
}

/// Channel name → engineering unit; serialises as a JSON object.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Units(pub Vec<(String, String)>);

impl Units {
    /// No scaled channel.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

impl Serialize for Units {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(self.0.iter().map(|(n, u)| (n, u)))
    }
}

/// `<addr>/diag` (retained): the last Slave_Diag.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct DiagPayload<'a> {
    /// Station address.
    pub address: u8,
    /// The Slave_Diag data unit, lower-case hex (empty before the first).
    #[serde(serialize_with = "ser_hex")]
    pub hex: &'a [u8],
    /// The station status bits in words (`"Ext_Diag, Stat_Diag"`, `"OK"`),
    /// when the diagnosis has its 6 standard bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub station_status: Option<String>,
    /// The master that parameterised the slave (`null`: none, 255 on the
    /// wire), when the diagnosis has its 6 standard bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub master: Option<Option<u8>>,
    /// The slave's ident number, when the diagnosis has its 6 standard
    /// bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ident_number: Option<u16>,
    /// The whole diagnosis in words ([`profibus_dp::pdu::diag::describe`],
    /// with the GSD's texts when known).
    pub text: Vec<String>,
    /// Wall-clock time, ms since the Unix epoch.
    pub ts: u64,
    /// The master's poll cycle counter.
    pub cycle: u64,
}

impl<'a> DiagPayload<'a> {
    /// The payload of the Slave_Diag `du`; `text` is its description.
    pub fn new(address: u8, du: &'a [u8], text: Vec<String>, ts: u64, cycle: u64) -> Self {
        let d = SlaveDiag::parse(du).ok();
        DiagPayload {
            address,
            hex: du,
            station_status: d.map(|d| d.status_words()),
            master: d.map(|d| (d.master_address != 255).then_some(d.master_address)),
            ident_number: d.map(|d| d.ident_number),
            text,
            ts,
            cycle,
        }
    }
}

/// `<addr>/alarm` (not retained): a DP-V1 alarm once the master
/// acknowledged it or gave up, with the fields of `dpctl master`'s alarm
/// event (`slave`, `type`, `slot`, `specifier`, `seq`, `data`, `text`,
/// `acknowledged`; [`AlarmReport`]) and the time.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct AlarmPayload {
    /// The alarm.
    #[serde(flatten)]
    pub alarm: AlarmReport,
    /// Wall-clock time, ms since the Unix epoch.
    pub ts: u64,
}

/// The result fields of a successful answer.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum AnswerData {
    /// A DP-V1 read: the record.
    Record {
        /// The data, lower-case hex.
        hex: String,
    },
    /// A PKW job.
    Pkw {
        /// The parameter value of the reply.
        value: u32,
        /// Whether the reply carried a double word.
        dword: bool,
        /// The PKW request words sent, hex.
        request: String,
        /// The PKW response words, hex.
        response: String,
    },
    /// An RFID command's answer.
    Rfid {
        /// The answer line, text (without CR).
        answer: String,
        /// The answer, hex.
        hex: String,
    },
}

/// The answer to a request, on its `reply_to` or response topic:
/// `{"ok": true, …}` or `{"ok": false, "error": "…"}`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Answer {
    /// Whether the request was carried out.
    pub ok: bool,
    /// Why not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// What it returned.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub data: Option<AnswerData>,
    /// The request's `"id"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub id: Option<serde_json::Value>,
    /// Wall-clock time, ms since the Unix epoch.
    pub ts: u64,
}

/// A payload as JSON bytes.
pub fn to_bytes(p: &impl Serialize) -> Vec<u8> {
    // Our payload types have string keys and no failing serialisers.
    serde_json::to_vec(p).expect("payloads serialise")
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_devices::channels::{NamedValue, Value};

    #[test]
    fn payload_shapes() {
        assert_eq!(to_bytes(&Status::Offline), br#"{"state":"offline"}"#);
        let s = Status::Online {
            master: OperatingState::Clear,
            ts: 5,
            slaves: vec![3],
            writable: vec![],
            outputs_timeout: Some(OutputsTimeout {
                safe_state: SafeState::Zero,
                at: 4,
            }),
        };
        assert_eq!(
            String::from_utf8(to_bytes(&s)).unwrap(),
            r#"{"state":"online","master":"clear","ts":5,"slaves":[3],"writable":[],"outputs_timeout":{"safe_state":"zero","at":4}}"#
        );
        let v = ChannelValues(vec![
            NamedValue {
                name: "ai1".into(),
                unit: Some("V".into()),
                value: Value::Float(2.5),
            },
            NamedValue {
                name: "st".into(),
                unit: None,
                value: Value::Int(1),
            },
        ]);
        let p = ImagePayload::new(7, &[0x0a, 0xff], Some(v), 1, 2);
        assert_eq!(
            String::from_utf8(to_bytes(&p)).unwrap(),
            r#"{"address":7,"hex":"0aff","values":{"ai1":2.5,"st":1},"units":{"ai1":"V"},"ts":1,"cycle":2}"#
        );
        let d = DiagPayload::new(7, &[0x08, 0x06, 0, 2, 0x12, 0x34], vec![], 1, 2);
        assert_eq!(
            String::from_utf8(to_bytes(&d)).unwrap(),
            r#"{"address":7,"hex":"080600021234","station_status":"Ext_Diag, Stat_Diag","master":2,"ident_number":4660,"text":[],"ts":1,"cycle":2}"#
        );
        let d = DiagPayload::new(7, &[0, 4, 0, 255, 0, 1], vec![], 1, 2);
        assert!(to_bytes(&d).windows(13).any(|w| w == br#""master":null"#));
        let a = Answer {
            ok: true,
            error: None,
            data: Some(AnswerData::Record { hex: "cafe".into() }),
            id: Some(3.into()),
            ts: 9,
        };
        assert_eq!(to_bytes(&a), br#"{"ok":true,"hex":"cafe","id":3,"ts":9}"#);
    }
}
