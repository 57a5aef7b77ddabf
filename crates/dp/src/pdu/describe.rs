//! Telegrams described for people and scripts: [`TelegramSummary`] is
//! what `dpctl decode` and `dpctl sniff` print (`Display`: one line;
//! with the feature `serde`: one JSON object), with the DP service a SAP
//! stands for.

use crate::pdu::sap;
use profibus_fdl::wire::{Format, FunctionCode, Hex, ParseError, Telegram};
use std::fmt;

/// A malformed telegram in a row of telegrams ([`summaries`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("malformed telegram at byte {offset}")]
pub struct Malformed {
    /// Where it starts.
    pub offset: usize,
    /// What is wrong.
    #[source]
    pub error: ParseError,
}

/// The telegrams of `bytes`, one after another (`dpctl decode`): each
/// described, up to the first malformed one.
pub fn summaries(bytes: &[u8]) -> impl Iterator<Item = Result<TelegramSummary<'_>, Malformed>> {
    let mut offset = 0;
    std::iter::from_fn(move || {
        let rest = bytes.get(offset..).filter(|r| !r.is_empty())?;
        match Telegram::parse(rest) {
            Ok((t, n)) => {
                offset += n;
                Some(Ok(TelegramSummary::new(t, &rest[..n])))
            }
            Err(error) => {
                let at = offset;
                offset = bytes.len();
                Some(Err(Malformed { offset: at, error }))
            }
        }
    })
}

/// A valid telegram described: its fields, its service in DP terms, its
/// raw bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct TelegramSummary<'a> {
    /// The frame format (`SD1`, `SD2`, `SD3`, `SD4`, `SC`).
    pub format: &'static str,
    /// `short_ack`, `token`, `request` or `response`.
    #[cfg_attr(feature = "serde", serde(rename = "type"))]
    pub kind: &'static str,
    /// Destination address.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub da: Option<u8>,
    /// Source address.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub sa: Option<u8>,
    /// The function code byte.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub fc: Option<u8>,
    /// The data unit.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub data: Option<Hex<'a>>,
    /// Its length.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub data_len: Option<usize>,
    /// The FCS was right (always, for a telegram that parsed).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub fcs_ok: Option<bool>,
    /// Request: the service's mnemonic.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub service: Option<&'static str>,
    /// Request: the function's code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub function: Option<u8>,
    /// Request: frame count bit.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub fcb: Option<bool>,
    /// Request: frame count bit valid.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub fcv: Option<bool>,
    /// Response: the status mnemonic.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub status: Option<&'static str>,
    /// Response: the status code.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub status_code: Option<u8>,
    /// Response: the responder's station type in words.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub station_type: Option<&'static str>,
    /// Destination SAP (without the segment bit).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub dsap: Option<u8>,
    /// Source SAP (without the segment bit).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub ssap: Option<u8>,
    /// The DP service of the slave's SAP (DSAP of a request, SSAP of a
    /// response), or `FMS` when the stream tells so
    /// ([`crate::pdu::decode::Exchanges::decode_layer`]; the text line
    /// names the SAP by it).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub service_sap: Option<&'static str>,
    /// The DSAP byte has the segment bit.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub dsap_segment: Option<bool>,
    /// The SSAP byte has the segment bit.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub ssap_segment: Option<bool>,
    /// The whole telegram.
    pub raw: Hex<'a>,
    /// The telegram, for the text line.
    #[cfg_attr(feature = "serde", serde(skip))]
    pub telegram: Telegram<'a>,
}

