//! The `[opcua]` table of a bus file and the users file.

use std::path::{Path, PathBuf};

/// The default TCP port of OPC UA (IANA `opcua-tcp`).
pub const DEFAULT_PORT: u16 = 4840;

/// Which message security the server offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Security {
    /// `Basic256Sha256` with `Sign`, `SignAndEncrypt` or both (the
    /// default: both).
    Basic256Sha256 {
        /// Offer `Sign`.
        sign: bool,
        /// Offer `SignAndEncrypt`.
        sign_encrypt: bool,
    },
    /// No security at all: only with `--opcua-insecure` on the command
    /// line, never from a bus file.
    None,
}

/// The OPC UA side of `dpctl gateway`.
#[derive(Debug, Clone, PartialEq)]
pub struct OpcuaSettings {
    /// Host name or address to listen on.
    pub host: String,
    /// TCP port.
    pub port: u16,
    /// Message security.
    pub security: Security,
    /// User names and passwords (`users_file`).
    pub users: Vec<User>,
    /// Whether anonymous sessions are allowed (`anonymous`).
    pub anonymous: bool,
    /// The PKI directory: own certificate and key, trusted and rejected
    /// client certificates (`pki_dir`; default [`default_pki_dir`]).
    pub pki_dir: PathBuf,
    /// Trust every client certificate instead of only those in
    /// `PKI/trusted` (`trust_client_certs`).
    pub trust_client_certs: bool,
    /// The last path component of the endpoint URL (empty: `/`).
    pub path: String,
}

/// One user of the users file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct User {
    /// User name.
    pub name: String,
    /// Password.
    pub password: String,
}

/// A bad `[opcua]` setting, endpoint URL or users file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SettingsError {
    /// A key this version does not know.
    #[error("[opcua]: unknown key `{0}` (known: endpoint, security, users_file, anonymous, pki_dir, trust_client_certs)")]
    UnknownKey(String),
    /// A key with a value of the wrong type or range.
    #[error("[opcua]: `{key}` {problem}")]
    Bad {
        /// The key.
        key: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// An endpoint URL that is not `opc.tcp://HOST[:PORT][/PATH]`.
    #[error("OPC UA endpoint `{0}` is not opc.tcp://HOST[:PORT]")]
    BadUrl(String),
    /// A users file that cannot be read or has a bad line.
    #[error("{0}")]
    Users(String),
    /// Neither anonymous access nor any user: nobody could log in.
    #[error("[opcua]: no way to log in: give `users_file` or `anonymous = true`")]
    NoLogin,
}

impl SettingsError {
    /// The dotted path in the bus file of the key this error is about
    /// (`opcua.security`), for its position; `None` for what is not in
    /// the table (an endpoint from the command line, a users file's line).
    pub fn key_path(&self) -> Option<String> {
        match self {
            SettingsError::UnknownKey(k) => Some(format!("opcua.{k}")),
            SettingsError::Bad { key, .. } => Some(format!("opcua.{key}")),
            SettingsError::NoLogin => Some("opcua".into()),
            SettingsError::BadUrl(_) | SettingsError::Users(_) => None,
        }
    }
}

/// The `[opcua]` table as written.
#[derive(Debug, Default, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
struct Raw {
    endpoint: Option<toml::Value>,
    security: Option<toml::Value>,
    users_file: Option<toml::Value>,
    anonymous: Option<toml::Value>,
    pki_dir: Option<toml::Value>,
    trust_client_certs: Option<toml::Value>,
}

fn bad(key: &'static str, problem: impl Into<String>) -> SettingsError {
    SettingsError::Bad {
        key,
        problem: problem.into(),
    }
}

fn string(v: Option<toml::Value>, key: &'static str) -> Result<Option<String>, SettingsError> {
    match v {
        None => Ok(None),
        Some(toml::Value::String(s)) => Ok(Some(s)),
        Some(_) => Err(bad(key, "must be a string")),
    }
}

fn boolean(v: Option<toml::Value>, key: &'static str) -> Result<Option<bool>, SettingsError> {
    match v {
        None => Ok(None),
        Some(toml::Value::Boolean(b)) => Ok(Some(b)),
        Some(_) => Err(bad(key, "must be true or false")),
    }
}

