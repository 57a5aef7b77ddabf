//! The BK3000's FMS face (DP/FMS mixed mode, manual pp. 58–68): its
//! object dictionary (OD), its communication relationship list (KBL) and
//! the FMS services on them, as a model over the coupler's process image.
//! It serves through [`profibus_dp::fms::lli::FmsApplication`].
//!
//! From the manual (page summaries; cut off where marked):
//! - p.60: the OD consists of a header, the list of static data types
//!   and the static object dictionary.
//! - p.61: the connection monitoring of the acyclic connections follows
//!   the master's choice at connect (see `profibus_dp::fms::lli`).
//! - p.62: per channel of a byte-oriented terminal an object with the
//!   channel's whole input (status byte plus n data bytes), read-only:
//!   index 2000 + slot × 20 + channel × 2, Array of (n+1) × Unsigned8,
//!   length n + 1.
//! - p.63: for KL3002…KL3302, KL2502, KL4002: objects i (channel 1),
//!   i+2 (channel 2) and i+1, i+3: Record of Unsigned8, Unsigned16,
//!   read/write (the rest of the table is cut off).
//! - p.64: programmed configuration: tables 71–72, register 0 the number
//!   of programmed objects, then per object from index 1000 two registers:
//!   offset in the local process image (lo, hi), data length, input (0) /
//!   output (1).
//! - p.66: the KBL; connections kr 3–8 are active only when table 0
//!   register 16 holds 2 ("FMS only").
//! - p.67–68: the OD of automatic and programmed configuration: OD header,
//!   data types Unsigned8, Unsigned16, Unsigned32, Octet-String, record
//!   types (U8,U16), (U8,2×U16), (U8,10×U16), (U8,U32), (U8,2×U32),
//!   (U8,10×U32), (U8,U16), 2×(U8,U16), 10×(U8,U16).
//!
//! Our reading where the summary is silent (each (unverified)):
//! - slot = the terminal's 1-based position (as `Owner::Terminal`),
//!   channel counted from 0 (channel 1 → i, channel 2 → i + 2, p.63).
//! - index i + 1 of a terminal with outputs (KL4002, KL2502, KL2xxx
//!   byte-oriented): the channel's output, control byte plus data,
//!   read/write; input terminals have no i + 1 object here.
//! - The status byte of a channel whose DP mapping carries none (compact)
//!   reads 0.
//! - Type indices: Unsigned8 5, Unsigned16 6, Unsigned32 7,
//!   Octet-String 10 (the usual FMS numbering), the record types of
//!   p.67–68 from 11 on in the manual's order.
//! - The encoding of object descriptions ([`ObjectDescription::encode`]).
//! - Table 0 register 16: 0 DP only, 1 DP/FMS mixed, 2 FMS only (only
//!   the value 2 is in the summary).
//! - The LSAPs of the KBL (the summary cuts the table off): kr 1, 2 MSAZ
//!   on LSAPs 40, 41; kr 3–8 (FMS only) on 42–47.

use super::catalogue::Role;
use super::image::{Dir, Entry, Image, Owner, Strip};
use profibus_dp::fms::lli::{FmsApplication, RelationshipType};
use profibus_dp::fms::od::{Description, OdHeader};
use profibus_dp::fms::pdu::{
    GetOdRequest, IdentifyResponse, InitiateRequest, InitiateResponse, Request, Response,
    ServiceError, StatusResponse, ACCESS_ATTRIBUTE_INCONSISTENT, ACCESS_DENIED,
    ACCESS_OBJECT_NON_EXISTENT, ACCESS_TYPE_CONFLICT, ERROR_CLASS_ACCESS, ERROR_CLASS_OD,
    LOGICAL_READY, OD_INVALID_INDEX, PHYSICAL_OPERATIONAL,
};
use profibus_fdl::Instant;

/// First index of the channel objects (p.62).
pub const CHANNEL_BASE: u16 = 2000;
/// First index of the programmed objects (p.64).
pub const PROGRAMMED_BASE: u16 = 1000;

/// The coupler's mode after table 0 register 16 (p.66; values other than
/// 2 are our reading).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FmsMode {
    /// DP only: no FMS.
    DpOnly,
    /// DP and FMS at once (mixed mode): KBL entries 1 and 2.
    Mixed,
    /// FMS only: every KBL entry (1–8).
    FmsOnly,
}

impl FmsMode {
    /// The mode of table 0 register 16.
    pub fn from_register16(v: u16) -> FmsMode {
        match v {
            1 => FmsMode::Mixed,
            2 => FmsMode::FmsOnly,
            _ => FmsMode::DpOnly,
        }
    }
}

/// One entry of the KBL (communication relationship list).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KblEntry {
    /// Communication reference (kr) 1..8.
    pub cref: u8,
    /// The coupler's LSAP (unverified values, see the module docs).
    pub lsap: u8,
    /// Relationship type.
    pub kind: RelationshipType,
}

/// The KBL active in `mode`.
pub fn kbl(mode: FmsMode) -> Vec<KblEntry> {
    let n = match mode {
        FmsMode::DpOnly => 0,
        FmsMode::Mixed => 2,
        FmsMode::FmsOnly => 8,
    };
    (1..=n)
        .map(|cref| KblEntry {
            cref,
            lsap: 39 + cref,
            kind: if cref <= 2 || cref % 2 == 1 {
                RelationshipType::Msaz
            } else {
                RelationshipType::Mszy
            },
        })
        .collect()
}

