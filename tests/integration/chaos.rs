//! `fleet run --chaos`: runs under a seeded schedule of kills, restarts and pauses (and an
//! explicit pause) complete with the guarantee intact, every agent back within a few steps,
//! and nothing of the run left behind.

use std::process::Command;
use std::time::Duration;

use serde_json::Value;
use tests::{ChildGuard, TestRun, binary, processes_mentioning};

/// Longest a chaos run may take: its pauses stop a lockstep world in real time.
const CHAOS_RUN_TIMEOUT: Duration = Duration::from_secs(300);
/// Steps within which a restarted or resumed agent's estimates must be back.
const MAX_RESYNC_STEPS: u64 = 5;

/// A small, quick scenario: 3 UAVs over a 200 m region, a small camera, 30 s.
const SMALL: [&str; 12] = [
    "--duration",
    "30",
    "--uavs",
    "3",
    "--set",
    "region.half_extent_m=100",
    "--set",
    "targets.count=3",
    "--set",
    "camera.rows=36",
    "--set",
    "camera.cols=48",
];

#[test]
fn chaos_runs_complete_with_agents_back_and_nothing_left() {
    let mut faults_seen = 0;
    let mut kinds = std::collections::BTreeSet::new();
    // Seed 4 under the measurement exchange: a restarted agent rebuilds from its checkpoint
    // and its peers' whole sets, and applies their measurements from then on.
    for seed in 1..=4u64 {
        let t = TestRun::new("chaos");
        let out_dir = t.dir.join("out");
        let seed_text = seed.to_string();
        let mut cmd = Command::new(binary("fleet"));
        cmd.args(["run", "--run-id", t.run.as_str(), "--strict", "--seed"])
            .arg(&seed_text)
            .args(SMALL)
            .args(["--chaos", &seed_text, "--chaos-faults", "8"])
            .arg("--out")
            .arg(&out_dir);
        if seed == 1 {
            // An explicit fault combines with the schedule.
            cmd.args(["--fault", "pause:2@4+2"]);
        }
        if seed == 4 {
            cmd.args(["--set", "comms.exchange=measurements"]);
        }
        let mut fleet = ChildGuard::spawn(&mut cmd);
        let out = fleet
            .wait_timeout(CHAOS_RUN_TIMEOUT)
            .unwrap_or_else(|| panic!("seed {seed}: the chaos run did not end in time"));
        let stderr = String::from_utf8_lossy(&out.stderr);
        // fleet reaps every child before it exits: nothing of the run may be running (or
        // stopped) now.
        let left = processes_mentioning(t.run.as_str());
        assert!(left.is_empty(), "seed {seed}: processes left: {left:?}");
        assert!(
            t.ipc_files().is_empty(),
            "seed {seed}: files left: {:?}",
            t.ipc_files()
        );
        assert!(out.status.success(), "seed {seed}: {stderr}");
        let text = std::fs::read_to_string(out_dir.join("summary.json")).expect("summary.json");
        let s: Value = serde_json::from_str(&text).expect("summary.json is JSON");
        assert_eq!(s["interrupted"], false, "seed {seed}: {stderr}");
        assert_eq!(s["steps"], 60, "seed {seed}: the run ended early: {stderr}");
        assert_eq!(s["violations"], 0, "seed {seed}");
        assert_eq!(s["timing"]["leftover_ipc_files"], 0, "seed {seed}");
        assert_eq!(s["chaos_seed"], seed, "seed {seed}");
        let faults = s["faults"].as_array().expect("faults");
        let chaos = faults.iter().filter(|f| f["origin"] == "chaos").count();
        assert_eq!(chaos, 8, "seed {seed}: {faults:?}");
        let mut worst = 0;
        for f in faults {
            let kind = f["kind"].as_str().expect("kind");
            kinds.insert(kind.to_owned());
            assert_eq!(
                f["effective"], true,
                "seed {seed}: not applied: {f}\n{stderr}"
            );
            assert!(f["applied_at_step"].is_u64(), "seed {seed}: {f}");
            if kind == "pause" {
                assert!(f["pause_s"].as_f64().is_some_and(|p| p > 0.0), "{f}");
                assert!(
                    f["resumed_at_step"].is_u64(),
                    "seed {seed}: a paused agent was not continued: {f}\n{stderr}"
                );
            }
            if kind == "restart" || kind == "pause" {
                let resync = f["resync_steps"].as_u64().unwrap_or_else(|| {
                    panic!("seed {seed}: the agent never came back: {f}\n{stderr}")
                });
                assert!(
                    resync <= MAX_RESYNC_STEPS,
                    "seed {seed}: back after {resync} steps: {f}\n{stderr}"
                );
                worst = worst.max(resync);
            }
        }
        assert_eq!(s["resync_steps_max"], worst, "seed {seed}");
        faults_seen += faults.len();
    }
    assert!(faults_seen >= 20, "only {faults_seen} faults");
    for kind in ["kill", "restart", "pause"] {
        assert!(kinds.contains(kind), "no {kind} in {kinds:?}");
    }
}

