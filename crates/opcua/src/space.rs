//! The address space under `Objects/PROFIBUS/<bus>/` and the values the
//! master gives it at each cycle boundary.
//!
//! [`Space::build`] inserts the nodes; [`Sampler::sample`] reads a
//! [`DpMaster`] and returns the values that changed since its last call,
//! with the cycle's time as source timestamp. Neither knows the server's
//! sessions: the driver hands the updates to the node manager.

use opcua::server::address_space::{
    AddressSpace, EventNotifier, MethodBuilder, ObjectBuilder, VariableBuilder,
};
use opcua::types::{
    Argument, ByteString, DataTypeId, DataValue, DateTime, EUInformation, LocalizedText, NodeId,
    ObjectId, ObjectTypeId, QualifiedName, StatusCode, UAString, VariableTypeId, Variant,
};
use profibus_devices::channels::{Channel, ChannelType, Direction, Value};
use profibus_dp::master::{DpMaster, SlaveState};
use profibus_gateway::SlaveInfo;
use profibus_gateway::WriteAccess;

/// The namespace of every node this server adds.
pub const NAMESPACE_URI: &str = "urn:profibus:dpctl";

/// The UNECE (CEFACT) units namespace of `EUInformation`.
const UNITS_URI: &str = "http://www.opcfoundation.org/UA/units/un/cefact";

/// Node ids of one slave's nodes: `<bus>.<address>.<path>`.
#[derive(Debug, Clone)]
pub struct SlaveNodes {
    /// The station address.
    pub address: u8,
    /// The slave object.
    pub object: NodeId,
    /// Its `ReadRecord` method (DP-V1 slaves).
    pub read_record: Option<NodeId>,
    /// Its `WriteRecord` method (DP-V1 slaves).
    pub write_record: Option<NodeId>,
    /// Its `PkwRead` method (slaves with a PKW channel).
    pub pkw_read: Option<NodeId>,
    /// Its `PkwWrite` method (slaves with a PKW channel).
    pub pkw_write: Option<NodeId>,
    /// Its output channels: node and channel name (each writable or
    /// not by `[mqtt] writable`, see [`access_levels`]).
    pub outputs: Vec<(NodeId, String)>,
}

/// The nodes of a bus.
pub struct Space {
    ns: u16,
    bus: String,
    /// The bus object `Objects/PROFIBUS/<bus>`.
    pub bus_object: NodeId,
    /// `DpAlarmEventType` ([`crate::events`]).
    pub alarm_type: NodeId,
    /// One entry per slave, in bus-file order.
    pub slaves: Vec<SlaveNodes>,
}

/// `Int(i)` or `Float(x)` of a channel as the variant of its data type.
pub fn variant(ch: &Channel, v: Value) -> Variant {
    if ch.scale.is_some() {
        return Variant::Double(match v {
            Value::Float(x) => x,
            Value::Int(i) => i as f64,
            Value::Bool(b) => b as u8 as f64,
        });
    }
    let i = match v {
        Value::Bool(b) => return Variant::Boolean(b),
        Value::Int(i) => i,
        Value::Float(x) => return Variant::Float(x as f32),
    };
    match ch.ty {
        ChannelType::Bool { .. } => Variant::Boolean(i != 0),
        ChannelType::U8 => Variant::Byte(i as u8),
        ChannelType::I8 => Variant::SByte(i as i8),
        ChannelType::U16 => Variant::UInt16(i as u16),
        ChannelType::I16 => Variant::Int16(i as i16),
        ChannelType::U32 => Variant::UInt32(i as u32),
        ChannelType::I32 => Variant::Int32(i as i32),
        ChannelType::F32 => Variant::Float(i as f32),
    }
}

/// A written variant as a channel value (`None`: not a number or bool).
pub fn value_of(v: &Variant) -> Option<Value> {
    Some(match v {
        Variant::Boolean(b) => Value::Bool(*b),
        Variant::SByte(i) => Value::Int(*i as i64),
        Variant::Byte(i) => Value::Int(*i as i64),
        Variant::Int16(i) => Value::Int(*i as i64),
        Variant::UInt16(i) => Value::Int(*i as i64),
        Variant::Int32(i) => Value::Int(*i as i64),
        Variant::UInt32(i) => Value::Int(*i as i64),
        Variant::Int64(i) => Value::Int(*i),
        Variant::UInt64(i) => Value::Int(i64::try_from(*i).ok()?),
        Variant::Float(x) => Value::Float(*x as f64),
        Variant::Double(x) => Value::Float(*x),
        _ => return None,
    })
}

