//! `fleet run --hosts N`: the processes spread over simulated hosts (own iceoryx2 domains)
//! joined by the Zenoh bridges; the same results as on one host, and faults across hosts.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use serde_json::Value;
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, processes_mentioning, wait_until};

/// A small 4-UAV scenario (every host gets an agent with up to 4 hosts).
fn scenario(duration_s: f64) -> String {
    format!(
        "seed = 5\nduration_s = {duration_s}\n\n[region]\nhalf_extent_m = 100.0\n\n\
         [targets]\ncount = 4\n\n[uavs]\ncount = 4\n\n[camera]\nrows = 120\ncols = 160\n"
    )
}

/// `fleet run --strict` of the test's scenario.
fn fleet_run(t: &TestRun, scenario: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut cmd = tests::fleet_run(t, scenario, out, &["--strict"]);
    cmd.args(extra);
    cmd
}

/// Runs to the end (bounded); checks that no process and no file of any host is left.
fn finish(t: &TestRun, mut fleet: ChildGuard) -> Output {
    let out = fleet
        .wait_timeout(EXIT_TIMEOUT)
        .expect("fleet run did not end in time");
    wait_until(
        "the run's processes to exit",
        Duration::from_secs(10),
        || processes_mentioning(t.run.as_str()).is_empty(),
    );
    assert!(t.ipc_files().is_empty(), "files left: {:?}", t.ipc_files());
    out
}

fn summary(out: &Path) -> Value {
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

/// A bridge's report: the one JSON line of its log. The bridge prints it on stdout when it
/// stops, and Zenoh's threads may still log to stderr (the same file) after it, so it is not
/// always the last line.
fn bridge_report(out: &Path, host: u16) -> Value {
    let log =
        std::fs::read_to_string(out.join(format!("logs/bridge-h{host}.log"))).expect("bridge log");
    let mut reports = log.lines().filter(|line| line.starts_with('{'));
    let report = reports
        .next()
        .unwrap_or_else(|| panic!("no report in the bridge's log:\n{log}"));
    assert!(reports.next().is_none(), "two reports in:\n{log}");
    serde_json::from_str(report).unwrap_or_else(|e| panic!("bridge report {report:?}: {e}"))
}

/// The world-server's report: the JSON line that ends its log.
fn world_report(out: &Path) -> Value {
    let log = std::fs::read_to_string(out.join("logs/world.log")).expect("world log");
    let report = log
        .lines()
        .rfind(|line| line.starts_with('{'))
        .unwrap_or_else(|| panic!("no report in the world's log:\n{log}"));
    serde_json::from_str(report).unwrap_or_else(|e| panic!("world report {report:?}: {e}"))
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Runs the 10 s scenario on `hosts` simulated hosts with `extra` flags to its end; checks
/// that it ran every step without a violation and that every bridge forwarded and refused
/// nothing of the fleet's; returns its `timeseries.csv` and summary.
fn run_on_hosts(hosts: u16, extra: &[&str]) -> (String, Value) {
    let t = TestRun::new(&format!("hosts-{hosts}"));
    let file = t.write("scenario.toml", &scenario(10.0));
    let out_dir = t.dir.join("out");
    let n = hosts.to_string();
    let args = [&["--hosts", n.as_str()][..], extra].concat();
    let out = finish(
        &t,
        ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, &args)),
    );
    assert!(out.status.success(), "{hosts} hosts: {}", stderr(&out));
    let s = summary(&out_dir);
    assert_eq!(s["violations"], 0, "{s}");
    assert_eq!(s["hosts"].as_u64(), Some(u64::from(hosts)), "{s}");
    for a in s["agents"].as_array().expect("agents") {
        assert_eq!(a["steps_processed"], 20, "{hosts} hosts: {a}");
    }
    // No agent was ever taken for dead: each one's hello and messages reached the world after
    // its proxy existed.
    let world = world_report(&out_dir);
    for a in world["agents"].as_array().expect("world's agents") {
        assert_eq!((&a["deaths"], &a["misses"]), (&0.into(), &0.into()), "{a}");
    }
    // One host runs no bridge.
    let bridges = if hosts > 1 { hosts } else { 0 };
    for host in 0..bridges {
        let r = bridge_report(&out_dir, host);
        assert_eq!(r["refused"], serde_json::json!({}), "host {host}: {r}");
        assert_eq!(r["unannounced"], 0, "host {host}: {r}");
        assert!(
            r["received"]["estimate"]["messages"].as_u64() > Some(0),
            "host {host}: {r}"
        );
        // Each agent host got its agents' frames over Zenoh, and none of the other hosts'
        // state messages: those are the observer's, which runs on host 0, which gets them.
        if host > 0 {
            assert!(
                r["received"]["frame"]["messages"].as_u64() >= Some(20),
                "{r}"
            );
            assert_eq!(r["received"].get("state"), None, "host {host}: {r}");
        } else {
            assert!(
                r["received"]["state"]["messages"].as_u64() >= Some(20),
                "host {host}: {r}"
            );
        }
    }
    let csv = std::fs::read_to_string(out_dir.join("timeseries.csv")).expect("csv");
    (csv, s)
}