/// Object codes and access rights of descriptions: the FMS client and
/// this server share them (`profibus_dp::fms::od`).
pub use profibus_dp::fms::od::{Access, ObjectCode};

/// Data type indices of the static type list (unverified numbering).
pub mod types {
    /// Unsigned8.
    pub const UNSIGNED8: u16 = 5;
    /// Unsigned16.
    pub const UNSIGNED16: u16 = 6;
    /// Unsigned32.
    pub const UNSIGNED32: u16 = 7;
    /// Octet-String.
    pub const OCTET_STRING: u16 = 10;
    /// Record (Unsigned8, Unsigned16): the first record type of p.67.
    pub const RECORD_U8_U16: u16 = 11;
}

/// The record types of p.67–68 in the manual's order, from index 11:
/// (name, elements as (type, count)).
const RECORD_TYPES: [(&str, &[(u16, u8)]); 9] = [
    (
        "Unsigned8, Unsigned16",
        &[(types::UNSIGNED8, 1), (types::UNSIGNED16, 1)],
    ),
    (
        "Unsigned8, 2 x Unsigned16",
        &[(types::UNSIGNED8, 1), (types::UNSIGNED16, 2)],
    ),
    (
        "Unsigned8, 10 x Unsigned16",
        &[(types::UNSIGNED8, 1), (types::UNSIGNED16, 10)],
    ),
    (
        "Unsigned8, Unsigned32",
        &[(types::UNSIGNED8, 1), (types::UNSIGNED32, 1)],
    ),
    (
        "Unsigned8, 2 x Unsigned32",
        &[(types::UNSIGNED8, 1), (types::UNSIGNED32, 2)],
    ),
    (
        "Unsigned8, 10 x Unsigned32",
        &[(types::UNSIGNED8, 1), (types::UNSIGNED32, 10)],
    ),
    (
        "Unsigned8, Unsigned16",
        &[(types::UNSIGNED8, 1), (types::UNSIGNED16, 1)],
    ),
    (
        "2 x (Unsigned8, Unsigned16)",
        &[(types::UNSIGNED8, 1), (types::UNSIGNED16, 1)],
    ),
    (
        "10 x (Unsigned8, Unsigned16)",
        &[(types::UNSIGNED8, 1), (types::UNSIGNED16, 1)],
    ),
];

/// One object of the OD and where its value lives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectDescription {
    /// Index.
    pub index: u16,
    /// Object code.
    pub code: ObjectCode,
    /// Data type index (element type of an array).
    pub data_type: u16,
    /// Length in bytes (of a variable; elements of an array).
    pub length: u8,
    /// Access rights.
    pub access: Access,
    /// What it is, for people.
    pub name: String,
    value: Value,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Value {
    /// No value (types).
    None,
    /// A channel: status/control byte entry (if mapped) and data entry.
    Channel {
        dir: Dir,
        head: Option<Entry>,
        data: Entry,
    },
    /// A programmed object: bytes of the input or output image.
    Image { dir: Dir, offset: usize, len: usize },
}

impl ObjectDescription {
    /// The description as Get-OD carries it ([`Description`], layout
    /// unverified): the name only in the long form.
    pub fn encode(&self, long_form: bool) -> Vec<u8> {
        Description {
            index: self.index,
            code: self.code as u8,
            data_type: self.data_type,
            length: self.length,
            access: match self.code {
                ObjectCode::DataType | ObjectCode::DataTypeStructure => 0,
                _ => self.access.to_u8(),
            },
            name: long_form.then(|| self.name.clone()),
        }
        .encode()
    }
}

/// A programmed FMS object (tables 71/72, p.64).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProgrammedObject {
    /// Offset in the local process image.
    pub offset: u16,
    /// Data length.
    pub len: u8,
    /// Output (true) or input.
    pub output: bool,
}

impl ProgrammedObject {
    /// The objects of tables 71–72 as registers: register 0 the count,
    /// then two registers per object (bytes 0–1 offset lo, hi; byte 2
    /// length; byte 3 direction; a register's high byte first is our
    /// reading).
    pub fn from_registers(regs: &[u16]) -> Vec<ProgrammedObject> {
        let n = regs.first().copied().unwrap_or(0) as usize;
        regs[1.min(regs.len())..]
            .chunks_exact(2)
            .take(n)
            .map(|r| {
                let [b0, b1] = r[0].to_be_bytes();
                let [b2, b3] = r[1].to_be_bytes();
                ProgrammedObject {
                    offset: u16::from_le_bytes([b0, b1]),
                    len: b2,
                    output: b3 == 1,
                }
            })
            .collect()
    }
}

/// The coupler's object dictionary.
#[derive(Debug, Clone)]
pub struct ObjectDictionary {
    objects: Vec<ObjectDescription>,
}

/// Index of the channel object of terminal `slot` (1-based), channel
/// `channel` (1-based): 2000 + slot × 20 + (channel − 1) × 2.
pub fn channel_index(slot: usize, channel: u8) -> u16 {
    CHANNEL_BASE + slot as u16 * 20 + (channel as u16 - 1) * 2
}