/// The OPC UA data type of a channel: the integer type of its width,
/// `Float` for `f32`, `Double` for a scaled channel.
pub fn data_type(ch: &Channel) -> DataTypeId {
    if ch.scale.is_some() {
        return DataTypeId::Double;
    }
    match ch.ty {
        ChannelType::Bool { .. } => DataTypeId::Boolean,
        ChannelType::U8 => DataTypeId::Byte,
        ChannelType::I8 => DataTypeId::SByte,
        ChannelType::U16 => DataTypeId::UInt16,
        ChannelType::I16 => DataTypeId::Int16,
        ChannelType::U32 => DataTypeId::UInt32,
        ChannelType::I32 => DataTypeId::Int32,
        ChannelType::F32 => DataTypeId::Float,
    }
}

/// `EUInformation` of a unit as the profiles write it: the UNECE common
/// code's `UnitId` where the unit is one of the usual ones, else -1 (OPC
/// UA Part 8, 5.6.3: -1 when no code is known).
pub fn eu_information(unit: &str) -> EUInformation {
    let code = match unit {
        "V" => "VLT",
        "mV" => "2Z",
        "A" => "AMP",
        "mA" => "4K",
        "°C" => "CEL",
        "%" => "P1",
        "ms" => "C26",
        "s" => "SEC",
        "Hz" => "HTZ",
        "rpm" | "1/min" => "RPM",
        "bar" => "BAR",
        "mm" => "MMT",
        "W" => "WTT",
        "kW" => "KWT",
        _ => "",
    };
    let unit_id = if code.is_empty() {
        -1
    } else {
        code.bytes().fold(0i32, |acc, b| (acc << 8) | b as i32)
    };
    EUInformation {
        namespace_uri: UAString::from(UNITS_URI),
        unit_id,
        display_name: LocalizedText::new("", unit),
        description: LocalizedText::new("", unit),
    }
}

/// Unix epoch milliseconds as an OPC UA time.
pub fn time(ts_ms: u64) -> DateTime {
    // 100 ns ticks since 1601-01-01.
    DateTime::from(ts_ms as i64 * 10_000 + 116_444_736_000_000_000)
}

fn arg(name: &str, ty: DataTypeId) -> Argument {
    Argument {
        name: UAString::from(name),
        data_type: ty.into(),
        value_rank: -1,
        array_dimensions: None,
        description: LocalizedText::new("", name),
    }
}

