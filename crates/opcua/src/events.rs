//! DP-V1 alarms as OPC UA events: the event type `DpAlarmEventType`
//! (a subtype of `BaseEventType` in namespace `urn:profibus:dpctl`) and
//! [`DpAlarmEvent`], one per alarm the master acknowledged or gave up
//! on (`MasterEvent::Alarm`, the MQTT gateway's `<addr>/alarm`).
//!
//! The event's `SourceNode` is the slave object, `SourceName` its name,
//! `Message` the alarm in words (the MQTT report's `text`, with the GSD's
//! texts), `Severity` from the alarm type ([`severity`]), `Time` the
//! cycle's time; the type's own fields are `Slot`, `AlarmType`,
//! `SequenceNumber`, `Specifier`, `Data` (Diagnostic_User_Data) and
//! `Acknowledged`. The alarm block is described in
//! `shared/reference/dpv1-c2-im-alarms.md` (alarm PDU, Alarm_Type codes).

use crate::space::time;
use opcua::nodes::BaseEventType;
use opcua::server::address_space::{AddressSpace, ObjectTypeBuilder, VariableBuilder};
use opcua::types::{
    ByteString, DataTypeId, LocalizedText, NodeId, ObjectTypeId, QualifiedName, UAString,
    VariableTypeId,
};

/// The string id of the event type in this crate's namespace.
pub const EVENT_TYPE: &str = "DpAlarmEventType";

pub use event::DpAlarmEvent;

mod event {
    // The derive adds constructors without documentation.
    #![allow(missing_docs)]
    use opcua::nodes::BaseEventType;
    use opcua::types::{ByteString, UAString};

    /// A DP-V1 alarm as an OPC UA event of `DpAlarmEventType`.
    #[derive(Debug, opcua::Event)]
    #[opcua(identifier = "s=DpAlarmEventType", namespace = "urn:profibus:dpctl")]
    pub struct DpAlarmEvent {
        /// The `BaseEventType` fields.
        pub base: BaseEventType,
        /// The namespace index of `urn:profibus:dpctl`.
        pub own_namespace_index: u16,
        /// Slot_Number.
        pub slot: u8,
        /// Alarm_Type in one word: `diagnostic`, `process`, `pull`, `plug`,
        /// `status`, `update`, `manufacturer` (or `reserved`).
        pub alarm_type: UAString,
        /// Seq_Nr of the Alarm_Specifier (0..=31).
        pub sequence_number: u8,
        /// The specifier's change: `appears`, `disappears`,
        /// `disappears-still-faulty` or `none`.
        pub specifier: UAString,
        /// Diagnostic_User_Data.
        pub data: ByteString,
        /// The slave confirmed the master's Alarm_Ack.
        pub acknowledged: bool,
    }
}

/// The fields of `DpAlarmEventType` beyond `BaseEventType`: browse name
/// and data type.
const FIELDS: [(&str, DataTypeId); 6] = [
    ("Slot", DataTypeId::Byte),
    ("AlarmType", DataTypeId::String),
    ("SequenceNumber", DataTypeId::Byte),
    ("Specifier", DataTypeId::String),
    ("Data", DataTypeId::ByteString),
    ("Acknowledged", DataTypeId::Boolean),
];

/// Insert `DpAlarmEventType` under `BaseEventType` with its fields as
/// properties, so that clients can browse it and select its fields.
pub fn build_type(sp: &mut AddressSpace, ns: u16) -> NodeId {
    let id = NodeId::new(ns, EVENT_TYPE);
    ObjectTypeBuilder::new(&id, QualifiedName::new(ns, EVENT_TYPE), EVENT_TYPE)
        .subtype_of(ObjectTypeId::BaseEventType)
        .is_abstract(false)
        .insert(sp);
    for (name, ty) in FIELDS {
        VariableBuilder::new(
            &NodeId::new(ns, format!("{EVENT_TYPE}.{name}")),
            QualifiedName::new(ns, name),
            name,
        )
        .data_type(ty)
        .has_type_definition(VariableTypeId::PropertyType)
        .property_of(id.clone())
        .insert(sp);
    }
    id
}

/// Enter `DpAlarmEventType` and its fields into the server's type tree,
/// where event filters (`OfType`, select clauses of the type's fields)
/// look for them.
pub fn register_type(tree: &mut opcua::nodes::DefaultTypeTree, ns: u16) {
    use opcua::types::NodeClass;
    let id = NodeId::new(ns, EVENT_TYPE);
    tree.add_type_node(
        &id,
        &ObjectTypeId::BaseEventType.into(),
        NodeClass::ObjectType,
    );
    for (name, _) in FIELDS {
        tree.add_type_property(
            &NodeId::new(ns, format!("{EVENT_TYPE}.{name}")),
            &id,
            &[&QualifiedName::new(ns, name)],
            NodeClass::Variable,
        );
    }
}

