//! Recovery: a stalled agent resumes, a fleet killed whole resumes from its checkpoints, a bad
//! checkpoint is refused. Every wait here is the product's own bounded wait; the tests
//! assert outcomes, not timings, so a busy machine only makes them slower.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use protocol::ipc::{RunNode, scan_nodes};
use serde_json::Value;
use tests::{
    ChildGuard, EXIT_TIMEOUT, TestRun, binary, processes_mentioning, run_process, wait_until,
};

/// A small scenario with a camera large enough to see and identify cars.
fn scenario(duration_s: f64, uavs: u32) -> String {
    format!(
        "seed = 3\nduration_s = {duration_s}\n\n[region]\nhalf_extent_m = 100.0\n\n\
         [targets]\ncount = 4\n\n[uavs]\ncount = {uavs}\n\n[camera]\nrows = 120\ncols = 160\n"
    )
}

fn process(name: &str, t: &TestRun, scenario: &Path, extra: &[&str]) -> ChildGuard {
    ChildGuard::spawn(run_process(name, t, scenario).args(extra))
}

fn finish(mut child: ChildGuard, what: &str) -> Output {
    child
        .wait_timeout(EXIT_TIMEOUT)
        .unwrap_or_else(|| panic!("{what} did not end within {EXIT_TIMEOUT:?}"))
}

/// The JSON report an agent prints last (on stdout, or in its log).
fn report_in(text: &str, context: &str) -> Value {
    let line = text
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .unwrap_or_default();
    serde_json::from_str(line)
        .unwrap_or_else(|e| panic!("no JSON report ({e}) in {text:?}; {context}"))
}

fn report(out: &Output) -> Value {
    let stderr = String::from_utf8_lossy(&out.stderr);
    report_in(
        &String::from_utf8_lossy(&out.stdout),
        &format!("stderr: {stderr}"),
    )
}

fn alive(t: &TestRun, node: &str) -> bool {
    scan_nodes(&t.run, false).is_ok_and(|s| s.is_alive(node))
}

/// An agent stopped (SIGSTOP) for longer than the world waits for an ack is skipped, then
/// resumes when continued: it rejoins with its late ack and runs to the end of the run. (A
/// wait cut short by SIGCONT once read as a termination request.)
#[test]
fn a_stalled_agent_resumes_and_runs_to_the_end() {
    let t = TestRun::new("stall");
    // Long enough that the world, which runs on without the stopped agent, is still
    // stepping when it is continued (a small scenario steps fast).
    let file = t.write("scenario.toml", &scenario(600.0, 2));
    // The world's own default waits: a world started by hand agrees with its agents.
    let world = process("world-server", &t, &file, &[]);
    let a0 = process("uav-agent", &t, &file, &["--id", "0"]);
    let a1 = process("uav-agent", &t, &file, &["--id", "1"]);
    wait_until("both agents", Duration::from_secs(60), || {
        alive(&t, &RunNode::agent_name(0)) && alive(&t, &RunNode::agent_name(1))
    });
    std::thread::sleep(Duration::from_secs(1));
    // Longer than the world's ack wait (7 s by default): the world skips agent 1 meanwhile.
    a1.signal(libc::SIGSTOP);
    std::thread::sleep(Duration::from_secs(8));
    a1.signal(libc::SIGCONT);
    let r1 = finish(a1, "agent 1");
    let r0 = finish(a0, "agent 0");
    let w = finish(world, "world-server");
    assert!(w.status.success(), "{}", String::from_utf8_lossy(&w.stderr));
    let (r0, r1) = (report(&r0), report(&r1));
    assert_eq!(r1["end"], "EndOfRun", "the stalled agent stopped: {r1}");
    assert_eq!(
        r1["final_step"], 1199,
        "the stalled agent did not catch up: {r1}"
    );
    assert_eq!(r0["frames"], 1200, "the other agent missed steps: {r0}");
    let world_log = String::from_utf8_lossy(&w.stderr);
    assert!(world_log.contains("agent rejoined"), "{world_log}");
}