/// A method's name, input and output arguments.
type Signature = (&'static str, Vec<Argument>, Vec<Argument>);

/// `ReadRecord(Slot, Index, Length) → Data` and `WriteRecord(Slot,
/// Index, Data)` of DP-V1 slaves (MSAC_C1 Read and Write).
fn record_methods() -> [Signature; 2] {
    let byte = |n| arg(n, DataTypeId::Byte);
    let data = || arg("Data", DataTypeId::ByteString);
    [
        (
            "ReadRecord",
            vec![byte("Slot"), byte("Index"), byte("Length")],
            vec![data()],
        ),
        (
            "WriteRecord",
            vec![byte("Slot"), byte("Index"), data()],
            vec![],
        ),
    ]
}

/// `PkwRead(Parameter, Index) → Value` and `PkwWrite(Parameter, Index,
/// Value)` of slaves with a PKW channel.
fn pkw_methods() -> [Signature; 2] {
    let word = |n| arg(n, DataTypeId::UInt16);
    let value = || arg("Value", DataTypeId::Int64);
    [
        (
            "PkwRead",
            vec![word("Parameter"), word("Index")],
            vec![value()],
        ),
        (
            "PkwWrite",
            vec![word("Parameter"), word("Index"), value()],
            vec![],
        ),
    ]
}

impl Space {
    fn id(&self, path: &str) -> NodeId {
        NodeId::new(self.ns, format!("{}.{path}", self.bus))
    }

    fn qn(&self, name: &str) -> QualifiedName {
        QualifiedName::new(self.ns, name)
    }

    fn object(&self, sp: &mut AddressSpace, id: &NodeId, name: &str, parent: &NodeId) {
        ObjectBuilder::new(id, self.qn(name), name)
            .has_type_definition(ObjectTypeId::BaseObjectType)
            .component_of(parent.clone())
            .insert(sp);
    }

    fn folder(&self, sp: &mut AddressSpace, id: &NodeId, name: &str, parent: &NodeId) {
        ObjectBuilder::new(id, self.qn(name), name)
            .has_type_definition(ObjectTypeId::FolderType)
            .organized_by(parent.clone())
            .insert(sp);
    }

    #[allow(clippy::too_many_arguments)]
    fn variable(
        &self,
        sp: &mut AddressSpace,
        id: &NodeId,
        name: &str,
        parent: &NodeId,
        ty: DataTypeId,
        value: impl Into<Variant>,
        writable: bool,
    ) {
        let mut b = VariableBuilder::new(id, self.qn(name), name)
            .data_type(ty)
            .value(value)
            .has_type_definition(VariableTypeId::BaseDataVariableType)
            .component_of(parent.clone());
        if writable {
            b = b.writable();
        }
        b.insert(sp);
        // Until the first cycle: no value yet.
        if let Some(opcua::nodes::NodeType::Variable(v)) = sp.find_mut(id) {
            let mut dv = v.value(
                opcua::types::TimestampsToReturn::Neither,
                &opcua::types::NumericRange::None,
                &opcua::types::DataEncoding::Binary,
                0.0,
            );
            dv.status = Some(StatusCode::BadWaitingForInitialData);
            v.set_data_value(dv);
        }
    }

    fn property(
        &self,
        sp: &mut AddressSpace,
        id: &NodeId,
        name: &str,
        parent: &NodeId,
        ty: DataTypeId,
        value: impl Into<Variant>,
    ) {
        VariableBuilder::new(id, QualifiedName::new(self.ns, name), name)
            .data_type(ty)
            .value(value)
            .has_type_definition(VariableTypeId::PropertyType)
            .property_of(parent.clone())
            .insert(sp);
    }

    /// Insert the nodes of `slaves` on bus `bus` into namespace `ns` of
    /// `sp`: the `PROFIBUS` folder under `Objects`, the bus object, and
    /// one object per slave. `writable` is the gateway's write access
    /// (`[mqtt] writable`): output channels are writable (access level
    /// `CurrentWrite`) only where it allows them.
    pub fn build(
        sp: &mut AddressSpace,
        ns: u16,
        bus: &str,
        slaves: &[SlaveInfo],
        writable: &[WriteAccess],
    ) -> Space {
        let mut space = Space {
            ns,
            bus: bus.to_string(),
            bus_object: NodeId::new(ns, bus.to_string()),
            alarm_type: crate::events::build_type(sp, ns),
            slaves: vec![],
        };
        let root = NodeId::new(ns, "PROFIBUS");
        ObjectBuilder::new(&root, space.qn("PROFIBUS"), "PROFIBUS")
            .has_type_definition(ObjectTypeId::FolderType)
            .organized_by(ObjectId::ObjectsFolder)
            .insert(sp);
        let bus_id = space.bus_object.clone();
        ObjectBuilder::new(&bus_id, space.qn(bus), bus)
            .has_type_definition(ObjectTypeId::BaseObjectType)
            .organized_by(root)
            .insert(sp);
        let s = &space;
        let counters: [(&str, DataTypeId, Variant); 4] = [
            ("MasterState", DataTypeId::String, "".into()),
            ("Cycles", DataTypeId::UInt64, 0u64.into()),
            ("CycleTimeAvg", DataTypeId::Double, 0.0.into()),
            ("CycleTimeMax", DataTypeId::Double, 0.0.into()),
        ];
        for (n, ty, v) in counters {
            s.variable(sp, &s.id(n), n, &bus_id, ty, v, false);
        }
        for u in ["CycleTimeAvg", "CycleTimeMax"] {
            s.property(
                sp,
                &s.id(&format!("{u}.EngineeringUnits")),
                "EngineeringUnits",
                &s.id(u),
                DataTypeId::EUInformation,
                opcua::types::ExtensionObject::from_message(eu_information("ms")),
            );
        }
        let mut nodes = vec![];
        for info in slaves {
            nodes.push(space.build_slave(sp, &bus_id, info, writable));
        }
        space.slaves = nodes;
        space
    }

    fn build_slave(
        &self,
        sp: &mut AddressSpace,
        bus_id: &NodeId,
        info: &SlaveInfo,
        writable: &[WriteAccess],
    ) -> SlaveNodes {
        let l = &info.layout;
        let a = l.address;
        let p = |s: &str| self.id(&format!("{a}.{s}"));
        let obj = NodeId::new(self.ns, format!("{}.{a}", self.bus));
        let name = format!("{a} {}", l.name);
        ObjectBuilder::new(&obj, self.qn(&name), name.as_str())
            .has_type_definition(ObjectTypeId::BaseObjectType)
            .event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS)
            .organized_by(bus_id.clone())
            .insert(sp);
        // Identity, named after the OPC UA for Devices `DeviceType`
        // properties (OPC 10000-100, 5.5.2) in this namespace; DP-V1
        // slaves' I&M0 replaces the GSD's values ([`crate::identity`]).
        let gsd = l.gsd.as_ref();
        let text = |f: Option<&String>| f.cloned().unwrap_or_default();
        self.property(
            sp,
            &p("IdentNumber"),
            "IdentNumber",
            &obj,
            DataTypeId::UInt16,
            l.ident_number,
        );
        let props: [(&str, String); 7] = [
            (
                "Manufacturer",
                text(gsd.and_then(|g| g.vendor_name.as_ref())),
            ),
            (
                "ProductCode",
                text(gsd.and_then(|g| g.order_number.as_ref())),
            ),
            ("SerialNumber", String::new()),
            ("Model", text(gsd.and_then(|g| g.model_name.as_ref()))),
            (
                "DeviceRevision",
                text(gsd.and_then(|g| g.revision.as_ref())),
            ),
            (
                "HardwareRevision",
                text(gsd.and_then(|g| g.hardware_release.as_ref())),
            ),
            (
                "SoftwareRevision",
                text(gsd.and_then(|g| g.software_release.as_ref())),
            ),
        ];
        for (n, v) in props {
            self.property(sp, &p(n), n, &obj, DataTypeId::String, v);
        }
        // -1: not known (OPC 10000-100); I&M0's REVISION_COUNTER.
        self.property(
            sp,
            &p("RevisionCounter"),
            "RevisionCounter",
            &obj,
            DataTypeId::Int32,
            -1i32,
        );
        if l.dpv1 {
            self.property(
                sp,
                &p("ManufacturerId"),
                "ManufacturerId",
                &obj,
                DataTypeId::UInt16,
                0u16,
            );
        }
        let diag = p("Diagnosis");
        self.object(sp, &diag, "Diagnosis", &obj);
        let status: [(&str, &NodeId, DataTypeId, Variant); 3] = [
            ("State", &obj, DataTypeId::String, "".into()),
            ("Diagnosis.Text", &diag, DataTypeId::String, "".into()),
            (
                "Diagnosis.Raw",
                &diag,
                DataTypeId::ByteString,
                ByteString::null().into(),
            ),
        ];
        for (path, parent, ty, v) in status {
            let name = path.rsplit('.').next().unwrap_or(path);
            self.variable(sp, &p(path), name, parent, ty, v, false);
        }
        let stats = p("Statistics");
        self.object(sp, &stats, "Statistics", &obj);
        for n in STATS {
            self.variable(
                sp,
                &p(&format!("Statistics.{n}")),
                n,
                &stats,
                DataTypeId::UInt64,
                0u64,
                false,
            );
        }
        let mut outputs = vec![];
        for (dir, folder) in [(Direction::Input, "Inputs"), (Direction::Output, "Outputs")] {
            let f = p(folder);
            self.folder(sp, &f, folder, &obj);
            let Some(map) = &info.channels else { continue };
            for ch in map.of(dir) {
                let id = p(&format!("{folder}.{}", ch.name));
                let can_write = dir == Direction::Output && can_write(writable, a, &ch.name);
                self.variable(
                    sp,
                    &id,
                    &ch.name,
                    &f,
                    data_type(ch),
                    variant(ch, Value::Int(0)),
                    can_write,
                );
                if dir == Direction::Output {
                    outputs.push((id.clone(), ch.name.clone()));
                }
                if let Some(scale) = &ch.scale {
                    self.property(
                        sp,
                        &NodeId::new(
                            self.ns,
                            format!(
                                "{}.{folder}.{}.EngineeringUnits",
                                self.bus_slave(a),
                                ch.name
                            ),
                        ),
                        "EngineeringUnits",
                        &id,
                        DataTypeId::EUInformation,
                        opcua::types::ExtensionObject::from_message(eu_information(&scale.unit)),
                    );
                }
            }
        }
        if !l.modules.is_empty() {
            let mf = p("Modules");
            self.folder(sp, &mf, "Modules", &obj);
            for (slot, m) in l.modules.iter().enumerate() {
                let mo = p(&format!("Modules.{slot}"));
                self.object(sp, &mo, &format!("{slot} {}", m.name), &mf);
                for n in ["InputBytes", "OutputBytes"] {
                    self.variable(
                        sp,
                        &p(&format!("Modules.{slot}.{n}")),
                        n,
                        &mo,
                        DataTypeId::ByteString,
                        ByteString::null(),
                        false,
                    );
                }
            }
        }
        let mut nodes = SlaveNodes {
            address: a,
            object: obj.clone(),
            read_record: None,
            write_record: None,
            pkw_read: None,
            pkw_write: None,
            outputs,
        };
        let method = |sp: &mut AddressSpace, (n, ins, outs): &Signature| {
            let id = p(n);
            MethodBuilder::new(&id, self.qn(n), *n)
                .component_of(obj.clone())
                .executable(true)
                .user_executable(true)
                .input_args(sp, &p(&format!("{n}.InputArguments")), ins)
                .output_args(sp, &p(&format!("{n}.OutputArguments")), outs)
                .insert(sp);
            Some(id)
        };
        if l.dpv1 {
            let [read, write] = record_methods();
            nodes.read_record = method(sp, &read);
            nodes.write_record = method(sp, &write);
        }
        if info.pkw.is_some() {
            let [read, write] = pkw_methods();
            nodes.pkw_read = method(sp, &read);
            nodes.pkw_write = method(sp, &write);
        }
        nodes
    }

    fn bus_slave(&self, a: u8) -> String {
        format!("{}.{a}", self.bus)
    }
}