impl ObjectDictionary {
    /// The OD of automatic configuration: types and one object per
    /// channel of every byte-oriented terminal in `image`; with
    /// `programmed`, the programmed objects from index 1000 instead of
    /// the channel objects (p.64, p.68).
    pub fn new(strip: &Strip, image: &Image, programmed: Option<&[ProgrammedObject]>) -> Self {
        let mut objects = Vec::new();
        let ty = |index, name: &str| ObjectDescription {
            index,
            code: ObjectCode::DataType,
            data_type: index,
            length: 0,
            access: Access::Read,
            name: name.into(),
            value: Value::None,
        };
        objects.push(ty(types::UNSIGNED8, "Unsigned8"));
        objects.push(ty(types::UNSIGNED16, "Unsigned16"));
        objects.push(ty(types::UNSIGNED32, "Unsigned32"));
        objects.push(ty(types::OCTET_STRING, "Octet-String"));
        for (i, (name, elements)) in RECORD_TYPES.iter().enumerate() {
            let len: usize = elements
                .iter()
                .map(|&(t, n)| {
                    n as usize
                        * if t == types::UNSIGNED8 {
                            1
                        } else if t == types::UNSIGNED16 {
                            2
                        } else {
                            4
                        }
                })
                .sum();
            objects.push(ObjectDescription {
                index: types::RECORD_U8_U16 + i as u16,
                code: ObjectCode::DataTypeStructure,
                data_type: types::RECORD_U8_U16 + i as u16,
                length: len as u8,
                access: Access::Read,
                name: format!("Record {name}"),
                value: Value::None,
            });
        }
        match programmed {
            Some(list) => {
                for (n, p) in list.iter().enumerate() {
                    objects.push(ObjectDescription {
                        index: PROGRAMMED_BASE + n as u16,
                        code: ObjectCode::SimpleVariable,
                        data_type: types::OCTET_STRING,
                        length: p.len,
                        access: if p.output {
                            Access::ReadWrite
                        } else {
                            Access::Read
                        },
                        name: format!(
                            "programmed {} bytes {}..{}",
                            if p.output { "output" } else { "input" },
                            p.offset,
                            p.offset as usize + p.len as usize
                        ),
                        value: Value::Image {
                            dir: if p.output { Dir::Out } else { Dir::In },
                            offset: p.offset as usize,
                            len: p.len as usize,
                        },
                    });
                }
            }
            None => {
                for (pos0, slot) in strip.slots().iter().enumerate() {
                    let pos = pos0 + 1;
                    if slot.ty.is_digital() || slot.ty.channels == 0 {
                        continue;
                    }
                    for ch in 1..=slot.ty.channels {
                        let find = |dir: Dir, role: Role| {
                            image
                                .entries
                                .iter()
                                .find(|e| {
                                    e.owner == Owner::Terminal(pos)
                                        && e.channel == ch
                                        && e.dir == dir
                                        && e.role == role
                                })
                                .cloned()
                        };
                        let index = channel_index(pos, ch);
                        for (dir, head, offset, access, what) in [
                            (Dir::In, Role::Status, 0, Access::Read, "input"),
                            (Dir::Out, Role::Control, 1, Access::ReadWrite, "output"),
                        ] {
                            let Some(data) = find(dir, Role::Value) else {
                                continue;
                            };
                            objects.push(ObjectDescription {
                                index: index + offset,
                                code: ObjectCode::Array,
                                data_type: types::UNSIGNED8,
                                length: data.bytes + 1,
                                access,
                                name: format!("{pos}.{}.{ch} {what}", slot.ty.name),
                                value: Value::Channel {
                                    dir,
                                    head: find(dir, head),
                                    data,
                                },
                            });
                        }
                    }
                }
            }
        }
        objects.sort_by_key(|o| o.index);
        ObjectDictionary { objects }
    }

    /// Every object, by index.
    pub fn objects(&self) -> &[ObjectDescription] {
        &self.objects
    }

    /// The object at `index`.
    pub fn get(&self, index: u16) -> Option<&ObjectDescription> {
        self.objects
            .binary_search_by_key(&index, |o| o.index)
            .ok()
            .map(|i| &self.objects[i])
    }

    /// The OD header (index 0; [`OdHeader`], layout unverified).
    pub fn header(&self) -> Vec<u8> {
        let first_object = self
            .objects
            .iter()
            .find(|o| o.value != Value::None)
            .map_or(0, |o| o.index);
        OdHeader {
            objects: self.objects.len() as u16,
            first_type: types::UNSIGNED8,
            last_type: types::RECORD_U8_U16 + RECORD_TYPES.len() as u16 - 1,
            first_object,
        }
        .encode()
    }

    /// Where element `subindex` (1-based) of the object at `index` lies
    /// in its value. The channel objects are Arrays of Unsigned8 (our
    /// reading of p.62–63), so an element is one octet: subindex 1 is
    /// the status (control) byte, 2… the data bytes. The manual says
    /// nothing of subindex access; a subindex beyond the array, or of
    /// an object that is no array, is refused as FMS does an
    /// impermissible subindex: class 6 code 5, object attribute
    /// inconsistent ([`ACCESS_ATTRIBUTE_INCONSISTENT`]).
    pub fn element(&self, index: u16, subindex: u8) -> Result<usize, ServiceError> {
        let o = self.get(index).ok_or_else(Self::not_there)?;
        if o.code != ObjectCode::Array || subindex == 0 || subindex > o.length {
            return Err(ServiceError::new(
                ERROR_CLASS_ACCESS,
                ACCESS_ATTRIBUTE_INCONSISTENT,
            ));
        }
        Ok(subindex as usize - 1)
    }