/// Over the default links (QUIC with the run's certificates and access control) and over plain
/// loopback TCP (`--insecure-links`).
#[test]
fn two_and_four_hosts_give_the_results_of_one_host_byte_for_byte() {
    let (one, _) = run_on_hosts(1, &[]);
    let cases: [(u16, &[&str]); 3] = [(2, &[]), (4, &[]), (2, &["--insecure-links"])];
    for (hosts, links) in cases {
        let (csv, _) = run_on_hosts(hosts, links);
        assert_eq!(
            one, csv,
            "{hosts} hosts {links:?}: timeseries.csv differs from 1 host"
        );
    }
}

/// The radios lose the same messages whether two agents share a host or not: the draw is the
/// receiver's, from the seed, and the bridges deliver every message (lost ones included) in
/// order.
#[test]
fn lossy_slow_radios_give_the_same_results_on_one_host_and_on_two() {
    let radio = ["--set", "comms.loss=0.3", "--set", "comms.latency_ms=700"];
    let (one, s) = run_on_hosts(1, &radio);
    let lost: u64 = s["agents"]
        .as_array()
        .expect("agents")
        .iter()
        .map(|a| a["estimates_lost"].as_u64().expect("estimates_lost"))
        .sum();
    assert!(lost > 0, "the radio lost nothing: {s}");
    let (two, _) = run_on_hosts(2, &radio);
    assert_eq!(one, two, "2 hosts: timeseries.csv differs from 1 host");
}

#[test]
fn an_agent_killed_and_restarted_on_another_host_rejoins() {
    let t = TestRun::new("hosts-fault");
    let file = t.write("scenario.toml", &scenario(20.0));
    let out_dir = t.dir.join("out");
    // UAV 3 runs on host 1 of 2: its death and restart cross the bridge as liveliness.
    let args = [
        "--hosts",
        "2",
        "--fault",
        "kill:3@4",
        "--fault",
        "restart:3@8",
    ];
    let out = finish(
        &t,
        ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, &args)),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let s = summary(&out_dir);
    assert_eq!(s["violations"], 0, "{s}");
    let agents = s["agents"].as_array().expect("agents");
    assert_eq!(agents[3]["restarts"], 1, "{s}");
    // UAV 3's neighbour on host 1 lived through it and answered every frame it was served:
    // all 40, unless the world reports that it missed an ack deadline (7 s: a loaded machine)
    // and stopped serving it until its late answer came.
    let world = world_report(&out_dir);
    let survivor = &world["agents"][2];
    assert_eq!(survivor["deaths"], 0, "{world}");
    let served =
        survivor["acks"].as_u64().expect("acks") + survivor["misses"].as_u64().expect("misses");
    assert_eq!(
        agents[2]["steps_processed"].as_u64(),
        Some(served),
        "{world}\n{s}"
    );
    if survivor["misses"] == 0 {
        assert_eq!(served, 40, "{world}");
    }
    assert_eq!(agents[2]["final_measured_step"], 39, "{s}");
    let processed = agents[3]["steps_processed"].as_u64().expect("steps");
    // Alive 0-4 s and 8-20 s, less the restart's start-up.
    assert!((28..40).contains(&processed), "{s}");
    // The world host saw the death through the bridge and made a new proxy at the restart.
    let r = bridge_report(&out_dir, 0);
    assert!(r["proxies_created"].as_u64() >= Some(3), "{r}");
}

/// A free UDP port on the loopback, for QUIC.
fn free_port() -> u16 {
    let socket = std::net::UdpSocket::bind(("127.0.0.1", 0)).expect("a free port");
    socket.local_addr().expect("its address").port()
}

/// An intruder's session to the world host's bridge at `port`: QUIC that trusts the fleet's
/// authority (its certificate is public), presenting `identity` (a certificate and key of
/// another authority) or no certificate at all.
fn intruder_config(port: u16, ca: &Path, identity: Option<&Path>) -> zenoh::Config {
    let mut config = zenoh::Config::default();
    let mut set = |key: &str, value: Value| {
        config
            .insert_json5(key, &value.to_string())
            .unwrap_or_else(|e| panic!("{key}: {e}"));
    };
    set("mode", serde_json::json!("peer"));
    set(
        "connect/endpoints",
        serde_json::json!([format!("quic/127.0.0.1:{port}")]),
    );
    set("listen/endpoints", serde_json::json!([]));
    set("scouting/multicast/enabled", serde_json::json!(false));
    set(
        "transport/link/tls/root_ca_certificate",
        serde_json::json!(ca),
    );
    match identity {
        Some(dir) => {
            set("transport/link/tls/enable_mtls", serde_json::json!(true));
            set(
                "transport/link/tls/connect_certificate",
                serde_json::json!(dir.join("h1.pem")),
            );
            set(
                "transport/link/tls/connect_private_key",
                serde_json::json!(dir.join("h1.key")),
            );
        }
        None => set("transport/link/tls/enable_mtls", serde_json::json!(false)),
    }
    config
}

