//! Sparkplug B templates (`[mqtt] sparkplug_templates = true`): each
//! device type's named channels as one template ("user defined type"),
//! defined once in the NBIRTH, and each device's channels as an
//! instance of it (the metric [`INSTANCE`]) in its DBIRTH and DDATA.
//!
//! The rules followed (Sparkplug 3.0, section 6.4.14 "Template", the TCK
//! ids in brackets): definitions only in the NBIRTH
//! [tck-id-payloads-template-definition-nbirth-only], with
//! `is_definition` true and no `template_ref`
//! [tck-id-payloads-template-definition-is-definition,
//! -definition-ref], with every member an instance will have
//! [-definition-members] and every parameter [-definition-parameters];
//! instances with `is_definition` false and `template_ref` the name of
//! the definition's metric [-instance-is-definition, -instance-ref],
//! all members in a birth [-instance-members-birth], only the changed
//! ones in a DDATA [-instance-members-data]. `version` is optional
//! [tck-id-payloads-template-version]: here a digest of the member
//! names and datatypes, so a host sees when a definition changed.
//!
//! Aliases: the members keep the aliases they have as flat metrics
//! ([`super::device_alias`] of their index), the instance metric itself
//! has index [`INSTANCE_INDEX`]; a DDATA carries the instance by alias
//! with its changed members by alias (no names, no datatypes).

use super::metrics::Device;
use super::proto::{DataType, Metric, MetricValue, Parameter, ParameterValue, Template};
use super::{data_metric, device_alias, metric};

/// The name of a device's template instance metric (its channels).
pub const INSTANCE: &str = "Channels";
/// The index of the instance metric in its device's aliases
/// ([`super::device_alias`]).
pub const INSTANCE_INDEX: usize = 0xFFFF;
/// Template parameter: the station address (UInt8).
pub const ADDRESS_PARAMETER: &str = "Address";
/// Template parameter: the slave's name in the bus file (String).
pub const NAME_PARAMETER: &str = "Name";

/// One template definition: a device type and its members.
#[derive(Debug, Clone, PartialEq)]
pub struct Definition {
    /// The name of its metric in the NBIRTH: the device type
    /// ([`Device::kind`]), with ` #2`, ` #3`, … for further member lists
    /// of the same type.
    pub name: String,
    /// The members: names and datatypes (the flat metrics' `Inputs/…`,
    /// `Outputs/…`).
    pub members: Vec<(String, DataType)>,
}

/// The members of a device's instance: its channel metrics.
fn members(d: &Device) -> Vec<(String, DataType)> {
    (d.metrics.iter())
        .filter(|m| m.is_channel())
        .map(|m| (m.name.clone(), m.datatype))
        .collect()
}

impl Definition {
    /// The version: FNV-1a (32 bit) of the members' names and datatype
    /// codes, 8 hex digits.
    pub fn version(&self) -> String {
        let mut h: u32 = 0x811c_9dc5;
        for (name, dt) in &self.members {
            for b in name.bytes().chain([0]).chain(dt.code().to_le_bytes()) {
                h = (h ^ b as u32).wrapping_mul(0x0100_0193);
            }
        }
        format!("{h:08x}")
    }

    /// Its metric for the NBIRTH: datatype Template, members with their
    /// datatypes and null values, the parameters without defaults.
    pub fn metric(&self, ts: u64) -> Metric {
        let template = Template {
            version: Some(self.version()),
            metrics: (self.members.iter())
                .map(|(name, dt)| Metric {
                    timestamp: None,
                    ..metric(name, *dt, None, ts)
                })
                .collect(),
            parameters: vec![
                parameter(ADDRESS_PARAMETER, DataType::UInt8, None),
                parameter(NAME_PARAMETER, DataType::String, None),
            ],
            template_ref: None,
            is_definition: Some(true),
        };
        metric(
            &self.name,
            DataType::Template,
            Some(MetricValue::TemplateValue(template)),
            ts,
        )
    }
}

fn parameter(name: &str, ty: DataType, value: Option<ParameterValue>) -> Parameter {
    Parameter {
        name: Some(name.into()),
        r#type: Some(ty.code()),
        value,
    }
}

/// The template definitions of `devices` and, per device, the index of
/// its definition (`None`: a device without channels, all flat). Devices
/// of one type with the same members share a definition.
pub fn definitions<'a>(
    devices: impl IntoIterator<Item = &'a Device>,
) -> (Vec<Definition>, Vec<Option<usize>>) {
    let mut defs: Vec<(String, Definition)> = vec![];
    let of = devices
        .into_iter()
        .map(|d| {
            let members = members(d);
            if members.is_empty() {
                return None;
            }
            if let Some(i) =
                (defs.iter()).position(|(k, def)| *k == d.kind && def.members == members)
            {
                return Some(i);
            }
            let name = std::iter::once(d.kind.clone())
                .chain((2..).map(|n| format!("{} #{n}", d.kind)))
                .find(|n| defs.iter().all(|(_, def)| def.name != *n))
                .expect("a free name");
            defs.push((d.kind.clone(), Definition { name, members }));
            Some(defs.len() - 1)
        })
        .collect();
    (defs.into_iter().map(|(_, d)| d).collect(), of)
}