impl<'a> TelegramSummary<'a> {
    /// Describe `t`, parsed from `raw`.
    pub fn new(t: Telegram<'a>, raw: &'a [u8]) -> TelegramSummary<'a> {
        let mut s = TelegramSummary {
            format: t.format().name(),
            kind: "",
            da: None,
            sa: None,
            fc: None,
            data: None,
            data_len: None,
            fcs_ok: None,
            service: None,
            function: None,
            fcb: None,
            fcv: None,
            status: None,
            status_code: None,
            station_type: None,
            dsap: None,
            ssap: None,
            service_sap: None,
            dsap_segment: None,
            ssap_segment: None,
            raw: Hex(raw),
            telegram: t,
        };
        match t {
            Telegram::ShortAck => s.kind = "short_ack",
            Telegram::Token { da, sa } => {
                s.kind = "token";
                s.da = Some(da);
                s.sa = Some(sa);
            }
            Telegram::Data(d) => {
                if let Some(f) = raw.first().and_then(|&sd| Format::from_start_delimiter(sd)) {
                    s.format = f.name();
                }
                s.da = Some(d.da);
                s.sa = Some(d.sa);
                s.fc = Some(d.fc.to_byte());
                s.data = Some(Hex(d.data));
                s.data_len = Some(d.data.len());
                s.fcs_ok = Some(true);
                match d.fc {
                    FunctionCode::Request { kind, fcb, fcv } => {
                        s.kind = "request";
                        s.service = Some(kind.mnemonic());
                        s.function = Some(kind.code());
                        s.fcb = Some(fcb);
                        s.fcv = Some(fcv);
                    }
                    FunctionCode::Response { status, station } => {
                        s.kind = "response";
                        s.status = Some(status.mnemonic());
                        s.status_code = Some(status.code());
                        s.station_type = Some(station.describe());
                    }
                }
                let req = d.fc.is_request();
                if let Some(x) = d.dsap {
                    s.dsap = Some(x & 0x3F);
                    s.dsap_segment = (x & 0x40 != 0).then_some(true);
                    if req {
                        s.service_sap = sap::name(x & 0x3F).or(s.service_sap);
                    }
                }
                if let Some(x) = d.ssap {
                    s.ssap = Some(x & 0x3F);
                    s.ssap_segment = (x & 0x40 != 0).then_some(true);
                    if !req {
                        s.service_sap = sap::name(x & 0x3F).or(s.service_sap);
                    }
                }
            }
        }
        s
    }
}

/// `name`: the service of the SAP when it is the slave's side of the
/// service (DSAP of a request, SSAP of a response).
fn sap_text(
    f: &mut fmt::Formatter<'_>,
    label: &str,
    s: u8,
    name: Option<&'static str>,
) -> fmt::Result {
    if s & 0x40 != 0 {
        return write!(f, " {label}=segment {}", s & 0x3F);
    }
    match name {
        Some(n) => write!(f, " {label}={} ({n})", s & 0x3F),
        None => write!(f, " {label}={}", s & 0x3F),
    }
}

impl fmt::Display for TelegramSummary<'_> {
    /// One line, e.g. `SD2 2→8 SRD_HIGH DSAP=61 (Set_Prm) SSAP=62 DU[7]=… FCS ok`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let fmt_name = self.telegram.format().name();
        match &self.telegram {
            Telegram::ShortAck => write!(f, "{fmt_name} short acknowledge"),
            Telegram::Token { da, sa } => write!(f, "{fmt_name} token {sa}→{da}"),
            Telegram::Data(d) => {
                write!(f, "{fmt_name} {}→", d.sa)?;
                if d.da == 127 {
                    f.write_str("127(broadcast)")?;
                } else {
                    write!(f, "{}", d.da)?;
                }
                write!(f, " {}", d.fc)?;
                let req = d.fc.is_request();
                if let Some(x) = d.dsap {
                    sap_text(f, "DSAP", x, self.service_sap.filter(|_| req))?;
                }
                if let Some(x) = d.ssap {
                    sap_text(f, "SSAP", x, self.service_sap.filter(|_| !req))?;
                } else if d.dsap.is_none() && d.fc.is_request() && !d.data.is_empty() {
                    f.write_str(" (default SAP)")?;
                }
                if !d.data.is_empty() {
                    write!(f, " DU[{}]={}", d.data.len(), Hex(d.data))?;
                }
                f.write_str(" FCS ok")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn summaries_of_telegrams_in_a_row_stop_at_the_first_malformed_one() {
        let bytes = [0xE5, 0x10, 0x02, 0x01, 0x49, 0x4C, 0x16, 0x10, 0x02];
        let got: Vec<_> = super::summaries(&bytes).collect();
        assert_eq!(got.len(), 3);
        assert!(got[0].is_ok() && got[1].is_ok());
        let e = got[2].as_ref().unwrap_err();
        assert_eq!(
            (e.offset, e.to_string().as_str()),
            (7, "malformed telegram at byte 7")
        );
        assert_eq!(super::summaries(&[]).count(), 0);
    }
}