/// `opc.tcp://HOST[:PORT][/PATH]` as host, port and path (split as the
/// MQTT broker's URL, [`profibus_gateway::url::split_url`]).
pub fn parse_endpoint(url: &str) -> Result<(String, u16, String), SettingsError> {
    let u = profibus_gateway::url::split_url(url, &["opc.tcp://"])
        .ok_or_else(|| SettingsError::BadUrl(url.to_string()))?;
    Ok((
        u.host.to_string(),
        u.port.unwrap_or(DEFAULT_PORT),
        u.path.to_string(),
    ))
}

/// Where the server keeps its certificate when `pki_dir` is not given:
/// `$XDG_DATA_HOME/dpctl/opcua/pki`, else `~/.local/share/dpctl/opcua/pki`,
/// else `./dpctl-opcua-pki`.
pub fn default_pki_dir() -> PathBuf {
    let base = std::env::var_os("XDG_DATA_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|v| !v.is_empty())
                .map(|h| PathBuf::from(h).join(".local/share"))
        });
    match base {
        Some(b) => b.join("dpctl/opcua/pki"),
        None => PathBuf::from("dpctl-opcua-pki"),
    }
}

/// The users file: one `name:password` a line; blank lines and lines
/// starting with `#` are skipped. `path` is only for messages.
pub fn parse_users(path: &Path, text: &str) -> Result<Vec<User>, SettingsError> {
    let mut users: Vec<User> = vec![];
    for (n, line) in text.lines().enumerate() {
        let at = || format!("{}:{}", path.display(), n + 1);
        let line = line.trim_end_matches('\r');
        if line.trim().is_empty() || line.trim_start().starts_with('#') {
            continue;
        }
        let Some((name, password)) = line.split_once(':') else {
            return Err(SettingsError::Users(format!(
                "{}: not `name:password`",
                at()
            )));
        };
        if name.is_empty() || password.is_empty() {
            return Err(SettingsError::Users(format!(
                "{}: empty user name or password",
                at()
            )));
        }
        if users.iter().any(|u| u.name == name) {
            return Err(SettingsError::Users(format!(
                "{}: user `{name}` given twice",
                at()
            )));
        }
        users.push(User {
            name: name.to_string(),
            password: password.to_string(),
        });
    }
    Ok(users)
}

impl OpcuaSettings {
    /// Settings from a bus file's `[opcua]` table (`None`: all defaults)
    /// and the command line: `endpoint` (`--opcua`, overrides the
    /// table's) and `insecure` (`--opcua-insecure`: security `None`).
    /// Relative paths are relative to `dir`, the bus file's directory.
    /// The users file is read here.
    pub fn new(
        table: Option<&toml::Table>,
        endpoint: Option<&str>,
        insecure: bool,
        dir: &Path,
    ) -> Result<OpcuaSettings, SettingsError> {
        let raw: Raw =
            profibus_gateway::settings::raw_table(table).map_err(SettingsError::UnknownKey)?;
        let written = string(raw.endpoint, "endpoint")?;
        let url = endpoint
            .map(str::to_string)
            .or(written)
            .unwrap_or_else(|| format!("opc.tcp://0.0.0.0:{DEFAULT_PORT}"));
        let (host, port, path) = parse_endpoint(&url)?;
        let modes = match raw.security {
            None => vec!["sign".to_string(), "sign_encrypt".to_string()],
            Some(toml::Value::Array(a)) => a
                .into_iter()
                .map(|v| match v {
                    toml::Value::String(s) => Ok(s),
                    _ => Err(bad("security", "must be a list of strings")),
                })
                .collect::<Result<Vec<_>, _>>()?,
            Some(_) => return Err(bad("security", "must be a list of strings")),
        };
        for m in &modes {
            match m.as_str() {
                "sign" | "sign_encrypt" => {}
                "none" => {
                    return Err(bad(
                        "security",
                        "`none` is only taken from the command line (--opcua-insecure)",
                    ))
                }
                other => {
                    return Err(bad(
                        "security",
                        format!("`{other}` is not `sign` or `sign_encrypt`"),
                    ))
                }
            }
        }
        if modes.is_empty() {
            return Err(bad("security", "must name `sign`, `sign_encrypt` or both"));
        }
        let users = match string(raw.users_file, "users_file")? {
            None => vec![],
            Some(f) => {
                let p = dir.join(f);
                let text = std::fs::read_to_string(&p)
                    .map_err(|e| SettingsError::Users(format!("{}: {e}", p.display())))?;
                parse_users(&p, &text)?
            }
        };
        let anonymous = boolean(raw.anonymous, "anonymous")?.unwrap_or(false);
        if !anonymous && users.is_empty() {
            return Err(SettingsError::NoLogin);
        }
        let pki_dir = match string(raw.pki_dir, "pki_dir")? {
            Some(p) => dir.join(p),
            None => default_pki_dir(),
        };
        let trust_client_certs =
            boolean(raw.trust_client_certs, "trust_client_certs")?.unwrap_or(false);
        Ok(OpcuaSettings {
            host,
            port,
            security: if insecure {
                Security::None
            } else {
                Security::Basic256Sha256 {
                    sign: modes.iter().any(|m| m == "sign"),
                    sign_encrypt: modes.iter().any(|m| m == "sign_encrypt"),
                }
            },
            users,
            anonymous,
            pki_dir,
            trust_client_certs,
            path,
        })
    }