/// The whole fleet killed at 10 s and restarted at 13 s: the world waits for the restarted
/// agents, which are back from the next step, resumed from their checkpoints: what was
/// explored and identified at the kill is still known, and the sets grew only by the motion
/// since (far from the whole region a fresh start would give).
#[test]
fn a_fleet_killed_whole_resumes_from_its_checkpoints() {
    let t = TestRun::new("fleet-restart");
    let file = t.write("scenario.toml", &scenario(20.0, 2));
    let out_dir = t.dir.join("out");
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["run", "--strict", "--run-id", t.run.as_str(), "--scenario"])
        .arg(&file)
        .arg("--out")
        .arg(&out_dir);
    for uav in 0..2 {
        cmd.args(["--fault", &format!("kill:{uav}@10")]);
        cmd.args(["--fault", &format!("restart:{uav}@13")]);
    }
    let out = finish(ChildGuard::spawn(&mut cmd), "fleet run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    wait_until(
        "the run's processes to exit",
        Duration::from_secs(10),
        || processes_mentioning(t.run.as_str()).is_empty(),
    );
    assert!(t.ipc_files().is_empty(), "files left: {:?}", t.ipc_files());

    let csv = std::fs::read_to_string(out_dir.join("timeseries.csv")).expect("timeseries");
    let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let rows: Vec<Vec<String>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    let at = |step: usize, name: &str| -> f64 {
        rows[step][col(name)]
            .parse()
            .unwrap_or_else(|_| panic!("{name} at step {step}: {:?}", rows[step]))
    };
    // Killed at step 20 (10 s), restarted at step 26 (13 s): both back at step 27.
    let (killed, back) = (20, 27);
    assert_eq!(
        at(back, "estimates"),
        2.0,
        "not back at once: {:?}",
        rows[back]
    );
    assert_eq!(at(back - 2, "estimates"), 0.0, "{:?}", rows[back - 2]);
    assert!(
        at(back, "explored") >= at(killed, "explored"),
        "explored ground lost"
    );
    assert!(
        at(back, "identified") >= at(killed, "identified"),
        "identified targets lost"
    );
    // X̄ grew by seven steps of motion only, far from the whole region of a fresh start.
    assert!(
        at(back, "ua") < 0.9,
        "the sets restarted from the region: {:?}",
        rows[back]
    );

    let summary: Value = serde_json::from_str(
        &std::fs::read_to_string(out_dir.join("summary.json")).expect("summary"),
    )
    .expect("summary.json is JSON");
    assert_eq!(summary["violations"], 0, "{summary}");
    for uav in 0..2 {
        let log = std::fs::read_to_string(out_dir.join(format!("logs/agent-{uav}.log")))
            .expect("agent log");
        let r = report_in(&log, "agent log");
        let resumed = r["resumed_from_step"]
            .as_u64()
            .expect("resumed from a checkpoint");
        // The last checkpoint before the kill: agents save one at every fourth step.
        assert!([16, 20].contains(&resumed), "{r}");
        assert_eq!(r["end"], "EndOfRun", "{r}");
    }
}

/// A checkpoint that is corrupt or another run's is refused with a clear log line; the agent
/// starts fresh and runs.
#[test]
fn a_corrupt_or_foreign_checkpoint_is_refused_and_the_agent_starts_fresh() {
    let t = TestRun::new("bad-ckpt");
    let file = t.write("scenario.toml", &scenario(2.0, 1));
    let dir = t.dir.join("checkpoints");
    std::fs::create_dir_all(&dir).expect("checkpoint dir");
    std::fs::write(dir.join("agent-0.ckpt"), b"SFCKPT02 and then garbage").expect("write");
    let dir_arg = dir.to_str().expect("utf-8 path");
    let world = process("world-server", &t, &file, &["--agents", "0"]);
    let agent = process(
        "uav-agent",
        &t,
        &file,
        &["--id", "0", "--checkpoint-dir", dir_arg],
    );
    let out = finish(agent, "agent");
    assert!(finish(world, "world-server").status.success());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r = report(&out);
    let why = r["checkpoint_refused"].as_str().expect("refused");
    assert!(why.contains("corrupt"), "{r}");
    assert_eq!(r["frames"], 4, "{r}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("checkpoint refused"));
    // It wrote its own checkpoint over the bad one.
    assert!(r["checkpoints"].as_u64().expect("checkpoints") > 0, "{r}");
}
