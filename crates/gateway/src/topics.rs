//! Topic names: the plain JSON topics under `<prefix>/<bus>/` and the
//! Sparkplug B topics under `spBv1.0/GROUP/`, and the request topics
//! that name a service and a station. The whole protocol:
//! `docs/gateway.md`.

use std::fmt;

/// The topics of one gateway: `<prefix>/<bus>/…`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topics {
    base: String,
}

/// What a request topic asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Service {
    /// `<addr>/outputs/set`: the output image or named output channels.
    Outputs,
    /// `<addr>/dpv1/request`: a DP-V1 (MSAC_C1) data record read or write.
    Dpv1,
    /// `<addr>/pkw/request`: a parameter job over the PKW channel.
    Pkw,
    /// `<addr>/rfid/request`: one command line to an RFID reader.
    Rfid,
}

impl Service {
    /// Every service.
    pub const ALL: [Service; 4] = [Service::Outputs, Service::Dpv1, Service::Pkw, Service::Rfid];

    /// The request topic's suffix.
    pub fn request(self) -> &'static str {
        match self {
            Service::Outputs => "outputs/set",
            Service::Dpv1 => "dpv1/request",
            Service::Pkw => "pkw/request",
            Service::Rfid => "rfid/request",
        }
    }

    /// The default response topic's suffix.
    pub fn response(self) -> &'static str {
        match self {
            Service::Outputs => "outputs/response",
            Service::Dpv1 => "dpv1/response",
            Service::Pkw => "pkw/response",
            Service::Rfid => "rfid/response",
        }
    }
}

/// The per-slave topics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlaveTopic {
    /// `<addr>/state`: the slave's state in the master (retained).
    State,
    /// `<addr>/inputs`: the input image (retained).
    Inputs,
    /// `<addr>/outputs`: the output image sent (retained).
    Outputs,
    /// `<addr>/diag`: the last diagnosis (retained).
    Diag,
    /// `<addr>/alarm`: a DP-V1 alarm, once acknowledged or given up (not
    /// retained: each alarm is an event).
    Alarm,
    /// A request topic (subscribed).
    Request(Service),
    /// The default response topic of a service.
    Response(Service),
}

impl SlaveTopic {
    fn suffix(self) -> &'static str {
        match self {
            SlaveTopic::State => "state",
            SlaveTopic::Inputs => "inputs",
            SlaveTopic::Outputs => "outputs",
            SlaveTopic::Diag => "diag",
            SlaveTopic::Alarm => "alarm",
            SlaveTopic::Request(s) => s.request(),
            SlaveTopic::Response(s) => s.response(),
        }
    }
}

impl Topics {
    /// Topics under `prefix` for the bus `bus`.
    pub fn new(prefix: &str, bus: &str) -> Topics {
        Topics {
            base: format!("{prefix}/{bus}"),
        }
    }

    /// `<prefix>/<bus>/status`: the gateway's status (retained; the last
    /// will sets it offline).
    pub fn status(&self) -> String {
        format!("{}/status", self.base)
    }

    /// A slave's topic.
    pub fn slave(&self, address: u8, t: SlaveTopic) -> String {
        format!("{}/{address}/{}", self.base, t.suffix())
    }

    /// The filters the gateway subscribes to: one per [`Service`].
    pub fn request_filters(&self) -> Vec<String> {
        Service::ALL
            .iter()
            .map(|s| format!("{}/+/{}", self.base, s.request()))
            .collect()
    }

    /// The service and station address of a request topic
    /// (`<prefix>/<bus>/<addr>/outputs/set`, …), `None` for any other
    /// topic. An address that is not a number is an error.
    pub fn parse_request(&self, topic: &str) -> Option<(Service, Result<u8, BadAddress>)> {
        let rest = topic.strip_prefix(&self.base)?.strip_prefix('/')?;
        Service::ALL.iter().find_map(|&s| {
            let addr = rest.strip_suffix(s.request())?.strip_suffix('/')?;
            if addr.contains('/') {
                return None;
            }
            Some((s, addr.parse::<u8>().map_err(|_| BadAddress(addr.into()))))
        })
    }
}

/// The address part of a request topic is not a station address.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` in a request topic is not a station address")]
pub struct BadAddress(pub String);

/// The Sparkplug B topic namespace.
pub const NAMESPACE: &str = "spBv1.0";

