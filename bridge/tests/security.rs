//! The bridge's security end to end, on loopback: certificates made at test time in a temp
//! dir, real Zenoh sessions over each secure protocol (QUIC and TLS over TCP, both with the
//! fleet's certificates), each test on its own port.
//!
//! Absence is never inferred from waiting: a forged message is sent *before* a legitimate
//! marker on the same link, so once the marker has arrived the forgery had its chance; an
//! intruder's refusal is read in the listener's log, then its session is seen to have no link.

use std::fs;
use std::io::{self, Write};
use std::net::{TcpListener, UdpSocket};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use bridge::keys;
use bridge::security::{
    AccessPolicy, CertWriteError, FleetAuthority, HostName, HostNameError, HostTlsFiles, LinkMode,
    LinkPlan, SECURE_PROTOCOLS, TlsFilesError, add_host_cert, write_fleet_certs, zenoh_config,
};
use protocol::service::RunId;
use zenoh::Wait;
use zenoh::qos::CongestionControl;
use zenoh::sample::Sample;

/// Longest wait for anything that should happen; it normally takes milliseconds.
const DEADLINE: Duration = Duration::from_secs(15);
const POLL: Duration = Duration::from_millis(20);

// ---------------------------------------------------------------------------------------------
// Harness

/// A directory removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> Self {
        static COUNT: AtomicUsize = AtomicUsize::new(0);
        let path = std::env::temp_dir().join(format!(
            "setfleet-bridge-security-{}-{tag}-{}",
            std::process::id(),
            COUNT.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = fs::remove_dir_all(&path);
        Self(path)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

/// An endpoint of `protocol` on a loopback port nothing uses now (UDP for QUIC, TCP for TLS).
fn free_endpoint(protocol: &str) -> String {
    let port = if protocol == "quic" {
        let socket = UdpSocket::bind("127.0.0.1:0").expect("a free loopback port");
        socket.local_addr().expect("a bound address").port()
    } else {
        let listener = TcpListener::bind("127.0.0.1:0").expect("a free loopback port");
        listener.local_addr().expect("a bound address").port()
    };
    format!("{protocol}/127.0.0.1:{port}")
}

/// The Zenoh crate that logs a link's refusals.
fn link_crate(protocol: &str) -> &'static str {
    match protocol {
        "quic" => "zenoh_link_commons::quic",
        _ => "zenoh_link_tls",
    }
}

/// Everything Zenoh logs at WARN and above, for every test of this binary.
#[derive(Clone)]
struct LogBuffer(Arc<Mutex<Vec<u8>>>);

impl Write for LogBuffer {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0
            .lock()
            .expect("the log buffer")
            .extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

fn logs() -> &'static LogBuffer {
    static LOGS: OnceLock<LogBuffer> = OnceLock::new();
    LOGS.get_or_init(|| {
        let buffer = LogBuffer(Arc::new(Mutex::new(Vec::new())));
        let writer = buffer.clone();
        tracing_subscriber::fmt()
            .with_env_filter("warn")
            .with_ansi(false)
            .with_writer(move || writer.clone())
            .init();
        buffer
    })
}

/// The first log line holding every one of `needles`.
fn find_log(needles: &[&str]) -> Option<String> {
    let text = String::from_utf8_lossy(&logs().0.lock().expect("the log buffer")).into_owned();
    text.lines()
        .find(|l| needles.iter().all(|n| l.contains(n)))
        .map(str::to_owned)
}

/// A fleet as the bridge lays it out: the world host is the router (and relay), agents `h1`
/// (UAV 1) and `h2` (UAV 2) are its clients; certificates in a temp dir; the router's
/// endpoint.
struct Fleet {
    dir: TempDir,
    endpoint: String,
    run: RunId,
    world: HostName,
    h1: HostName,
    h2: HostName,
    policy: AccessPolicy,
}

impl Fleet {
    /// A fleet whose links use `protocol` (`quic` or `tls`).
    fn new(tag: &str, protocol: &str) -> Self {
        let tag = format!("{tag}-{protocol}");
        let dir = TempDir::new(&tag);
        let hosts = ["world", "h1", "h2"].map(str::to_owned);
        write_fleet_certs(&dir.0, &hosts, &[], false).expect("the fleet's certificates");
        let run = RunId::new(&tag).expect("a valid run id");
        let [world, h1, h2] = hosts.map(|h| HostName::new(&h).expect("a valid host name"));
        let policy = AccessPolicy::new(&run)
            .world_host(&world)
            .and_then(|p| p.relay_host(&world).agent_host(&h1, &[1]))
            .and_then(|p| p.agent_host(&h2, &[2]))
            .expect("a valid policy");
        Self {
            dir,
            endpoint: free_endpoint(protocol),
            run,
            world,
            h1,
            h2,
            policy,
        }
    }

    fn files(&self, host: &HostName) -> HostTlsFiles {
        HostTlsFiles::in_dir(&self.dir.0, host)
    }

    /// The world host's router, listening on the fleet's endpoint, with the fleet's ACL.
    fn router(&self) -> zenoh::Session {
        let plan = LinkPlan {
            mode: LinkMode::Router,
            listen: vec![self.endpoint.clone()],
            connect: vec![],
        };
        open(
            zenoh_config(&plan, Some(&self.files(&self.world)), Some(&self.policy))
                .expect("the router's configuration"),
        )
    }

    /// A client of the router, with the fleet's ACL or, as a compromised host would run, none.
    fn client(&self, host: &HostName, acl: bool) -> zenoh::Session {
        let acl = acl.then_some(&self.policy);
        open(
            zenoh_config(&client(&self.endpoint), Some(&self.files(host)), acl)
                .expect("a client's configuration"),
        )
    }
}

fn client(endpoint: &str) -> LinkPlan {
    LinkPlan {
        mode: LinkMode::Client,
        listen: vec![],
        connect: vec![endpoint.to_owned()],
    }
}

fn open(config: zenoh::Config) -> zenoh::Session {
    zenoh::open(config).wait().expect("the session opens")
}

fn put(session: &zenoh::Session, key: &str, payload: &str) {
    session
        .put(key, payload)
        .congestion_control(CongestionControl::Block)
        .wait()
        .expect("the put is sent");
}

fn text(sample: &Sample) -> String {
    String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned()
}

type Receiver = zenoh::handlers::FifoChannelHandler<Sample>;

/// Puts `payload` on `key` from `sender` until every receiver got it (the first puts are lost
/// while links and subscriptions are being set up); returns what each received meanwhile.
fn put_until_received(
    sender: &zenoh::Session,
    key: &str,
    payload: &str,
    receivers: &[&Receiver],
) -> Vec<Vec<String>> {
    let start = Instant::now();
    let mut seen = vec![Vec::new(); receivers.len()];
    let mut done = vec![false; receivers.len()];
    while start.elapsed() < DEADLINE {
        put(sender, key, payload);
        std::thread::sleep(POLL);
        for ((receiver, seen), done) in receivers.iter().zip(&mut seen).zip(&mut done) {
            while let Some(sample) = receiver.try_recv().expect("the subscriber is alive") {
                *done |= sample.key_expr().as_str() == key && text(&sample) == payload;
                seen.push(format!("{} {}", sample.key_expr(), text(&sample)));
            }
        }
        if done.iter().all(|d| *d) {
            return seen;
        }
    }
    panic!("{payload:?} on {key} never arrived everywhere; got {seen:?}");
}

/// Receives until `key` brings `payload`; returns everything received, marker included.
fn receive_until(receiver: &Receiver, key: &str, payload: &str) -> Vec<String> {
    let start = Instant::now();
    let mut seen = Vec::new();
    while start.elapsed() < DEADLINE {
        if let Some(sample) = receiver
            .recv_timeout(POLL)
            .expect("the subscriber is alive")
        {
            seen.push(format!("{} {}", sample.key_expr(), text(&sample)));
            if sample.key_expr().as_str() == key && text(&sample) == payload {
                return seen;
            }
        }
    }
    panic!("{payload:?} on {key} never arrived; got {seen:?}");
}

/// The routers and peers `session` has a link to.
fn links(session: &zenoh::Session) -> usize {
    session.info().routers_zid().wait().count() + session.info().peers_zid().wait().count()
}

// ---------------------------------------------------------------------------------------------
// Links

/// The production configuration (mutual TLS and the ACL on both hosts) lets the fleet's
/// traffic through in both directions; the agent's certificate is issued later by the
/// authority reloaded from `ca.pem` and `ca.key`.
#[test]
fn fleet_hosts_with_mutual_tls_exchange_puts_both_ways() {
    for protocol in SECURE_PROTOCOLS {
        let dir = TempDir::new(&format!("mtls-{protocol}"));
        write_fleet_certs(&dir.0, &["world".to_owned()], &[], false).unwrap();
        add_host_cert(&dir.0, "h1", &[], false).unwrap();
        let run = RunId::new("mtls").unwrap();
        let world = HostName::new("world").unwrap();
        let h1 = HostName::new("h1").unwrap();
        let policy = AccessPolicy::new(&run)
            .world_host(&world)
            .unwrap()
            .relay_host(&world)
            .agent_host(&h1, &[1])
            .unwrap();
        let endpoint = free_endpoint(protocol);
        let router = LinkPlan {
            mode: LinkMode::Router,
            listen: vec![endpoint.clone()],
            connect: vec![],
        };
        let world_files = HostTlsFiles::in_dir(&dir.0, &world);
        let h1_files = HostTlsFiles::in_dir(&dir.0, &h1);

        let world_session = open(zenoh_config(&router, Some(&world_files), Some(&policy)).unwrap());
        let h1_session =
            open(zenoh_config(&client(&endpoint), Some(&h1_files), Some(&policy)).unwrap());
        let estimates = world_session
            .declare_subscriber(keys::estimate(&run, 1))
            .wait()
            .unwrap();
        let frames = h1_session
            .declare_subscriber(keys::frame(&run, 1))
            .wait()
            .unwrap();

        put_until_received(
            &h1_session,
            &keys::estimate(&run, 1),
            "estimate",
            &[&estimates],
        );
        put_until_received(&world_session, &keys::frame(&run, 1), "frame", &[&frames]);
    }
}

/// The TLS settings zenoh_config writes: the host's files on both sides of a link, mutual
/// authentication, name verification, the endpoint's protocol only (QUIC and TLS over TCP
/// read the same settings).
#[test]
fn tls_config_presents_the_host_certificate_both_ways() {
    for protocol in SECURE_PROTOCOLS {
        let fleet = Fleet::new("tlsconf", protocol);
        let files = fleet.files(&fleet.h1);
        let config =
            zenoh_config(&client(&fleet.endpoint), Some(&files), Some(&fleet.policy)).unwrap();
        let get = |key: &str| config.get_json(&format!("transport/link/{key}")).unwrap();
        let quoted = |path: &Path| serde_json::json!(path).to_string();
        assert_eq!(get("tls/root_ca_certificate"), quoted(&files.ca));
        assert_eq!(get("tls/listen_certificate"), quoted(&files.cert));
        assert_eq!(get("tls/connect_certificate"), quoted(&files.cert));
        assert_eq!(get("tls/listen_private_key"), quoted(&files.key));
        assert_eq!(get("tls/connect_private_key"), quoted(&files.key));
        assert_eq!(get("tls/enable_mtls"), "true");
        assert_eq!(get("tls/verify_name_on_connect"), "true");
        assert_eq!(get("protocols"), format!("[{protocol:?}]"));
        assert_eq!(
            config
                .get_json("access_control/default_permission")
                .unwrap(),
            r#""deny""#
        );
        let tcp = LinkPlan {
            mode: LinkMode::Client,
            listen: vec![],
            connect: vec!["tcp/127.0.0.1:7447".to_owned()],
        };
        assert!(zenoh_config(&tcp, Some(&files), None).is_err());
    }
    let fleet = Fleet::new("mixed", "quic");
    let mixed = LinkPlan {
        mode: LinkMode::Router,
        listen: vec![fleet.endpoint.clone()],
        connect: vec!["tls/127.0.0.1:7447".to_owned()],
    };
    let err = zenoh_config(&mixed, Some(&fleet.files(&fleet.world)), None).unwrap_err();
    assert!(err.to_string().contains("different protocols"), "{err}");
}

/// Opens a stranger that dials the fleet's router with settings of its own, puts on a key the
/// world listens to until the router logs `refusal`, and checks that the stranger never got a
/// link and nothing it put arrived, while a fleet host's puts did.
fn intruder_is_refused(
    tag: &str,
    protocol: &str,
    intruder: impl FnOnce(&Fleet) -> zenoh::Config,
    refusal: &str,
) {
    logs();
    let fleet = Fleet::new(tag, protocol);
    let world = fleet.router();
    let estimates = world
        .declare_subscriber(keys::estimate(&fleet.run, 1))
        .wait()
        .expect("a subscriber");
    let h1 = fleet.client(&fleet.h1, true);
    put_until_received(
        &h1,
        &keys::estimate(&fleet.run, 1),
        "from h1",
        &[&estimates],
    );

    // A peer retries its connection in the background, so the stranger keeps trying.
    let stranger = open(intruder(&fleet));
    let start = Instant::now();
    let mut line = None;
    while line.is_none() && start.elapsed() < DEADLINE {
        put(&stranger, &keys::estimate(&fleet.run, 1), "forged");
        std::thread::sleep(POLL);
        line = find_log(&[link_crate(protocol), refusal]);
    }
    let line = line.unwrap_or_else(|| {
        let logged =
            String::from_utf8_lossy(&logs().0.lock().expect("the log buffer")).into_owned();
        panic!("the router never logged {refusal:?} ({protocol}); it logged:\n{logged}")
    });
    assert!(line.contains("WARN"), "{line}");
    eprintln!("the router logged: {line}");

    assert_eq!(links(&stranger), 0, "the stranger has a link");
    put(&stranger, &keys::estimate(&fleet.run, 1), "forged");
    let seen = put_until_received(
        &h1,
        &keys::estimate(&fleet.run, 1),
        "from h1 again",
        &[&estimates],
    );
    assert!(seen[0].iter().all(|s| !s.contains("forged")), "{seen:?}");
}

fn stranger_plan(endpoint: &str) -> LinkPlan {
    LinkPlan {
        mode: LinkMode::Peer,
        listen: vec![],
        connect: vec![endpoint.to_owned()],
    }
}

/// A stranger that trusts the fleet's CA (public) but presents no certificate is refused.
#[test]
fn intruder_without_certificate_cannot_connect() {
    for protocol in SECURE_PROTOCOLS {
        intruder_is_refused(
            "nocert",
            protocol,
            |fleet| {
                // No certificate to give: built by hand, as zenoh_config always presents one.
                let mut config = zenoh::Config::default();
                let ca = fleet.files(&fleet.world).ca;
                for (key, value) in [
                    ("mode", r#""peer""#.to_owned()),
                    (
                        "connect/endpoints",
                        serde_json::json!(stranger_plan(&fleet.endpoint).connect).to_string(),
                    ),
                    ("listen/endpoints", "[]".to_owned()),
                    ("scouting/multicast/enabled", "false".to_owned()),
                    (
                        "transport/link/tls/root_ca_certificate",
                        serde_json::json!(ca).to_string(),
                    ),
                    ("transport/link/tls/enable_mtls", "false".to_owned()),
                ] {
                    config.insert_json5(key, &value).unwrap();
                }
                config
            },
            "peer sent no certificates",
        );
    }
}

/// A stranger with a certificate of another authority is refused, even though its certificate
/// claims a fleet host's name (`h1`) and it trusts the fleet's CA.
#[test]
fn intruder_with_certificate_of_another_authority_cannot_connect() {
    for protocol in SECURE_PROTOCOLS {
        intruder_is_refused(
            "foreign",
            protocol,
            |fleet| {
                let foreign = FleetAuthority::generate("impostor").unwrap();
                let id = foreign.issue_host(&fleet.h1, &[]).unwrap();
                let dir = fleet.dir.0.join("impostor");
                fs::create_dir(&dir).unwrap();
                let files = HostTlsFiles {
                    ca: fleet.files(&fleet.world).ca,
                    cert: dir.join("h1.pem"),
                    key: dir.join("h1.key"),
                };
                fs::write(&files.cert, &id.cert_pem).unwrap();
                fs::write(&files.key, &id.key_pem).unwrap();
                fs::set_permissions(&files.key, fs::Permissions::from_mode(0o600)).unwrap();
                zenoh_config(&stranger_plan(&fleet.endpoint), Some(&files), None).unwrap()
            },
            "invalid peer certificate: UnknownIssuer",
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Access control

/// `h1` (valid fleet certificate, agent of UAV 1, but running without any ACL of its own, as a
/// compromised host would) puts forged messages, then a legitimate marker, on its one link to
/// the router. Returns what the world host (the router's own subscriber) and `h2` (a client,
/// served by the router's relay) received of the whole run.
fn forgeries_received(tag: &str, protocol: &str, acl: bool) -> [Vec<String>; 2] {
    let mut fleet = Fleet::new(tag, protocol);
    if !acl {
        // Nobody checks: ACL off everywhere (zenoh_config takes none).
        fleet.policy = AccessPolicy::new(&fleet.run);
    }
    let world = if acl {
        fleet.router()
    } else {
        let plan = LinkPlan {
            mode: LinkMode::Router,
            listen: vec![fleet.endpoint.clone()],
            connect: vec![],
        };
        open(
            zenoh_config(&plan, Some(&fleet.files(&fleet.world)), None)
                .expect("the router's configuration"),
        )
    };
    let everything = format!("{}/**", keys::run_root(&fleet.run));
    let at_world = world
        .declare_subscriber(&everything)
        .wait()
        .expect("a subscriber");
    let h2 = fleet.client(&fleet.h2, acl);
    let at_h2 = h2
        .declare_subscriber(&everything)
        .wait()
        .expect("a subscriber");
    let h1 = fleet.client(&fleet.h1, false);
    let run = &fleet.run;

    let [mut world_seen, mut h2_seen]: [Vec<String>; 2] =
        put_until_received(&h1, &keys::estimate(run, 1), "legit", &[&at_world, &at_h2])
            .try_into()
            .expect("one list per receiver");
    put(&h1, &keys::estimate(run, 0), "forged estimate of UAV 0");
    put(&h1, &keys::token(run, 0), "forged guidance of UAV 0");
    put(&h1, &keys::estimate(run, 2), "forged estimate of UAV 2");
    put(&h1, &keys::frame(run, 1), "forged frame");
    put(
        &h1,
        &format!("{}/truth", keys::run_root(run)),
        "forged truth",
    );
    put(&h1, &keys::end_of_run(run), "forged end of run");
    put(&h1, &keys::estimate(run, 1), "marker");
    world_seen.extend(receive_until(&at_world, &keys::estimate(run, 1), "marker"));
    h2_seen.extend(receive_until(&at_h2, &keys::estimate(run, 1), "marker"));
    [world_seen, h2_seen]
}

/// The router drops every publication outside the sender's role, so neither its own
/// subscribers nor the other clients get it, and relays the ones inside.
#[test]
fn acl_refuses_publications_outside_the_senders_role() {
    for protocol in SECURE_PROTOCOLS {
        for seen in forgeries_received("acl", protocol, true) {
            assert!(seen.iter().all(|s| !s.contains("forged")), "{seen:?}");
            let legit = format!("setfleet/acl-{protocol}/uav/1/estimate legit");
            assert!(seen.contains(&legit), "{seen:?}");
        }
    }
}

/// Control for the test above: without the ACL the same forgeries arrive, so it is the ACL
/// that stops them, not the way the test sends them.
#[test]
fn without_acl_the_same_forgeries_arrive() {
    for protocol in SECURE_PROTOCOLS {
        for seen in forgeries_received("noacl", protocol, false) {
            for forged in [
                "uav/0/estimate forged estimate of UAV 0",
                "guidance/0 forged guidance of UAV 0",
                "uav/2/estimate forged estimate of UAV 2",
                "uav/1/cvs forged frame",
                "truth forged truth",
                "world/end forged end of run",
            ] {
                let forged = format!("setfleet/noacl-{protocol}/{forged}");
                assert!(seen.contains(&forged), "{forged:?} missing from {seen:?}");
            }
        }
    }
}

/// A host may declare liveliness tokens under its own name only; the router relays its own
/// ones to the other clients. Under its own name it may announce only its own processes.
#[test]
fn acl_refuses_liveliness_tokens_under_another_hosts_name() {
    for protocol in SECURE_PROTOCOLS {
        let fleet = Fleet::new("tokens", protocol);
        let world = fleet.router();
        let all_alive = keys::all_alive(&fleet.run);
        let at_world = world
            .liveliness()
            .declare_subscriber(&all_alive)
            .wait()
            .unwrap();
        let estimates = world
            .declare_subscriber(keys::estimate(&fleet.run, 1))
            .wait()
            .unwrap();
        let h2 = fleet.client(&fleet.h2, true);
        let at_h2 = h2
            .liveliness()
            .declare_subscriber(&all_alive)
            .history(true)
            .wait()
            .unwrap();
        let h1 = fleet.client(&fleet.h1, false);
        put_until_received(&h1, &keys::estimate(&fleet.run, 1), "linked", &[&estimates]);

        let forged = keys::alive(&fleet.run, fleet.world.as_str(), "world");
        let not_its_own = [
            keys::alive(&fleet.run, fleet.h1.as_str(), "world"),
            keys::alive(&fleet.run, fleet.h1.as_str(), "agent-2"),
        ];
        let own = keys::alive(&fleet.run, fleet.h1.as_str(), "agent-1");
        let forged_tokens: Vec<_> = std::iter::once(&forged)
            .chain(&not_its_own)
            .map(|key| h1.liveliness().declare_token(key).wait().unwrap())
            .collect();
        let own_token = h1.liveliness().declare_token(&own).wait().unwrap();
        assert_eq!(receive_until(&at_world, &own, ""), [format!("{own} ")]);
        assert_eq!(receive_until(&at_h2, &own, ""), [format!("{own} ")]);
        drop((forged_tokens, own_token));
    }
}

// ---------------------------------------------------------------------------------------------
// Certificate files

fn mode(path: &Path) -> u32 {
    fs::metadata(path)
        .expect("the file exists")
        .permissions()
        .mode()
        & 0o777
}

#[test]
fn fleet_cert_files_are_written_with_secret_keys() {
    let tmp = TempDir::new("files");
    let dir = tmp.0.join("certs");
    let hosts = ["world", "h1", "h_2"].map(str::to_owned);
    let files = write_fleet_certs(&dir, &hosts, &["10.0.0.1".to_owned()], false).unwrap();

    assert_eq!(mode(&dir), 0o700);
    assert_eq!(files.ca_cert, dir.join("ca.pem"));
    assert_eq!(files.ca_key, dir.join("ca.key"));
    assert_eq!(mode(&files.ca_cert), 0o644);
    assert_eq!(mode(&files.ca_key), 0o600);
    let names: Vec<_> = files.hosts.iter().map(|(h, _)| h.as_str()).collect();
    assert_eq!(names, hosts);
    for (host, tls) in &files.hosts {
        assert_eq!(tls, &HostTlsFiles::in_dir(&dir, host));
        assert_eq!(tls.cert, dir.join(format!("{host}.pem")));
        assert_eq!(mode(&tls.cert), 0o644);
        assert_eq!(mode(&tls.key), 0o600);
        tls.check().unwrap();
    }
    let mut listed: Vec<_> = fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    listed.sort();
    assert_eq!(
        listed,
        [
            "ca.key",
            "ca.pem",
            "h1.key",
            "h1.pem",
            "h_2.key",
            "h_2.pem",
            "world.key",
            "world.pem"
        ]
    );
}

#[test]
fn fleet_cert_files_are_not_overwritten_unless_asked() {
    let tmp = TempDir::new("overwrite");
    let hosts = ["world".to_owned()];
    write_fleet_certs(&tmp.0, &hosts, &[], false).unwrap();
    let ca = fs::read(tmp.0.join("ca.pem")).unwrap();

    let again = write_fleet_certs(&tmp.0, &["h9".to_owned(), "world".to_owned()], &[], false);
    assert!(
        matches!(&again, Err(CertWriteError::Exists(p)) if p.ends_with("ca.pem")),
        "{again:?}"
    );
    assert_eq!(fs::read(tmp.0.join("ca.pem")).unwrap(), ca);
    assert!(
        !tmp.0.join("h9.pem").exists(),
        "nothing is written when refusing"
    );
    assert!(matches!(
        add_host_cert(&tmp.0, "world", &[], false),
        Err(CertWriteError::Exists(p)) if p.ends_with("world.pem")
    ));

    // A replaced key gets mode 0600 back even if someone loosened it.
    fs::set_permissions(tmp.0.join("world.key"), fs::Permissions::from_mode(0o644)).unwrap();
    write_fleet_certs(&tmp.0, &hosts, &[], true).unwrap();
    assert_ne!(fs::read(tmp.0.join("ca.pem")).unwrap(), ca);
    assert_eq!(mode(&tmp.0.join("world.key")), 0o600);

    add_host_cert(&tmp.0, "h3", &[], false).unwrap();
    HostTlsFiles::in_dir(&tmp.0, &HostName::new("h3").unwrap())
        .check()
        .unwrap();
}

#[test]
fn bad_host_lists_are_refused_before_writing() {
    let tmp = TempDir::new("names");
    let write = |hosts: &[&str]| {
        let hosts: Vec<String> = hosts.iter().map(|s| (*s).to_owned()).collect();
        write_fleet_certs(&tmp.0, &hosts, &[], false).unwrap_err()
    };
    assert!(matches!(write(&[]), CertWriteError::NoHosts));
    assert!(matches!(
        write(&["world", "h1.lab"]),
        CertWriteError::HostName {
            source: HostNameError::Character('.'),
            ..
        }
    ));
    assert!(matches!(
        write(&["../x"]),
        CertWriteError::HostName {
            source: HostNameError::Character('.'),
            ..
        }
    ));
    assert!(matches!(
        write(&[""]),
        CertWriteError::HostName {
            source: HostNameError::Length(0),
            ..
        }
    ));
    assert!(matches!(
        write(&[&"h".repeat(41)]),
        CertWriteError::HostName {
            source: HostNameError::Length(41),
            ..
        }
    ));
    assert!(matches!(
        write(&["ca"]),
        CertWriteError::HostName {
            source: HostNameError::Reserved(_),
            ..
        }
    ));
    assert!(matches!(write(&["h1", "H1"]), CertWriteError::DuplicateHost(h) if h == "H1"));
    let err = write(&["world", "h1.lab"]);
    assert_eq!(
        err.to_string(),
        "invalid host name \"h1.lab\": host name may hold only ASCII letters, digits, '-' and '_', got '.'"
    );
    assert!(!tmp.0.exists(), "nothing is written for a bad list");
}

#[test]
fn unusable_tls_files_are_named() {
    let tmp = TempDir::new("check");
    write_fleet_certs(&tmp.0, &["h1".to_owned()], &[], false).unwrap();
    let h1 = HostName::new("h1").unwrap();
    let files = HostTlsFiles::in_dir(&tmp.0, &h1);

    let missing = HostTlsFiles::in_dir(&tmp.0, &HostName::new("h2").unwrap());
    assert!(
        matches!(missing.check(), Err(TlsFilesError::Read { path, .. }) if path.ends_with("h2.pem"))
    );

    fs::set_permissions(&files.key, fs::Permissions::from_mode(0o640)).unwrap();
    let err = files.check().unwrap_err();
    assert!(
        matches!(err, TlsFilesError::KeyPermissions { mode: 0o640, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("chmod 600"), "{err}");
    fs::set_permissions(&files.key, fs::Permissions::from_mode(0o600)).unwrap();

    let swapped = HostTlsFiles {
        cert: files.key.clone(),
        ..files.clone()
    };
    assert!(matches!(
        swapped.check(),
        Err(TlsFilesError::NotPem {
            expected: "certificate",
            ..
        })
    ));
    // zenoh_config checks the files before Zenoh would.
    assert!(zenoh_config(&client(&free_endpoint("quic")), Some(&missing), None).is_err());
    files.check().unwrap();
}
