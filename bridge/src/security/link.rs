//! The Zenoh configuration of one bridge session: where it listens and connects, that it finds
//! no one else, its TLS identity and the access policy.

use std::path::Path;
use std::str::FromStr;

use serde_json::{Value, json};
use zenoh::config::EndPoint;

use super::access::AccessPolicy;
use super::cert_files::{HostTlsFiles, TlsFilesError};

/// The protocols of authenticated, encrypted links, in order of preference. Both take the
/// same certificates and settings (Zenoh's `transport/link/tls`).
///
/// - `quic`: QUIC, TLS 1.3 inside; one connection carries independent send and receive
///   streams, so traffic both ways at once is safe. The default of `fleet run --hosts`.
/// - `tls`: TLS over TCP. Zenoh 1.10.2's TLS link reads and writes one TLS stream from two
///   tasks at once without a lock; under heavy traffic both ways (frames one way, estimates
///   and acks the other) that stream can be corrupted and the link drops, losing the
///   messages in flight (seen here once in a 300 s run of 2 hosts, and within minutes of a
///   bench with acks on the same link). Kept for networks that let only TCP through.
pub const SECURE_PROTOCOLS: [&str; 2] = ["quic", "tls"];

/// How a bridge session joins the others.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkMode {
    /// A router: the hub the clients connect to; it relays their messages to each other.
    Router,
    /// A client: talks only through the router it connects to.
    Client,
    /// A peer: talks directly to the peers it connects to or that connect to it. Peers do not
    /// relay one peer's messages to another, so every pair of hosts that exchange data needs
    /// a link (each pair: one listens, the other connects).
    Peer,
}

/// Where a session listens and which endpoints it connects to: the only links it will ever
/// have. With the fleet's certificates, endpoints are `quic/{host}:{port}` (QUIC: TLS 1.3 over
/// UDP, the recommended link) or `tls/{host}:{port}` (TLS over TCP, see [`SECURE_PROTOCOLS`]);
/// without them, `tcp/{host}:{port}` (e.g. `quic/10.0.0.7:7447`, `quic/[::1]:7447`). With TLS,
/// the host part of a connect endpoint must be one of the target's certificate names (subject
/// alternative names).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LinkPlan {
    /// Router, client or peer.
    pub mode: LinkMode,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
    /// Endpoints to connect to (retried in the background by a peer or router until they
    /// answer; a client fails to open if none answers within Zenoh's `connect/timeout_ms`).
    pub connect: Vec<String>,
}

/// Why a Zenoh configuration could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ConfigBuildError {
    /// The plan has no endpoint at all: the session could never meet anyone.
    #[error("no endpoint: a session needs at least one endpoint to listen on or connect to")]
    NoEndpoints,
    /// A client needs a router to connect to.
    #[error("a client needs at least one endpoint to connect to")]
    ClientWithoutConnect,
    /// Zenoh cannot parse the endpoint.
    #[error("invalid endpoint {endpoint:?}: {reason}")]
    Endpoint {
        /// The endpoint as given.
        endpoint: String,
        /// What Zenoh said.
        reason: String,
    },
    /// The endpoint carries metadata (`?...`) or per-endpoint configuration (`#...`), which
    /// could override the session's TLS settings for that link.
    #[error("endpoint {0:?} carries options ('?' or '#'): give the plain protocol/address")]
    EndpointOptions(String),
    /// The endpoint's protocol is not the one the session uses.
    #[error("endpoint {endpoint:?} is not {expected}: {why}")]
    Protocol {
        /// The endpoint as given.
        endpoint: String,
        /// The protocol required.
        expected: &'static str,
        /// Why that protocol.
        why: &'static str,
    },
    /// The endpoints mix protocols: a session uses one.
    #[error("endpoints {0:?} and {1:?} use different protocols: a session uses one")]
    MixedProtocols(String, String),
    /// An access policy needs TLS: it knows hosts by their certificates.
    #[error("an access policy needs TLS: its subjects are certificate common names")]
    AclWithoutTls,
    /// The host's TLS files are not usable.
    #[error(transparent)]
    TlsFiles(#[from] TlsFilesError),
    /// Zenoh's configuration takes file paths as UTF-8 text.
    #[error("{} is not valid UTF-8: Zenoh's configuration cannot name it", .0.display())]
    NonUtf8Path(std::path::PathBuf),
    /// Zenoh refused a setting (a bug of this module if it ever happens).
    #[error("zenoh refused setting {key}: {reason}")]
    Zenoh {
        /// The configuration key.
        key: &'static str,
        /// What Zenoh said.
        reason: String,
    },
}