/// A Sparkplug group id and edge node id.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SparkplugId {
    /// Group id.
    pub group: String,
    /// Edge node id.
    pub edge: String,
}

/// A `GROUP/EDGE` that is not two valid ids.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not GROUP/EDGE (two non-empty ids without `/`, `+` or `#`)")]
pub struct IdError(String);

impl SparkplugId {
    /// Parse `GROUP/EDGE`.
    pub fn parse(text: &str) -> Result<SparkplugId, IdError> {
        let valid = |s: &str| !s.is_empty() && !s.contains(['/', '+', '#', '\0']);
        match text.split_once('/') {
            Some((g, e)) if valid(g) && valid(e) => Ok(SparkplugId {
                group: g.into(),
                edge: e.into(),
            }),
            _ => Err(IdError(text.into())),
        }
    }

    /// The topic of an edge node message: `spBv1.0/GROUP/TYPE/EDGE`.
    pub fn node_topic(&self, t: MessageType) -> String {
        format!("{NAMESPACE}/{}/{}/{}", self.group, t.name(), self.edge)
    }

    /// The topic of a device message: `spBv1.0/GROUP/TYPE/EDGE/DEVICE`.
    pub fn device_topic(&self, t: MessageType, device: &str) -> String {
        format!("{}/{device}", self.node_topic(t))
    }
}

impl std::str::FromStr for SparkplugId {
    type Err = IdError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        SparkplugId::parse(s)
    }
}

impl fmt::Display for SparkplugId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.group, self.edge)
    }
}

/// The Sparkplug message types this edge node uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageType {
    /// Edge node birth.
    NBirth,
    /// Edge node death (the last will).
    NDeath,
    /// Edge node data (the node's own metrics).
    NData,
    /// Device birth.
    DBirth,
    /// Device death.
    DDeath,
    /// Device data.
    DData,
    /// Edge node command.
    NCmd,
    /// Device command.
    DCmd,
}

impl MessageType {
    /// The topic level.
    pub fn name(self) -> &'static str {
        match self {
            MessageType::NBirth => "NBIRTH",
            MessageType::NDeath => "NDEATH",
            MessageType::NData => "NDATA",
            MessageType::DBirth => "DBIRTH",
            MessageType::DDeath => "DDEATH",
            MessageType::DData => "DDATA",
            MessageType::NCmd => "NCMD",
            MessageType::DCmd => "DCMD",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics() {
        let t = Topics::new("plant/a", "seg1");
        assert_eq!(t.status(), "plant/a/seg1/status");
        assert_eq!(t.slave(7, SlaveTopic::Inputs), "plant/a/seg1/7/inputs");
        assert_eq!(
            t.request_filters(),
            [
                "plant/a/seg1/+/outputs/set",
                "plant/a/seg1/+/dpv1/request",
                "plant/a/seg1/+/pkw/request",
                "plant/a/seg1/+/rfid/request"
            ]
        );
        assert_eq!(
            t.parse_request("plant/a/seg1/7/outputs/set"),
            Some((Service::Outputs, Ok(7)))
        );
        assert_eq!(
            t.parse_request("plant/a/seg1/7/pkw/request"),
            Some((Service::Pkw, Ok(7)))
        );
        assert_eq!(
            t.parse_request("plant/a/seg1/x/outputs/set"),
            Some((Service::Outputs, Err(BadAddress("x".into()))))
        );
        assert_eq!(t.parse_request("plant/a/seg1/7/outputs"), None);
        assert_eq!(t.parse_request("plant/a/seg1/7/pkw/response"), None);
        assert_eq!(t.parse_request("plant/a/seg2/7/outputs/set"), None);
    }

    #[test]
    fn sparkplug_ids_and_topics() {
        let id = SparkplugId::parse("plant/line1").unwrap();
        assert_eq!(id.to_string(), "plant/line1");
        assert_eq!(
            id.node_topic(MessageType::NBirth),
            "spBv1.0/plant/NBIRTH/line1"
        );
        assert_eq!(
            id.device_topic(MessageType::DData, "7"),
            "spBv1.0/plant/DDATA/line1/7"
        );
        for bad in ["plant", "a/b/c", "/e", "g/", "g+/e", "g/#"] {
            assert!(SparkplugId::parse(bad).is_err(), "{bad}");
        }
    }
}