/// The instance of `def` with the members of `d` given by `members`
/// (index into [`Device::metrics`], metric as sent).
fn instance(d: &Device, def: &Definition, members: Vec<Metric>, birth: bool, ts: u64) -> Metric {
    let address = d.info.layout.address;
    let template = Template {
        version: birth.then(|| def.version()),
        metrics: members,
        parameters: if birth {
            vec![
                parameter(
                    ADDRESS_PARAMETER,
                    DataType::UInt8,
                    Some(ParameterValue::IntValue(address as u32)),
                ),
                parameter(
                    NAME_PARAMETER,
                    DataType::String,
                    Some(ParameterValue::StringValue(d.info.layout.name.clone())),
                ),
            ]
        } else {
            vec![]
        },
        template_ref: Some(def.name.clone()),
        is_definition: Some(false),
    };
    let value = Some(MetricValue::TemplateValue(template));
    let alias = device_alias(address, INSTANCE_INDEX);
    if birth {
        Metric {
            alias: Some(alias),
            ..metric(INSTANCE, DataType::Template, value, ts)
        }
    } else {
        data_metric(alias, DataType::Template, value, ts)
    }
}

/// The DBIRTH metrics of `d` with `values` (in [`Device::metrics`]
/// order): every metric with name, alias and datatype; with a definition
/// the channels go into one instance of it, at the place of the first.
pub fn birth(
    d: &Device,
    def: Option<&Definition>,
    values: &[Option<MetricValue>],
    ts: u64,
) -> Vec<Metric> {
    let address = d.info.layout.address;
    let metrics = d.metrics.iter().zip(values).enumerate().map(|(k, (m, v))| {
        let one = Metric {
            alias: Some(device_alias(address, k)),
            ..metric(&m.name, m.datatype, v.clone(), ts)
        };
        (m.is_channel(), one)
    });
    with_instance(d, def, metrics, true, ts)
}

/// `metrics` (each marked whether it is a channel) in order; with a
/// definition the channels go into one instance of it, in the place of
/// the first channel.
fn with_instance(
    d: &Device,
    def: Option<&Definition>,
    metrics: impl Iterator<Item = (bool, Metric)>,
    birth: bool,
    ts: u64,
) -> Vec<Metric> {
    let mut out = vec![];
    let mut channels = vec![];
    let mut at = None;
    for (is_channel, one) in metrics {
        if def.is_some() && is_channel {
            at.get_or_insert(out.len());
            channels.push(one);
        } else {
            out.push(one);
        }
    }
    if let (Some(def), Some(at)) = (def, at) {
        out.insert(at, instance(d, def, channels, birth, ts));
    }
    out
}

/// The DDATA metrics of `d` for the `changed` metrics (index into
/// [`Device::metrics`], new value): by alias only; with a definition the
/// changed channels go into one instance of it.
pub fn data(
    d: &Device,
    def: Option<&Definition>,
    changed: Vec<(usize, Option<MetricValue>)>,
    ts: u64,
) -> Vec<Metric> {
    let address = d.info.layout.address;
    let metrics = changed.into_iter().map(|(k, v)| {
        let m = &d.metrics[k];
        let one = data_metric(device_alias(address, k), m.datatype, v, ts);
        (m.is_channel(), one)
    });
    with_instance(d, def, metrics, false, ts)
}