    fn not_there() -> ServiceError {
        ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_OBJECT_NON_EXISTENT)
    }

    /// Read: the object's value from the process image (`inputs` as the
    /// last Data_Exchange carried them, `outputs` as applied).
    pub fn read(&self, index: u16, inputs: &[u8], outputs: &[u8]) -> Result<Vec<u8>, ServiceError> {
        let o = self.get(index).ok_or_else(Self::not_there)?;
        let image = |dir: Dir| if dir == Dir::In { inputs } else { outputs };
        match &o.value {
            Value::None => Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_DENIED)),
            Value::Channel { dir, head, data } => {
                let img = image(*dir);
                let mut v = vec![head.as_ref().map_or(0, |h| Image::get(h, img) as u8)];
                let bytes = img
                    .get(data.byte..data.byte + data.bytes as usize)
                    .ok_or_else(Self::not_there)?;
                v.extend_from_slice(bytes);
                Ok(v)
            }
            Value::Image { dir, offset, len } => image(*dir)
                .get(*offset..offset + len)
                .map(<[u8]>::to_vec)
                .ok_or_else(Self::not_there),
        }
    }

    /// Write: the new value into `outputs` (read-only objects and wrong
    /// lengths refused).
    pub fn write(&self, index: u16, value: &[u8], outputs: &mut [u8]) -> Result<(), ServiceError> {
        let o = self.get(index).ok_or_else(Self::not_there)?;
        if o.access != Access::ReadWrite {
            return Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_DENIED));
        }
        let conflict = ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_TYPE_CONFLICT);
        match &o.value {
            Value::Channel {
                dir: Dir::Out,
                head,
                data,
            } => {
                if value.len() != data.bytes as usize + 1 {
                    return Err(conflict);
                }
                if let Some(h) = head {
                    Image::put(h, outputs, value[0] as i64);
                }
                outputs
                    .get_mut(data.byte..data.byte + data.bytes as usize)
                    .ok_or_else(Self::not_there)?
                    .copy_from_slice(&value[1..]);
                Ok(())
            }
            Value::Image {
                dir: Dir::Out,
                offset,
                len,
            } => {
                if value.len() != *len {
                    return Err(conflict);
                }
                outputs
                    .get_mut(*offset..offset + len)
                    .ok_or_else(Self::not_there)?
                    .copy_from_slice(value);
                Ok(())
            }
            _ => Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_DENIED)),
        }
    }

    /// Get-OD: index 0 is the OD header; with `from_index` the
    /// descriptions from `index` on, as many as fit into `room` bytes.
    pub fn get_od(&self, req: &GetOdRequest, room: usize) -> Result<Response, ServiceError> {
        if req.index == 0 && !req.from_index {
            return Ok(Response::GetOd {
                more_follows: false,
                descriptions: vec![self.header()],
            });
        }
        if !req.from_index {
            let o = self
                .get(req.index)
                .ok_or(ServiceError::new(ERROR_CLASS_OD, OD_INVALID_INDEX))?;
            return Ok(Response::GetOd {
                more_follows: false,
                descriptions: vec![o.encode(req.long_form)],
            });
        }
        let mut descriptions = Vec::new();
        let mut used = 0;
        let mut more_follows = false;
        for o in self.objects.iter().filter(|o| o.index >= req.index) {
            let d = o.encode(req.long_form);
            // The first always goes (a description is at most 42 bytes,
            // far below a PDU's room).
            if !descriptions.is_empty() && used + d.len() + 1 > room {
                more_follows = true;
                break;
            }
            used += d.len() + 1;
            descriptions.push(d);
        }
        Ok(Response::GetOd {
            more_follows,
            descriptions,
        })
    }
}

/// The coupler's FMS server: its OD over a snapshot of the process image.
/// Writes land in `outputs`; the owner applies them to the terminals.
#[derive(Debug)]
pub struct FmsServer<'a> {
    /// The object dictionary.
    pub od: &'a ObjectDictionary,
    /// The inputs of the last Data_Exchange.
    pub inputs: &'a [u8],
    /// The applied outputs (changed by Write).
    pub outputs: &'a mut Vec<u8>,
    /// Whether a Write changed `outputs`.
    pub written: bool,
}

/// Room for Get-OD descriptions in one response: the PDU limit minus the
/// response header (type, invoke ID, service, more-follows, count).
const GET_OD_ROOM: usize = profibus_dp::fms::pdu::MAX_PDU_LEN - 5;