    /// The endpoint URL clients use.
    pub fn url(&self) -> String {
        let host = if self.host.contains(':') {
            format!("[{}]", self.host)
        } else {
            self.host.clone()
        };
        format!("opc.tcp://{host}:{}/{}", self.port, self.path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(s: &str) -> toml::Table {
        s.parse().unwrap()
    }

    #[test]
    fn endpoints() {
        assert_eq!(
            parse_endpoint("opc.tcp://127.0.0.1:4841").unwrap(),
            ("127.0.0.1".into(), 4841, "".into())
        );
        assert_eq!(
            parse_endpoint("opc.tcp://plc").unwrap(),
            ("plc".into(), 4840, "".into())
        );
        assert_eq!(
            parse_endpoint("opc.tcp://[::1]:5000/dp/").unwrap(),
            ("::1".into(), 5000, "dp".into())
        );
        for bad in [
            "http://x:1",
            "opc.tcp://:1",
            "opc.tcp://x:0",
            "opc.tcp://x:y",
        ] {
            assert_eq!(
                parse_endpoint(bad).unwrap_err().to_string(),
                format!("OPC UA endpoint `{bad}` is not opc.tcp://HOST[:PORT]")
            );
        }
    }

    #[test]
    fn security_none_only_from_the_command_line() {
        let t = table("anonymous = true\nsecurity = [\"none\"]");
        let e = OpcuaSettings::new(Some(&t), None, false, Path::new(".")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "[opcua]: `security` `none` is only taken from the command line (--opcua-insecure)"
        );
        let t = table("anonymous = true");
        let s = OpcuaSettings::new(Some(&t), Some("opc.tcp://h:1"), true, Path::new(".")).unwrap();
        assert_eq!(s.security, Security::None);
        let s = OpcuaSettings::new(Some(&t), None, false, Path::new(".")).unwrap();
        assert_eq!(
            s.security,
            Security::Basic256Sha256 {
                sign: true,
                sign_encrypt: true
            }
        );
        assert_eq!(s.url(), "opc.tcp://0.0.0.0:4840/");
    }

    #[test]
    fn nobody_can_log_in_without_users_or_anonymous() {
        assert_eq!(
            OpcuaSettings::new(None, None, false, Path::new(".")),
            Err(SettingsError::NoLogin)
        );
        let t = table("anonymus = true");
        assert_eq!(
            OpcuaSettings::new(Some(&t), None, false, Path::new("."))
                .unwrap_err()
                .to_string(),
            "[opcua]: unknown key `anonymus` (known: endpoint, security, users_file, anonymous, pki_dir, trust_client_certs)"
        );
    }

    #[test]
    fn users_file() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("users"),
            "# operators\nanna:s3cret\n\nbob:pw:with:colons\n",
        )
        .unwrap();
        let t = table("users_file = \"users\"");
        let s = OpcuaSettings::new(Some(&t), None, false, dir.path()).unwrap();
        assert_eq!(s.users.len(), 2);
        assert_eq!(s.users[1].password, "pw:with:colons");
        assert!(!s.anonymous);
        let e = parse_users(Path::new("u"), "anna:x\nbroken\n").unwrap_err();
        assert_eq!(e.to_string(), "u:2: not `name:password`");
    }
}
