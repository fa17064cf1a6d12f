//! An external planner (docs/python.md) played by the test: `fleet run --planner external:0`
//! asks it for UAV 0's decisions over `{run}/uav/0/plan`. Its answers steer the UAV, a
//! malformed answer and a planner that left are refused with a fallback decision, and the run
//! completes without a violation. (The Python package's tests drive the same services from
//! Python.)

use std::time::{Duration, Instant};

use iceoryx2::prelude::SignalHandlingMode;
use protocol::ipc::RunNode;
use protocol::plan::{Answer, REQUEST_MAGIC, Steer, request_arrays};
use serde_json::Value;
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, fleet_run, small_scenario_toml};

/// How the test's planner answers its `n`-th request (from 0) of step `step`.
fn answer(n: u32, step: u64) -> Option<Vec<u8>> {
    let good = Answer {
        steer: Steer::Increments(vec![0.5]),
        poses: vec![[0.0, 0.0, 60.0, 0.5]],
        planner_ns: 1000,
    };
    match n {
        // A valid answer.
        0 | 1 | 3 => Some(good.encode(step, 0)),
        // The answer to another step: refused.
        2 => Some(good.encode(step + 1, 0)),
        // Then the planner leaves.
        _ => None,
    }
}

#[test]
fn an_external_planners_answers_steer_and_bad_or_missing_ones_fall_back() {
    let t = TestRun::new("planner");
    let scenario = t.write("scenario.toml", &small_scenario_toml(30.0));
    let out = t.dir.join("out");
    let mut fleet = ChildGuard::spawn(&mut fleet_run(
        &t,
        &scenario,
        &out,
        &["--strict", "--planner", "external:0"],
    ));
    let run = t.run.clone();
    let planner = std::thread::spawn(move || {
        let node = RunNode::new(&run, "planner", SignalHandlingMode::Disabled).expect("node");
        let deadline = Instant::now() + EXIT_TIMEOUT;
        // The agent creates the service; open it as soon as it is there.
        let service = loop {
            let exists = <protocol::ipc::Ipc as iceoryx2::service::Service>::does_exist(
                &protocol::service::plan(&run, 0),
                node.node().config(),
                iceoryx2::prelude::MessagingPattern::RequestResponse,
            );
            if exists.unwrap_or(false) {
                break node.open_plan(0).expect("plan service");
            }
            assert!(Instant::now() < deadline, "no plan service");
            std::thread::sleep(Duration::from_millis(20));
        };
        let server = service
            .server_builder()
            .initial_max_slice_len(256)
            .allocation_strategy(iceoryx2::prelude::AllocationStrategy::PowerOfTwo)
            .create()
            .expect("server");
        let mut requests = Vec::new();
        while requests.len() < 5 {
            assert!(Instant::now() < deadline, "too few requests");
            let Some(request) = server.receive().expect("receive") else {
                std::thread::sleep(Duration::from_millis(1));
                continue;
            };
            let bytes = request.payload();
            let magic = u32::from_le_bytes(bytes[..4].try_into().unwrap());
            let step = u64::from_le_bytes(bytes[16..24].try_into().unwrap());
            assert_eq!(magic, REQUEST_MAGIC);
            assert!(request_arrays(bytes).is_some(), "a bad array table");
            let n = requests.len() as u32;
            requests.push(step);
            match answer(n, step) {
                Some(reply) => request
                    .loan_slice_uninit(reply.len())
                    .expect("loan")
                    .write_from_slice(&reply)
                    .send()
                    .expect("answer"),
                None => break,
            }
        }
        // Leaving: the server, then the node go; the agent falls back from now on.
        requests
    });
    let done = fleet
        .wait_timeout(EXIT_TIMEOUT)
        .unwrap_or_else(|| panic!("the run did not end within {EXIT_TIMEOUT:?}"));
    let requests = planner.join().expect("the planner thread");
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    assert_eq!(requests.len(), 5, "{requests:?}");
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    let s: Value = serde_json::from_str(&text).expect("JSON");
    assert_eq!(s["violations"], 0, "{s}");
    assert_eq!(s["steps"], 60, "{s}");
    // 10 guidance steps of 3 s: 3 answered, one malformed, then no planner.
    let log = std::fs::read_to_string(out.join("logs/agent-0.log")).expect("log");
    let report: Value = log
        .lines()
        .rev()
        .find(|l| l.starts_with('{') && l.contains("final_undetected_digest"))
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .expect("the agent's report");
    let external = &report["external"];
    assert_eq!(external["asked"], 10, "{external}");
    assert_eq!(external["answered"], 3, "{external}");
    assert_eq!(external["malformed"], 1, "{external}");
    assert_eq!(external["absent"], 6, "{external}");
    assert!(log.contains("answer refused"), "{log}");
    assert_eq!(external["round_trip_ms"]["n"], 3, "{external}");
    // The summary counts them from the agent's estimates (all but the last decision).
    let agent = &s["agents"][0];
    assert_eq!(agent["external_decisions"], 3, "{agent}");
    assert!(
        agent["external_fallbacks"].as_u64().unwrap() >= 6,
        "{agent}"
    );
    assert_eq!(s["agents"][1]["external_decisions"], 0);
    // The answers steered: UAV 0 turned by +0.5 rad per guidance period where it was answered.
    let tracks = std::fs::read_to_string(out.join("tracks.csv")).expect("tracks.csv");
    let yaw = |step: u64| -> f64 {
        let row = tracks
            .lines()
            .find(|l| l.starts_with(&format!("{step},")) && l.split(',').nth(2) == Some("0"))
            .expect("a row of UAV 0");
        row.rsplit(',').next().unwrap().parse().unwrap()
    };
    // The first answer's turn of 0.5 rad (not one of the yaw increments U of the MPC), flown
    // at the yaw-rate bound of 1 rad/s in the first 0.5 s step.
    let turn = (yaw(1) - yaw(0) + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
        - std::f64::consts::PI;
    assert!((turn - 0.5).abs() < 1e-6, "the answered turn: {turn}");
}