/// Whether `[mqtt] writable` lets OPC UA write output `channel` of
/// slave `address`.
pub fn can_write(writable: &[WriteAccess], address: u8, channel: &str) -> bool {
    writable
        .iter()
        .find(|w| w.address == address)
        .is_some_and(|w| {
            w.channels
                .as_ref()
                .is_none_or(|c| c.iter().any(|n| n == channel))
        })
}

/// The access levels of `slaves`' output variables under `writable`:
/// node and whether it is writable.
pub fn access_levels(slaves: &[SlaveNodes], writable: &[WriteAccess]) -> Vec<(NodeId, bool)> {
    slaves
        .iter()
        .flat_map(|s| {
            s.outputs
                .iter()
                .map(|(id, ch)| (id.clone(), can_write(writable, s.address, ch)))
        })
        .collect()
}

/// The counters under `Statistics`, from the master's slave statistics.
const STATS: [&str; 5] = [
    "DataExchanges",
    "Retries",
    "Errors",
    "Restarts",
    "DiagReads",
];

/// What a slave's nodes showed last.
#[derive(Default)]
struct Shown {
    state: Option<SlaveState>,
    inputs: Option<Vec<u8>>,
    outputs: Option<Vec<u8>>,
    diag: Option<Vec<u8>>,
    stats: Option<[u64; 5]>,
}

