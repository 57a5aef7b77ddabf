//! `SCHEME://HOST[:PORT][/PATH]` URLs: the MQTT broker's
//! ([`crate::settings::parse_broker`]) and the OPC UA endpoint's
//! (`profibus-opcua`), split the same way.

/// The parts of a `SCHEME://HOST[:PORT][/PATH]` URL.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UrlParts<'a> {
    /// The scheme as matched, with `://` (one of the schemes asked for).
    pub scheme: &'a str,
    /// Host name or address; an IPv6 address without its brackets.
    pub host: &'a str,
    /// The port, if the URL gives one (1..=65535).
    pub port: Option<u16>,
    /// What follows the authority, without the slashes around it (empty
    /// for none).
    pub path: &'a str,
}

/// Split `url` whose scheme is one of `schemes` (each with `://`).
/// The host is a name, an IPv4 address, an IPv6 address in brackets
/// (`[::1]:4840`) or a bare IPv6 address without a port (`::1`). `None`
/// for another scheme, an empty host, user information (`user@host`) or
/// a port that is not 1..=65535.
pub fn split_url<'a>(url: &'a str, schemes: &[&'a str]) -> Option<UrlParts<'a>> {
    let (scheme, rest) = schemes
        .iter()
        .find_map(|s| url.strip_prefix(s).map(|r| (*s, r)))?;
    let (authority, path) = rest.split_once('/').unwrap_or((rest, ""));
    let (host, port) = if let Some(v6) = authority.strip_prefix('[') {
        let (h, after) = v6.split_once(']')?;
        match after {
            "" => (h, None),
            _ => (h, Some(after.strip_prefix(':')?)),
        }
    } else if authority.matches(':').count() > 1 {
        (authority, None)
    } else {
        match authority.rsplit_once(':') {
            Some((h, p)) => (h, Some(p)),
            None => (authority, None),
        }
    };
    if host.is_empty() || host.contains(['@', '[', ']']) {
        return None;
    }
    let port = match port {
        None => None,
        Some(p) => Some(p.parse::<u16>().ok().filter(|p| *p > 0)?),
    };
    Some(UrlParts {
        scheme,
        host,
        port,
        path: path.trim_matches('/'),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_split_into_host_port_and_path() {
        let s = ["mqtt://", "opc.tcp://"];
        let parts = |u| split_url(u, &s).map(|p| (p.scheme, p.host, p.port, p.path));
        assert_eq!(
            parts("mqtt://h:1884"),
            Some(("mqtt://", "h", Some(1884), ""))
        );
        assert_eq!(parts("mqtt://h/"), Some(("mqtt://", "h", None, "")));
        assert_eq!(
            parts("opc.tcp://[::1]:5000/dp/"),
            Some(("opc.tcp://", "::1", Some(5000), "dp"))
        );
        assert_eq!(
            parts("opc.tcp://[fe80::1]"),
            Some(("opc.tcp://", "fe80::1", None, ""))
        );
        assert_eq!(parts("mqtt://::1"), Some(("mqtt://", "::1", None, "")));
        for bad in [
            "http://h:1",
            "mqtt://:1",
            "mqtt://h:0",
            "mqtt://h:y",
            "mqtt://h:70000",
            "mqtt://u@h",
            "mqtt://[::1",
            "mqtt://[::1]x",
            "mqtt://",
        ] {
            assert_eq!(parts(bad), None, "{bad}");
        }
    }
}
