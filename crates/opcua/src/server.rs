//! The OPC UA server on `async-opcua`: endpoints, security, users, the
//! address space of [`crate::space`], and the callbacks that turn writes
//! and method calls into requests of the gateway core ([`crate::face`]).
//!
//! The server runs on a tokio runtime of its own, on its own threads, so
//! that a callback waiting for the bus never holds up the bus driver.

use crate::face::{Face, Requests, ToServer};
use crate::identity::Identities;
use crate::settings::{OpcuaSettings, Security};
use crate::space::{value_of, Sampler, Space, NAMESPACE_URI};
use opcua::crypto::SecurityPolicy;
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::memory::{simple_node_manager, SimpleNodeManager};
use opcua::server::{ServerBuilder, ServerHandle, ServerUserToken, ANONYMOUS_USER_TOKEN_ID};
use opcua::types::{ByteString, MessageSecurityMode, StatusCode, Variant};
use profibus_gateway::topics::Service;
use profibus_gateway::{Gateway, MqttSettings, SlaveInfo};
use serde_json::{json, Value as Json};
use std::sync::Arc;
use std::time::Duration;

/// The server could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// The runtime, the certificate or the listening socket.
    #[error("OPC UA server on {url}: {cause}")]
    Start {
        /// The endpoint.
        url: String,
        /// What failed.
        cause: String,
    },
}