impl FmsApplication for FmsServer<'_> {
    fn initiate(&mut self, _req: &InitiateRequest) -> Result<InitiateResponse, u8> {
        Ok(InitiateResponse {
            version_od: 1,
            profile: [0, 0],
            access_protection: false,
            password: 0,
            access_groups: 0,
        })
    }

    fn confirmed(&mut self, _now: Instant, req: &Request) -> Result<Response, ServiceError> {
        match req {
            Request::Status => Ok(Response::Status(StatusResponse {
                logical: LOGICAL_READY,
                physical: PHYSICAL_OPERATIONAL,
                local_detail: [0; 3],
            })),
            Request::Identify => Ok(Response::Identify(IdentifyResponse {
                vendor: "Beckhoff".into(),
                model: "BK3000".into(),
                revision: "emulated".into(),
            })),
            Request::Read { index, subindex } => {
                let v = self.od.read(*index, self.inputs, self.outputs)?;
                match subindex {
                    // Subindex 0: the whole object (as a Write's 0).
                    None | Some(0) => Ok(Response::Read(v)),
                    Some(s) => {
                        let at = self.od.element(*index, *s)?;
                        Ok(Response::Read(
                            v.get(at).map(|b| vec![*b]).unwrap_or_default(),
                        ))
                    }
                }
            }
            Request::Write {
                index,
                subindex: None,
                data,
            } => {
                self.od.write(*index, data, self.outputs)?;
                self.written = true;
                Ok(Response::Write)
            }
            Request::Write {
                index,
                subindex: Some(s),
                data,
            } => {
                // One element: the object's other elements stay.
                let o = self
                    .od
                    .get(*index)
                    .ok_or_else(ObjectDictionary::not_there)?;
                if o.access != Access::ReadWrite {
                    return Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_DENIED));
                }
                let at = self.od.element(*index, *s)?;
                if data.len() != 1 {
                    return Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_TYPE_CONFLICT));
                }
                let mut v = self.od.read(*index, self.inputs, self.outputs)?;
                if let Some(b) = v.get_mut(at) {
                    *b = data[0];
                }
                self.od.write(*index, &v, self.outputs)?;
                self.written = true;
                Ok(Response::Write)
            }
            Request::GetOd(g) => self.od.get_od(g, GET_OD_ROOM),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::image::Options;
    use super::*;
    use profibus_dp::fms::lli::{ClientEvent, LliClient, LliServer};
    use profibus_dp::fms::pdu::FmsPdu;
    use std::time::Duration;

    fn strip() -> (Strip, Image) {
        let strip = Strip::parse("KL3102:complete, KL4002:complete, KL1104, KL9010").unwrap();
        let image = strip.default_image(Options::default());
        (strip, image)
    }

    #[test]
    fn channel_objects_sit_at_2000_plus_slot_times_20_plus_channel_times_2() {
        let (strip, image) = strip();
        let od = ObjectDictionary::new(&strip, &image, None);
        let idx: Vec<u16> = od
            .objects()
            .iter()
            .filter(|o| o.index >= CHANNEL_BASE)
            .map(|o| o.index)
            .collect();
        // KL3102 at 1: inputs 2020, 2022; KL4002 at 2: outputs 2041,
        // 2043 (and its status inputs, when the mapping has them).
        assert!(idx.contains(&2020) && idx.contains(&2022), "{idx:?}");
        assert!(idx.contains(&2041) && idx.contains(&2043), "{idx:?}");
        assert!(
            !idx.iter().any(|&i| i >= 2060),
            "no objects for digital terminals"
        );
        let o = od.get(2020).unwrap();
        assert_eq!(
            (o.code, o.length, o.access),
            (ObjectCode::Array, 3, Access::Read)
        );
        assert_eq!(od.get(2041).unwrap().access, Access::ReadWrite);
        assert_eq!(
            od.get(types::UNSIGNED16).unwrap().code,
            ObjectCode::DataType
        );
    }

    #[test]
    fn a_channel_object_reads_the_bytes_data_exchange_carries() {
        let (strip, image) = strip();
        let od = ObjectDictionary::new(&strip, &image, None);
        let status = image
            .entries
            .iter()
            .find(|e| e.name == "1.KL3102.2.status")
            .unwrap();
        let value = image
            .entries
            .iter()
            .find(|e| e.name == "1.KL3102.2")
            .unwrap();
        let mut inputs = vec![0u8; image.in_len];
        Image::put(status, &mut inputs, 0x41);
        Image::put(value, &mut inputs, 0x1234);
        let got = od.read(2022, &inputs, &[]).unwrap();
        assert_eq!(got, [0x41, 0x12, 0x34]);
        // Writes: the KL4002's channel 2 output object lands in the image.
        let mut outputs = vec![0u8; image.out_len];
        od.write(2043, &[0x00, 0x40, 0x00], &mut outputs).unwrap();
        let out = image
            .entries
            .iter()
            .find(|e| e.name == "2.KL4002.2")
            .unwrap();
        assert_eq!(Image::get(out, &outputs), 0x4000);
        assert_eq!(
            od.write(2022, &[0, 0, 0], &mut outputs),
            Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_DENIED))
        );
        assert_eq!(
            od.write(2043, &[0, 0], &mut outputs),
            Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_TYPE_CONFLICT))
        );
        assert_eq!(
            od.read(2999, &inputs, &outputs),
            Err(ServiceError::new(
                ERROR_CLASS_ACCESS,
                ACCESS_OBJECT_NON_EXISTENT
            ))
        );
    }

    #[test]
    fn programmed_objects_start_at_1000() {
        let (strip, image) = strip();
        let regs = [2, 0x0200, 0x0400, 0x0000, 0x0201];
        let list = ProgrammedObject::from_registers(&regs);
        assert_eq!(
            list,
            [
                ProgrammedObject {
                    offset: 2,
                    len: 4,
                    output: false
                },
                ProgrammedObject {
                    offset: 0,
                    len: 2,
                    output: true
                },
            ]
        );
        let od = ObjectDictionary::new(&strip, &image, Some(&list));
        assert!(od.get(2020).is_none());
        let inputs = [9, 9, 1, 2, 3, 4];
        assert_eq!(od.read(1000, &inputs, &[]).unwrap(), [1, 2, 3, 4]);
        let mut outputs = vec![0; 4];
        od.write(1001, &[7, 8], &mut outputs).unwrap();
        assert_eq!(outputs, [7, 8, 0, 0]);
    }

    #[test]
    fn get_od_pages_the_dictionary_and_kbl_follows_register_16() {
        let (strip, image) = strip();
        let od = ObjectDictionary::new(&strip, &image, None);
        let mut index = 1;
        let mut seen = 0;
        loop {
            let req = GetOdRequest {
                long_form: true,
                from_index: true,
                index,
            };
            let Response::GetOd {
                more_follows,
                descriptions,
            } = od.get_od(&req, 40).unwrap()
            else {
                panic!()
            };
            assert!(!descriptions.is_empty());
            seen += descriptions.len();
            let last = descriptions.last().unwrap();
            index = u16::from_be_bytes([last[0], last[1]]) + 1;
            if !more_follows {
                break;
            }
        }
        assert_eq!(seen, od.objects().len());
        assert_eq!(kbl(FmsMode::from_register16(0)), []);
        assert_eq!(kbl(FmsMode::from_register16(1)).len(), 2);
        assert_eq!(kbl(FmsMode::from_register16(2)).len(), 8);
    }

    #[test]
    fn a_subindex_reads_and_writes_one_element_of_a_channel_array() {
        let (strip, image) = strip();
        let od = ObjectDictionary::new(&strip, &image, None);
        let inputs: Vec<u8> = (0..image.in_len as u8).map(|i| 0x10 + i).collect();
        let mut outputs = vec![0u8; image.out_len];
        let whole_in = od.read(2020, &inputs, &outputs).unwrap();
        let whole_out = od.read(2041, &inputs, &outputs).unwrap();
        assert_eq!((whole_in.len(), whole_out.len()), (3, 3));
        let mut app = FmsServer {
            od: &od,
            inputs: &inputs,
            outputs: &mut outputs,
            written: false,
        };
        let now = Instant::ZERO;
        let read = |index, subindex| Request::Read { index, subindex };
        let write = |index, subindex, data: &[u8]| Request::Write {
            index,
            subindex,
            data: data.to_vec(),
        };
        for s in 1..=3u8 {
            assert_eq!(
                app.confirmed(now, &read(2020, Some(s))),
                Ok(Response::Read(vec![whole_in[s as usize - 1]]))
            );
        }
        // Subindex 0 is the whole object, as without one.
        assert_eq!(
            app.confirmed(now, &read(2020, Some(0))),
            Ok(Response::Read(whole_in.clone()))
        );
        // Element 3 of the KL4002 channel: the low data byte; the others
        // stay.
        assert_eq!(
            app.confirmed(now, &write(2041, Some(3), &[0x7F])),
            Ok(Response::Write)
        );
        assert!(app.written);
        assert_eq!(
            app.confirmed(now, &read(2041, None)),
            Ok(Response::Read(vec![whole_out[0], whole_out[1], 0x7F]))
        );
        let inconsistent = Err(ServiceError::new(
            ERROR_CLASS_ACCESS,
            ACCESS_ATTRIBUTE_INCONSISTENT,
        ));
        // Beyond the array, or of an object that is no array.
        assert_eq!(app.confirmed(now, &read(2020, Some(4))), inconsistent);
        assert_eq!(
            app.confirmed(now, &write(2041, Some(4), &[1])),
            inconsistent
        );
        assert_eq!(
            app.confirmed(now, &read(types::UNSIGNED8, Some(1))),
            Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_DENIED))
        );
        // One octet per element; read-only stays read-only.
        assert_eq!(
            app.confirmed(now, &write(2041, Some(2), &[1, 2])),
            Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_TYPE_CONFLICT))
        );
        assert_eq!(
            app.confirmed(now, &write(2020, Some(2), &[1])),
            Err(ServiceError::new(ERROR_CLASS_ACCESS, ACCESS_DENIED))
        );
        assert_eq!(
            app.confirmed(now, &read(2999, Some(1))),
            Err(ServiceError::new(
                ERROR_CLASS_ACCESS,
                ACCESS_OBJECT_NON_EXISTENT
            ))
        );
    }

    #[test]
    fn an_fms_client_reads_and_writes_through_the_lli() {
        let (strip, image) = strip();
        let od = ObjectDictionary::new(&strip, &image, None);
        let value = image
            .entries
            .iter()
            .find(|e| e.name == "1.KL3102.1")
            .unwrap();
        let mut inputs = vec![0u8; image.in_len];
        Image::put(value, &mut inputs, -2);
        let mut outputs = vec![0u8; image.out_len];
        let entry = kbl(FmsMode::Mixed)[0];
        let mut server = LliServer::new(entry.lsap, entry.kind, None);
        let mut client = LliClient::new(5, entry.lsap, 33, Some(Duration::from_secs(1)));
        let mut now = Instant::ZERO;
        let mut run = |client: &mut LliClient, server: &mut LliServer, outputs: &mut Vec<u8>| {
            now += Duration::from_millis(1);
            let du = client.next_srd(now).unwrap();
            let mut app = FmsServer {
                od: &od,
                inputs: &inputs,
                outputs,
                written: false,
            };
            let reply = server.on_srd(now, 2, 33, &du, &mut app);
            client.on_reply(now, reply.as_deref());
            client.take_events()
        };
        client.connect(
            Instant::ZERO,
            InitiateRequest {
                version_od: 0,
                profile: [0, 0],
                access_protection: false,
                password: 0,
                access_groups: 0,
                max_pdu_send_high: 0,
                max_pdu_send_low: 241,
                max_pdu_recv_high: 0,
                max_pdu_recv_low: 241,
                features: [0; 6],
            },
        );
        assert!(matches!(
            run(&mut client, &mut server, &mut outputs)[..],
            [ClientEvent::Connected(_)]
        ));
        client
            .request(Request::Read {
                index: 2020,
                subindex: None,
            })
            .unwrap();
        let ev = run(&mut client, &mut server, &mut outputs);
        assert!(
            matches!(&ev[..], [ClientEvent::Confirmation { result: Ok(Response::Read(v)), .. }] if v == &[0, 0xFF, 0xFE]),
            "{ev:?}"
        );
        client
            .request(Request::Write {
                index: 2041,
                subindex: None,
                data: vec![0, 0x12, 0x34],
            })
            .unwrap();
        let ev = run(&mut client, &mut server, &mut outputs);
        assert!(
            matches!(
                &ev[..],
                [ClientEvent::Confirmation {
                    result: Ok(Response::Write),
                    ..
                }]
            ),
            "{ev:?}"
        );
        let out = image
            .entries
            .iter()
            .find(|e| e.name == "2.KL4002.1")
            .unwrap();
        assert_eq!(Image::get(out, &outputs), 0x1234);
        client.request(Request::Identify).unwrap();
        let ev = run(&mut client, &mut server, &mut outputs);
        let text = match &ev[..] {
            [ClientEvent::Confirmation {
                invoke_id,
                result: Ok(r),
            }] => FmsPdu::Response {
                invoke_id: *invoke_id,
                response: r.clone(),
            }
            .to_string(),
            other => panic!("{other:?}"),
        };
        assert!(text.ends_with("Beckhoff BK3000 emulated"), "{text}");
    }

    /// The checks of issue 35 at the slave: a BK3000 with KL3102 and
    /// KL4002 in Data_Exchange with a class-1 master while an FMS client
    /// on the same slave reads a channel object (status byte plus value
    /// equal to what Data_Exchange carries), writes an output channel
    /// object and reads the OD; DP only: the LSAP is not activated; a
    /// silent client is aborted by connection monitoring.
    #[test]
    fn mixed_mode_serves_fms_beside_data_exchange() {
        use super::super::master::Bk3000Master;
        use super::super::Bk3000;
        use profibus_dp::pdu::sap;
        use profibus_dp::slave::{Device, DpSlave, SlaveState};
        use profibus_fdl::station::passive::{Reply, Responder};
        use profibus_fdl::{DataTelegram, FunctionCode, RequestKind};

        const LIST: &str = "KL3102,KL4002,KL9010";
        let names: Vec<&str> = LIST.split(',').collect();
        let m = Bk3000Master::from_names(&names).unwrap();
        let mut prm = vec![0x88, 1, 100, 11, 0xBE, 0xCF, 0];
        prm.extend_from_slice(&m.user_prm_data());
        let req = |slave: &mut DpSlave<Bk3000>,
                   now: Instant,
                   saps: Option<(u8, u8)>,
                   data: &[u8]|
         -> (Reply, Vec<u8>) {
            let fc = FunctionCode::request(RequestKind::SrdHigh);
            let t =
                DataTelegram::new(5, 2, fc, data).with_saps(saps.map(|s| s.0), saps.map(|s| s.1));
            let mut out = [0u8; 246];
            let r = slave.on_request(now, &t, &mut out);
            let len = match r {
                Reply::Data { len, .. } => len,
                _ => 0,
            };
            (r, out[..len].to_vec())
        };
        for mode in [FmsMode::DpOnly, FmsMode::Mixed] {
            let dev = Bk3000::new(Strip::parse(LIST).unwrap()).with_fms_mode(mode);
            let mut slave = DpSlave::new(dev, 5);
            let mut now = Instant::ZERO;
            req(&mut slave, now, Some((sap::SET_PRM, sap::MASTER)), &prm);
            req(
                &mut slave,
                now,
                Some((sap::CHK_CFG, sap::MASTER)),
                m.chk_cfg(),
            );
            let outputs = vec![0u8; m.image().out_len];
            let inputs = req(&mut slave, now, None, &outputs).1;
            assert_eq!(slave.state(), SlaveState::DataExch);
            let lsap = 40;
            let mut client = LliClient::new(5, lsap, 33, Some(Duration::from_millis(300)));
            client.connect(
                now,
                InitiateRequest {
                    version_od: 0,
                    profile: [0, 0],
                    access_protection: false,
                    password: 0,
                    access_groups: 0,
                    max_pdu_send_high: 0,
                    max_pdu_send_low: 241,
                    max_pdu_recv_high: 0,
                    max_pdu_recv_low: 241,
                    features: [0; 6],
                },
            );
            let du = client.next_srd(now).unwrap();
            let (reply, data) = req(&mut slave, now, Some((lsap, 33)), &du);
            if mode == FmsMode::DpOnly {
                assert!(
                    matches!(
                        reply,
                        Reply::Data {
                            status: profibus_fdl::ResponseStatus::Rs,
                            ..
                        }
                    ),
                    "SAP not activated: {reply:?}"
                );
                continue;
            }
            client.on_reply(now, Some(&data));
            assert!(client.is_open(), "{:?}", client.take_events());
            client.take_events();
            // Read KL3102 channel 2 (slot 1): index 2022, equal to the
            // bytes the last Data_Exchange carried.
            now += Duration::from_millis(10);
            client
                .request(Request::Read {
                    index: 2022,
                    subindex: None,
                })
                .unwrap();
            let du = client.next_srd(now).unwrap();
            let data = req(&mut slave, now, Some((lsap, 33)), &du).1;
            client.on_reply(now, Some(&data));
            let img = slave.device().image().clone();
            let st = img.entries.iter().find(|e| e.name == "1.KL3102.2.status");
            let val = img.entries.iter().find(|e| e.name == "1.KL3102.2").unwrap();
            let mut expect = vec![st.map_or(0, |e| Image::get(e, &inputs) as u8)];
            expect.extend_from_slice(&inputs[val.byte..val.byte + 2]);
            let ev = client.take_events();
            assert!(
                matches!(&ev[..], [ClientEvent::Confirmation { result: Ok(Response::Read(v)), .. }] if *v == expect),
                "{ev:?} expected {expect:02X?}"
            );
            // Write KL4002 channel 1 (slot 2): index 2041.
            client
                .request(Request::Write {
                    index: 2041,
                    subindex: None,
                    data: vec![0, 0x20, 0x00],
                })
                .unwrap();
            let du = client.next_srd(now).unwrap();
            let data = req(&mut slave, now, Some((lsap, 33)), &du).1;
            client.on_reply(now, Some(&data));
            assert!(matches!(
                &client.take_events()[..],
                [ClientEvent::Confirmation {
                    result: Ok(Response::Write),
                    ..
                }]
            ));
            assert_eq!(slave.device().output_value("2.KL4002.1"), Some(0x2000));
            // Get-OD from index 2000 on.
            client
                .request(Request::GetOd(GetOdRequest {
                    long_form: false,
                    from_index: true,
                    index: 2000,
                }))
                .unwrap();
            let du = client.next_srd(now).unwrap();
            let data = req(&mut slave, now, Some((lsap, 33)), &du).1;
            client.on_reply(now, Some(&data));
            let ev = client.take_events();
            let [ClientEvent::Confirmation {
                result: Ok(Response::GetOd { descriptions, .. }),
                ..
            }] = &ev[..]
            else {
                panic!("{ev:?}")
            };
            let idx: Vec<u16> = descriptions
                .iter()
                .map(|d| u16::from_be_bytes([d[0], d[1]]))
                .collect();
            assert!(idx.contains(&2020) && idx.contains(&2041), "{idx:?}");
            // Data_Exchange went on all along; the master's unchanged
            // outputs keep the written value, different ones replace it.
            req(&mut slave, now, None, &outputs);
            assert_eq!(slave.state(), SlaveState::DataExch);
            assert_eq!(slave.device().output_value("2.KL4002.1"), Some(0x2000));
            let mut other = outputs.clone();
            let ch2 = img.entries.iter().find(|e| e.name == "2.KL4002.2").unwrap();
            Image::put(ch2, &mut other, 0x0100);
            req(&mut slave, now, None, &other);
            assert_eq!(slave.device().output_value("2.KL4002.1"), Some(0));
            assert_eq!(slave.device().output_value("2.KL4002.2"), Some(0x0100));
            // The client falls silent: connection monitoring aborts it.
            let due = slave.device().poll_timeout().unwrap();
            assert!(due <= now + Duration::from_millis(300));
            slave.device_mut().handle_timeout(due);
            let texts: Vec<String> = std::iter::from_fn(|| slave.device_mut().poll_event())
                .filter(|e| e.kind == "fms")
                .map(|e| e.text)
                .collect();
            assert!(
                texts
                    .iter()
                    .any(|t| t.contains("aborted by the coupler") && t.contains("client silent")),
                "{texts:?}"
            );
        }
    }

    #[test]
    fn the_fms_device_option_names_its_modes() {
        use super::super::profile::{Bk3000Profile, Options};
        use crate::profile::Profile;
        let o = Options {
            fms: Some("both".into()),
            ..Default::default()
        };
        let e = Bk3000Profile::configure(o, None).unwrap_err().to_string();
        assert!(e.contains("use dp, mixed or fms"), "{e}");
        let o = Options {
            fms: Some("mixed".into()),
            ..Default::default()
        };
        assert!(Bk3000Profile::configure(o, None).is_ok());
    }
}