#[test]
fn a_pause_ends_with_its_agent_or_with_the_run() {
    let t = TestRun::new("chaos-pauses");
    let out_dir = t.dir.join("out");
    let mut small = SMALL.to_vec();
    small[1] = "10";
    small[3] = "2";
    // Agent 1 is stopped for 30 s, killed while stopped and restarted; agent 0 is stopped for
    // a minute, past the end of the run.
    let faults = ["pause:1@2+30", "kill:1@3", "restart:1@5", "pause:0@6+60"];
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["run", "--run-id", t.run.as_str(), "--strict"])
        .args(small)
        .arg("--out")
        .arg(&out_dir);
    for f in faults {
        cmd.args(["--fault", f]);
    }
    let mut fleet = ChildGuard::spawn(&mut cmd);
    let out = fleet
        .wait_timeout(CHAOS_RUN_TIMEOUT)
        .expect("the run did not end in time");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let left = processes_mentioning(t.run.as_str());
    assert!(left.is_empty(), "processes left: {left:?}");
    assert!(t.ipc_files().is_empty(), "files left: {:?}", t.ipc_files());
    assert!(out.status.success(), "{stderr}");
    let text = std::fs::read_to_string(out_dir.join("summary.json")).expect("summary.json");
    let s: Value = serde_json::from_str(&text).expect("summary.json is JSON");
    assert_eq!(s["interrupted"], false, "{stderr}");
    assert_eq!(s["steps"], 20, "{stderr}");
    assert_eq!(s["violations"], 0);
    assert_eq!(s["chaos_seed"], Value::Null);
    let f = s["faults"].as_array().expect("faults");
    let kinds: Vec<&str> = f
        .iter()
        .map(|f| f["kind"].as_str().expect("kind"))
        .collect();
    assert_eq!(kinds, ["pause", "kill", "restart", "pause"], "{s}");
    assert!(f.iter().all(|f| f["effective"] == true), "{s}");
    assert!(f.iter().all(|f| f["origin"] == "explicit"), "{s}");
    // The killed process never got its SIGCONT; its successor was not sent one.
    assert_eq!(f[0]["resumed_at_step"], Value::Null, "{s}");
    assert_eq!(f[0]["resync_steps"], Value::Null, "{s}");
    let back = f[2]["resync_steps"]
        .as_u64()
        .expect("the restarted agent came back");
    assert!(back <= MAX_RESYNC_STEPS, "{s}");
    // The long pause was ended by the end of the run, at its last step.
    assert_eq!(f[3]["pause_s"], 60.0, "{s}");
    assert_eq!(f[3]["resumed_at_step"], 19, "{s}\n{stderr}");
    assert!(stderr.contains("agent 1 ended while paused"), "{stderr}");
}