/// The metrics of a DCMD to device `address` with each instance of its
/// template (named [`INSTANCE`] or by its alias) replaced by the members
/// it carries (by name or alias, as flat metrics).
pub fn expand(address: u8, metrics: &[Metric]) -> Vec<Metric> {
    let alias = device_alias(address, INSTANCE_INDEX);
    metrics
        .iter()
        .flat_map(|m| match &m.value {
            Some(MetricValue::TemplateValue(t))
                if m.name.as_deref() == Some(INSTANCE) || m.alias == Some(alias) =>
            {
                t.metrics.clone()
            }
            _ => vec![m.clone()],
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slave::SlaveInfo;
    use profibus_devices::channels::{ChannelMap, ChannelType, Direction};
    use profibus_dp::config::layout::SlaveLayout;

    fn device(address: u8, kind: &str, channels: &[&str]) -> Device {
        let mut ch = ChannelMap::new();
        for (i, c) in channels.iter().enumerate() {
            ch.push(*c, Direction::Input, 2 * i, ChannelType::I16);
        }
        ch.push("set", Direction::Output, 0, ChannelType::U8);
        let info = SlaveInfo {
            layout: SlaveLayout {
                address,
                name: format!("s{address}"),
                ..SlaveLayout::default()
            },
            channels: Some(ch),
            pkw: None,
        };
        let mut d = Device::of_info(info);
        d.kind = kind.into();
        d
    }

    #[test]
    fn one_definition_per_type_and_member_list() {
        let devs = [
            device(3, "bk3000", &["a", "b"]),
            device(4, "bk3000", &["a", "b"]),
            device(5, "bk3000", &["a"]),
            device(6, "omega", &["x"]),
            device(7, "bk3000", &["a"]),
        ];
        let (defs, of) = definitions(&devs);
        let names: Vec<_> = defs.iter().map(|d| d.name.as_str()).collect();
        assert_eq!(names, ["bk3000", "bk3000 #2", "omega"]);
        assert_eq!(of, [Some(0), Some(0), Some(1), Some(2), Some(1)]);
        assert_eq!(
            defs[0].members,
            [
                ("Inputs/a".to_string(), DataType::Int16),
                ("Inputs/b".into(), DataType::Int16),
                ("Outputs/set".into(), DataType::UInt8)
            ]
        );
        assert_ne!(defs[0].version(), defs[1].version());
        assert_eq!(defs[0].version().len(), 8);
        let plain = Device::of_info(SlaveInfo {
            channels: None,
            ..devs[0].info.clone()
        });
        assert_eq!(definitions([&plain]).1, [None], "no channels: flat");
    }

    #[test]
    fn definitions_instances_and_data_follow_the_rules() {
        let d = device(3, "bk3000", &["a", "b"]);
        let (defs, _) = definitions([&d]);
        let def = &defs[0];
        let dm = def.metric(5);
        assert_eq!(dm.datatype, Some(DataType::Template.code()));
        let Some(MetricValue::TemplateValue(t)) = &dm.value else {
            panic!("{dm:?}")
        };
        assert_eq!((t.is_definition, &t.template_ref), (Some(true), &None));
        assert_eq!(t.metrics.len(), 3);
        assert!(t.metrics.iter().all(|m| m.is_null == Some(true)));
        assert_eq!(t.parameters[0].name.as_deref(), Some("Address"));

        let values: Vec<_> = (0..d.metrics.len())
            .map(|k| Some(MetricValue::IntValue(k as u32)))
            .collect();
        let b = birth(&d, Some(def), &values, 5);
        let flat = birth(&d, None, &values, 5);
        assert_eq!(b.len(), flat.len() - 3 + 1, "three channels, one instance");
        let inst = b
            .iter()
            .find(|m| m.name.as_deref() == Some(INSTANCE))
            .unwrap();
        assert_eq!(inst.alias, Some(device_alias(3, INSTANCE_INDEX)));
        let Some(MetricValue::TemplateValue(t)) = &inst.value else {
            panic!()
        };
        assert_eq!(
            (t.is_definition, t.template_ref.as_deref()),
            (Some(false), Some("bk3000"))
        );
        // The members are the flat metrics, aliases and all.
        let flat_channels: Vec<_> = flat
            .iter()
            .filter(|m| m.name.as_deref().is_some_and(|n| n.contains("puts/")))
            .cloned()
            .collect();
        assert_eq!(t.metrics, flat_channels);
        assert_eq!(
            t.parameters[0].value,
            Some(ParameterValue::IntValue(3)),
            "Address"
        );

        // DDATA: the changed channel inside the instance, by alias; the
        // rest flat.
        let k = d.metrics.iter().position(|m| m.name == "Inputs/b").unwrap();
        let diag = d
            .metrics
            .iter()
            .position(|m| m.name == "Diagnosis/Text")
            .unwrap();
        let v = Some(MetricValue::IntValue(9));
        let dd = data(&d, Some(def), vec![(k, v.clone()), (diag, None)], 6);
        assert_eq!(dd.len(), 2);
        assert_eq!(dd[0].alias, Some(device_alias(3, INSTANCE_INDEX)));
        assert!(dd[0].name.is_none() && dd[0].datatype.is_none());
        let Some(MetricValue::TemplateValue(t)) = &dd[0].value else {
            panic!()
        };
        assert_eq!(t.template_ref.as_deref(), Some("bk3000"));
        assert_eq!(t.metrics.len(), 1);
        assert_eq!(t.metrics[0].alias, Some(device_alias(3, k)));
        assert_eq!(t.metrics[0].value, v);
        assert_eq!(dd[1].alias, Some(device_alias(3, diag)));

        // A DCMD with the instance: its members, as flat metrics.
        let cmd = expand(3, &dd);
        assert_eq!(cmd.len(), 2);
        assert_eq!(cmd[0].alias, Some(device_alias(3, k)));
        assert_eq!(expand(4, &dd).len(), 2, "another device's alias: as it is");
        assert!(matches!(
            expand(4, &dd)[0].value,
            Some(MetricValue::TemplateValue(_))
        ));
    }
}