/// Builds the Zenoh configuration of a bridge session.
///
/// - Links: only the plan's endpoints. Multicast scouting and gossip are off, so the session
///   never discovers, nor is discovered by, anything else on the network.
/// - With `tls`: the endpoints' one protocol, QUIC or TLS over TCP ([`SECURE_PROTOCOLS`]; a
///   `tcp/` endpoint is refused), is the only one the session speaks, with mutual
///   authentication: the session presents the host's certificate on every link, listening or
///   connecting, and accepts only a peer whose certificate the fleet authority signed; a
///   connecting session also checks the name it dialled against the listener's certificate.
///   Links close when a certificate expires. The files are checked first
///   ([`HostTlsFiles::check`]).
/// - With `acl`: Zenoh's access control as [`AccessPolicy::to_json`] says (needs `tls`).
///
/// The result is an ordinary [`zenoh::Config`]: settings this module does not own (e.g. a
/// client's `connect/timeout_ms` and `connect/retry`) can be added to it with `insert_json5`.
pub fn zenoh_config(
    link: &LinkPlan,
    tls: Option<&HostTlsFiles>,
    acl: Option<&AccessPolicy>,
) -> Result<zenoh::Config, ConfigBuildError> {
    if link.listen.is_empty() && link.connect.is_empty() {
        return Err(ConfigBuildError::NoEndpoints);
    }
    if link.mode == LinkMode::Client && link.connect.is_empty() {
        return Err(ConfigBuildError::ClientWithoutConnect);
    }
    if acl.is_some() && tls.is_none() {
        return Err(ConfigBuildError::AclWithoutTls);
    }
    let protocol = session_protocol(link, tls.is_some())?;

    let mut config = zenoh::Config::default();
    let mode = match link.mode {
        LinkMode::Router => "router",
        LinkMode::Client => "client",
        LinkMode::Peer => "peer",
    };
    set(&mut config, "mode", json!(mode))?;
    set(&mut config, "listen/endpoints", json!(link.listen))?;
    set(&mut config, "connect/endpoints", json!(link.connect))?;
    set(&mut config, "scouting/multicast/enabled", json!(false))?;
    set(&mut config, "scouting/gossip/enabled", json!(false))?;
    set(&mut config, "transport/link/protocols", json!([protocol]))?;
    if let Some(files) = tls {
        files.check()?;
        let ca = utf8(&files.ca)?;
        let cert = utf8(&files.cert)?;
        let key = utf8(&files.key)?;
        set(
            &mut config,
            "transport/link/tls/root_ca_certificate",
            json!(ca),
        )?;
        set(
            &mut config,
            "transport/link/tls/listen_certificate",
            json!(cert),
        )?;
        set(
            &mut config,
            "transport/link/tls/listen_private_key",
            json!(key),
        )?;
        set(
            &mut config,
            "transport/link/tls/connect_certificate",
            json!(cert),
        )?;
        set(
            &mut config,
            "transport/link/tls/connect_private_key",
            json!(key),
        )?;
        set(&mut config, "transport/link/tls/enable_mtls", json!(true))?;
        set(
            &mut config,
            "transport/link/tls/verify_name_on_connect",
            json!(true),
        )?;
        set(
            &mut config,
            "transport/link/tls/close_link_on_expiration",
            json!(true),
        )?;
    }
    if let Some(policy) = acl {
        set(&mut config, "access_control", policy.to_json())?;
    }
    Ok(config)
}

/// The one protocol of the plan's endpoints: `tcp` without TLS files, one of
/// [`SECURE_PROTOCOLS`] with them.
fn session_protocol(link: &LinkPlan, secure: bool) -> Result<&'static str, ConfigBuildError> {
    let mut chosen: Option<(&'static str, &String)> = None;
    for endpoint in link.listen.iter().chain(&link.connect) {
        let protocol = endpoint_protocol(endpoint, secure)?;
        match chosen {
            Some((first, other)) if first != protocol => {
                return Err(ConfigBuildError::MixedProtocols(
                    other.clone(),
                    endpoint.clone(),
                ));
            }
            _ => chosen = Some((protocol, endpoint)),
        }
    }
    // The caller checked that there is an endpoint.
    Ok(chosen.map_or("tcp", |(protocol, _)| protocol))
}

