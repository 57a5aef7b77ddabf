//! I&M0 in a slave's identity: once a DP-V1 slave first reaches
//! Data_Exchange, the master reads its I&M0 over MSAC_C1 (the I&M call
//! on slot 0, index 255: a selecting write, then the read;
//! `shared/reference/dpv1-c2-im-alarms.md` §4.6) and the identity
//! properties named after OPC UA for Devices `DeviceType` (OPC
//! 10000-100, 5.5.2) take its values: `SerialNumber`, `RevisionCounter`,
//! `ProductCode` (ORDER_ID), `HardwareRevision`, `SoftwareRevision`,
//! `ManufacturerId` (MANUFACTURER_ID).
//!
//! `Manufacturer` keeps the GSD's `Vendor_Name`: I&M0 carries only the
//! number of the PI manufacturer table, which the project does not ship;
//! without a vendor name in the GSD it becomes `manufacturer 0x…`.
//! DP-V0 slaves are not asked; a slave that refuses or fails the read
//! keeps the GSD's values, and the gateway logs that once.

use crate::space::{time, Update};
use opcua::types::{DataValue, NodeId, StatusCode, Variant};
use profibus_dp::master::records::{C1Records, ImReader, RecordAnswer, RecordOp, RecordOps};
use profibus_dp::master::{DpMaster, SlaveState, SlaveTask};
use profibus_dp::pdu::im::Im0;
use profibus_fdl::Instant;

/// [`ImReader`] stopped after I&M0.
#[derive(Debug)]
struct Im0Only(ImReader);

impl RecordOps for Im0Only {
    fn next_op(&mut self) -> Option<RecordOp> {
        if self.0.records[0].is_some() {
            return None;
        }
        self.0.next_op()
    }

    fn answered(&mut self, op: &RecordOp, answer: &RecordAnswer) {
        self.0.answered(op, answer);
    }
}

/// Where one slave's I&M0 read is.
#[derive(Debug)]
enum Read {
    /// Not yet in Data_Exchange.
    Waiting,
    /// Jobs of the master run.
    Running(Box<C1Records<Im0Only>>),
    /// Read (its values shown) or given up (logged).
    Done,
}

/// One slave's read.
#[derive(Debug)]
struct Slave {
    address: u8,
    has_vendor: bool,
    read: Read,
}

/// The I&M0 reads of a bus's DP-V1 slaves.
#[derive(Debug)]
pub struct Identities {
    ns: u16,
    bus: String,
    slaves: Vec<Slave>,
}

impl Identities {
    /// Reads for the DP-V1 slaves among `slaves` (address, DP-V1, whether
    /// the GSD names the vendor), node ids `<bus>.<address>.<property>`
    /// in namespace `ns`.
    pub fn new(ns: u16, bus: &str, slaves: impl IntoIterator<Item = (u8, bool, bool)>) -> Self {
        let slaves = slaves
            .into_iter()
            .filter(|(_, dpv1, _)| *dpv1)
            .map(|(address, _, has_vendor)| Slave {
                address,
                has_vendor,
                read: Read::Waiting,
            })
            .collect();
        Identities {
            ns,
            bus: bus.to_string(),
            slaves,
        }
    }

    /// Drive the reads at a cycle boundary; the property values of the
    /// I&M0s read now.
    pub fn step(&mut self, m: &mut DpMaster, now: Instant, ts_ms: u64) -> Vec<Update> {
        let mut out = vec![];
        for s in &mut self.slaves {
            let Some(h) = m.handle(s.address) else {
                s.read = Read::Done;
                continue;
            };
            let in_dx = m.slave(h).state == SlaveState::DataExchange;
            let mut task = match std::mem::replace(&mut s.read, Read::Done) {
                Read::Waiting if in_dx => {
                    Box::new(C1Records::new(s.address, Im0Only(ImReader::new(0, None))))
                }
                Read::Running(t) => t,
                r => {
                    s.read = r;
                    continue;
                }
            };
            match task.step(m, now, in_dx) {
                Ok(false) => s.read = Read::Running(task),
                Ok(true) => match task.ops().0.im0() {
                    Some(im) => {
                        tracing::info!(
                            address = s.address,
                            serial = %im.serial_number(),
                            "I&M0 read for the OPC UA identity"
                        );
                        out.extend(updates(self.ns, &self.bus, s, &im, ts_ms));
                    }
                    None => tracing::warn!(
                        address = s.address,
                        "I&M0 not read, the OPC UA identity keeps the GSD's values: {}",
                        why(&task.ops().0)
                    ),
                },
                Err(e) => tracing::warn!(
                    address = s.address,
                    "I&M0 not read, the OPC UA identity keeps the GSD's values: {e}"
                ),
            }
        }
        out
    }
}

/// Why I&M0 is missing from a finished read.
fn why(r: &ImReader) -> String {
    use profibus_dp::master::records::ImRead;
    match &r.records[0] {
        Some(ImRead::Refused(e)) => e.describe(),
        Some(ImRead::Invalid(why)) => why.clone(),
        Some(ImRead::Record(b)) => match Im0::parse(b) {
            Ok(_) => "no error".into(),
            Err(e) => e.to_string(),
        },
        None => "no answer".into(),
    }
}

/// The property values of `im` for slave `s`.
fn updates(ns: u16, bus: &str, s: &Slave, im: &Im0, ts_ms: u64) -> Vec<Update> {
    let src = time(ts_ms);
    let dv = |v: Variant| DataValue {
        value: Some(v),
        status: Some(StatusCode::Good),
        source_timestamp: Some(src),
        server_timestamp: Some(src),
        ..Default::default()
    };
    let id = |p: &str| NodeId::new(ns, format!("{bus}.{}.{p}", s.address));
    let mut out = vec![
        (id("SerialNumber"), dv(im.serial_number().into())),
        (
            id("RevisionCounter"),
            dv(Variant::Int32(im.revision_counter.into())),
        ),
        (id("ProductCode"), dv(im.order_id().into())),
        (
            id("HardwareRevision"),
            dv(im.hardware_revision.to_string().into()),
        ),
        (
            id("SoftwareRevision"),
            dv(im.software_revision.to_string().into()),
        ),
        (
            id("ManufacturerId"),
            dv(Variant::UInt16(im.manufacturer_id)),
        ),
    ];
    if !s.has_vendor {
        out.push((
            id("Manufacturer"),
            dv(format!("manufacturer 0x{:04X}", im.manufacturer_id).into()),
        ));
    }
    out
}