/// What an intruder forges: an estimate, a state message and a token of UAV 0 and the end of
/// the run, each a well-formed envelope, as a peer would send them.
fn forgeries(run: &protocol::service::RunId) -> Vec<(String, Vec<u8>)> {
    use protocol::wire::{WireHeader, WireKind};
    let mut out = Vec::new();
    for (key, kind) in [
        (bridge::keys::estimate(run, 0), WireKind::Estimate),
        (bridge::keys::state(run, 0), WireKind::State),
        (bridge::keys::token(run, 0), WireKind::Token),
    ] {
        let payload = [0u8; 16];
        let header = WireHeader::new(kind, run.tag(), 0, 1, payload.len() as u32, 0);
        let mut bytes = Vec::new();
        bridge::envelope::encode_wire(&header, &payload, &mut bytes);
        out.push((key, bytes));
    }
    out.push((bridge::keys::end_of_run(run), Vec::new()));
    out
}

#[test]
fn intruders_without_the_fleets_certificate_are_refused_and_reach_nobody() {
    use zenoh::Wait;
    let t = TestRun::new("hosts-intruder");
    let file = t.write("scenario.toml", &scenario(10.0));
    let out_dir = t.dir.join("out");
    let port = free_port();
    let listen = format!("quic/127.0.0.1:{port}");
    // In real time (10 s of wall clock for the 10 s scenario) the run outlasts the intruders'
    // first attempts by seconds; in lockstep it could end before they connect.
    let mut fleet = ChildGuard::spawn(&mut fleet_run(
        &t,
        &file,
        &out_dir,
        &[
            "--hosts",
            "2",
            "--listen",
            &listen,
            "--mode",
            "realtime",
            "--speedup",
            "1",
        ],
    ));
    let ca = out_dir.join("certs/ca.pem");
    wait_until("the run's certificates", EXIT_TIMEOUT, || ca.exists());
    // The world host's bridge listens once its session is open: an attempt before that would
    // wait out a QUIC handshake to a closed port.
    let world_bridge_log = out_dir.join("logs/bridge-h0.log");
    wait_until("the world host's bridge to listen", EXIT_TIMEOUT, || {
        std::fs::read_to_string(&world_bridge_log).is_ok_and(|l| l.contains("Zenoh session open"))
    });
    // An impostor: a certificate that claims host h1 from an authority of its own.
    let impostor = t.dir.join("impostor");
    let authority = bridge::security::FleetAuthority::generate("impostor").expect("authority");
    let h1 = bridge::security::HostName::new("h1").expect("name");
    let id = authority
        .issue_host(&h1, &[])
        .expect("the impostor's certificate");
    std::fs::create_dir_all(&impostor).expect("impostor dir");
    std::fs::write(impostor.join("h1.pem"), &id.cert_pem).expect("cert");
    std::fs::write(impostor.join("h1.key"), &id.key_pem).expect("key");
    let sessions: Vec<zenoh::Session> = [None, Some(impostor.as_path())]
        .into_iter()
        .map(|identity| {
            zenoh::open(intruder_config(port, &ca, identity))
                .wait()
                .expect("an intruder's session opens (it has no link yet)")
        })
        .collect();
    // Forge for as long as the run lasts: every attempt to connect is refused.
    let forged = forgeries(&t.run);
    let mut attempts_while_live = 0;
    while fleet.is_running() {
        for s in &sessions {
            for (key, bytes) in &forged {
                let _ = s.put(key, bytes.clone()).wait();
            }
        }
        if fleet.is_running() {
            attempts_while_live += 1;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(
        attempts_while_live > 0,
        "the run ended before the intruders tried"
    );
    for s in sessions {
        assert_eq!(
            s.info().routers_zid().wait().count() + s.info().peers_zid().wait().count(),
            0,
            "an intruder got a link"
        );
    }
    let out = finish(&t, fleet);
    assert!(out.status.success(), "{}", stderr(&out));
    let s = summary(&out_dir);
    assert_eq!(s["violations"], 0, "{s}");
    // A forged end of run would have ended it early.
    assert_eq!(s["steps"], 20, "{s}");
    // A forged estimate or token is malformed (16 zero bytes): an agent that got one would
    // have logged its drop as such.
    for uav in 0..4 {
        let log = std::fs::read_to_string(out_dir.join(format!("logs/agent-{uav}.log")))
            .expect("agent log");
        assert!(
            !log.contains("reason=Malformed"),
            "a forgery reached agent {uav}"
        );
    }
    for host in 0..2 {
        let r = bridge_report(&out_dir, host);
        assert_eq!(r["refused"], serde_json::json!({}), "host {host}: {r}");
        assert_eq!(r["unannounced"], 0, "host {host}: {r}");
    }
    // The world host's bridge logged each refusal.
    let log = std::fs::read_to_string(&world_bridge_log).expect("log");
    for refusal in [
        "peer sent no certificates",
        "invalid peer certificate: UnknownIssuer",
    ] {
        assert!(
            log.lines().any(|l| l.contains(refusal)),
            "no {refusal:?} in the world host's bridge log"
        );
    }
}