/// The protocol of one endpoint, if it is a plain one the session may use.
fn endpoint_protocol(endpoint: &str, secure: bool) -> Result<&'static str, ConfigBuildError> {
    let parsed = EndPoint::from_str(endpoint).map_err(|e| ConfigBuildError::Endpoint {
        endpoint: endpoint.to_owned(),
        reason: e.to_string(),
    })?;
    if !parsed.metadata().is_empty() || !parsed.config().is_empty() {
        return Err(ConfigBuildError::EndpointOptions(endpoint.to_owned()));
    }
    let (allowed, expected, why): (&[&'static str], _, _) = if secure {
        (
            &SECURE_PROTOCOLS,
            "quic or tls",
            "the session authenticates and encrypts every link",
        )
    } else {
        (
            &["tcp"],
            "tcp",
            "without TLS files the session uses plain TCP",
        )
    };
    allowed
        .iter()
        .copied()
        .find(|p| *p == parsed.protocol().as_str())
        .ok_or_else(|| ConfigBuildError::Protocol {
            endpoint: endpoint.to_owned(),
            expected,
            why,
        })
}

fn utf8(path: &Path) -> Result<&str, ConfigBuildError> {
    path.to_str()
        .ok_or_else(|| ConfigBuildError::NonUtf8Path(path.to_owned()))
}

/// Sets one key from a JSON value: serde_json does the quoting, so no text given by a user is
/// ever pasted into the configuration.
fn set(
    config: &mut zenoh::Config,
    key: &'static str,
    value: Value,
) -> Result<(), ConfigBuildError> {
    config
        .insert_json5(key, &value.to_string())
        .map_err(|e| ConfigBuildError::Zenoh {
            key,
            reason: e.to_string(),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(listen: &[&str], connect: &[&str]) -> LinkPlan {
        LinkPlan {
            mode: LinkMode::Peer,
            listen: listen.iter().map(|s| (*s).to_owned()).collect(),
            connect: connect.iter().map(|s| (*s).to_owned()).collect(),
        }
    }

    #[test]
    fn plain_tcp_plan_uses_only_its_endpoints() {
        let config = zenoh_config(
            &plan(&["tcp/127.0.0.1:7447"], &["tcp/127.0.0.1:7448"]),
            None,
            None,
        )
        .unwrap();
        let get = |key| config.get_json(key).unwrap();
        assert_eq!(get("mode"), r#""peer""#);
        assert_eq!(get("listen/endpoints"), r#"["tcp/127.0.0.1:7447"]"#);
        assert_eq!(get("connect/endpoints"), r#"["tcp/127.0.0.1:7448"]"#);
        assert_eq!(get("scouting/multicast/enabled"), "false");
        assert_eq!(get("scouting/gossip/enabled"), "false");
        assert_eq!(get("transport/link/protocols"), r#"["tcp"]"#);

        let mut router = plan(&["tcp/127.0.0.1:7447"], &[]);
        router.mode = LinkMode::Router;
        let config = zenoh_config(&router, None, None).unwrap();
        assert_eq!(config.get_json("mode").unwrap(), r#""router""#);
    }

    #[test]
    fn refuses_plans_that_would_leak_or_never_connect() {
        let err = |p: LinkPlan| zenoh_config(&p, None, None).unwrap_err();
        assert!(matches!(err(plan(&[], &[])), ConfigBuildError::NoEndpoints));
        let mut client = plan(&["tcp/127.0.0.1:1"], &[]);
        client.mode = LinkMode::Client;
        assert!(matches!(
            err(client),
            ConfigBuildError::ClientWithoutConnect
        ));
        for secure in ["tls/127.0.0.1:1", "quic/127.0.0.1:1"] {
            assert!(matches!(
                err(plan(&[secure], &[])),
                ConfigBuildError::Protocol {
                    expected: "tcp",
                    ..
                }
            ));
        }
        assert!(matches!(
            err(plan(&["udp/127.0.0.1:1"], &[])),
            ConfigBuildError::Protocol { .. }
        ));
        assert!(matches!(
            err(plan(&["tcp/127.0.0.1:1#enable_mtls=false"], &[])),
            ConfigBuildError::EndpointOptions(_)
        ));
        assert!(matches!(
            err(plan(&["tcp/127.0.0.1:1?iface=lo"], &[])),
            ConfigBuildError::EndpointOptions(_)
        ));
        assert!(matches!(
            err(plan(&["127.0.0.1:1"], &[])),
            ConfigBuildError::Endpoint { .. }
        ));
        let policy = AccessPolicy::new(&protocol::service::RunId::new("r").unwrap());
        assert!(matches!(
            zenoh_config(&plan(&["tcp/127.0.0.1:1"], &[]), None, Some(&policy)),
            Err(ConfigBuildError::AclWithoutTls)
        ));
    }
}
