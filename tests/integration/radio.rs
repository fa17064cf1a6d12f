//! Lossy, slow, range-limited radio links between agents (`comms.loss`, `comms.latency_ms`,
//! `comms.range_m`) in whole lockstep runs: messages are lost, nothing waits for them, the
//! guarantee holds, and the observer measures exactly what each agent fused. (The same seed
//! giving the same results under loss and range is in
//! `run::the_same_seed_in_lockstep_gives_the_same_results`.)

use std::path::Path;
use std::process::Command;

use serde_json::Value;
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, binary};

/// 3 UAVs over the tests' small region, 30 s.
const SCENARIO: &str = "seed = 3\nduration_s = 30.0\n\n[region]\nhalf_extent_m = 100.0\n\n\
                        [targets]\ncount = 4\n\n[uavs]\ncount = 3\n\n[camera]\nrows = 120\n\
                        cols = 160\n";
const STEPS: u64 = 60;

/// Runs `fleet run --strict` with `overrides` to its end (bounded) and returns its summary.
fn run(t: &TestRun, overrides: &[&str]) -> Value {
    let file = t.write("scenario.toml", SCENARIO);
    let out = t.dir.join("out");
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["run", "--strict", "--run-id", t.run.as_str(), "--scenario"])
        .arg(&file)
        .arg("--out")
        .arg(&out);
    for o in overrides {
        cmd.args(["--set", o]);
    }
    let done = ChildGuard::spawn(&mut cmd)
        .wait_timeout(EXIT_TIMEOUT)
        .unwrap_or_else(|| panic!("a lossy run did not end within {EXIT_TIMEOUT:?}"));
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

/// Agent `uav`'s own report: the last JSON line of its log.
fn agent_report(out: &Path, uav: u64) -> Value {
    let log = std::fs::read_to_string(out.join(format!("logs/agent-{uav}.log"))).expect("log");
    let line = log
        .lines()
        .rev()
        .find(|l| l.starts_with('{') && l.contains("final_undetected_digest"))
        .unwrap_or_else(|| panic!("no report in agent {uav}'s log:\n{log}"));
    serde_json::from_str(line).expect("the report is JSON")
}

/// `key` summed over the summary's agents.
fn total(s: &Value, key: &str) -> u64 {
    s["agents"]
        .as_array()
        .expect("agents")
        .iter()
        .map(|a| a[key].as_u64().unwrap_or_else(|| panic!("{key} in {a}")))
        .sum()
}

/// The checks every lossy run passes: all steps run, no violation, and each agent's `X̄`
/// after its last fusion is the one the observer rebuilt for it (the observer draws the same
/// losses and fuses the same estimates).
fn assert_complete_and_exact(t: &TestRun, s: &Value) {
    assert_eq!(s["steps"], STEPS, "{s}");
    assert_eq!(s["violations"], 0, "{s}");
    for a in s["agents"].as_array().expect("agents") {
        assert_eq!(a["steps_processed"], STEPS, "{a}");
        let uav = a["uav"].as_u64().expect("uav");
        let own = agent_report(&t.dir.join("out"), uav);
        assert_eq!(own["final_step"], STEPS - 1, "{own}");
        assert_eq!(a["final_measured_step"], STEPS - 1, "{a}");
        assert_eq!(
            a["final_undetected_digest"], own["final_undetected_digest"],
            "agent {uav}: the observer did not fuse what the agent fused"
        );
        // The summary has the counters of the agent's last estimate, sent before its last
        // step's losses were counted.
        let (summary, report) = (a["estimates_lost"].as_u64(), own["estimates_lost"].as_u64());
        assert!(summary <= report, "{a} / {own}");
    }
}

#[test]
fn lossy_links_lose_messages_never_the_guarantee_and_nothing_waits_for_them() {
    let t = TestRun::new("radio-loss");
    let s = run(&t, &["comms.loss=0.3"]);
    assert_complete_and_exact(&t, &s);
    let sum = |key: &str| total(&s, key);
    let (lost, fused) = (sum("estimates_lost"), sum("estimates_received"));
    // Each agent hears 2 peers at each of the 59 steps its last estimate counts.
    assert_eq!(lost + fused, 3 * 2 * (STEPS - 1), "{s}");
    let share = lost as f64 / (lost + fused) as f64;
    assert!(
        (0.2..0.4).contains(&share),
        "{lost} of {} lost",
        lost + fused
    );
    assert!(sum("tokens_lost") > 0, "{s}");
    // A lost token is its sender's turn passed: no holder was waited out.
    assert_eq!(sum("token_timeouts"), 0, "{s}");
    for a in s["agents"].as_array().expect("agents") {
        assert_eq!(a["decisions"], 10, "one decision per guidance period: {a}");
    }
    // The default links lose nothing.
    let t = TestRun::new("radio-perfect");
    let s = run(&t, &[]);
    assert_complete_and_exact(&t, &s);
    let lost = (total(&s, "estimates_lost"), total(&s, "tokens_lost"));
    assert_eq!(lost, (0, 0), "{s}");
}