/// Reads the master at cycle boundaries and returns what changed.
pub struct Sampler {
    ns: u16,
    bus: String,
    slaves: Vec<SlaveInfo>,
    shown: Vec<Shown>,
    master: Option<&'static str>,
    last_counters_ms: Option<u64>,
}

/// How often the counters (cycles, cycle times, statistics) are
/// refreshed: they change every cycle.
pub const COUNTERS_PERIOD_MS: u64 = 100;

/// One value update: the node and its new data value.
pub type Update = (NodeId, DataValue);

impl Sampler {
    /// A sampler of the nodes [`Space::build`] made for the same slaves.
    pub fn new(ns: u16, bus: &str, slaves: Vec<SlaveInfo>) -> Sampler {
        let shown = slaves.iter().map(|_| Shown::default()).collect();
        Sampler {
            ns,
            bus: bus.to_string(),
            slaves,
            shown,
            master: None,
            last_counters_ms: None,
        }
    }

    fn id(&self, path: String) -> NodeId {
        NodeId::new(self.ns, format!("{}.{path}", self.bus))
    }

    /// The values that changed since the last call, read from `m` at a
    /// cycle boundary whose wall-clock time is `ts_ms` (the source
    /// timestamp). Process values (inputs, outputs, module bytes) carry
    /// `Good` while their slave is in Data_Exchange and
    /// `BadCommunicationError` otherwise (the last value kept).
    pub fn sample(&mut self, m: &DpMaster, ts_ms: u64) -> Vec<Update> {
        let src = time(ts_ms);
        let dv = |v: Variant, status: StatusCode| DataValue {
            value: Some(v),
            status: Some(status),
            source_timestamp: Some(src),
            server_timestamp: Some(src),
            ..Default::default()
        };
        let mut out = vec![];
        let state = m.operating_state().as_str();
        if self.master != Some(state) {
            self.master = Some(state);
            out.push((
                self.id("MasterState".into()),
                dv(state.into(), StatusCode::Good),
            ));
        }
        let counters = self
            .last_counters_ms
            .is_none_or(|t| ts_ms.saturating_sub(t) >= COUNTERS_PERIOD_MS);
        if counters {
            self.last_counters_ms = Some(ts_ms);
            let c = m.cycle_stats();
            let ms = |ns: u64| ns as f64 / 1e6;
            out.push((
                self.id("Cycles".into()),
                dv(c.cycles.into(), StatusCode::Good),
            ));
            out.push((
                self.id("CycleTimeAvg".into()),
                dv(ms(c.avg().as_nanos() as u64).into(), StatusCode::Good),
            ));
            out.push((
                self.id("CycleTimeMax".into()),
                dv(ms(c.max_ns).into(), StatusCode::Good),
            ));
        }
        for (info, shown) in self.slaves.iter().zip(self.shown.iter_mut()) {
            let a = info.layout.address;
            let Some(h) = m.handle(a) else { continue };
            let v = m.slave(h);
            let id = |p: &str| NodeId::new(self.ns, format!("{}.{a}.{p}", self.bus));
            let state_changed = shown.state != Some(v.state);
            if state_changed {
                shown.state = Some(v.state);
                out.push((id("State"), dv(v.state.name().into(), StatusCode::Good)));
            }
            let status = if v.state == SlaveState::DataExchange {
                StatusCode::Good
            } else {
                StatusCode::BadCommunicationError
            };
            for (dir, folder, img, last) in [
                (Direction::Input, "Inputs", v.inputs, &mut shown.inputs),
                (Direction::Output, "Outputs", v.outputs, &mut shown.outputs),
            ] {
                if !state_changed && last.as_deref() == Some(img) {
                    continue;
                }
                *last = Some(img.to_vec());
                if let Some(map) = &info.channels {
                    for ch in map.of(dir) {
                        let Some(val) = ch.read(img) else { continue };
                        out.push((
                            id(&format!("{folder}.{}", ch.name)),
                            dv(variant(ch, val), status),
                        ));
                    }
                }
                for (slot, module) in info.layout.modules.iter().enumerate() {
                    let (span, n) = match dir {
                        Direction::Input => (module.inputs, "InputBytes"),
                        Direction::Output => (module.outputs, "OutputBytes"),
                    };
                    let bytes = img
                        .get(span.offset..(span.offset + span.len).min(img.len()))
                        .unwrap_or(&[]);
                    out.push((
                        id(&format!("Modules.{slot}.{n}")),
                        dv(ByteString::from(bytes.to_vec()).into(), status),
                    ));
                }
            }
            if shown.diag.as_deref() != Some(v.diag) {
                shown.diag = Some(v.diag.to_vec());
                let text = if v.diag.is_empty() {
                    vec![]
                } else {
                    profibus_dp::pdu::diag::describe(
                        v.diag,
                        info.layout.gsd.as_ref(),
                        info.layout.dpv1,
                    )
                };
                out.push((
                    id("Diagnosis.Text"),
                    dv(text.join("\n").into(), StatusCode::Good),
                ));
                out.push((
                    id("Diagnosis.Raw"),
                    dv(ByteString::from(v.diag.to_vec()).into(), StatusCode::Good),
                ));
            }
            if counters {
                let s = v.stats;
                let now = [
                    s.data_exchanges,
                    s.retries,
                    s.errors,
                    s.restarts,
                    s.diag_reads,
                ];
                for (i, n) in STATS.iter().enumerate() {
                    if shown.stats.is_none_or(|old| old[i] != now[i]) {
                        out.push((
                            id(&format!("Statistics.{n}")),
                            dv(now[i].into(), StatusCode::Good),
                        ));
                    }
                }
                shown.stats = Some(now);
            }
        }
        out
    }
}