/// A running OPC UA server; stops when dropped or on [`OpcuaServer::stop`].
pub struct OpcuaServer {
    handle: ServerHandle,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl OpcuaServer {
    /// Start the server of `settings` for `slaves` and return it with the
    /// [`Face`] the bus driver steps instead of the bare `core`; `mqtt`:
    /// whether a broker link also uses the face.
    pub fn start(
        settings: &OpcuaSettings,
        mqtt_settings: MqttSettings,
        slaves: Vec<SlaveInfo>,
        mqtt: bool,
    ) -> Result<(OpcuaServer, Face), ServerError> {
        let url = settings.url();
        let fail = |cause: String| ServerError::Start {
            url: url.clone(),
            cause,
        };
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("opcua")
            .enable_all()
            .build()
            .map_err(|e| fail(e.to_string()))?;
        let bus = mqtt_settings.bus.clone();
        let writable = mqtt_settings.writable.clone();
        let job_timeout = mqtt_settings.job_timeout;
        let builder = builder(settings);
        std::fs::create_dir_all(&settings.pki_dir)
            .map_err(|e| fail(format!("{}: {e}", settings.pki_dir.display())))?;
        let (server, handle) = {
            let _guard = rt.enter();
            builder.build().map_err(fail)?
        };
        let nm = handle
            .node_managers()
            .get_of_type::<SimpleNodeManager>()
            .ok_or_else(|| fail("no node manager".into()))?;
        let ns = handle
            .get_namespace_index(NAMESPACE_URI)
            .ok_or_else(|| fail("no namespace".into()))?;
        let space = {
            let mut sp = nm.address_space().write();
            Space::build(&mut sp, ns, &bus, &slaves, &writable)
        };
        crate::events::register_type(&mut handle.type_tree().write(), ns);
        let requests = Arc::new(Requests::default());
        let wait = job_timeout + Duration::from_secs(1);
        for s in &space.slaves {
            let a = s.address;
            // Every output: its access level says whether OPC UA may
            // write it now (it follows a reload of `writable`), the core
            // checks the permission again.
            for (id, channel) in &s.outputs {
                let rq = requests.clone();
                let channel = channel.clone();
                nm.inner().add_write_callback(id.clone(), move |dv, range| {
                    if !matches!(range, opcua::types::NumericRange::None) {
                        return StatusCode::BadIndexRangeInvalid;
                    }
                    let Some(v) = dv.value.as_ref().and_then(value_of) else {
                        return StatusCode::BadTypeMismatch;
                    };
                    let mut body = serde_json::Map::new();
                    body.insert("channels".into(), json!({ channel.as_str(): v }));
                    match call(&rq, a, Service::Outputs, body, wait) {
                        Ok(_) => StatusCode::Good,
                        Err(e) => e,
                    }
                });
            }
            if let Some(id) = &s.read_record {
                let rq = requests.clone();
                nm.inner().add_method_callback(id.clone(), move |args| {
                    let [slot, index, length] = bytes_args::<3>(args)?;
                    if length == 0 || length > 240 {
                        return Err(StatusCode::BadOutOfRange);
                    }
                    let body =
                        json!({"op": "read", "slot": slot, "index": index, "length": length});
                    let answer = call(&rq, a, Service::Dpv1, obj(body), wait)?;
                    let data = answer["hex"]
                        .as_str()
                        .and_then(unhex)
                        .ok_or(StatusCode::BadUnexpectedError)?;
                    Ok(vec![Variant::ByteString(ByteString::from(data))])
                });
            }
            if let Some(id) = &s.write_record {
                let rq = requests.clone();
                nm.inner().add_method_callback(id.clone(), move |args| {
                    let [slot, index] = bytes_args::<2>(args)?;
                    let data = match args.get(2) {
                        Some(Variant::ByteString(b)) => b.value.clone().unwrap_or_default(),
                        _ => return Err(StatusCode::BadTypeMismatch),
                    };
                    let hex: String = data.iter().map(|b| format!("{b:02x}")).collect();
                    let body = json!({"op": "write", "slot": slot, "index": index, "hex": hex});
                    call(&rq, a, Service::Dpv1, obj(body), wait)?;
                    Ok(vec![])
                });
            }
            if let Some(id) = &s.pkw_read {
                let rq = requests.clone();
                nm.inner().add_method_callback(id.clone(), move |args| {
                    let pnu = u16_arg(args, 0)?;
                    let index = u16_arg(args, 1)?;
                    let body = json!({"op": "read", "pnu": pnu, "index": index});
                    let answer = call(&rq, a, Service::Pkw, obj(body), wait)?;
                    let v = answer["value"]
                        .as_i64()
                        .ok_or(StatusCode::BadUnexpectedError)?;
                    Ok(vec![Variant::Int64(v)])
                });
            }
            if let Some(id) = &s.pkw_write {
                let rq = requests.clone();
                nm.inner().add_method_callback(id.clone(), move |args| {
                    let pnu = u16_arg(args, 0)?;
                    let index = u16_arg(args, 1)?;
                    let value = match args.get(2).and_then(value_of) {
                        Some(profibus_devices::channels::Value::Int(i)) => i,
                        _ => return Err(StatusCode::BadTypeMismatch),
                    };
                    let body = json!({"op": "write", "pnu": pnu, "index": index, "value": value});
                    call(&rq, a, Service::Pkw, obj(body), wait)?;
                    Ok(vec![])
                });
            }
        }
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<ToServer>();
        let subs = handle.subscriptions().clone();
        let nm2 = nm.clone();
        let sources: std::collections::HashMap<u8, (opcua::types::NodeId, String)> =
            (space.slaves.iter())
                .zip(&slaves)
                .map(|(n, info)| {
                    let name = format!("{} {}", n.address, info.layout.name);
                    (n.address, (n.object.clone(), name))
                })
                .collect();
        let thread = std::thread::Builder::new()
            .name("opcua-server".into())
            .spawn(move || {
                rt.block_on(async move {
                    tokio::spawn(async move {
                        let mut raised = 0u64;
                        while let Some(first) = rx.recv().await {
                            // Everything waiting: values in one lock of
                            // the space, events and access levels in order.
                            let mut values = vec![];
                            let mut next = Some(first);
                            while let Some(msg) = next.take().or_else(|| rx.try_recv().ok()) {
                                match msg {
                                    ToServer::Values(v) => values.extend(v),
                                    ToServer::Access(levels) => set_access(&nm2, &levels),
                                    ToServer::Alarm { address, report } => {
                                        let Some((source, name)) = sources.get(&address) else {
                                            continue;
                                        };
                                        raised += 1;
                                        let Some(ev) = crate::events::from_report(
                                            &report,
                                            ns,
                                            source.clone(),
                                            name,
                                            raised,
                                        ) else {
                                            continue;
                                        };
                                        // The slave notifies it, and with
                                        // it the Server object (the
                                        // library adds it), which stands
                                        // for the bus: one server per
                                        // bus. Notifying the bus object
                                        // too would hand the Server's
                                        // subscribers every alarm twice.
                                        let ev: &dyn opcua::nodes::Event = &ev;
                                        subs.notify_events([(ev, source)].into_iter());
                                    }
                                }
                            }
                            if values.is_empty() {
                                continue;
                            }
                            let it = values.iter().map(|(id, dv)| (id, None, dv.clone()));
                            if let Err(e) = nm2.set_values(&subs, it) {
                                tracing::warn!("OPC UA value update: {e}");
                            }
                        }
                    });
                    if let Err(e) = server.run().await {
                        tracing::error!("OPC UA server: {e}");
                    }
                });
            })
            .map_err(|e| fail(e.to_string()))?;
        let sampler = Sampler::new(ns, &bus, slaves.clone());
        let identities = Identities::new(
            ns,
            &bus,
            slaves.iter().map(|s| {
                let l = &s.layout;
                let vendor = l.gsd.as_ref().is_some_and(|g| g.vendor_name.is_some());
                (l.address, l.dpv1, vendor)
            }),
        );
        let core = Gateway::new(mqtt_settings, slaves);
        let face = Face::new(core, sampler, identities, space.slaves, requests, tx, mqtt);
        tracing::info!("OPC UA server on {url}");
        Ok((
            OpcuaServer {
                handle,
                thread: Some(thread),
            },
            face,
        ))
    }

    /// Close every session and stop the server.
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.handle.cancel();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for OpcuaServer {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Sessions at once (the library's default is 20; a session a client
/// dropped without closing it counts until it times out).
pub const MAX_SESSIONS: usize = 100;

/// The server's configuration from the settings.
fn builder(s: &OpcuaSettings) -> ServerBuilder {
    let mut ids: Vec<String> = s.users.iter().map(|u| format!("user:{}", u.name)).collect();
    if s.anonymous {
        ids.push(ANONYMOUS_USER_TOKEN_ID.to_string());
    }
    let ids: Vec<&str> = ids.iter().map(String::as_str).collect();
    let path = format!("/{}", s.path);
    let mut b = ServerBuilder::new()
        .application_name("dpctl gateway")
        .application_uri("urn:profibus:dpctl:gateway")
        .product_uri(NAMESPACE_URI)
        .create_sample_keypair(true)
        .certificate_path("own/cert.der")
        .private_key_path("private/private.pem")
        .pki_dir(s.pki_dir.clone())
        .trust_client_certs(s.trust_client_certs)
        .host(s.host.clone())
        .port(s.port)
        .discovery_urls(vec![path.clone()])
        .max_sessions(MAX_SESSIONS)
        .with_node_manager(simple_node_manager(
            NamespaceMetadata {
                namespace_uri: NAMESPACE_URI.to_string(),
                ..Default::default()
            },
            "profibus",
        ));
    for u in &s.users {
        b = b.add_user_token(
            format!("user:{}", u.name),
            ServerUserToken::user_pass(u.name.as_str(), u.password.as_str()),
        );
    }
    match s.security {
        Security::None => {
            b = b.add_endpoint(
                "none",
                (
                    path.as_str(),
                    SecurityPolicy::None,
                    MessageSecurityMode::None,
                    &ids as &[&str],
                ),
            );
        }
        Security::Basic256Sha256 { sign, sign_encrypt } => {
            for (id, mode, on) in [
                ("basic256sha256_sign", MessageSecurityMode::Sign, sign),
                (
                    "basic256sha256_sign_encrypt",
                    MessageSecurityMode::SignAndEncrypt,
                    sign_encrypt,
                ),
            ] {
                if !on {
                    continue;
                }
                b = b.add_endpoint(
                    id,
                    (
                        path.as_str(),
                        SecurityPolicy::Basic256Sha256,
                        mode,
                        &ids as &[&str],
                    ),
                );
            }
        }
    }
    b
}

/// Output variables writable (`CurrentRead | CurrentWrite`) or not
/// (`CurrentRead`), attribute and user attribute alike.
fn set_access(nm: &SimpleNodeManager, levels: &[(opcua::types::NodeId, bool)]) {
    use opcua::server::address_space::AccessLevel;
    let mut sp = nm.address_space().write();
    for (id, writable) in levels {
        if let Some(opcua::nodes::NodeType::Variable(v)) = sp.find_mut(id) {
            let level = match writable {
                true => AccessLevel::CURRENT_READ | AccessLevel::CURRENT_WRITE,
                false => AccessLevel::CURRENT_READ,
            };
            v.set_access_level(level);
            v.set_user_access_level(level);
        }
    }
}

fn obj(v: Json) -> serde_json::Map<String, Json> {
    match v {
        Json::Object(m) => m,
        _ => serde_json::Map::new(),
    }
}

/// Send a request to the core and wait for its answer (at most `wait`):
/// the answer's fields, or the status code of its error.
fn call(
    rq: &Requests,
    address: u8,
    service: Service,
    body: serde_json::Map<String, Json>,
    wait: Duration,
) -> Result<Json, StatusCode> {
    let rx = rq.submit(address, service, body);
    let answer = tokio::task::block_in_place(|| rx.recv_timeout(wait))
        .map_err(|_| StatusCode::BadTimeout)?;
    if answer["ok"].as_bool() == Some(true) {
        return Ok(answer);
    }
    let error = answer["error"].as_str().unwrap_or("refused");
    tracing::info!("OPC UA request to slave {address} refused: {error}");
    Err(status_of(error))
}

/// The status code of an error answer of the core.
fn status_of(error: &str) -> StatusCode {
    if error.contains("writable") {
        StatusCode::BadUserAccessDenied
    } else if error.contains("too many requests") {
        StatusCode::BadTooManyOperations
    } else if error.contains("timed out") || error.contains("timeout") {
        StatusCode::BadTimeout
    } else if error.contains("range") || error.contains("out of") {
        StatusCode::BadOutOfRange
    } else {
        StatusCode::BadInvalidArgument
    }
}

fn byte_arg(v: Option<&Variant>) -> Result<u8, StatusCode> {
    match v.and_then(value_of) {
        Some(profibus_devices::channels::Value::Int(i)) => {
            u8::try_from(i).map_err(|_| StatusCode::BadOutOfRange)
        }
        None if v.is_none() => Err(StatusCode::BadArgumentsMissing),
        _ => Err(StatusCode::BadTypeMismatch),
    }
}

fn bytes_args<const N: usize>(args: &[Variant]) -> Result<[u8; N], StatusCode> {
    let mut out = [0; N];
    for (i, o) in out.iter_mut().enumerate() {
        *o = byte_arg(args.get(i))?;
    }
    Ok(out)
}

fn u16_arg(args: &[Variant], i: usize) -> Result<u16, StatusCode> {
    match args.get(i).and_then(value_of) {
        Some(profibus_devices::channels::Value::Int(v)) => {
            u16::try_from(v).map_err(|_| StatusCode::BadOutOfRange)
        }
        None if args.get(i).is_none() => Err(StatusCode::BadArgumentsMissing),
        _ => Err(StatusCode::BadTypeMismatch),
    }
}

fn unhex(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}