#[test]
fn late_estimates_are_fused_late_and_measured_as_fused() {
    let t = TestRun::new("radio-latency");
    // 1.2 s is 3 steps of 0.5 s; half the messages lost too.
    let s = run(&t, &["comms.latency_ms=1200", "comms.loss=0.5"]);
    assert_complete_and_exact(&t, &s);
    let sum = |key: &str| total(&s, key);
    // Lost: those of steps 0..=58; fused: those of steps 0..=55 (3 steps late), delivered.
    let (lost, fused) = (sum("estimates_lost"), sum("estimates_received"));
    assert!(lost > 0 && fused > 0, "{s}");
    assert!(
        lost + fused < 3 * 2 * (STEPS - 1),
        "the last 3 steps are in flight: {s}"
    );
}

/// With `comms.relay_hops`, agents forward the peers' measurements they applied: a
/// measurement the radio lost on one link comes a step later through another agent, and is
/// applied once. The guarantee holds and the observer still measures what each agent holds.
#[test]
fn forwarded_measurements_bring_what_the_radio_lost_and_keep_the_guarantee() {
    let t = TestRun::new("radio-relay");
    let s = run(&t, &["comms.loss=0.5", "comms.relay_hops=1"]);
    assert_complete_and_exact(&t, &s);
    let sum = |key: &str| total(&s, key);
    // Every measurement an agent applied from its sender, it forwards once in its next
    // estimate; some of them are what the radio lost on another link.
    assert_eq!(sum("relayed_sent"), sum("estimates_received"), "{s}");
    assert!(sum("relayed_applied") > 0, "{s}");
    assert!(sum("relayed_applied") <= sum("estimates_lost"), "{s}");
    // Without relaying nothing is forwarded.
    let t = TestRun::new("radio-no-relay");
    let s = run(&t, &["comms.loss=0.5"]);
    let relayed = (total(&s, "relayed_sent"), total(&s, "relayed_applied"));
    assert_eq!(relayed, (0, 0), "{s}");
}

/// Under a limited range the token and whom an agent knows live come only through the radio
/// (`comms.token_range` and `comms.liveness` at their default, `"radio"`): agents out of range
/// of each other read none of each other's tokens and wait for none of them, and the run
/// still ends with every agent deciding in every round, no wait run out and the guarantee
/// kept. The 3 UAVs start 115 m apart (evenly on a circle of radius 66.6 m, the geofence's
/// 0.9), beyond 80 m: in round 0 each decides alone and the radio loses each token to both
/// other agents; they then meet near the centre and part again.
#[test]
fn under_a_limited_range_tokens_and_liveness_come_only_through_the_radio() {
    let t = TestRun::new("radio-range");
    let s = run(&t, &["comms.range_m=80"]);
    assert_complete_and_exact(&t, &s);
    let sum = |key: &str| total(&s, key);
    assert!(sum("tokens_lost") >= 3 * 2, "round 0's tokens: {s}");
    assert_eq!(
        sum("estimates_lost"),
        0,
        "no loss: out of range is not lost: {s}"
    );
    assert!(sum("estimates_received") > 0, "{s}");
    assert_eq!(sum("token_timeouts"), 0, "{s}");
    for a in s["agents"].as_array().expect("agents") {
        assert_eq!(a["decisions"], 10, "one decision per guidance period: {a}");
    }
    // The behaviour before the keys: every token reaches everyone, the world says who is live.
    let t = TestRun::new("radio-range-world");
    let s = run(
        &t,
        &[
            "comms.range_m=80",
            "comms.token_range=unlimited",
            "comms.liveness=world",
        ],
    );
    assert_complete_and_exact(&t, &s);
    assert_eq!(total(&s, "tokens_lost"), 0, "{s}");
    assert_eq!(total(&s, "token_timeouts"), 0, "{s}");
    for a in s["agents"].as_array().expect("agents") {
        assert_eq!(a["decisions"], 10, "{a}");
    }
}
