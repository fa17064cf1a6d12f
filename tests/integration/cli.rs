//! Bad input to the binaries: exit code 2, a message that names the problem, never a panic.

use std::process::{Command, Output};

use tests::{TestRun, binary, run_to_end};

fn assert_refused(out: &Output, needle: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
    assert!(
        stderr.contains(needle),
        "stderr does not name {needle:?}: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

fn world(t: &TestRun) -> Command {
    let mut cmd = Command::new(binary("world-server"));
    cmd.arg("--run-id").arg(t.run.as_str());
    cmd
}

fn fleet_render(t: &TestRun) -> Command {
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["render", "--uav", "0", "--time", "0"])
        .arg("--out")
        .arg(t.dir.join("out"));
    cmd
}

#[test]
fn unknown_scenario_key_is_named() {
    let t = TestRun::new("cli-key");
    let file = t.write("bad.toml", "[guidance]\nkapa = 1.0\n");
    assert_refused(
        &run_to_end(world(&t).arg("--scenario").arg(&file)),
        "guidance.kapa",
    );
    assert_refused(
        &run_to_end(fleet_render(&t).arg("--scenario").arg(&file)),
        "guidance.kapa",
    );
}

#[test]
fn out_of_range_override_is_named() {
    let t = TestRun::new("cli-range");
    let set = ["--set", "targets.max_speed_mps=-3"];
    assert_refused(&run_to_end(world(&t).args(set)), "targets.max_speed_mps");
    assert_refused(
        &run_to_end(fleet_render(&t).args(set)),
        "targets.max_speed_mps",
    );
}

#[test]
fn unreadable_or_invalid_scenario_file_is_refused() {
    let t = TestRun::new("cli-file");
    let missing = t.dir.join("missing.toml");
    assert_refused(
        &run_to_end(world(&t).arg("--scenario").arg(&missing)),
        "missing.toml",
    );
    let broken = t.write("broken.toml", "seed = = 1\n");
    assert_refused(
        &run_to_end(fleet_render(&t).arg("--scenario").arg(&broken)),
        "broken.toml",
    );
}

#[test]
fn unknown_flag_is_refused() {
    let t = TestRun::new("cli-flag");
    assert_refused(&run_to_end(world(&t).arg("--frobnicate")), "--frobnicate");
    assert_refused(
        &run_to_end(fleet_render(&t).arg("--frobnicate")),
        "--frobnicate",
    );
}

#[test]
fn render_arguments_outside_the_scenario_are_refused() {
    let t = TestRun::new("cli-render");
    let out = t.dir.join("out");
    let mut cmd = Command::new(binary("fleet"));
    cmd.args([
        "render",
        "--uav",
        "9",
        "--time",
        "0",
        "--set",
        "uavs.count=2",
    ])
    .arg("--out")
    .arg(&out);
    assert_refused(&run_to_end(&mut cmd), "--uav");
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["render", "--uav", "0", "--time", "1e6"])
        .arg("--out")
        .arg(&out);
    assert_refused(&run_to_end(&mut cmd), "--time");
    assert_refused(&run_to_end(world(&t).args(["--agents", "7"])), "--agents");
}