/// The event's `Severity` (1..=1000, OPC UA Part 5 6.4.2) for an alarm
/// type, by what the alarm usually means for the process: a pulled
/// module (its I/O gone) 800, a diagnostic alarm (a fault) 700, a
/// process alarm (a limit the process crossed) 600, a manufacturer
/// alarm 500, a plugged module 400, a status alarm 300, an update alarm
/// (parameters changed) 200, anything else 500.
pub fn severity(alarm_type: &str) -> u16 {
    match alarm_type {
        "pull" => 800,
        "diagnostic" => 700,
        "process" => 600,
        "plug" => 400,
        "status" => 300,
        "update" => 200,
        _ => 500,
    }
}

/// A numbered event id: unique for the server's lifetime.
fn event_id(n: u64, ts_ms: u64) -> ByteString {
    let mut b = ts_ms.to_be_bytes().to_vec();
    b.extend_from_slice(&n.to_be_bytes());
    ByteString::from(b)
}

/// The event of the gateway core's alarm report `report` (the JSON of
/// `<addr>/alarm`: `slave`, `type`, `slot`, `specifier`, `seq`, `data`,
/// `text`, `acknowledged`, `ts`), raised by `source` named `name`;
/// `n` numbers it. `None` for a report without `slave` or `type`.
pub fn from_report(
    report: &serde_json::Value,
    ns: u16,
    source: NodeId,
    name: &str,
    n: u64,
) -> Option<DpAlarmEvent> {
    let alarm_type = report["type"].as_str()?;
    let ts = report["ts"].as_u64().unwrap_or(0);
    let text = report["text"].as_str().unwrap_or(alarm_type);
    let data = report["data"]
        .as_str()
        .and_then(|h| profibus_fdl::wire::parse_hex(h).ok())
        .unwrap_or_default();
    let base = BaseEventType::new(
        NodeId::new(ns, EVENT_TYPE),
        event_id(n, ts),
        LocalizedText::new("", text),
        time(ts),
    )
    .set_source_node(source)
    .set_source_name(UAString::from(name))
    .set_severity(severity(alarm_type));
    Some(DpAlarmEvent {
        base,
        own_namespace_index: ns,
        slot: report["slot"].as_u64().unwrap_or(0) as u8,
        alarm_type: UAString::from(alarm_type),
        sequence_number: report["seq"].as_u64().unwrap_or(0) as u8,
        specifier: UAString::from(report["specifier"].as_str().unwrap_or("none")),
        data: ByteString::from(data),
        acknowledged: report["acknowledged"].as_bool().unwrap_or(false),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use opcua::nodes::Event;
    use opcua::types::{AttributeId, NumericRange, Variant};

    #[test]
    fn an_alarm_report_becomes_an_event_with_its_fields() {
        let report = serde_json::json!({
            "slave": 9, "type": "plug", "slot": 3, "specifier": "appears", "seq": 5,
            "data": "01 02", "text": "plug alarm slot 3", "acknowledged": true, "ts": 1000
        });
        let e = from_report(&report, 2, NodeId::new(2, "line.9"), "9 io", 1).unwrap();
        let own = NodeId::new(2, EVENT_TYPE);
        let field = |ns: u16, name: &str| {
            let base = ObjectTypeId::BaseEventType.into();
            let ty = if ns == 0 { &base } else { &own };
            e.get_field(
                ty,
                AttributeId::Value,
                &NumericRange::None,
                &[QualifiedName::new(ns, name)],
            )
        };
        assert_eq!(field(2, "Slot"), Variant::Byte(3));
        assert_eq!(field(2, "SequenceNumber"), Variant::Byte(5));
        assert_eq!(field(2, "AlarmType"), Variant::from("plug"));
        assert_eq!(field(2, "Specifier"), Variant::from("appears"));
        assert_eq!(
            field(2, "Data"),
            Variant::ByteString(ByteString::from(vec![1, 2]))
        );
        assert_eq!(field(2, "Acknowledged"), Variant::Boolean(true));
        assert_eq!(field(0, "Severity"), Variant::UInt16(400));
        assert_eq!(
            field(0, "SourceNode"),
            Variant::from(NodeId::new(2, "line.9"))
        );
        assert_eq!(
            field(0, "Message"),
            Variant::from(LocalizedText::new("", "plug alarm slot 3"))
        );
        assert!(from_report(&serde_json::json!({"slot": 1}), 2, NodeId::null(), "", 2).is_none());
    }
}
